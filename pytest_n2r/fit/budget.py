"""What a time budget chooses for a fit: the colour's spherical-harmonics degree.

A field's colour depends on the viewing direction through spherical harmonics (``FieldConfig.sh_degree``).
Degree 2 fits better per step, but its step costs about twice a degree-1 step. On 2 CPU cores the two tie at
the default 10 minutes on the fox; at twice the budget degree 1 stops gaining (the fox's validation views
27.94 → 27.61 dB from 10 to 20 minutes, the wall's phone capture 27.09 → 26.93 dB from 3 to 6) while degree 2
keeps gaining and wins on both (28.35 against 27.61 dB, 27.19 against 26.93 dB): docs/scene-field-log.md, "A
longer fit". So a budget of :data:`LONG_BUDGET_S` or more, which both measurements reach, takes degree 2 unless
the caller fixed the degree; a shorter one keeps the default.

Convention
    Budgets are seconds of training (a fit's ``time_budget_s``), not counting ingestion or evaluation. A fit
    without a time budget (``max_steps`` alone) keeps its config: its length is given in steps, and at equal
    steps degree 2 always fits better and always costs more, a trade its caller has already chosen.
"""

from __future__ import annotations

import math
from collections.abc import Collection

from ..errors import InvalidArgument
from ..field.config import FieldConfig

__all__ = ["LONG_BUDGET_S", "LONG_BUDGET_SH_DEGREE", "budget_config"]

#: Training seconds from which a fit takes :data:`LONG_BUDGET_SH_DEGREE` (20 minutes: the shortest budget at
#: which degree 2 was measured to win on both scenes; at 10 minutes it tied on the fox).
LONG_BUDGET_S = 1200.0
#: The spherical-harmonics degree of a long fit.
LONG_BUDGET_SH_DEGREE = 2


def budget_config(config: FieldConfig, time_budget_s: float | None, *, fixed: Collection[str] = ()) -> FieldConfig:
    """``config`` with the spherical-harmonics degree a training budget of ``time_budget_s`` seconds chooses:
    :data:`LONG_BUDGET_SH_DEGREE` from :data:`LONG_BUDGET_S` on, where ``config`` has the default degree and
    ``"sh_degree"`` is not among ``fixed`` (the settings its caller gave); ``config`` itself otherwise.

    >>> budget_config(FieldConfig(), 1800.0).sh_degree
    2
    >>> budget_config(FieldConfig(), 600.0).sh_degree, budget_config(FieldConfig(), None).sh_degree
    (1, 1)
    >>> budget_config(FieldConfig(), 1800.0, fixed={"sh_degree"}).sh_degree
    1
    >>> budget_config(FieldConfig(sh_degree=0), 1800.0).sh_degree
    0
    """
    if time_budget_s is not None and not (math.isfinite(time_budget_s) and time_budget_s > 0):
        raise InvalidArgument(f"time_budget_s={time_budget_s!r}: expected seconds > 0, or None")
    if (time_budget_s is None or time_budget_s < LONG_BUDGET_S or "sh_degree" in fixed
            or config.sh_degree != FieldConfig().sh_degree):
        return config
    return config.replace(sh_degree=LONG_BUDGET_SH_DEGREE)
