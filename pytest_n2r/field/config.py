"""How a scene field is fitted: grid schedule, optimizer and regularization settings."""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields, replace
from typing import TYPE_CHECKING, Any

from ..errors import InvalidArgument
from .density import MAX_DENSITY_SHIFT, alpha_range, density_shift_for, step_ratio_range

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = ["LATER_SETTINGS", "SH_DEGREES", "FieldConfig", "check_setting_types"]

#: The spherical-harmonics degrees a field's colour can have (:func:`pytest_n2r.field.grid.n_sh_coefficients`).
SH_DEGREES = (0, 1, 2)


def _is_number(value: object, kind: type) -> bool:
    """``value`` is an int (``kind`` int) or an int or float (``kind`` float), not a bool."""
    allowed = (int,) if kind is int else (int, float)
    return isinstance(value, allowed) and not isinstance(value, bool)


#: What a setting of each declared type accepts: (what is expected, the check); ``X | None`` also takes None.
_KINDS: dict[str, tuple[str, Callable[[object], bool]]] = {
    "bool": ("True or False", lambda v: isinstance(v, bool)),
    "int": ("an integer", lambda v: _is_number(v, int)),
    "float": ("a number", lambda v: _is_number(v, float)),
    "str": ("a string", lambda v: isinstance(v, str)),
    "tuple[int, ...]": ("a list of integers",
                        lambda v: isinstance(v, (tuple, list)) and all(_is_number(x, int) for x in v)),
    "tuple[float, ...]": ("a list of numbers",
                          lambda v: isinstance(v, (tuple, list)) and all(_is_number(x, float) for x in v)),
}
#: a colour: also a 1-D NumPy array of numbers (the caller checks its length and range and stores plain floats)
_KINDS["tuple[float, float, float]"] = (
    "three numbers", lambda v: (isinstance(v, (tuple, list)) or (
        type(v).__name__ == "ndarray" and getattr(v, "ndim", None) == 1 and isinstance(v, Iterable)))
    and all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in v))


def check_setting_types(settings: DataclassInstance) -> None:
    """Every field of the dataclass ``settings`` has its declared type, before any range is checked (a string,
    None or a bool where a number belongs is named, with the type expected and the default), else
    :class:`~pytest_n2r.errors.InvalidArgument`."""
    for f in fields(settings):
        value, declared = getattr(settings, f.name), str(f.type)
        optional = declared.endswith(" | None")
        kind, ok = _KINDS[declared.removesuffix(" | None")]
        if not (ok(value) or (optional and value is None)):
            default = ",".join(map(str, f.default)) if isinstance(f.default, tuple) else f.default
            raise InvalidArgument(f"{type(settings).__name__}.{f.name}={value!r}: expected {kind}"
                                  f"{' or None' if optional else ''} (default: {default})")


#: Settings added after scene files were first written. A config stores them only where they differ from their
#: defaults, so that a config written before them reads, writes and hashes the same (a fitted demo scene's recipe
#: digest covers its config: a new key would make the shipped files stale and refit them on first use).
LATER_SETTINGS = ("max_pixels_per_voxel", "detail_grid_max")


