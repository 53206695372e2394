"""The per-photo appearance correction (fit(..., appearance=True)): gains follow the photos' exposure and
never reach a render."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pytest_n2r.data.capture import Capture
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.fit import fit
from pytest_n2r.fit.appearance import APPEARANCE_JUMP
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


def test_auto_measures_the_exposure_of_the_training_photos_only(capture48, monkeypatch):
    """The held-out photos are the truth a fit is scored against: their colours must not decide how it is fitted."""
    from pytest_n2r.fit import appearance as appearance_module

    measured = []
    real = appearance_module.measure_exposure

    def spy(views, **kwargs):
        measured.append([v.name for v in views])
        return real(views, **kwargs)

    monkeypatch.setattr(appearance_module, "measure_exposure", spy)
    appearance_module.measured_appearance(capture48)
    train = [v.name for v in capture48.train_views if v.image is not None]
    others = sorted({name for names in measured for name in names} - set(train))
    assert measured == [train], (f"appearance='auto' measured {[len(names) for names in measured]} photos, expected "
                                 f"the {len(train)} training photos only; not training photos among them: {others}")


@pytest.mark.parametrize(("jump", "wanted"), [
    (None, False), (0.005, False), (0.012, False), (0.026, False), (0.033, False), (APPEARANCE_JUMP, False),
    (0.073, True), (0.079, True), (0.099, True)])
def test_auto_corrects_the_jumps_measured_to_gain_and_not_those_measured_to_wash(jump, wanted):
    """needs_appearance's docstring: 0.026-0.033 (±0.15 stops) was a wash, 0.073-0.099 (±0.5 stops) a gain; the
    threshold falls between them, and a jump equal to it does not exceed it."""
    from types import SimpleNamespace

    from pytest_n2r.fit.appearance import needs_appearance

    assert needs_appearance(SimpleNamespace(jump=jump)) is wanted, (
        f"a capture jumping {jump} was {'not ' if wanted else ''}given the correction (threshold {APPEARANCE_JUMP})")
