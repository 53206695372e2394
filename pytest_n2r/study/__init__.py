"""``n2r study``: characterize SUTs on scenes the way the N2R-Tester paper did (RQ1–RQ3)."""

from .output import write_study
from .run import StudyConfig, StudyResult, run_study
from .suts import SUT, resolve_sut

__all__ = ["StudyConfig", "StudyResult", "run_study", "write_study", "SUT", "resolve_sut"]