@dataclass(frozen=True)
class FieldConfig:
    """Settings of :func:`pytest_n2r.fit.fit`. The defaults were chosen by measurement
    (docs/scene-field.md); every field is stored in the scene file.

    Grid
        ``resolutions``: the grid's vertices per axis, coarse to fine; training moves to the next one at
        each of ``stage_fractions`` of the run (fractions of the time budget or of ``max_steps``). A last
        grid of 224³ won against 192³ (which had won against 160³) at equal training time on both scenes
        the priors were chosen on, once the learning rates were doubled. A 32³ first grid, not 48³: on a
        capture that orbits its subject with sky behind it, a 48³ start grows floaters of sky on the camera
        circle that no later grid removes (the object's phone capture, validation views at 10 minutes: 24.89 dB
        started on 32³, 20.48 on 48³), and at equal time the 32³ start tied on the wall's capture and gained
        0.55 dB on the fox's (docs/scene-field-log.md, "A 32³ start").
        ``max_pixels_per_voxel``: with the library's ladders (the default, or a long budget's ending on 256³),
        where a voxel of their last grid would span more training pixels than this where the cameras look
        closest (:mod:`pytest_n2r.fit.detail`), the fit trains one finer grid for the last 30 % of the run,
        sized for this many pixels a voxel (rounded up to a multiple of 64, at most ``detail_grid_max``); 0 turns
        it off, and any other ladder is trained as given.
        On a phone-style capture of the wall (480×270 photos, 9 pixels a voxel at 224³) a 384³ grid for the
        last 30 % gained 0.9 dB and SIFT's repeatability against the photos 0.29 → 0.58 at equal training
        time; on the object's 960×540 capture (10.1 pixels a voxel) 0.5 dB, and all three detectors'
        repeatability; the fox (5.1 pixels a voxel) keeps 224³ (docs/scene-field-log.md, "A grid that follows
        the capture's detail", "The 10-minute default on fine phone captures"). ``n2r fit`` with a budget of 30
        minutes or more sets 3.5 (:mod:`pytest_n2r.fit.budget`).
        ``shell``: thickness of the contracted outer shell (normalized units). ``sh_degree``: 0, 1 or 2 (the
        colour's spherical harmonics); degree 2 fits the fox 1.1–1.3 dB better at equal steps, but a step takes
        1.85× as long, at 10 minutes it ties, at 20 it wins, and its field renders 1.3–1.5× slower
        (docs/scene-field-log.md, "Spherical harmonics of degree 2", "A longer fit"); ``n2r fit`` takes it, and a
        last grid of 256³, from a 20-minute budget (:mod:`pytest_n2r.fit.budget`).
    Sampling
        ``step_ratio``: sample spacing in voxels. ``batch_rays``: rays per step.
    Optimizer (Adam on the rows a step touches)
        ``lr_density``, ``lr_color``: learning rates, decayed exponentially to ``lr_final_ratio`` of them;
        twice the earlier 0.2 and 0.1 won at equal training time on both scenes the priors were chosen on.
    Initialization and regularization
        ``random_background``: every training ray is composited over its own random colour, so the field
        cannot let a constant background stand in for dark or distant parts of the scene: each ray must
        become opaque inside the field (photos show the scene in every pixel; sky and far walls go to the
        contracted shell). Opaque surfaces also stop rays early when rendering. ``distortion``: weight of
        mip-NeRF 360's distortion loss (mean over rays, positions in contracted units): it gathers each
        ray's compositing weight into one short interval, turning fog and floaters into surfaces.
        ``alpha_init``: opacity per sample of the empty field (with ``step_ratio``, one whose density shift a scene
        file holds: :mod:`pytest_n2r.field.density`). ``sparsity``: weight of the mean sample
        opacity in the loss (keeps empty space empty). ``prune_alpha``: cells whose densest corner gives
        less opacity per sample are dropped from the occupancy every ``prune_every`` steps, and so are cells
        that training rays sampled in that time without any sample reaching a compositing weight of
        ``prune_weight`` (one cell of dilation keeps surfaces free to grow). On the finest grid (and, where
        a fit adds a finer grid for the end, on the grid before it) the opacity threshold is
        ``final_prune_alpha`` instead: thin haze in front of surfaces is dropped while the
        fit can still adapt to its absence, so rays reach surfaces in fewer samples (faster steps and
        renders). Nothing is pruned before step ``prune_after``: the field needs that long to show where
        its surfaces are. ``tv`` and ``tv_density``: weights of a total-variation prior on the colour and on
        the density of the vertices a step touches (the mean over them of the squared differences to their
        stored grid neighbours): on fine grids, where a vertex is seen by few rays, it fills in what the
        rays leave free from the neighbourhood instead of from noise. On the density it also thins surfaces
        seen only at grazing angles, which haze pruning can then cut open. Defaults ``1e-4`` and ``2e-5``:
        they won at equal training time on the fox's validation views and a phone capture of the wall.
    ``seed``: seeds ray sampling, so a fit with ``max_steps`` is reproducible.
    """

    resolutions: tuple[int, ...] = (32, 96, 224)
    stage_fractions: tuple[float, ...] = (0.1, 0.35)
    max_pixels_per_voxel: float = 6.0
    detail_grid_max: int = 384
    shell: float = 0.25
    sh_degree: int = 1
    step_ratio: float = 0.5
    batch_rays: int = 4096
    lr_density: float = 0.4
    lr_color: float = 0.2
    lr_final_ratio: float = 0.1
    random_background: bool = True
    distortion: float = 1e-3
    alpha_init: float = 1e-4
    sparsity: float = 1e-2
    prune_alpha: float = 1e-3
    final_prune_alpha: float = 8e-2
    prune_weight: float = 1e-3
    prune_every: int = 25
    prune_after: int = 25
    tv: float = 1e-4
    tv_density: float = 2e-5
    seed: int = 0

    def __post_init__(self) -> None:
        check_setting_types(self)
        object.__setattr__(self, "resolutions", tuple(int(r) for r in self.resolutions))
        object.__setattr__(self, "stage_fractions", tuple(float(f) for f in self.stage_fractions))
        res, fr = self.resolutions, self.stage_fractions
        if not res or any(r < 8 or r > 1024 for r in res) or list(res) != sorted(res):
            raise InvalidArgument(f"resolutions={res!r}: expected increasing grid sizes in 8..1024")
        if len(fr) != len(res) - 1 or list(fr) != sorted(fr) or any(not 0.0 < f < 1.0 for f in fr):
            raise InvalidArgument(f"stage_fractions={fr!r}: expected {len(res) - 1} increasing fractions in (0, 1)")
        positive = ("shell", "step_ratio", "lr_density", "lr_color", "lr_final_ratio", "alpha_init")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InvalidArgument(f"FieldConfig.{name}={value!r}: expected a finite number > 0")
        if not 0 < self.alpha_init < 1:
            raise InvalidArgument(f"FieldConfig.alpha_init={self.alpha_init!r}: expected an opacity in (0, 1)")
        self._check_density_shift()
        for name in ("prune_alpha", "final_prune_alpha", "prune_weight"):
            if not 0 <= getattr(self, name) < 1:
                raise InvalidArgument(f"FieldConfig.{name}={getattr(self, name)!r}: expected a threshold in [0, 1)")
        if not 8 <= self.detail_grid_max <= 1024:
            raise InvalidArgument(f"FieldConfig.detail_grid_max={self.detail_grid_max!r}: expected a grid size in "
                                  "8..1024")
        for name in ("sparsity", "distortion", "tv", "tv_density", "max_pixels_per_voxel"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InvalidArgument(f"FieldConfig.{name}={value!r}: expected a finite number >= 0")
        for name in ("batch_rays", "prune_every", "prune_after"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise InvalidArgument(f"FieldConfig.{name}={getattr(self, name)!r}: expected an integer >= 1")
        if not isinstance(self.random_background, bool):
            raise InvalidArgument(f"FieldConfig.random_background={self.random_background!r}: expected True or False")
        if self.sh_degree not in SH_DEGREES:
            raise InvalidArgument(f"FieldConfig.sh_degree={self.sh_degree!r}: expected 0, 1 or 2")

    def _check_density_shift(self) -> None:
        """The field's density shift (:func:`~pytest_n2r.field.density.density_shift_for`) is one a scene file can
        hold: refused here, not after the whole fit when the scene is saved."""
        alpha, ratio = self.alpha_init, self.step_ratio
        shift = density_shift_for(alpha, ratio)
        if abs(shift) <= MAX_DENSITY_SHIFT:
            return
        (alpha_lo, alpha_hi), (ratio_lo, ratio_hi) = alpha_range(ratio), step_ratio_range(alpha)
        raise InvalidArgument(
            f"FieldConfig.alpha_init={alpha!r} with step_ratio={ratio!r} gives the field a density shift of "
            f"{shift:.4g}, beyond the ±{MAX_DENSITY_SHIFT:g} a scene file holds (every sample would be empty or "
            f"opaque alike): at step_ratio={ratio!r}, alpha_init must be in [{alpha_lo:.3g}, {alpha_hi:.3g}]; at "
            f"alpha_init={alpha!r}, step_ratio in [{ratio_lo:.3g}, {ratio_hi:.3g}]")

    def stage(self, progress: float) -> int:
        """The index into ``resolutions`` at ``progress`` (0..1) of the run."""
        return sum(progress >= f for f in self.stage_fractions)

    def to_dict(self) -> dict:
        """The settings as plain JSON values; those of :data:`LATER_SETTINGS` only where they differ from their
        defaults."""
        data = asdict(self)
        defaults = {f.name: f.default for f in fields(self)}
        return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()
                if k not in LATER_SETTINGS or v != defaults[k]}

    @classmethod
    def from_dict(cls, data: dict) -> FieldConfig:
        """The config of ``data``; unknown keys are an error (they would be silently ignored otherwise)."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InvalidArgument(f"field config has unknown keys {unknown}; known: {sorted(known)}")
        return cls(**data)

    def replace(self, **changes: Any) -> FieldConfig:
        return replace(self, **changes)
