"""An independent, straightforward float64 splat renderer for the tests: every Gaussian at every pixel.

Written from the 3DGS paper and reference rasterizer's rules, not from pytest_n2r's kernels: no tiles, no
rectangles, no runs, no sorting tricks. It also returns, per pixel, whether a compositing decision (opacity
against 1/255, transmittance against the stop, the uint8 rounding of a colour) lies so close to its threshold
that float rounding may decide it either way; comparisons skip those pixels.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from pytest_n2r.geometry import Camera
from pytest_n2r.splats import Gaussians

#: The 3DGS constants, written out once more here (from the reference's sh_utils / forward.cu).
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435]


def sh_basis(d: np.ndarray, degree: int) -> np.ndarray:
    """``(N, (degree+1)²)`` basis values at unit directions ``d`` (N, 3), with the reference's signs."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    cols = [np.full_like(x, C0)]
    if degree >= 1:
        cols += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        cols += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * z * z - x * x - y * y), C2[3] * x * z,
                 C2[4] * (x * x - y * y)]
    if degree >= 3:
        cols += [C3[0] * y * (3 * x * x - y * y), C3[1] * x * y * z, C3[2] * y * (4 * z * z - x * x - y * y),
                 C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y), C3[4] * x * (4 * z * z - x * x - y * y),
                 C3[5] * z * (x * x - y * y), C3[6] * x * (x * x - 3 * y * y)]
    return np.stack(cols, axis=1)


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of w-first quaternions (normalized here), via the axis-angle (Rodrigues) form."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    angle = 2 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), q[:, 0])
    axis = q[:, 1:] / np.maximum(np.linalg.norm(q[:, 1:], axis=1, keepdims=True), 1e-300)
    k = np.zeros((len(q), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k = k - k.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def exact_conics(M: np.ndarray, F: np.ndarray, dilation: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """The inverses ``(a, b, c)`` (N × 3, rounded to float64 once) of the 2-D covariances ``(M F)(M F)ᵀ +
    dilation·I``, computed exactly in rational arithmetic from the float64 ``M`` (N × 2 × 3) and ``F`` (the
    rotation times the scales, N × 3 × 3), and whether each is defined (finite inputs, a determinant float64
    holds). In float64 these lose every digit for a needle or a flat disc with one huge scale (the covariance's
    long-axis entries round by more than its short axes measure, and ``det = ac - b²`` cancels): with
    log-scales like (−85, 9.4, −56) ``np.linalg.inv`` was 0.2 % off the exact conic, which moved a pixel's
    opacity by 1e-3."""
    out = np.zeros((len(M), 3))
    ok = np.zeros(len(M), bool)
    d = Fraction(dilation)
    for i in range(len(M)):
        if not (np.isfinite(M[i]).all() and np.isfinite(F[i]).all()):
            continue
        m = [[Fraction(x) for x in row] for row in M[i].tolist()]
        f = [[Fraction(x) for x in row] for row in F[i].tolist()]
        A = [[sum(m[r][j] * f[j][k] for j in range(3)) for k in range(3)] for r in range(2)]
        a = sum(x * x for x in A[0]) + d
        b = sum(x * y for x, y in zip(A[0], A[1]))
        c = sum(x * x for x in A[1]) + d
        det = a * c - b * b
        try:
            out[i] = float(c / det), float(-b / det), float(a / det)
            ok[i] = np.isfinite(float(det))
        except OverflowError:
            continue
    return out, ok


def render_reference(g: Gaussians, c2w: np.ndarray, camera: Camera, background=(0.0, 0.0, 0.0), near: float = 0.01,
                     t_stop: float = 1e-4, eps: float = 1e-7) -> dict[str, np.ndarray]:
    """``rgb`` (float64 in [0, 1] and uint8), ``depth``, ``opacity`` and ``ambiguous`` (H×W bool)."""
    w, h = camera.width, camera.height
    w2c = np.linalg.inv(c2w)
    R, t = w2c[:3, :3], w2c[:3, 3]
    means = g.means.astype(np.float64)
    cam = means @ R.T + t
    opacity = 1 / (1 + np.exp(-g.opacity_logits.astype(np.float64)))
    factor = quat_matrix(g.quats.astype(np.float64)) * np.exp(g.log_scales.astype(np.float64))[:, None, :]
    # the projection's Jacobian, evaluated no farther than 15 % of the image beyond its edges
    xz = np.clip(cam[:, 0] / cam[:, 2], (-0.5 - camera.cx) / camera.fx - 0.15 * w / camera.fx,
                 (w - 0.5 - camera.cx) / camera.fx + 0.15 * w / camera.fx)
    yz = np.clip(cam[:, 1] / cam[:, 2], (-0.5 - camera.cy) / camera.fy - 0.15 * h / camera.fy,
                 (h - 0.5 - camera.cy) / camera.fy + 0.15 * h / camera.fy)
    J = np.zeros((len(g), 2, 3))
    J[:, 0, 0], J[:, 0, 2] = camera.fx / cam[:, 2], -camera.fx * xz / cam[:, 2]
    J[:, 1, 1], J[:, 1, 2] = camera.fy / cam[:, 2], -camera.fy * yz / cam[:, 2]
    conics, defined = exact_conics(J @ R, factor)
    mean2 = np.stack([camera.fx * cam[:, 0] / cam[:, 2] + camera.cx, camera.fy * cam[:, 1] / cam[:, 2] + camera.cy], 1)
    keep = (opacity >= 1 / 255) & (cam[:, 2] > near) & defined
    dirs = means - c2w[:3, 3]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    colour = np.maximum(np.einsum("nk,nkc->nc", sh_basis(dirs, g.sh_degree), g.sh.astype(np.float64)) + 0.5, 0)
    idx = np.nonzero(keep)[0]
    idx = idx[np.argsort(cam[idx, 2].astype(np.float32), kind="stable")]
    px, py = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    T = np.ones((h, w))
    rgb = np.zeros((h, w, 3))
    dsum = np.zeros((h, w))
    live = np.ones((h, w), bool)
    ambiguous = np.zeros((h, w), bool)
    for i in idx:
        ca, cb, cc = conics[i]
        dx, dy = mean2[i, 0] - px, mean2[i, 1] - py
        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
        alpha = np.minimum(0.99, opacity[i] * np.exp(power))
        ambiguous |= live & (np.abs(alpha - 1 / 255) < eps)
        take = live & (alpha >= 1 / 255)
        after = T * (1 - alpha)
        ambiguous |= take & (np.abs(after - t_stop) < eps)
        stop = take & (after < t_stop)
        live &= ~stop
        add = take & ~stop
        weight = np.where(add, alpha * T, 0.0)
        rgb += weight[..., None] * colour[i]
        dsum += weight * cam[i, 2]
        T = np.where(add, after, T)
    rgb += T[..., None] * np.asarray(background, dtype=np.float64)
    scaled = rgb * 255
    ambiguous |= (np.abs(scaled - np.floor(scaled) - 0.5) < 1e-6).any(axis=2)
    opacity_map = 1 - T
    depth = np.where(opacity_map > 0, dsum / np.where(opacity_map > 0, opacity_map, 1), 0.0)
    return {"rgb_float": rgb, "rgb": np.clip(np.rint(scaled), 0, 255).astype(np.uint8), "depth": depth,
            "opacity": opacity_map, "ambiguous": ambiguous}
