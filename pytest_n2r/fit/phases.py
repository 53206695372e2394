"""Where a fit's training time goes: milliseconds per step by grid and phase (``FitResult.report["step_ms"]``); and
what those measured steps let a time budget start (:func:`growth_fits`, :func:`step_fits`).

A time budget is checked before each step, so one step or one grid's growth can run past it: on a 64×36 capture
on a loaded machine, 20 s grew an unpruned 96³ grid to a 100 %-occupied 224³ one whose growth and single step
took 36 s (44.5 s of training in all, 3.2 GB, a 102 MiB scene file). A fit paced by its budget therefore grows a
grid only once that grid has been pruned and where growing and one step on the finer grid are predicted to fit in
what the budget has left, and starts no step predicted to end more than :data:`BUDGET_OVERRUN` past it.
"""

from __future__ import annotations

import time

import numpy as np

from .compile_clock import CompileClock

__all__ = ["BUDGET_OVERRUN", "StepPhases", "growth_fits", "step_fits"]

#: How far past its time budget a step may be predicted to end and still be started: a tenth of the budget (a
#: 10-minute fit's steps take 0.05–0.4 s on 2 cores, so only a step a hundred times slower meets it).
BUDGET_OVERRUN = 0.1


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

    def step_seconds(self, resolution: int) -> float | None:
        """The mean wall seconds of a step on grid ``resolution`` so far, growth and pruning left out (None: none
        yet)."""
        steps = self.steps.get(resolution, 0)
        if not steps:
            return None
        skipped = [self.NAMES.index(name) for name in ("prune", "refine")]
        return float(np.delete(self.seconds[resolution][:, 0], skipped).sum()) / steps

    def may_grow(self, finer: int, left_s: float) -> bool:
        """Whether the current grid may grow to ``finer`` with ``left_s`` seconds left (:func:`growth_fits`)."""
        return growth_fits(self.step_seconds(self.resolution), self.resolution, finer, left_s)

    def may_step(self, left_s: float, budget_s: float) -> bool:
        """Whether a step on the current grid may start, ``left_s`` of ``budget_s`` seconds left (:func:`step_fits`)."""
        return step_fits(self.step_seconds(self.resolution), left_s, budget_s)

    def report(self) -> dict:
        """Per grid (and ``"all"``): its steps, and the wall and CPU milliseconds per step of each phase."""
        out = {}
        grids = [(str(res), self.steps[res], s) for res, s in self.seconds.items()]
        if grids:
            total = sum((s for _, _, s in grids), np.zeros((len(self.NAMES), 2)))
            grids.append(("all", sum(self.steps.values()), total))
        for name, steps, seconds in grids:
            ms = 1e3 * seconds / max(steps, 1)
            out[name] = {"steps": steps, **{kind: {p: round(float(ms[k, j]), 3) for k, p in enumerate(self.NAMES)}
                                           for j, kind in enumerate(("wall_ms", "cpu_ms"))}}
        return out


def growth_fits(step_s: float | None, resolution: int, finer: int, left_s: float) -> bool:
    """Whether growing grid ``resolution`` (a step on it took ``step_s``) to ``finer`` and one step there are
    predicted to fit in ``left_s`` seconds of budget. A step marches, gathers and updates at most the cells and rows
    of the grid, which grows by ``(finer / resolution)³`` with its occupied fraction kept; upsampling writes each row
    of the finer grid once, which took less than a step there (32³ → 96³ on a 64×36 capture: 0.43 s, a step 0.15 s,
    the bound 0.86 s; 96³ → 224³: 1.26 s, a step 1.0–1.3 s, the bound 1.8 s). Where no step was timed, it fits.

    >>> growth_fits(0.1, 96, 224, 390.0)  # a 10-minute fit at 35 %: 2.5 s predicted
    True
    >>> growth_fits(1.0, 96, 224, 13.0)  # an unpruned 96³ grid on a small budget: 25 s predicted
    False
    """
    return step_s is None or 2.0 * step_s * (finer / resolution) ** 3 <= left_s


def step_fits(step_s: float | None, left_s: float, budget_s: float) -> bool:
    """Whether a step that is predicted to take ``step_s`` (the mean on its grid; None: not timed yet) ends within
    :data:`BUDGET_OVERRUN` of ``budget_s`` when ``left_s`` of it is left.

    >>> step_fits(0.3, 0.1, 600.0), step_fits(30.0, 13.0, 20.0), step_fits(None, 0.1, 20.0)
    (True, False, True)
    """
    return step_s is None or step_s <= left_s + BUDGET_OVERRUN * budget_s
