"""Where a fit's training time goes: milliseconds per step by grid and phase (``FitResult.report["step_ms"]``)."""

from __future__ import annotations

import time

import numpy as np

from .compile_clock import CompileClock

__all__ = ["StepPhases"]


class StepPhases:
    """Training time by grid and phase of a step, summed over the fit: where a step's cost goes. Both the wall
    time and the process's CPU time (all threads; on one thread it is the work done, whatever else the machine
    runs). ``refine`` is charged to the grid refined to, ``prune`` to the grid pruned. The kernels' compiles that
    ``compiles`` counts are not training: their seconds are taken off both (a compile runs on one thread)."""

    NAMES = ("rays", "march", "corners", "forward", "backward", "update", "prune", "refine")

    def __init__(self, compiles: CompileClock | None = None):
        self.seconds: dict[int, np.ndarray] = {}  # per grid: (phase, [wall, cpu])
        self.steps: dict[int, int] = {}
        self.resolution = 0
        self.compiles = compiles
        self._last = self._now()

    def _now(self) -> tuple[float, float]:
        compiled = self.compiles.seconds if self.compiles is not None else 0.0
        return time.perf_counter() - compiled, time.process_time() - compiled

    def start(self, resolution: int) -> None:
        self.resolution = resolution
        self.seconds.setdefault(resolution, np.zeros((len(self.NAMES), 2)))
        self.steps.setdefault(resolution, 0)
        self._last = self._now()

    def lap(self, name: str) -> None:
        """Charge the time since the last ``start`` or ``lap`` to phase ``name`` of the current grid."""
        now = self._now()
        self.seconds[self.resolution][self.NAMES.index(name)] += (now[0] - self._last[0], now[1] - self._last[1])
        self._last = now

    def report(self) -> dict:
        """Per grid (and ``"all"``): its steps, and the wall and CPU milliseconds per step of each phase."""
        out = {}
        grids = [(str(res), self.steps[res], s) for res, s in self.seconds.items()]
        if grids:
            grids.append(("all", sum(self.steps.values()), sum(s for _, _, s in grids)))
        for name, steps, seconds in grids:
            ms = 1e3 * seconds / max(steps, 1)
            out[name] = {"steps": steps, **{kind: {p: round(float(ms[k, j]), 3) for k, p in enumerate(self.NAMES)}
                                           for j, kind in enumerate(("wall_ms", "cpu_ms"))}}
        return out
