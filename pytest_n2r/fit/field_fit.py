"""Fitting a scene field to a capture: coarse-to-fine sparse voxel optimization with empty-space skipping.

Each step takes ``batch_rays`` random pixels of the training views, marches their rays through the current occupancy
grid (only occupied cells are sampled), renders them differentiably and takes an Adam step on the grid rows those
samples touched. Every ``prune_every`` steps cells the field left (nearly) empty are dropped from the occupancy, so
training and rendering get faster as the field takes shape; at each stage the grid is refined. A non-finite loss stops
the fit with :class:`~pytest_n2r.errors.FitError` (the last checkpoint stays good).
"""

from __future__ import annotations

import math
import platform
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import Literal

import numba
import numpy as np
import torch
import torch.nn.functional as F

from .. import __version__
from ..data.capture import Capture, CapturedView
from ..errors import FitError, InvalidArgument
from ..field.config import FieldConfig
from ..field.device import resolve_device
from ..field.grid import SceneField
from ..field.lattice import grid_coords, lattice_position
from ..field.march import MarchGrid, march_compiled, march_dense
from ..field.query import ALPHA_MAX, composite, distinct_rows, distortion, interpolate, sh_basis, shade, trilinear
from ..field.space import SceneSpace
from .appearance import Appearance, decide_appearance
from .budget import check_time_budget
from .compile_clock import CompileClock
from .detail import capture_detail, detailed_config
from .evaluate import FIT_RENDER, evaluate_views, final_scores, mean_scores
from .free_memory import free_bytes
from .memory import GridMemoryLimit, choose_grid
from .optim import RowAdam
from .phases import StepPhases
from .prior import add_tv_gradient, tv_gradient, tv_neighbours
from .prune import pruned_occupancy, pruned_occupancy_dense
from .rays import TrainingRays, fit_views
from .train_kernels import Composite, RowIndex, lattice_positions, sample_corners, scatter_max

__all__ = ["fit", "fit_space", "FitResult"]


@dataclass
class FitResult:
    """A fitted field, the config it was fitted with, and the fit report (plain JSON-ready values)."""

    field: SceneField
    config: FieldConfig
    report: dict = dataclass_field(default_factory=dict)


def _versions() -> dict:
    return {"pytest_n2r": __version__, "torch": torch.__version__, "numba": numba.__version__,
            "numpy": np.__version__, "python": platform.python_version()}


def fit_space(capture: Capture, config: FieldConfig) -> SceneSpace:
    """The space a field of ``capture`` is fitted in: its unit cube holds the capture's bounds and every
    camera, its shell is ``config.shell`` thick."""
    centers = np.stack([v.c2w[:3, 3] for v in capture.views])
    return SceneSpace.around(capture.bounds, centers, shell=config.shell)


