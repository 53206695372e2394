"""The N2R-Tester paper's transforms τ1–τ6 as strategies, scale-normalized: translations in reference
lengths (the median viewing distance), look-at compensated so the subject stays in view, plus extra
rotation (degrees)."""

from __future__ import annotations

from hypothesis import strategies as st

from ..geometry import Transform
from .pose_strategies import transforms

__all__ = ["PRESETS", "tau1", "tau2", "tau3", "tau4", "tau5", "tau6"]

tau1 = transforms(x=0.05, yaw=3.0, look_at=True)  #: small x translation + small yaw
tau2 = transforms(y=0.05, pitch=3.0, look_at=True)  #: small y translation + small pitch
tau3 = transforms(x=0.25, yaw=10.0, look_at=True)  #: large x translation + large yaw
tau4 = transforms(y=0.25, pitch=10.0, look_at=True)  #: large y translation + large pitch
tau5 = transforms(x=0.05, yaw=3.0, roll=5.0, look_at=True)  #: τ1 + small roll
tau6 = transforms(y=0.05, pitch=3.0, roll=5.0, look_at=True)  #: τ2 + small roll

#: Presets by name, for ``@metamorphic(..., transform="tau3")``.
PRESETS: dict[str, st.SearchStrategy[Transform]] = {
    "tau1": tau1, "tau2": tau2, "tau3": tau3, "tau4": tau4, "tau5": tau5, "tau6": tau6,
}
