"""What a time budget chooses for a fit: the colour's spherical-harmonics degree, the grid ladder and how fine
its last grid follows the photos.

A field's colour depends on the viewing direction through spherical harmonics (``FieldConfig.sh_degree``).
Degree 2 fitted the fox better per step (1.1–1.3 dB at 1 000–1 500 steps), but its step costs 1.85× a degree-1
step. On 2 CPU cores the two tied at 10 minutes on the fox; at twice the budgets first screened (the fox's 20
minutes, the 160 px wall phone capture's 6) degree 1 gained nothing while degree 2 won on both. The threshold,
:data:`LONG_BUDGET_S`, is the fox's 20 minutes: the shortest budget at which degree 2 was measured to win on the
fox; the wall's smaller capture won already at 6. At 15 minutes (the wall's 4.5) the long recipe below won the
fox's validation views by a seed's spread (28.15 against 27.89 dB) but not the wall's (+0.10 dB, ORB 0.553
against 0.707, held out −0.34 dB), so the threshold stays at 20 (docs/scene-field-log.md, "Fifteen minutes").
The rule does not look at the capture's size or the device; its evidence is from a 2-core CPU
(docs/scene-field-log.md, "A longer fit").

The same budget trains a last grid of 256³ instead of 224³ (:data:`LONG_BUDGET_RESOLUTIONS`). With degree 2,
at the same budgets, it fitted the validation views of both scenes better than 224³ (the fox +0.13 dB, the
wall's capture +0.22 dB side by side, +0.06 against an earlier run that took more steps) and then the fox's
held-out views (29.03 against 28.86 dB, every detector higher), while an hour of degree 2 on 224³ scored no
better held out than 20 minutes, nor on its fitted views: more steps on that grid bought nothing
(docs/scene-field-log.md, "An hour on the fox"). A capture finer than the 256³ voxel still gets its finer grid
for the end of the fit (:func:`~pytest_n2r.fit.detail.detailed_config`). It starts on 32³, as the default
ladder does: a 48³ start grows floaters of sky on captures that orbit their subject, with this ladder too (the
object's phone capture in 3-minute fits: 25.77 dB held out started on 32³, 18.41 on 48³; docs/scene-field-log.md,
"A 32³ start"). Every fox figure in this docstring was measured started on 48³; with 32³ the fox's 20 minutes scored
29.26 dB held out in 10 352 steps against 29.03 in 10 371 (docs/scene-field-log.md, "The twins' whole ladder").

From 30 minutes (:data:`FINE_BUDGET_S`) that finer grid is sized for 3.5 of the photos' pixels a voxel where the
cameras look closest, not 6 (:data:`FINE_BUDGET_PIXELS_PER_VOXEL`): on the fox, whose 256³ voxel spans 4.4 pixels,
the last 30 % of the fit runs on 384³. At 40 minutes on 256³ the fox's validation views scored 28.57 dB against
20 minutes' 28.48 (the time bought nothing on that grid), with the 384³ end 28.99 dB, SSIM +0.020, ORB +0.049,
SIFT +0.022; the wall's 320 px phone capture at 12 minutes (5.15 pixels a voxel at 256³) 26.43 against 26.29 dB,
SSIM +0.012. Held out, the fox scored 29.52 dB, ORB 0.561, SIFT 0.614, AKAZE 0.765 against the 20-minute
recipe's 29.03 / 0.542 / 0.592 / 0.732. Such a field renders 1.4–1.7× slower than the 256³ one
(docs/scene-field-log.md, "Forty minutes"). An hour of the same recipe scored 29.33 dB, ORB 0.560, SIFT 0.611, AKAZE
0.764 held out: nothing over forty minutes (docs/scene-field-log.md, "An hour with the forty-minute recipe").
Every figure with a finer end above carries a handicap found later and mended: the 256³ grid before it was not the
last, kept its thin haze and stepped at a fifth of its speed. Pruned as the last grid is, the finer end at 30 minutes
won the validation views of both scenes over the 30-minute recipe without it: the fox 29.00 against 28.48 dB, ORB
+0.039, SIFT +0.032, AKAZE +0.038 (docs/scene-field-log.md, "A finer end at thirty minutes"); the wall's 320 px
capture at 9 minutes 25.78 against 25.51 dB, ORB +0.027, SIFT +0.059, AKAZE +0.075, side by side. So the threshold
is 30 minutes, the budget measured; between 20 and 30 nothing was (docs/scene-field-log.md, "The finer end from
thirty minutes"). With the mend an hour scored 29.60 dB held out, still rising at its end (docs/scene-field-log.md,
"An hour with the haze mended").

Convention
----------
Budgets are seconds of training (a fit's ``time_budget_s``), not counting ingestion, evaluation or a fresh
installation's compile of the training kernels (:mod:`.compile_clock`). Only a fit
whose length is a time budget alone is changed: one given ``max_steps`` (with or without a budget) keeps its
config, since its caller chose a length in steps, where degree 2 and a finer grid are a different trade (better
per step, dearer per second). A setting its caller gave is kept, and so is one that is not the default.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from numbers import Real
from typing import Any

from ..errors import InvalidArgument, InvalidType
from ..field.config import FieldConfig

__all__ = ["FINE_BUDGET_PIXELS_PER_VOXEL", "FINE_BUDGET_S", "LONG_BUDGET_RESOLUTIONS", "LONG_BUDGET_S",
           "LONG_BUDGET_SH_DEGREE", "budget_config", "check_time_budget"]

#: Training seconds from which a fit takes :data:`LONG_BUDGET_SH_DEGREE`: 20 minutes.
LONG_BUDGET_S = 1200.0
#: The spherical-harmonics degree of a long fit.
LONG_BUDGET_SH_DEGREE = 2
#: The grid ladder of a long fit (vertices per axis), switched at the default ``stage_fractions``.
LONG_BUDGET_RESOLUTIONS = (32, 96, 256)
#: Training seconds from which a fit's finer grid for the end is sized for :data:`FINE_BUDGET_PIXELS_PER_VOXEL`:
#: 30 minutes.
FINE_BUDGET_S = 1800.0
#: The pixels a voxel (where the cameras look closest) that a fit of :data:`FINE_BUDGET_S` or more sizes its
#: finer grid for (``FieldConfig.max_pixels_per_voxel``; the default is 6).
FINE_BUDGET_PIXELS_PER_VOXEL = 3.5


def check_time_budget(time_budget_s: Any) -> float | None:
    """``time_budget_s`` as seconds (a finite number > 0) or ``None``; raise naming it otherwise.

    >>> check_time_budget(600), check_time_budget(None)
    (600.0, None)
    """
    if time_budget_s is None:
        return None
    expected = "expected a finite number of seconds > 0, or None"
    if isinstance(time_budget_s, bool) or not isinstance(time_budget_s, Real):
        raise InvalidType(f"time_budget_s={time_budget_s!r}: {expected}, not {type(time_budget_s).__name__}")
    seconds = float(time_budget_s)
    if not (math.isfinite(seconds) and seconds > 0):
        raise InvalidArgument(f"time_budget_s={time_budget_s!r}: {expected}")
    return seconds


def budget_config(config: FieldConfig, time_budget_s: float | None, *, max_steps: int | None = None,
                  fixed: Collection[str] = ()) -> FieldConfig:
    """``config`` with what a training budget of ``time_budget_s`` seconds chooses: from :data:`LONG_BUDGET_S`
    on, where no ``max_steps`` is given, the spherical-harmonics degree :data:`LONG_BUDGET_SH_DEGREE` and the
    grids :data:`LONG_BUDGET_RESOLUTIONS`, and from :data:`FINE_BUDGET_S` on ``max_pixels_per_voxel`` =
    :data:`FINE_BUDGET_PIXELS_PER_VOXEL`, each where ``config`` has the default and its caller did not give
    it (``fixed``: the names of the settings given; ``resolutions`` or ``stage_fractions`` fixes the ladder);
    ``config`` itself otherwise.

    >>> long = budget_config(FieldConfig(), 1200.0)
    >>> long.sh_degree, long.resolutions, long.max_pixels_per_voxel
    (2, (32, 96, 256), 6.0)
    >>> budget_config(FieldConfig(), 1800.0).max_pixels_per_voxel
    3.5
    >>> budget_config(FieldConfig(), 600.0) == budget_config(FieldConfig(), None) == FieldConfig()
    True
    >>> budget_config(FieldConfig(), 1800.0, max_steps=5000) == FieldConfig()
    True
    >>> given = budget_config(FieldConfig(), 1200.0, fixed={"sh_degree"})
    >>> given.sh_degree, given.resolutions
    (1, (32, 96, 256))
    >>> chosen = FieldConfig(sh_degree=0, resolutions=(32, 64), stage_fractions=(0.5,))
    >>> budget_config(chosen, 1200.0) == chosen
    True
    """
    time_budget_s = check_time_budget(time_budget_s)
    if time_budget_s is None or time_budget_s < LONG_BUDGET_S or max_steps is not None:
        return config
    default = FieldConfig()
    if "sh_degree" not in fixed and config.sh_degree == default.sh_degree:
        config = config.replace(sh_degree=LONG_BUDGET_SH_DEGREE)
    ladder = (config.resolutions, config.stage_fractions)
    if not {"resolutions", "stage_fractions"} & set(fixed) and ladder == (default.resolutions, default.stage_fractions):
        config = config.replace(resolutions=LONG_BUDGET_RESOLUTIONS)
    if (time_budget_s >= FINE_BUDGET_S and "max_pixels_per_voxel" not in fixed
            and config.max_pixels_per_voxel == default.max_pixels_per_voxel):
        config = config.replace(max_pixels_per_voxel=FINE_BUDGET_PIXELS_PER_VOXEL)
    return config
