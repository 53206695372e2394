"""Gaussian splats of the exact demo scenes: what a splat trainer would produce, with known truth.

Gaussians are placed on the true surfaces where the training views see them (random pixels of each
training view, cast exactly), so their density follows the views' pixel density as a trained scene's does.
Each is a flat disc in the surface's tangent plane: in-plane standard deviation ``spread`` times the RMS
distance to its three nearest neighbours (the 3DGS initialization's rule), a tenth of that along the
normal, peak opacity ``opacity``, and the exact scene's colour there (albedo × light, prefiltered over the
disc) as its SH DC term. Higher SH degrees get small random coefficients (``sh_noise``), as a trained
scene's view-dependent terms. A render of these splats can be scored against the exact render.
"""

from __future__ import annotations

import math

import numpy as np

from .._validation import check_positive, check_range, check_real
from ..errors import InvalidArgument
from ..geometry import camera_rays
from ..splats.gaussians import Gaussians
from ..splats.sh import rgb_to_sh, sh_count
from .exact import GroundTruthScene

__all__ = ["sample_splats", "similarity_transformed"]


def sample_splats(scene: GroundTruthScene, count: int, *, sh_degree: int = 0, seed: int = 0, spread: float = 0.7,
                  opacity: float = 0.95, sh_noise: float = 0.02) -> Gaussians:
    """``count`` Gaussians on the surfaces of ``scene`` seen by its training views (see the module docstring)."""
    from scipy.spatial import cKDTree

    if not (isinstance(count, int) and count >= 8):
        raise InvalidArgument(f"count={count!r}; expected an int >= 8")
    if sh_degree not in (0, 1, 2, 3):
        raise InvalidArgument(f"sh_degree={sh_degree!r}; expected 0, 1, 2 or 3")
    spread = check_positive("spread", spread)
    sh_noise = check_range("sh_noise", sh_noise, lo=0.0)
    opacity = check_real("opacity", opacity)
    if not 0.0 < opacity < 1.0:  # its logit is stored: finite only strictly between 0 and 1
        raise InvalidArgument(f"opacity={opacity!r} is out of range; expected a peak opacity in (0, 1), both excluded")
    rng = np.random.default_rng(seed)
    train = [v for v in scene.views if v.split == "train"]
    per_view = math.ceil(2 * count / len(train))
    origins, dirs, ts, which = [], [], [], []
    for view in train:
        cam = view.camera
        uv = rng.uniform((-0.5, -0.5), (cam.width - 0.5, cam.height - 0.5), size=(per_view, 2))
        o, d = camera_rays(cam, view.c2w, uv)
        t, k = scene.cast(o, d)
        hit = np.isfinite(t)
        origins.append(o[hit])
        dirs.append(d[hit])
        ts.append(t[hit])
        which.append(k[hit])
    o, d, t, k = (np.concatenate(a) for a in (origins, dirs, ts, which))
    if len(t) < count:
        raise InvalidArgument(f"scene {scene.name!r}: the training views hit a surface {len(t)} times; asked for "
                              f"{count} Gaussians")
    keep = np.sort(rng.choice(len(t), size=count, replace=False))
    o, d, t, k = o[keep], d[keep], t[keep], k[keep]
    points = o + t[:, None] * d
    normals = np.empty_like(points)
    for index, primitive in enumerate(scene.primitives):
        sel = np.nonzero(k == index)[0]
        if sel.size:
            normals[sel] = primitive.surface(points[sel])[0]
    dist, _ = cKDTree(points).query(points, k=4)
    sigma = spread * np.sqrt(np.mean(dist[:, 1:] ** 2, axis=1))
    colour = scene.shade(o, d, t, k, 2.0 * sigma).astype(np.float64)
    sh = np.zeros((count, sh_count(sh_degree), 3))
    sh[:, 0] = rgb_to_sh(colour)
    if sh_degree:
        sh[:, 1:] = rng.normal(0.0, sh_noise, size=(count, sh_count(sh_degree) - 1, 3))
    # the quaternion turning local z onto the normal: (1 + n_z, -n_y, n_x, 0), normalized
    quats = np.stack([1.0 + normals[:, 2], -normals[:, 1], normals[:, 0], np.zeros(count)], axis=1)
    flip = quats[:, 0] < 1e-9  # n = -z: any half turn about a horizontal axis
    quats[flip] = (0.0, 1.0, 0.0, 0.0)
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    log_scales = np.log(np.stack([sigma, sigma, 0.1 * sigma], axis=1))
    logit = math.log(opacity / (1.0 - opacity))
    return Gaussians(means=points, quats=quats, log_scales=log_scales, opacity_logits=np.full(count, logit), sh=sh)


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products ``a ⊗ b`` of w-first quaternions (broadcasting)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def similarity_transformed(gaussians: Gaussians, rotation_wxyz: np.ndarray, translation: np.ndarray,
                           scale: float) -> Gaussians:
    """The Gaussians in a world ``x' = scale · R x + translation`` (``R`` the unit quaternion ``rotation_wxyz``).

    SH coefficients above degree 0 would have to be rotated too; this refuses them.
    """
    from ..geometry.conventions import quaternion_to_rotation

    if gaussians.sh_degree:
        raise InvalidArgument("similarity_transformed: rotating SH coefficients above degree 0 is not implemented")
    scale = check_positive("scale", scale)
    q = np.asarray(rotation_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q)
    means = scale * gaussians.means.astype(np.float64) @ quaternion_to_rotation(q).T + np.asarray(translation)
    quats = _quat_multiply(q, gaussians.quats.astype(np.float64))
    return Gaussians(means=means, quats=quats, log_scales=gaussians.log_scales + np.float32(math.log(scale)),
                     opacity_logits=gaussians.opacity_logits, sh=gaussians.sh)
