"""Analytic surfaces of the demo scenes and their exact ray intersections (vectorized numpy).

Convention
----------
- World frame of the demo scenes: **z up**, scene units (think metres).
- Rays are ``origins + t * directions`` with directions of any length (the renderer passes directions with
  camera-frame z = 1, so ``t`` is the z-depth). ``intersect`` returns ``t`` per ray, ``inf`` on a miss;
  only hits with ``t > T_MIN`` count.
- ``surface`` returns, for hit points, the unit outward normal and the surface coordinates ``(a, b)`` that
  materials map (scene units; on vertical faces ``a`` runs right and ``b`` down as seen from outside).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from .materials import Material

__all__ = ["Primitive", "Group", "Disc", "Box", "Cylinder", "ReliefWall", "T_MIN", "slab_hits", "primitive_bounds"]

#: Hits closer than this (scene units along the ray parameter) are ignored.
T_MIN = 1e-6
_AXES = {"x": 0, "y": 1, "z": 2}
_UP = np.array([0.0, 0.0, 1.0])

#: What :meth:`Primitive.surface` returns: normals ``(N, 3)``, surface coordinates ``a`` and ``b`` ``(N,)``, and
#: ``(indices, material)`` groups.
Surface = tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[np.ndarray, Material]]]


class Primitive(ABC):
    """A surface with an exact ray intersection."""

    @abstractmethod
    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Ray parameter ``t`` ``(N,)`` of the first hit of rays ``o + t d`` (each ``(N, 3)``), ``inf`` on a miss."""

    @abstractmethod
    def surface(self, p: np.ndarray) -> Surface:
        """For hit points ``p (N, 3)``: normals ``(N, 3)``, ``a``, ``b`` and ``(indices, material)`` groups."""

    @abstractmethod
    def describe(self) -> str:
        """A stable text form of every parameter (part of the scene's content hash)."""


