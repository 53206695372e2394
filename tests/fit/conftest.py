"""A small exact capture and one short fit of it, shared by the fit tests of this session."""

from __future__ import annotations

import pytest

from pytest_n2r.data.capture import Capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.fit import FitResult

#: Two small grids, small batches and an initial opacity the first prune keeps (0.01 per sample).
#: Measured on the 48×27 capture: 80 steps take about 1 s and reach 21.2 dB held-out PSNR at the default learning
#: rates (0.4 / 0.2 since 2 December 2026; 18.2 dB at the earlier 0.2 / 0.1, and 18.6 dB at those without the
#: total-variation priors, which pull harder on grids this small; with a random background a field needs more steps
#: to become opaque: 14.5 dB after 40 steps, 16.8 dB with a black one, both at the earlier rates).
SHORT_CONFIG = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,), batch_rays=256, prune_every=20,
                           alpha_init=0.01)
SHORT_STEPS = 80


@pytest.fixture(scope="session")
def capture48() -> Capture:
    """The demo ``object`` scene captured exactly at 48×27 (48 views, 6 held out; about 1 s)."""
    from pytest_n2r.demo.rendered_capture import capture_scene
    from pytest_n2r.demo.scenes import build_scene

    return capture_scene(build_scene("object"), size=(48, 27))


@pytest.fixture(scope="session")
def short_fit(capture48: Capture) -> FitResult:
    """:data:`SHORT_CONFIG` fitted for :data:`SHORT_STEPS` steps on the CPU."""
    from pytest_n2r.fit import fit

    return fit(capture48, SHORT_CONFIG, max_steps=SHORT_STEPS, device="cpu")
