"""The ray caster's screen rectangles hold every pixel whose ray meets the box (``raycast.screen_rects``), also
for boxes that reach behind the camera or hold it, and they end where such a box does."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.demo.primitives import T_MIN
from pytest_n2r.demo.raycast import screen_rects
from pytest_n2r.demo.scenes import look_at

FX = FY = 400.0
CX, CY = 240.0, 135.0

coordinate = st.floats(-6.0, 6.0, allow_nan=False)
extent = st.floats(0.0, 8.0, allow_nan=False)  # 0: a flat box, as a disc's


def rays_meet_box(c2w: np.ndarray, us: np.ndarray, vs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether the ray through each pixel ``(us, vs)`` meets the closed box ``lo, hi`` at ``t > T_MIN`` (slabs), as
    the ray caster's hits do."""
    d = np.stack([(us - CX) / FX, (vs - CY) / FY, np.ones_like(us)], axis=-1) @ c2w[:3, :3].T
    o = c2w[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    # a direction along a slab's plane: inside it for all t, or never
    along = d == 0
    inside = (o >= lo) & (o <= hi)
    near = np.where(along, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1)).max(axis=-1)
    far = np.where(along, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1)).min(axis=-1)
    return (near <= far) & (far > T_MIN)


@settings(max_examples=150, deadline=None)
@given(st.tuples(coordinate, coordinate, coordinate), st.tuples(extent, extent, extent),
       st.tuples(coordinate, coordinate, coordinate), st.tuples(coordinate, coordinate, coordinate))
def test_every_pixel_whose_ray_meets_a_box_lies_in_its_rectangle(lo, size, eye, target):
    lo = np.array(lo)
    hi = lo + np.array(size)
    eye, target = np.array(eye), np.array(target)
    if np.linalg.norm(target - eye) < 1e-3 or np.linalg.norm(np.cross(target - eye, [0.0, 0.0, 1.0])) < 1e-3:
        return  # no pose looks from here to there
    c2w = look_at(eye, target)
    (u_lo, u_hi, v_lo, v_hi), = screen_rects(np.concatenate([lo, hi])[None], c2w, FX, FY, CX, CY)
    us, vs = np.meshgrid(np.linspace(-400.0, 880.0, 97), np.linspace(-300.0, 570.0, 67))
    meet = rays_meet_box(c2w, us, vs, lo, hi)
    outside = (us < u_lo) | (us > u_hi) | (vs < v_lo) | (vs > v_hi)
    assert not np.any(meet & outside), (
        f"{np.sum(meet & outside)} pixels outside the rectangle {u_lo:.1f}..{u_hi:.1f} x {v_lo:.1f}..{v_hi:.1f} see "
        f"the box {lo} .. {hi} from {eye}, e.g. ({us[meet & outside][0]:.1f}, {vs[meet & outside][0]:.1f})")


def test_a_floor_reaching_behind_the_camera_ends_at_its_far_edge():
    # the wall scene's seabed seen from a captured pose (view 5): it used to get the whole image
    eye, target = np.array([-2.0, -2.2, 1.0]), np.array([-1.8, 0.0, 0.85])
    c2w = look_at(eye, target)
    seabed = np.array([[-14.0, -19.0, -1.6, 14.0, 9.0, -1.6]])
    (u_lo, u_hi, v_lo, v_hi), = screen_rects(seabed, c2w, FX, FY, CX, CY)
    assert (u_lo, u_hi, v_hi) == (-np.inf, np.inf, np.inf), "the seabed's sides and bottom are open"
    far_corners = (np.array([[-14.0, 9.0, -1.6], [14.0, 9.0, -1.6]]) - eye) @ c2w[:3, :3]
    top = np.min(FY * far_corners[:, 1] / far_corners[:, 2] + CY) - 1.0
    assert v_lo == top, f"the seabed's top is row {v_lo}, not its far edge's {top}"
    assert 150 < v_lo < 270, f"rows above {v_lo:.0f} still test the seabed"


def test_a_box_wholly_behind_the_camera_has_no_pixel_and_one_holding_it_every_pixel():
    c2w = look_at(np.zeros(3), np.array([0.0, 1.0, 0.0]))
    behind = np.array([-1.0, -3.0, -1.0, 1.0, -2.0, 1.0])
    around = np.array([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
    rects = screen_rects(np.stack([behind, around]), c2w, FX, FY, CX, CY)
    assert rects[0, 0] > rects[0, 1] and rects[0, 2] > rects[0, 3], f"a box behind the camera gets {rects[0]}"
    assert rects[1].tolist() == [-np.inf, np.inf, -np.inf, np.inf], f"a box around the camera gets {rects[1]}"
