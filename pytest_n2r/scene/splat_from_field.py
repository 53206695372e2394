"""A fitted scene field turned into 3-D Gaussian splats: one Gaussian per occupied voxel.

Each occupied cell of the field's grid (:class:`~pytest_n2r.field.grid.SceneField`) whose opacity reaches
``1/255`` becomes one Gaussian:

- **mean**: the cell's centre, taken back from the contracted space to the world (scene units);
- **scale**: ``size`` times the cell's side in the world along each world axis (inside the unit cube a
  cell is a cube; in the contracted shell its world extent grows with the distance, and the Gaussian is
  stretched along the axes to match: the contraction's shear is not kept); no rotation;
- **opacity**: ``1 - exp(-σ · path)``, the opacity of ``path`` voxels of the cell's density ``σ`` (per
  voxel; the density at the centre, from the mean of the 8 corners' raw values);
- **colour**: the field's colour ``sigmoid(Σ Y_l k_l)`` at the centre, as splat SH of the same degree (0, 1
  or 2, the same real SH basis): the DC term gives ``sigmoid(C0 k_0)`` exactly, the view-dependent terms are the
  sigmoid's first-order expansion around it.

It is a conversion, not a fit: a field renders smooth trilinear densities along rays, the splats render
blobs, so the splats lose detail (measured in docs/splat-scenes.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InvalidArgument
from ..field.grid import SceneField, n_sh_coefficients
from ..field.space import SceneSpace
from ..render.splat_kernels import ALPHA_MIN
from ..render.splat_render import SplatSettings
from ..splats.gaussians import Gaussians
from ..splats.sh import SH_C0
from .splat_scene import SplatScene

if TYPE_CHECKING:
    from .field_scene import FieldScene

__all__ = ["DEFAULT_PATH", "DEFAULT_SIZE", "field_to_gaussians", "splat_scene_from_field", "uncontract"]

#: The corner offsets of a cell, (8, 3).
_CORNERS = torch.tensor([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
#: The conversion's defaults (:func:`field_to_gaussians`), chosen on training views of two fitted fields
#: (the fox capture's 10-minute field and the demo ``object`` field; see docs/splat-scenes.md): a Gaussian's
#: standard deviation in cell sides, and the voxels of density its peak opacity stands for.
DEFAULT_SIZE, DEFAULT_PATH = 0.4, 0.8
#: Opacities are kept below this, so that their logits stay finite in float32.
_MAX_OPACITY = 1.0 - 1e-6


def uncontract(space: SceneSpace, q: np.ndarray) -> np.ndarray:
    """Contracted points ``(..., 3)`` (``‖q‖∞ < 1 + shell``) → normalized points: the inverse of
    :meth:`SceneSpace.contract` (identity inside the unit cube; beyond, ``r = shell / (1 + shell - ‖q‖∞)``
    and ``p = r · q / ‖q‖∞``).

    >>> space = SceneSpace((0.0, 0.0, 0.0), 1.0, shell=0.25)
    >>> uncontract(space, np.array([[0.5, 0.0, 0.0], [1.125, 0.0, 0.0]])).tolist()
    [[0.5, 0.0, 0.0], [2.0, 0.0, 0.0]]
    """
    q = np.asarray(q, dtype=np.float64)
    r = np.max(np.abs(q), axis=-1, keepdims=True)
    if (r >= space.half_size).any():
        raise InvalidArgument(f"uncontract: points with ‖q‖∞ >= 1 + shell = {space.half_size} lie at infinity")
    with np.errstate(divide="ignore", invalid="ignore"):
        outer = q / r * (space.shell / (space.half_size - r))
    return np.where(r <= 1.0, q, outer)


def check_voxels(value: float, where: str) -> float:
    """``value`` if it is a conversion knob's valid value (a finite number of voxels > 0), else an
    :class:`InvalidArgument` whose message starts with ``where`` (the argument or option and its value)."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InvalidArgument(f"{where} expected a finite number > 0 (voxels)")
    return value


def field_to_gaussians(field: SceneField, *, size: float = DEFAULT_SIZE, path: float = DEFAULT_PATH) -> Gaussians:
    """The Gaussians of ``field`` (see the module docstring): ``size`` is each Gaussian's standard deviation in
    cell sides, ``path`` the voxels of density its peak opacity stands for."""
    for name, value in (("size", size), ("path", path)):
        check_voxels(value, f"{name}={value!r};")
    res = field.resolution
    cells = field.occupancy.nonzero().cpu()
    corners = (cells[:, None, :] + _CORNERS[None]).reshape(-1, 3)
    rows = field.vertex_rows(((corners[:, 0] * res + corners[:, 1]) * res + corners[:, 2]).to(field.device))
    if bool((rows < 0).any()):
        raise InvalidArgument("field_to_gaussians: the field does not store every vertex of its occupied cells")
    values = field.values[rows].reshape(len(cells), 8, -1).mean(dim=1).double().cpu()
    sigma = F.softplus(values[:, 0] + field.density_shift)
    opacity = (-torch.expm1(-sigma * path)).clamp(max=_MAX_OPACITY).numpy()
    keep = opacity >= ALPHA_MIN
    kept, values, opacity = cells[keep].numpy(), values[keep], opacity[keep]

    space = field.space
    voxel = space.voxel_size(res)
    centre = -space.half_size + voxel * (kept + 0.5)
    world = lambda q: np.asarray(space.center) + space.radius * uncontract(space, q)
    means = world(centre)
    extent = np.empty_like(means)
    for axis in range(3):  # central differences over half a cell (the outermost cells end at infinity)
        step = np.zeros(3)
        step[axis] = 0.25 * voxel
        extent[:, axis] = 2.0 * np.linalg.norm(world(centre + step) - world(centre - step), axis=1)

    n_sh = n_sh_coefficients(field.sh_degree)
    coeff = values[:, 1:].reshape(-1, n_sh, 3).numpy()  # stored [l·3 + channel]
    base = 1.0 / (1.0 + np.exp(-SH_C0 * coeff[:, 0]))  # the DC colour, sigmoid(C0 k_0)
    sh = np.empty_like(coeff)
    sh[:, 0] = (base - 0.5) / SH_C0
    sh[:, 1:] = (base * (1.0 - base))[:, None, :] * coeff[:, 1:]
    return Gaussians(means=means, quats=np.tile([1.0, 0.0, 0.0, 0.0], (len(means), 1)),
                     log_scales=np.log(size * extent), opacity_logits=np.log(opacity / (1.0 - opacity)), sh=sh)


def splat_scene_from_field(scene: FieldScene, *, size: float = DEFAULT_SIZE, path: float = DEFAULT_PATH,
                           settings: SplatSettings | None = None) -> SplatScene:
    """A fitted scene (:class:`~pytest_n2r.scene.field_scene.FieldScene`) as a :class:`SplatScene` with the same
    views, reference length, scale and background (:func:`field_to_gaussians` with ``size`` and ``path``)."""
    field = scene.field
    return SplatScene(field_to_gaussians(field, size=size, path=path), scene.views, name=f"{scene.name}-splats",
                      reference_length=scene.reference_length, background=field.background, settings=settings,
                      metres_per_unit=scene.metres_per_unit)