def slab_hits(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ``t`` of rays through the axis-aligned box ``[lo, hi]`` (no hit where entry > exit)."""
    t_near = np.full(len(o), -np.inf)
    t_far = np.full(len(o), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            inv = 1.0 / d[:, k]
            t0, t1 = (lo[k] - o[:, k]) * inv, (hi[k] - o[:, k]) * inv
            # a ray parallel to a slab gives (+-inf, +-inf) or NaN on its boundary; fmin/fmax ignore NaN
            t_near = np.fmax(t_near, np.fmin(t0, t1))
            t_far = np.fmin(t_far, np.fmax(t0, t1))
    return t_near, t_far


@dataclass(frozen=True, eq=False)
class Group:
    """Primitives inside the box ``[lo, hi]``: rays that miss the box are not tested against them (speed)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    children: tuple[Primitive, ...]


def _vertical_face_coords(p: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a`` to the right and ``b`` down, seen from outside a vertical face with outward ``normal``."""
    right = np.cross(-normal, _UP)
    return p @ right, -p[:, 2]


@dataclass(frozen=True, eq=False)
class Disc(Primitive):
    """A horizontal disc ``z = height``, radius ``radius`` about ``(cx, cy)`` (the ground); normal +z."""

    height: float
    radius: float
    material: Material
    centre: tuple[float, float] = (0.0, 0.0)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height - o[:, 2]) / d[:, 2]
        p = o + t[:, None] * d
        r2 = (p[:, 0] - self.centre[0]) ** 2 + (p[:, 1] - self.centre[1]) ** 2
        return np.where((t > T_MIN) & (r2 <= self.radius**2), t, np.inf)

    def surface(self, p: np.ndarray) -> Surface:
        n = np.broadcast_to(_UP, p.shape)
        return n, p[:, 0], p[:, 1], [(np.arange(len(p)), self.material)]

    def describe(self) -> str:
        return f"Disc({self.height!r}, {self.radius!r}, {self.centre}, {self.material.describe()})"


@dataclass(frozen=True, eq=False)
class Box(Primitive):
    """An axis-aligned box ``[lo, hi]`` with a material per face (``"+x"``, ``"-x"``, ... ``"-z"``).

    ``materials`` maps face names to materials; ``"*"`` is the default for faces not named.
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    materials: dict[str, Material]

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        t_near, t_far = slab_hits(o, d, np.asarray(self.lo, float), np.asarray(self.hi, float))
        hit = (t_near <= t_far) & (t_far > T_MIN)
        t = np.where(t_near > T_MIN, t_near, t_far)  # from inside, the exit face
        return np.where(hit, t, np.inf)

    def _material(self, face: str) -> Material:
        return self.materials[face] if face in self.materials else self.materials["*"]

    def surface(self, p: np.ndarray) -> Surface:
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        dist = np.concatenate([np.abs(p - lo), np.abs(p - hi)], axis=1)  # -x -y -z +x +y +z
        face = np.argmin(dist, axis=1)
        normals = np.zeros_like(p)
        a = np.empty(len(p))
        b = np.empty(len(p))
        groups = []
        for k, name in enumerate(("-x", "-y", "-z", "+x", "+y", "+z")):
            idx = np.nonzero(face == k)[0]
            if not idx.size:
                continue
            n = np.zeros(3)
            n[k % 3] = 1.0 if k >= 3 else -1.0
            normals[idx] = n
            if k % 3 == 2:
                a[idx], b[idx] = p[idx, 0], p[idx, 1]
            else:
                a[idx], b[idx] = _vertical_face_coords(p[idx], n)
            groups.append((idx, self._material(name)))
        return normals, a, b, groups

    def describe(self) -> str:
        mats = {k: self.materials[k].describe() for k in sorted(self.materials)}
        return f"Box({self.lo}, {self.hi}, {mats})"


@dataclass(frozen=True, eq=False)
class Cylinder(Primitive):
    """A capped cylinder along world axis ``axis`` (``"x"``, ``"y"`` or ``"z"``) through ``centre``.

    Side coordinates: ``a`` = arc length around the axis, ``b`` = position along it. Cap coordinates are
    relative to the axis (so :class:`~pytest_n2r.demo.materials.Radial` draws hubs on them).
    """

    centre: tuple[float, float, float]
    axis: str
    radius: float
    half_length: float
    side: Material
    cap: Material

    def _frame(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        k = _AXES[self.axis]
        return o - np.asarray(self.centre), d, k

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        q, d, k = self._frame(o, d)
        i, j = [m for m in range(3) if m != k]
        A = d[:, i] ** 2 + d[:, j] ** 2
        B = 2 * (q[:, i] * d[:, i] + q[:, j] * d[:, j])
        C = q[:, i] ** 2 + q[:, j] ** 2 - self.radius**2
        disc = B * B - 4 * A * C
        best = np.full(len(q), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(np.where(disc >= 0, disc, np.nan))
            for t in ((-B - root) / (2 * A), (-B + root) / (2 * A)):
                along = q[:, k] + t * d[:, k]
                ok = (t > T_MIN) & (np.abs(along) <= self.half_length)
                best = np.where(ok & (t < best), t, best)
            for sign in (-1.0, 1.0):
                t = (sign * self.half_length - q[:, k]) / d[:, k]
                pi, pj = q[:, i] + t * d[:, i], q[:, j] + t * d[:, j]
                ok = (t > T_MIN) & (pi * pi + pj * pj <= self.radius**2)
                best = np.where(ok & (t < best), t, best)
        return best

    def surface(self, p: np.ndarray) -> Surface:
        k = _AXES[self.axis]
        i, j = [m for m in range(3) if m != k]
        q = p - np.asarray(self.centre)
        radial = np.hypot(q[:, i], q[:, j])
        on_cap = (np.abs(np.abs(q[:, k]) - self.half_length) < 1e-7 * max(1.0, self.half_length)) & (
            radial < self.radius * (1 - 1e-9)
        )
        normals = np.zeros_like(p)
        side = np.nonzero(~on_cap)[0]
        normals[side, i] = q[side, i] / self.radius
        normals[side, j] = q[side, j] / self.radius
        cap = np.nonzero(on_cap)[0]
        normals[cap, k] = np.sign(q[cap, k])
        a = np.where(on_cap, q[:, i], np.arctan2(q[:, j], q[:, i]) * self.radius)
        b = np.where(on_cap, q[:, j], q[:, k])
        return normals, a, b, [(side, self.side), (cap, self.cap)]

    def describe(self) -> str:
        return (
            f"Cylinder({self.centre}, {self.axis!r}, {self.radius!r}, {self.half_length!r}, "
            f"{self.side.describe()}, {self.cap.describe()})"
        )


@dataclass(frozen=True, eq=False)
class ReliefWall(Primitive):
    """A vertical wall facing -y: the surface ``y = y0 - h(x, z)`` over ``x0 <= x <= x1, z0 <= z <= z1``.

    The relief ``h(x, z) = depth * (0.5 + sum_k amp_k * sin(fx_k x + px_k) * sin(fz_k z + pz_k))`` lies in
    ``[0, depth]`` (the amplitudes sum to at most 0.5) and is smooth, so normals are exact from its
    gradient. Along a ray the residual ``f(t) = y - y0 + h`` is negative where the ray enters the relief
    slab and positive where it leaves it. Where the ray is steep enough that ``f`` is monotonic
    (``d_y > L |d_xz|`` with ``L`` a bound of ``|grad h|``: within about 70° of the wall's normal) the root
    is found by Newton's method safeguarded by bisection (at most ``newton`` iterations, until the
    residual is below ``1e-7``); other rays march ``steps`` samples to the first sign change and bisect
    ``bisections`` times. The relief is evaluated in float32, so hits are within about ``1e-6`` scene units of
    the surface.
    """

    y0: float
    extent: tuple[float, float, float, float]  # x0, x1, z0, z1
    depth: float
    waves: tuple[tuple[float, float, float, float, float], ...]  # amp, fx, px, fz, pz
    material: Material
    newton: int = 40
    steps: int = 32
    bisections: int = 40
    _w: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        w = np.asarray(self.waves, dtype=np.float64).reshape(-1, 5)
        if np.abs(w[:, 0]).sum() > 0.5 + 1e-12:
            raise ValueError("ReliefWall: the wave amplitudes must sum to at most 0.5")
        object.__setattr__(self, "_w", w)

    @property
    def slope_bound(self) -> float:
        """An upper bound ``L`` of ``|grad h|`` (dimensionless)."""
        return float(self.depth * np.sum(np.abs(self._w[:, 0]) * np.hypot(self._w[:, 1], self._w[:, 3])))

    def height(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The relief ``h(x, z)`` in scene units, in ``[0, depth]`` (how far the surface stands out)."""
        return self.height_and_gradient(x, z)[0]

    def height_and_gradient(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``h``, ``dh/dx`` and ``dh/dz`` at ``(x, z)``."""
        x32, z32 = np.asarray(x, np.float32), np.asarray(z, np.float32)  # float32 trig: ~10x faster
        h = np.full(np.shape(x), 0.5, np.float32)
        gx = np.zeros(np.shape(x), np.float32)
        gz = np.zeros(np.shape(x), np.float32)
        for amp, fx, px, fz, pz in self._w.astype(np.float32):
            ax, az = fx * x32 + px, fz * z32 + pz
            sx, cx, sz, cz = np.sin(ax), np.cos(ax), np.sin(az), np.cos(az)
            h += amp * sx * sz
            gx += amp * fx * cx * sz
            gz += amp * fz * sx * cz
        d = self.depth
        return d * h.astype(np.float64), d * gx.astype(np.float64), d * gz.astype(np.float64)

    def residual(self, p: np.ndarray) -> np.ndarray:
        """``y - (y0 - h)``: negative in front of the surface, positive inside the wall (scene units)."""
        return p[:, 1] - (self.y0 - self.height(p[:, 0], p[:, 2]))

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        out = np.full(len(o), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_in = (self.y0 - self.depth - o[:, 1]) / d[:, 1]
            t_out = (self.y0 - o[:, 1]) / d[:, 1]
        live = np.nonzero((d[:, 1] > 0) & (t_out > T_MIN))[0]
        if not live.size:
            return out
        lo, hi = np.maximum(t_in[live], T_MIN), t_out[live]
        o, d = o[live], d[live]
        t = np.full(len(live), np.inf)
        steep = d[:, 1] > 1.05 * self.slope_bound * np.hypot(d[:, 0], d[:, 2])
        idx = np.nonzero(steep)[0]
        t[idx] = self._newton(o[idx], d[idx], lo[idx], hi[idx])
        idx = np.nonzero(~steep)[0]
        if idx.size:
            t[idx] = self._march(o[idx], d[idx], lo[idx], hi[idx])
        x0, x1, z0, z1 = self.extent
        with np.errstate(invalid="ignore"):
            px, pz = o[:, 0] + t * d[:, 0], o[:, 2] + t * d[:, 2]
            ok = np.isfinite(t) & (px >= x0) & (px <= x1) & (pz >= z0) & (pz <= z1)
        out[live[ok]] = t[ok]
        return out

    def _f(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual along the rays and its derivative with respect to ``t``."""
        h, gx, gz = self.height_and_gradient(o[:, 0] + t * d[:, 0], o[:, 2] + t * d[:, 2])
        return o[:, 1] + t * d[:, 1] - self.y0 + h, d[:, 1] + gx * d[:, 0] + gz * d[:, 2]

    def _newton(self, o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The single root of a monotonic residual in ``[lo, hi]``: Newton steps, bisection as a fallback.

        Iterates only the rays whose residual is still above ``1e-7`` units, at most ``newton`` times.
        """
        a, b = lo.copy(), hi.copy()
        t = 0.5 * (a + b)
        active = np.arange(len(t))
        for _ in range(self.newton):
            f, df = self._f(o[active], d[active], t[active])
            done = np.abs(f) <= 1e-7
            active, f, df = active[~done], f[~done], df[~done]
            if not active.size:
                break
            ta = t[active]
            a[active] = np.where(f < 0, ta, a[active])
            b[active] = np.where(f < 0, b[active], ta)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = ta - f / df
            inside = (step > a[active]) & (step < b[active])
            t[active] = np.where(inside, step, 0.5 * (a[active] + b[active]))
        return t

    def _march(self, o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The first root in ``[lo, hi]`` of a residual that may not be monotonic (grazing rays)."""
        res = lambda t: self.residual(o + t[:, None] * d)
        a, b = lo.copy(), lo.copy()
        found = res(lo) >= 0
        t_prev = lo
        for s in range(1, self.steps + 1):
            t = lo + (hi - lo) * (s / self.steps)
            new = ~found & (res(t) >= 0)
            a, b = np.where(new, t_prev, a), np.where(new, t, b)
            found |= new
            t_prev = t
        for _ in range(self.bisections):
            m = 0.5 * (a + b)
            inside = res(m) >= 0
            a, b = np.where(inside, a, m), np.where(inside, m, b)
        return np.where(found, 0.5 * (a + b), np.inf)

    def surface(self, p: np.ndarray) -> Surface:
        _, gx, gz = self.height_and_gradient(p[:, 0], p[:, 2])
        n = np.stack([-gx, -np.ones(len(p)), -gz], axis=1)  # outward: towards -y
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        a, b = _vertical_face_coords(p, np.array([0.0, -1.0, 0.0]))
        return n, a, b, [(np.arange(len(p)), self.material)]

    def describe(self) -> str:
        return (
            f"ReliefWall({self.y0!r}, {self.extent}, {self.depth!r}, {self.waves}, {self.newton}, "
            f"{self.steps}, {self.bisections}, {self.material.describe()})"
        )


def primitive_bounds(prim: Primitive) -> list[float]:
    """``[*lo, *hi]`` of an axis-aligned box that holds every hit of ``prim`` (scene units, world frame): the ray
    caster's culling boxes and the check that a :class:`Group`'s box holds its children."""
    if isinstance(prim, Disc):
        (x, y), r = prim.centre, prim.radius
        return [x - r, y - r, prim.height, x + r, y + r, prim.height]
    if isinstance(prim, Box):
        return [*prim.lo, *prim.hi]
    if isinstance(prim, Cylinder):
        half = [prim.radius] * 3
        half["xyz".index(prim.axis)] = prim.half_length
        return [c - h for c, h in zip(prim.centre, half)] + [c + h for c, h in zip(prim.centre, half)]
    if isinstance(prim, ReliefWall):
        x0, x1, z0, z1 = prim.extent
        return [x0, prim.y0 - prim.depth, z0, x1, prim.y0, z1]
    raise TypeError(f"primitive_bounds: {type(prim).__name__} is not a primitive of pytest_n2r.demo.primitives")
