"""What a time budget chooses for a fit: the colour's spherical-harmonics degree.

A field's colour depends on the viewing direction through spherical harmonics (``FieldConfig.sh_degree``).
Degree 2 fitted the fox better per step (1.1–1.3 dB at 1 000–1 500 steps), but its step costs 1.85× a degree-1
step. On 2 CPU cores the two tied at 10 minutes on the fox; at twice the budgets first screened (the fox's 20
minutes, the 160 px wall phone capture's 6) degree 1 gained nothing while degree 2 won on both. The threshold,
:data:`LONG_BUDGET_S`, is the fox's 20 minutes: the shortest budget at which degree 2 was measured to win on the
fox; the wall's smaller capture won already at 6. The rule does not look at the capture's size or the device;
its evidence is from a 2-core CPU (docs/scene-field-log.md, "A longer fit").

Convention
----------
Budgets are seconds of training (a fit's ``time_budget_s``), not counting ingestion or evaluation. Only a fit
whose length is a time budget alone is changed: one given ``max_steps`` (with or without a budget) keeps its
config, since its caller chose a length in steps, where degree 2 is a different trade (better per step, dearer
per second).
"""

from __future__ import annotations

import math
from collections.abc import Collection

from ..errors import InvalidArgument
from ..field.config import FieldConfig

__all__ = ["LONG_BUDGET_S", "LONG_BUDGET_SH_DEGREE", "budget_config"]

#: Training seconds from which a fit takes :data:`LONG_BUDGET_SH_DEGREE`: 20 minutes.
LONG_BUDGET_S = 1200.0
#: The spherical-harmonics degree of a long fit.
LONG_BUDGET_SH_DEGREE = 2


def budget_config(config: FieldConfig, time_budget_s: float | None, *, max_steps: int | None = None,
                  fixed: Collection[str] = ()) -> FieldConfig:
    """``config`` with the spherical-harmonics degree a training budget of ``time_budget_s`` seconds chooses:
    :data:`LONG_BUDGET_SH_DEGREE` from :data:`LONG_BUDGET_S` on, where no ``max_steps`` is given, ``config``
    has the default degree and ``"sh_degree"`` is not among ``fixed`` (the settings its caller gave); ``config``
    itself otherwise.

    >>> budget_config(FieldConfig(), 1800.0).sh_degree
    2
    >>> budget_config(FieldConfig(), 600.0).sh_degree, budget_config(FieldConfig(), None).sh_degree
    (1, 1)
    >>> budget_config(FieldConfig(), 1800.0, max_steps=5000).sh_degree
    1
    >>> budget_config(FieldConfig(), 1800.0, fixed={"sh_degree"}).sh_degree
    1
    >>> budget_config(FieldConfig(sh_degree=0), 1800.0).sh_degree
    0
    """
    if time_budget_s is not None and not (math.isfinite(time_budget_s) and time_budget_s > 0):
        raise InvalidArgument(f"time_budget_s={time_budget_s!r}: expected a finite number of seconds > 0, or None")
    if (time_budget_s is None or time_budget_s < LONG_BUDGET_S or max_steps is not None or "sh_degree" in fixed
            or config.sh_degree != FieldConfig().sh_degree):
        return config
    return config.replace(sh_degree=LONG_BUDGET_SH_DEGREE)