class _Trainer:
    def __init__(self, capture: Capture, config: FieldConfig, device: torch.device, appearance: bool = False,
                 haze_from: int | None = None, train: list[CapturedView] | None = None):
        train = fit_views(capture) if train is None else train  # fit() has checked them already
        self.config, self.device = config, device
        #: The first stage whose prunes drop thin haze (``final_prune_alpha``): the ladder's last grid, or the
        #: caller's last where a finer grid for the end was added (:func:`~pytest_n2r.fit.detail.detailed_config`).
        #: Kept with its haze, the fox's 256³ grid before a 384³ end stepped 1.1 against 5.9 times a second; pruned,
        #: the 30-minute fit's validation views gained 0.37 dB, the wall's capture 0.63 dB (docs/scene-field-log.md,
        #: "A finer end at thirty minutes").
        self.haze_from = len(config.resolutions) - 1 if haze_from is None else haze_from
        #: Compiled (numba) kernels on the CPU; the torch path on CUDA (tests also run it on the CPU).
        self.compiled = device.type == "cpu"
        self.space = fit_space(capture, config)
        self.rays = TrainingRays(train, self.space, device)
        self.appearance = Appearance([v.name for v in train], device) if appearance else None
        self.generator = torch.Generator().manual_seed(config.seed)
        # the field renders over the mean of the backgrounds its training rays are composited over
        background = (0.5, 0.5, 0.5) if config.random_background else (0.0, 0.0, 0.0)
        self.field = SceneField.empty(self.space, config.resolutions[0], config.sh_degree, config.alpha_init,
                                      config.step_ratio, device, background)
        self.stage = 0
        self.limits: list[dict] = []  # a report row for each grid memory kept the fit from (see refine)
        self.steps = 0
        #: numba's compiles during the training steps (a fresh installation's first fit): not training time
        self.compiles = CompileClock()
        self.phases = StepPhases(self.compiles)
        self._reset_optimizer()

    def _reset_optimizer(self) -> None:
        c = self.config
        width = self.field.values.shape[1]
        lrs = torch.tensor([c.lr_density] + [c.lr_color] * (width - 1))
        self.tv_weights = torch.tensor([c.tv_density] + [c.tv] * (width - 1), device=self.device)
        self.adam = RowAdam(self.field.values, lrs)
        self._index_rows()
        #: Whether the next prune should drop the rows no occupied cell uses (once per grid: see ``prune``).
        self.compact_pending = True
        self._rebuild_grid()
        self._reset_visibility()

    def _index_rows(self) -> None:
        self.row_index = RowIndex(self.field.values.shape[0]) if self.compiled else None
        #: The field's vertex → row map for the compiled kernels (empty: a dense field).
        self.row_map = self.field.kernel_rows()
        #: The flat vertex index of each row.
        self.flat_of_row = self.field.row_vertices()
        #: Each row's stored grid neighbours, for the compiled prior (see ``tv_neighbours``).
        self.tv_rows = tv_neighbours(self.flat_of_row, self.row_map, self.field.resolution) if self.compiled else None

    def _compact(self) -> None:
        """Keep only the rows of vertices an occupied cell uses, with their Adam moments (a grid upsampled from
        the last stores every vertex of its dilated occupancy: a sixth stay in use on the fox's 224³ grid)."""
        old, self.field = self.field, self.field.compact()
        self._index_rows()
        rows = old.vertex_rows(self.flat_of_row)
        del old  # the old values go before the moments are gathered
        self.adam.keep(rows, self.field.values)

    def _reset_visibility(self) -> None:
        #: The largest compositing weight of any training sample in each cell since the last prune (-1: no
        #: sample), flat over the occupancy grid.
        self.cell_weight = torch.full((self.field.occupancy.numel(),), -1.0, device=self.device)

    def _rebuild_grid(self) -> None:
        self.grid = MarchGrid(self.field.occupancy, self.space.shell, self.config.step_ratio, None, FIT_RENDER.far)

    def march(self, o: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The batch's occupied samples, packed: ``(ray_idx, t, offsets)`` (:mod:`pytest_n2r.field.march`)."""
        return (march_compiled if self.compiled else march_dense)(o, d, self.grid)

    def step(self, lr_scale: float) -> tuple[float, float]:
        """One optimization step; returns (loss, batch PSNR in dB)."""
        c, f, clock = self.config, self.field, self.phases
        clock.start(f.resolution)
        clock.steps[f.resolution] += 1
        pick = torch.randint(self.rays.n, (c.batch_rays,), generator=self.generator).to(self.device)
        o, d = self.rays.o(pick), self.rays.d[pick]
        target = self.rays.rgb[pick].float() / 255.0
        if c.random_background:
            background = torch.rand(c.batch_rays, 3, generator=self.generator).to(self.device)
        else:
            background = torch.zeros(3, device=self.device)
        clock.lap("rays")
        ray_idx, t, offsets = self.march(o, d)
        clock.lap("march")
        unit = d / d.norm(dim=-1, keepdim=True)
        n_samples = max(t.numel(), 1)
        g = self.grid
        if self.compiled:
            s = lattice_positions(o, d, t, ray_idx, g.step, g.shell_samples, g.far)
            assert self.row_index is not None  # built with the compiled kernels' tables (_index_rows)
            rows, corner_weights, cells = sample_corners(o.numpy(), d.numpy(), t.numpy(), ray_idx.numpy(),
                                                         self.space.shell, f.resolution, self.row_map)
            unique, inverse, weights = (torch.from_numpy(a) for a in (*self.row_index.unique(rows), corner_weights))
            sub = f.values[unique].requires_grad_(True)
            clock.lap("corners")
            rgb, alpha_sum, dist, sample_weight = Composite.apply(
                sub, inverse, weights, sh_basis(unit, f.sh_degree), offsets, s, g.step, f.density_shift,
                c.step_ratio, ALPHA_MAX, background)
            scatter_max(cells, sample_weight.numpy(), self.cell_weight.numpy())
        else:
            s = lattice_position(o, d, t, ray_idx, g.step, g.shell_samples, g.far)
            p = o[ray_idx] + t[:, None] * d[ray_idx]
            coords = grid_coords(p, self.space.shell, f.resolution)
            corners, weights = trilinear(coords, f.resolution)
            unique, inverse = distinct_rows(f.vertex_rows(corners))
            sub = f.values[unique].requires_grad_(True)
            clock.lap("corners")
            alpha, colors = shade(interpolate(sub, inverse, weights), sh_basis(unit[ray_idx], f.sh_degree),
                                  f.density_shift, c.step_ratio)
            out = composite(alpha, colors, t, ray_idx, offsets, o.shape[0], background)
            rgb = out["rgb"]
            n = f.resolution - 1
            cell = coords.detach().floor().to(torch.int64).clamp(0, n - 1)
            flat = (cell[:, 0] * n + cell[:, 1]) * n + cell[:, 2]
            self.cell_weight.scatter_reduce_(0, flat, out["weights"].detach(), reduce="amax")
            alpha_sum = alpha.clamp(max=ALPHA_MAX).sum()[None]
            dist = distortion(out["weights"], s, ray_idx, offsets, o.shape[0], g.step)
        if self.appearance is not None:
            rgb = rgb * self.appearance.gains()[self.rays.view[pick]]
        mse = F.mse_loss(rgb, target)
        loss = mse + c.sparsity * alpha_sum.sum() / n_samples + c.distortion * dist.mean()
        if not torch.isfinite(loss):
            raise FitError(f"the fit diverged at step {self.steps}: the loss is {float(loss.detach())} "
                           "(lower lr_density / lr_color; the last checkpoint is still good)")
        clock.lap("forward")
        if t.numel():
            loss.backward()
            clock.lap("backward")
            grad = sub.grad
            assert grad is not None  # sub is a leaf of the loss wherever a sample was marched
            if c.tv > 0 or c.tv_density > 0:
                if self.tv_rows is not None:  # the compiled prior's neighbour table (_index_rows)
                    add_tv_gradient(f.values, unique, self.tv_rows, self.tv_weights, grad)
                else:
                    grad += self.tv_weights * tv_gradient(f, self.flat_of_row, unique)
            if not torch.isfinite(grad.sum()):
                raise FitError(f"the fit diverged at step {self.steps}: non-finite gradients")
            self.adam.step(unique, grad, lr_scale)
            if self.appearance is not None:
                self.appearance.step(lr_scale)
            clock.lap("update")
        self.steps += 1
        return float(loss.detach()), -10.0 * math.log10(max(float(mse.detach()), 1e-10))

    @torch.no_grad()
    def prune(self) -> None:
        """Drop cells the field left empty, and cells that training rays reached but that never contributed
        (hidden behind surfaces or clear air): one cell of dilation keeps what is left free to grow."""
        c = self.config
        threshold = c.final_prune_alpha if self.stage >= self.haze_from else c.prune_alpha
        if self.compiled:
            occupancy = pruned_occupancy(self.field, self.grid.numpy()[0], self.row_map, self.cell_weight,
                                         threshold, c.prune_weight, c.step_ratio)
        else:
            occupancy = pruned_occupancy_dense(self.field, self.cell_weight, threshold, c.prune_weight, c.step_ratio)
        self._reset_visibility()
        if not occupancy.any():  # nothing has formed yet (a very short fit): pruning would leave no field
            return
        self.field.occupancy = occupancy
        if self.compact_pending:
            # the unused rows' stale values pulled on the TV prior and the prune: the fox's validation views
            # score 25.85 against 25.33 dB without them (docs/performance-log.md, "The training step")
            self.compact_pending = False
            self._compact()
        self._rebuild_grid()

    @torch.no_grad()
    def refine(self) -> None:
        """Move to the next grid, or to the finest coarser one the free memory holds, or stay (then pruned as the
        last) where none does (:func:`~pytest_n2r.fit.memory.choose_grid`); ``config`` names the grids trained."""
        stage = self.stage + 1
        choice = choose_grid(self.field, self.config.resolutions[stage], free_bytes(self.device))
        self.phases.start(choice.resolution)
        if choice.limited:
            self.config = choice.applied_to(self.config, stage)
            self.limits.append({"step": self.steps, **choice.describe()})
            warnings.warn(f"at step {self.steps}, {choice.message()}", GridMemoryLimit, stacklevel=4)  # fit's caller
        if not choice.limited or choice.resolution > self.field.resolution:
            del self.adam  # the old grid's moments go before the new grid is made
            self.stage, self.field = stage, self.field.upsampled(choice.resolution)
            self._reset_optimizer()


def fit(
    capture: Capture,
    config: FieldConfig | None = None,
    *,
    time_budget_s: float | None = None,
    max_steps: int | None = None,
    device: str | torch.device = "auto",
    progress: Callable[[dict], None] | None = None,
    checkpoint: Callable[[FitResult], None] | None = None,
    checkpoint_every_s: float = 60.0,
    eval_at_s: Sequence[float] = (),
    appearance: bool | Literal["auto"] = False,
    stop: Callable[[], bool] | None = None,
) -> FitResult:
    """Fit a scene field to ``capture`` (images loaded) within ``time_budget_s`` seconds of training and/or
    ``max_steps`` steps. The stage schedule follows whichever limit is given (steps when both: a fit with
    ``max_steps`` alone is reproducible bit for bit on the same machine and thread count, where memory limited no
    grid). Where the capture shows finer detail than ``config``'s finest grid holds, the fit trains one finer grid
    at the end of the run (:func:`~pytest_n2r.fit.detail.detailed_config`). A grid that would not fit in the
    memory free is replaced by the finest that does (:func:`~pytest_n2r.fit.memory.choose_grid`), with a warning
    and a row of ``report["grid_limits"]``; the result's ``config`` names the grids trained.

    ``progress`` receives ``{step, stage, resolution, loss, psnr, elapsed_s, eta_s, occupied}`` about once a
    second; ``checkpoint`` receives a :class:`FitResult` every ``checkpoint_every_s`` seconds (quantized, as
    a scene file stores it); ``eval_at_s`` lists training times at which held-out PSNR/SSIM are recorded
    in ``report["history"]``. Neither evaluation nor compiling the training kernels (a fresh installation's first
    fit, ``report["compile_seconds"]``) counts as training time. The report's scores of held-out and a few training
    views, and how far each held-out view is from the fitted ones: :func:`~pytest_n2r.fit.evaluate.final_scores`.

    ``appearance=True`` fits a colour gain per training photo and channel alongside the field, for captures whose
    exposure and white balance change from photo to photo; the field keeps their average and renders no gain at any
    pose (``report["appearance"]``: the gains by photo). ``"auto"`` (``n2r fit``'s default) fits them where
    neighbouring photos differ by more than :data:`~pytest_n2r.fit.appearance.APPEARANCE_JUMP` (measured in
    seconds, not training time; ``report["exposure"]``); ``False``, the default here, keeps older fits bit for bit.

    ``stop`` is asked after every step whether to end the fit there (say the user pressed Ctrl-C); the field
    is then pruned and evaluated as at the end of the budget, and ``report["stopped"]`` is true unless that
    step had reached the budget anyway.
    """
    config = config or FieldConfig()
    if time_budget_s is None and max_steps is None:
        raise InvalidArgument("fit needs time_budget_s or max_steps (or both)")
    time_budget_s = check_time_budget(time_budget_s)
    budget_s = math.inf if time_budget_s is None else time_budget_s  # with no budget, max_steps paces the fit
    if max_steps is not None and (isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1):
        raise InvalidArgument(f"max_steps={max_steps!r}: expected an integer >= 1")
    dev = resolve_device(device)
    train = fit_views(capture)  # every view checked before its photos are measured or its rays built
    appearance, exposure = decide_appearance(capture, appearance)
    detail = capture_detail(capture, fit_space(capture, config))
    given, config = config, detailed_config(config, detail)
    trainer = _Trainer(capture, config, dev, appearance=appearance, haze_from=len(given.resolutions) - 1, train=train)
    heldout = [v for v in capture.heldout_views if v.image is not None]
    history: list[dict] = []
    pending_evals = sorted(float(s) for s in eval_at_s)
    train_s = eval_s = 0.0
    start = time.perf_counter()
    last_report = last_checkpoint = 0.0
    loss = batch_psnr = float("nan")
    stopped = False

    def progress_fraction() -> float:
        return trainer.steps / max_steps if max_steps is not None else train_s / budget_s

    def budget_left() -> bool:  # and a step on this grid predicted to end within it, or nearly (phases.py)
        return (progress_fraction() < 1.0 and budget_s > train_s
                and trainer.phases.may_step(budget_s - train_s, budget_s))

    def snapshot() -> FitResult:
        so_far = {"steps": trainer.steps, "train_seconds": round(train_s, 2), "grid_limits": list(trainer.limits)}
        return FitResult(trainer.field.quantized(), trainer.config, so_far)

    compiles = trainer.compiles  # a fresh installation's kernel compiles: not training (compile_clock.py)
    while budget_left():
        t0, compiled_before = time.perf_counter(), compiles.seconds
        frac = progress_fraction()
        grow = config.stage(frac) > trainer.stage
        if grow and max_steps is None:  # paced by its budget: a grid grows once pruned, where growth fits (phases.py)
            finer, left_s = config.resolutions[trainer.stage + 1], budget_s - train_s
            grow = not trainer.compact_pending and trainer.phases.may_grow(finer, left_s)  # compact_pending: unpruned
        with compiles.counting():
            if grow:
                trainer.refine()
                trainer.phases.lap("refine")
                config = trainer.config
            loss, batch_psnr = trainer.step(config.lr_final_ratio ** frac)
            if trainer.steps >= config.prune_after and trainer.steps % config.prune_every == 0:
                trainer.phases.start(trainer.field.resolution)
                trainer.prune()
                trainer.phases.lap("prune")
        train_s += time.perf_counter() - t0 - (compiles.seconds - compiled_before)
        while pending_evals and train_s >= pending_evals[0]:
            e0 = time.perf_counter()
            rows = evaluate_views(trainer.field, heldout)
            history.append({"seconds": round(pending_evals.pop(0), 3), "train_seconds": round(train_s, 2),
                            "step": trainer.steps, **mean_scores(rows)})
            eval_s += time.perf_counter() - e0
        now = time.perf_counter() - start
        if progress is not None and now - last_report >= 1.0:
            last_report = now
            eta = (train_s / max(frac, 1e-9)) * (1.0 - frac) if frac > 0 else float("nan")
            progress({"step": trainer.steps, "stage": trainer.stage, "resolution": trainer.field.resolution,
                      "loss": loss, "psnr": batch_psnr, "elapsed_s": train_s, "eta_s": eta,
                      "occupied": float(trainer.field.occupancy.float().mean())})
        if checkpoint is not None and now - last_checkpoint >= checkpoint_every_s:
            last_checkpoint = now
            checkpoint(snapshot())
        if stop is not None and stop():
            stopped = budget_left()
            break
    if trainer.steps >= config.prune_after:  # a very short fit has not had time to grow anything yet
        trainer.prune()
    del trainer.adam  # its moments (two floats a value) are not needed from here on
    final = trainer.field.quantized()
    e0 = time.perf_counter()
    scores = final_scores(final, heldout, train, capture.reference_length)
    eval_s += time.perf_counter() - e0
    report = {
        "steps": trainer.steps,
        "train_seconds": round(train_s, 2),
        "eval_seconds": round(eval_s, 2),
        "compile_seconds": round(compiles.seconds, 2),
        "device": str(dev),
        "threads": torch.get_num_threads(),
        "time_budget_s": time_budget_s,
        "max_steps": max_steps,
        "stopped": stopped,
        "final_loss": round(loss, 6),
        "step_ms": trainer.phases.report(),
        "field": final.describe(),
        "detail": None if detail is None else {**detail.describe(final.resolution),
                                                "grid_added": final.resolution if final.resolution
                                                > given.resolutions[-1] else None},
        "grid_limits": trainer.limits,
        **scores,
        "history": history,
        "versions": _versions(),
    }
    report.update({"exposure": exposure} if exposure is not None else {})
    if trainer.appearance is not None:
        report["appearance"] = trainer.appearance.report()
    return FitResult(final, config, report)
