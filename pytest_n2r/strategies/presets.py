"""The N2R-Tester paper's transforms τ1–τ6, scale-normalized: translations in reference lengths (the
median viewing distance), look-at compensated so the subject stays in view, plus extra rotation
(degrees). Each is a :class:`~pytest_n2r.strategies.pose_strategies.PoseChangeFamily` (what ``n2r study``
samples) and a strategy (what ``@metamorphic(transform="tau3")`` draws)."""

from __future__ import annotations

from hypothesis import strategies as st

from .pose_change import PoseChange
from .pose_strategies import PoseChangeFamily

__all__ = ["PRESET_FAMILIES", "PRESETS", "tau1", "tau2", "tau3", "tau4", "tau5", "tau6"]

#: The families τ1–τ6 by name.
PRESET_FAMILIES: dict[str, PoseChangeFamily] = {
    "tau1": PoseChangeFamily.of(x=0.05, yaw=3.0, look_at=True),  # small x translation + small yaw
    "tau2": PoseChangeFamily.of(y=0.05, pitch=3.0, look_at=True),  # small y translation + small pitch
    "tau3": PoseChangeFamily.of(x=0.25, yaw=10.0, look_at=True),  # large x translation + large yaw
    "tau4": PoseChangeFamily.of(y=0.25, pitch=10.0, look_at=True),  # large y translation + large pitch
    "tau5": PoseChangeFamily.of(x=0.05, yaw=3.0, roll=5.0, look_at=True),  # τ1 + small roll
    "tau6": PoseChangeFamily.of(y=0.05, pitch=3.0, roll=5.0, look_at=True),  # τ2 + small roll
}

#: Their strategies by name, for ``@metamorphic(..., transform="tau3")``.
PRESETS: dict[str, st.SearchStrategy[PoseChange]] = {name: f.strategy() for name, f in PRESET_FAMILIES.items()}

tau1, tau2, tau3, tau4, tau5, tau6 = (PRESETS[f"tau{i}"] for i in range(1, 7))
