"""Speed of the keypoint metrics on 5 000 x 5 000 points (target: repeatability < 50 ms).

Run: ``python benchmarks/metrics.py``. Views are 960x540 renders of a plane with exact depth (the
paper's test resolution); the follow-up camera is yawed by 5 degrees and moved sideways. Times are the
best of 5 runs, single thread, and include parsing, mapping both point sets and matching.
"""

from __future__ import annotations

import time

import numpy as np

from pytest_n2r.geometry import Camera, Transform, camera_rays
from pytest_n2r.metrics import interest_point_spread, repeatability
from pytest_n2r.metrics._matching import maximum_matching, mutual_nearest
from pytest_n2r.metrics.correspondence import DepthMapping
from pytest_n2r.render.view import RenderedView

N = 5000
CAMERA = Camera(960, 540, 800.0, 800.0, 479.5, 269.5)


def plane_view(c2w: np.ndarray) -> RenderedView:
    """The wall z = 4 seen from ``c2w``: exact z-depth, full opacity."""
    origins, dirs = camera_rays(CAMERA, c2w)
    depth = ((4.0 - origins[..., 2]) / dirs[..., 2]).astype(np.float32)
    return RenderedView(CAMERA, c2w, depth=depth, opacity=np.ones_like(depth))


def best_ms(fn, repeats: int = 5) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def main() -> None:
    rng = np.random.default_rng(0)
    source = plane_view(np.eye(4))
    follow = plane_view(Transform(yaw=5, x=0.2).apply(np.eye(4)))
    p = rng.uniform([0, 0], [CAMERA.width - 1, CAMERA.height - 1], size=(N, 2))
    mapped = DepthMapping(source, follow).to_follow(p)
    q = mapped.uv[mapped.visible] + rng.normal(0, 1.0, size=(int(mapped.visible.sum()), 2))
    q = np.vstack([q, rng.uniform([0, 0], [CAMERA.width - 1, CAMERA.height - 1], size=(N - len(q), 2))])
    plane = (np.array([0.0, 0.0, 1.0]), -4.0)
    rows = [
        ("largest one-to-one matching only (cKDTree)", lambda: maximum_matching(p, q, 2.0)),
        ("largest one-to-one matching only (numpy)", lambda: maximum_matching(p, q, 2.0, use_scipy=False)),
        ("mutual nearest neighbours only (cKDTree)", lambda: mutual_nearest(p, q, 2.0)),
        ("mutual nearest neighbours only (numpy)", lambda: mutual_nearest(p, q, 2.0, use_scipy=False)),
        ("repeatability, mapping='depth'", lambda: repeatability(px=2)(p, q, source, follow)),
        ("repeatability, mapping='depth', matching='mutual'",
         lambda: repeatability(px=2, matching="mutual")(p, q, source, follow)),
        ("repeatability, mapping='homography'",
         lambda: repeatability(px=2, mapping="homography", plane=plane)(p, q, source, follow)),
        ("interest_point_spread(radius=8), depth", lambda: interest_point_spread()(p, q, source, follow)),
    ]
    score = repeatability(px=2)(p, q, source, follow).score
    mutual = repeatability(px=2, matching="mutual")(p, q, source, follow).score
    print(f"Keypoint metrics, {N} x {N} points, {CAMERA.width}x{CAMERA.height} views, best of 5, one thread")
    print(f"(repeatability of this pair: {score:.3f}; {mutual:.3f} counting mutual nearest neighbours only)")
    print(f"{'what':<50} {'ms':>8}")
    times = {}
    for name, fn in rows:
        times[name] = best_ms(fn)
        print(f"{name:<50} {times[name]:>8.1f}")
    kd, npy = times[rows[2][0]], times[rows[3][0]]
    print(f"cKDTree matching is {npy / kd:.0f}x faster than the numpy fallback")


if __name__ == "__main__":
    main()
