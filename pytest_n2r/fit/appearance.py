"""The per-photo appearance correction of a fit (``fit(..., appearance=True)``): exposure and white balance."""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import torch

from ..data.capture import Capture
from ..data.exposure import ExposureSpread, measure_exposure
from ..errors import InvalidArgument

__all__ = ["APPEARANCE_LR", "Appearance", "APPEARANCE_JUMP", "needs_appearance", "measured_appearance",
           "decide_appearance"]


#: Adam learning rate of the per-photo log colour gains (``appearance=True``).
APPEARANCE_LR = 0.01


class Appearance:
    """Per training photo, a colour gain per channel (exposure and white balance) that multiplies the field's
    colour in the loss only. The gains are ``exp(a - mean(a))`` over the photos, so the field keeps the
    capture's average exposure and white balance, which is what it renders at every pose (a render never
    applies a gain: the correction cannot leak into new views)."""

    def __init__(self, names: Sequence[str], device: torch.device):
        self.names = list(names)
        self.log_gain = torch.zeros(len(self.names), 3, device=device, requires_grad=True)
        self.adam = torch.optim.Adam([self.log_gain], lr=APPEARANCE_LR)

    def gains(self) -> torch.Tensor:
        return torch.exp(self.log_gain - self.log_gain.mean(dim=0, keepdim=True))

    def step(self, lr_scale: float) -> None:
        for group in self.adam.param_groups:
            group["lr"] = APPEARANCE_LR * lr_scale
        self.adam.step()
        self.adam.zero_grad(set_to_none=True)

    def report(self) -> dict:
        gains = self.gains().detach().cpu().numpy()
        return {name: [round(float(x), 4) for x in g] for name, g in zip(self.names, gains)}


#: How much neighbouring photos' colours may differ (``jump`` of :mod:`pytest_n2r.data.exposure` with its default
#: 4 neighbours a photo, natural log) before ``appearance="auto"`` fits the correction. See
#: :func:`needs_appearance` for the measurements behind it.
APPEARANCE_JUMP = 0.05


def needs_appearance(exposure: ExposureSpread) -> bool:
    """Whether a capture's photos differ enough from one to the next for the per-photo correction: their
    measured ``jump`` exceeds :data:`APPEARANCE_JUMP`. A capture that could not be measured (no two photos
    linked by matches) gets no correction.

    Measured (6 December 2026, docs/scene-field-log.md "Exposure measured from the photos"; ``python
    benchmarks/exposure.py``, ``python benchmarks/phone_capture.py --exposure-stops S --white-balance W``) on the
    phone captures' held-out and moved poses against the exact scene (the only scores they have: for this
    threshold they are not untouched) and on the fox's validation views, not its held-out ones. The demo scenes'
    phone captures jump 0.003-0.005 with exposure and white balance held, 0.011-0.012 with ±0.05 stops and ±1 %,
    0.026-0.033 with ±0.15 stops and ±3 % (there the correction moved held-out PSNR against the exact scene by
    −0.22 dB on the wall and +0.20 on the object: a wash), 0.079-0.099 with ±0.5 stops and ±8 % (+0.45 dB on the
    wall with the 48³ first grid of the time, +1.46 dB on the object with today's 32³). The fox, a handheld video
    whose colour drifts along the path (spread 0.15), jumps 0.019; there the correction cost 0.49 dB on the
    validation views (4 December): its fit keeps most of a drift in the view-dependent colour, which follows a
    drift but not a jump. Those phone captures had their portrait photos on their side (the generator then rolled
    the camera); with them upright (18:26 UTC) the jumps are 0.003-0.005, 0.011-0.013, 0.026-0.033 and 0.073-0.099,
    and at ±0.5 stops the correction gained +0.29 dB held out on the wall, +2.02 dB on the object: the threshold
    still falls between the wash and the gain.
    """
    jump = exposure.jump
    return jump is not None and jump > APPEARANCE_JUMP


def measured_appearance(capture: Capture) -> dict:
    """Measure the training photos' exposure (:func:`~pytest_n2r.data.exposure.measure_exposure`) and decide
    the correction: the record a fit's ``report["exposure"]`` holds, with ``"appearance"`` the decision and
    ``"threshold"`` :data:`APPEARANCE_JUMP` and ``"seconds"`` the measurement's wall-clock time."""
    start = time.perf_counter()
    exposure = measure_exposure([v for v in capture.train_views if v.image is not None])
    return {**exposure.summary(), "threshold": APPEARANCE_JUMP, "appearance": needs_appearance(exposure),
            "seconds": round(time.perf_counter() - start, 2)}


def decide_appearance(capture: Capture, appearance: bool | str) -> tuple[bool, dict | None]:
    """``fit``'s ``appearance`` argument resolved: ``(fit the gains?, the measurement or None)``; ``"auto"``
    measures the capture (:func:`measured_appearance`), ``True`` and ``False`` are taken as given."""
    if isinstance(appearance, (bool, np.bool_)):
        return bool(appearance), None
    if not (isinstance(appearance, str) and appearance == "auto"):
        raise InvalidArgument(f"appearance={appearance!r}: expected True, False or 'auto'")
    exposure = measured_appearance(capture)
    return exposure["appearance"], exposure
