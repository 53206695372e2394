"""How to run relations: the run-wide defaults a relation's own values override."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import defaults
from ..render.size import RenderSize

__all__ = ["RunSettings"]


@dataclass(frozen=True)
class RunSettings:
    """How to run relations: defaults for ``examples`` and ``size`` (a relation's own values win),
    ``derandomize`` (same examples every run: for CI), ``timeout`` seconds per render / SUT call
    (``None``: no limit), where failure pictures go (``artifacts``; ``None``: nowhere), the Hypothesis
    example ``database`` (``"default"``: Hypothesis's own setting) and whether a failure is shrunk to its smallest
    transform (``shrink``; ``False``: the worst failing example of the search is reported as drawn, as for a test
    expected to fail, where the shrink would only cost time)."""

    examples: int = defaults.EXAMPLES
    size: RenderSize | None = None
    derandomize: bool = False
    timeout: float | None = defaults.TIMEOUT_S
    artifacts: Path | None = None
    database: Any = "default"
    shrink: bool = True
