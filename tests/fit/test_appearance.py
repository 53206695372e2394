"""The per-photo appearance correction (fit(..., appearance=True)): gains follow the photos' exposure and
never reach a render."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pytest_n2r.data.capture import Capture
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.fit import fit
from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import FieldRenderer

from .conftest import SHORT_CONFIG

STEPS = 160


def _exposed(capture: Capture, gains: np.ndarray) -> Capture:
    """``capture`` with training photo ``k`` brightened by ``gains[k % len(gains)]`` (linear light); the
    held-out photos stay as they are (the truth a render is compared with)."""
    views, k = [], 0
    for v in capture.views:
        if v.split == "train":
            linear = (v.image / 255.0) ** 2.2 * gains[k % len(gains)]
            v = dataclasses.replace(v, image=(np.clip(linear, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8))
            k += 1
        views.append(v)
    return dataclasses.replace(capture, views=views)


def test_gains_follow_the_exposure_and_the_field_keeps_the_truth(capture48):
    exposures = np.array([0.55, 1.0, 1.6])  # about -0.9, 0, +0.7 stops, cycling over the training photos
    capture = _exposed(capture48, exposures)
    plain = fit(capture, SHORT_CONFIG, max_steps=STEPS, device="cpu")
    corrected = fit(capture, SHORT_CONFIG, max_steps=STEPS, device="cpu", appearance=True)

    per_channel = np.asarray(list(corrected.report["appearance"].values()))  # (photos, RGB), rounded to 1e-4
    assert per_channel.shape == (len(capture.train_views), 3) and "appearance" not in plain.report
    gains = per_channel.mean(axis=1)
    by_exposure = [gains[k::3].mean() for k in range(3)]
    assert by_exposure[0] < by_exposure[1] < by_exposure[2], f"gains do not follow the exposure: {by_exposure}"
    assert np.abs(np.log(per_channel).mean(axis=0)).max() < 1e-3, \
        "the gains are normalized per channel: the field keeps the capture's average exposure"

    heldout = capture.heldout_views  # untouched photos at poses never fitted

    def mean_psnr(field):
        renderer = FieldRenderer(field)
        return np.mean([psnr(v.image, renderer.render(v.c2w, v.camera, ("rgb",))["rgb"]) for v in heldout])

    assert mean_psnr(corrected.field) > mean_psnr(plain.field) + 0.3, (mean_psnr(corrected.field),
                                                                       mean_psnr(plain.field))


def test_appearance_off_changes_nothing(capture48, short_fit):
    """The default fit is the one every shipped scene was made with, bit for bit."""
    again = fit(capture48, SHORT_CONFIG, max_steps=80, device="cpu", appearance=False)
    assert all(np.array_equal(a, b) for a, b in zip(again.field.tensors().values(), short_fit.field.tensors().values()))


def test_auto_with_nothing_measured_is_the_plain_fit_bit_for_bit(capture48, short_fit):
    """``appearance="auto"`` on photos too small to match (48×27: no pair, nothing measured) is no evidence of a
    changing exposure: it decides "off", says why in the report and trains exactly what the default trains
    (measured captures: tests/data/test_exposure.py and n2r fit in tests/demo/test_phone_capture.py)."""
    auto = fit(capture48, SHORT_CONFIG, max_steps=80, device="cpu", appearance="auto")
    exposure = auto.report["exposure"]
    assert exposure["jump"] is None and exposure["pairs"] == 0, exposure
    assert exposure["appearance"] is False and "appearance" not in auto.report, exposure
    assert all(np.array_equal(a, b) for a, b in zip(auto.field.tensors().values(), short_fit.field.tensors().values()))


def test_appearance_takes_true_false_or_auto(capture48):
    with pytest.raises(InvalidArgument, match="appearance='yes': expected True, False or 'auto'"):
        fit(capture48, SHORT_CONFIG, max_steps=1, device="cpu", appearance="yes")
