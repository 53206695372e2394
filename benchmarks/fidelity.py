"""Fidelity the way the tests use a scene: held-out PSNR / SSIM and the reality-to-field shift of ORB, SIFT
and AKAZE (repeatability and interest-point spread, reference image vs field render at the same held-out
pose), per scene.

Run: ``python benchmarks/fidelity.py SCENE [SCENE ...] [--size 480] [--views N] [--ceiling] [--bands]
[--placement] [--neighbours] [--json out.json]``

``SCENE`` is a ``.n2r`` file (reference: the photos it stores) or ``demo:wall-field`` / ``demo:object-field``
(reference: the exact scene's render at the same pose). Only held-out views are scored; nothing in this
script is tuned, and a scene fitted with a validation split must hold out its reported views separately
(see docs/scene-field.md). ``--targets`` checks issue 14's targets (PSNR >= 28 dB, repeatability >= 0.65
for each detector) and prints which are met. ``--ceiling`` measures what the targets ask of a render: each
detector's repeatability between the reference image and the reference image itself degraded as a render
degrades it (half, a third, a quarter of its resolution, a blur, JPEG), with the render's geometry, so no
field error enters; and whether the metric measures the field or the detector's own noise (the image sampled
half a pixel off, with and without the mapping knowing it; sensor noise). ``--bands`` says where a render's
error is: PSNR against the reference after both are blurred (Gaussian, 1, 2 and 4 px: what is left is shape,
placement and colour, not fine texture) and after the best per-channel gain and offset (exposure), on the
held-out views and on as many fitted (training) views spread over the capture (the gap between the two is
what the fit does not carry to new poses).
``--neighbours`` scores, beside the render, the nearest other fitted photo brought to each pose through the
field's depth (:mod:`pytest_n2r.relation.floor.nearby`), and the same aligned onto the reference by optical flow
(:func:`aligned_onto`): what a real image
taken nearby scores against the reference, the yardstick the targets are read against; on the held-out views
and on as many fitted views.
``--placement`` says where the render's texture lands: its global shift against the reference per view; the
fidelity of the field with its view-dependent colour frozen at the capture's mean viewing direction; at each
held-out pose refined (the rigid correction that best aligns the render with the reference: how much of the
shift is the capture's pose, not the field); and rendered with 2×2 rays a pixel, area-averaged as the reference
photo was (how much is a pixel's footprint, not the field).
Results: docs/scene-field.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace

import cv2
import numpy as np
import torch
from _scoring import defined_mean, format_repeatabilities

from pytest_n2r.errors import N2RError
from pytest_n2r.metrics.image_quality import psnr, ssim
from pytest_n2r.relation.floor.nearby import nearby_image
from pytest_n2r.relation.floor.reference import floor_views, reference_image, reference_kind, shift_sample
from pytest_n2r.render.size import RenderSize
from pytest_n2r.render.view import OUTPUTS, RenderedView
from pytest_n2r.study.fidelity import DETECTORS, measure_fidelity
from pytest_n2r.study.suts import resolve_sut

#: Issue 14's targets on the fox (10-minute CPU fit): held-out PSNR and each detector's repeatability.
TARGET_PSNR_DB = 28.0
TARGET_REPEATABILITY = 0.65


def load(spec: str):
    """A scene from a ``.n2r`` path or ``demo:<name>-field``, rendered on the CPU, photos loaded."""
    if spec.startswith("demo:"):
        from pytest_n2r.demo import load_demo

        return load_demo(spec[len("demo:"):], "cpu")
    from pytest_n2r.scene import load_scene

    return load_scene(spec, device="cpu")


def _rescaled(factor: int):
    """The image at 1/``factor`` of its resolution (area averaging), brought back to its size (bilinear)."""
    def degrade(image: np.ndarray) -> np.ndarray:
        h, w = image.shape[:2]
        small = cv2.resize(image, (max(1, round(w / factor)), max(1, round(h / factor))), interpolation=cv2.INTER_AREA)
        return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    return degrade


class _Shifted:
    """The image moved by ``(du, dv)`` pixels (Lanczos resampling, edges reflected): the same scene sampled on
    another pixel grid. ``known``: the mapping is told (its principal point moves with the image), so a
    detector's points are compared where they should land; otherwise the shift is an error the metric sees, as
    a pose that is off by that much."""

    def __init__(self, du: float, dv: float, known: bool):
        self.offset = (du, dv) if known else (0.0, 0.0)
        self.matrix = np.array([[1.0, 0.0, du], [0.0, 1.0, dv]])

    def __call__(self, image: np.ndarray) -> np.ndarray:
        h, w = image.shape[:2]
        return cv2.warpAffine(image, self.matrix, (w, h), flags=cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REFLECT)


def _noisy(sigma: float):
    """The image with Gaussian noise of ``sigma`` grey levels (a fixed seed), as a sensor adds."""
    def degrade(image: np.ndarray) -> np.ndarray:
        noise = np.random.default_rng(0).normal(0.0, sigma, image.shape)
        return np.clip(np.rint(image + noise), 0, 255).astype(np.uint8)
    return degrade


def _jpeg(image: np.ndarray, quality: int = 90) -> np.ndarray:
    _, encoded = cv2.imencode(".jpg", np.ascontiguousarray(image[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
    return np.ascontiguousarray(cv2.imdecode(encoded, cv2.IMREAD_COLOR)[..., ::-1])


#: ``--ceiling``: how the reference image is degraded (name → H×W×3 uint8 RGB → same). The first is the image
#: itself: every detector must find all of its points again (repeatability 1), or the mapping is wrong; so must
#: the second (a whole-pixel shift the mapping is told of resamples nothing), or the shifts' convention is wrong.
#: The rows up to the noise ask whether the metric measures the field or the detector's own noise: the scene
#: sampled half a pixel off, a pose error of half a pixel, sensor noise.
DEGRADATIONS = {
    "the reference itself": np.array,
    "shifted 1 px right and down, mapping told": _Shifted(1.0, 1.0, known=True),
    "shifted 0.5 px right and down, mapping told": _Shifted(0.5, 0.5, known=True),
    "shifted 0.5 px right and down, mapping not told": _Shifted(0.5, 0.5, known=False),
    "Gaussian noise, sigma 2 grey levels": _noisy(2.0),
    "JPEG quality 90": _jpeg,
    "Gaussian blur, sigma 1 px": lambda image: cv2.GaussianBlur(image, (0, 0), 1.0),
    "1/2 resolution": _rescaled(2),
    "1/3 resolution": _rescaled(3),
    "1/4 resolution": _rescaled(4),
}


def ceiling(scene, size: str, max_views: int | None) -> dict[str, dict]:
    """Per degradation (:data:`DEGRADATIONS`): PSNR / SSIM of the degraded reference image against the reference,
    and each detector's repeatability between the two, on ``scene``'s held-out views at ``size``; their points are
    paired by the homography between the two cameras (one pose: the identity, or the shift a degradation tells
    the mapping of), as in :func:`measure_fidelity`. Empty when the scene has no reference image."""
    kind, _ = reference_kind(scene)
    if kind == "none":
        return {}
    render_size = RenderSize.parse(size)
    suts = {name: resolve_sut(name, None) for name in DETECTORS}
    rows = {name: {"psnr": [], "ssim": [], **{d: [] for d in DETECTORS}} for name in DEGRADATIONS}
    for view in floor_views(scene, max_views):
        camera = render_size.apply(view.camera)
        rendered = scene.render(view.c2w, camera, ("rgb", "depth", "opacity"))
        image = np.asarray(reference_image(scene, view, camera, kind))
        real = RenderedView(rendered.camera, rendered.c2w, rgb=image, depth=rendered.depth, opacity=rendered.opacity)
        outputs = {d: sut.fn(image) for d, sut in suts.items()}
        for name, degrade in DEGRADATIONS.items():
            worse = degrade(image)
            du, dv = getattr(degrade, "offset", (0.0, 0.0))
            moved = replace(rendered.camera, cx=rendered.camera.cx + du, cy=rendered.camera.cy + dv)
            other = RenderedView(moved, rendered.c2w, rgb=worse, depth=rendered.depth, opacity=rendered.opacity)
            rows[name]["psnr"].append(psnr(image, worse))
            rows[name]["ssim"].append(ssim(image, worse))
            for d, score in _repeatabilities(real, other, view.name, outputs).items():
                rows[name][d].append(score)
    return {name: {"psnr": float(np.mean(row["psnr"])), "ssim": float(np.mean(row["ssim"])),
                   **{d: defined_mean(row[d]) for d in DETECTORS}} for name, row in rows.items()}


def _repeatabilities(reference: RenderedView, other: RenderedView, view: str, outputs: dict) -> dict[str, float]:
    """Each detector's repeatability between ``reference`` (a view's reference image with its render's geometry;
    ``outputs``: the detectors' outputs on it) and ``other`` (another image of the same pose, same geometry);
    NaN where the metric is undefined."""
    scores = {}
    for d in DETECTORS:
        sut = resolve_sut(d, None)
        metric = sut.same_pose_metrics()["repeatability"]
        sample = shift_sample(metric, outputs[d], sut.fn(other.rgb), reference, other, view)
        scores[d] = sample.score if sample.valid else float("nan")
    return scores


def aligned_onto(reference: np.ndarray, image: np.ndarray) -> np.ndarray:
    """``image`` moved onto ``reference`` (both H×W×3 uint8 RGB) by the dense optical flow between their grey
    images (OpenCV's DIS, medium preset), resampled bilinearly: what placement error is left, taken out."""
    grey = [cv2.cvtColor(np.ascontiguousarray(x), cv2.COLOR_RGB2GRAY) for x in (reference, image)]
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(grey[0], grey[1], None)
    h, w = grey[0].shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(np.ascontiguousarray(image), u + flow[..., 0], v + flow[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


#: ``--neighbours``: the images scored against each view's reference (see :mod:`pytest_n2r.relation.floor.nearby`).
NEIGHBOUR_ROWS = ("the field's render", "the nearest other photo, brought to the pose by the field's depth",
                  "the same, aligned onto the reference by optical flow")
#: ``--neighbours``: the fitted views are also grouped by how far (degrees between optical axes) their nearest
#: other photo is, since what a photo taken nearby scores falls with the angle.
NEIGHBOUR_ANGLE_BINS = ((0.0, 2.0), (2.0, 4.0), (4.0, 180.0))


def _neighbour_record(scene, view, render_size: RenderSize, kind: str) -> dict | None:
    """One view's :func:`neighbours` measurements: the nearest other photo's angle, distance and share of pixels
    brought, and PSNR and each detector's repeatability of each of :data:`NEIGHBOUR_ROWS`; ``None`` when the
    scene has no other fitted view with a reference image."""
    def render(s, c2w: np.ndarray, camera) -> RenderedView:
        return s.render(c2w, camera, OUTPUTS if s is scene else ("rgb",))

    camera = render_size.apply(view.camera)
    rendered = render(scene, view.c2w, camera)
    reference = np.asarray(reference_image(scene, view, camera, kind, render))
    near = nearby_image(scene, view, rendered, render_size, kind, render)
    if near is None:
        return None
    real = replace(rendered, rgb=reference)
    outputs = {d: resolve_sut(d, None).fn(reference) for d in DETECTORS}
    scores = {}
    for name, image in zip(NEIGHBOUR_ROWS, (rendered.rgb, near.image, aligned_onto(reference, near.image))):
        scores[name] = {"psnr": psnr(reference, image),
                        **_repeatabilities(real, replace(rendered, rgb=image), view.name, outputs)}
    return {"view": view.name, "degrees": near.degrees, "reference lengths": near.distance,
            "share brought": near.share, "scores": scores}


def neighbours(scene, size: str, max_views: int | None) -> dict[str, dict]:
    """What a real image taken nearby scores against each view's reference, beside the field's render: per group
    of views (the held-out ones; as many fitted ones spread over the capture, and those again by the angle to
    their nearest other photo, :data:`NEIGHBOUR_ANGLE_BINS`), PSNR and each detector's repeatability of each of
    :data:`NEIGHBOUR_ROWS` against the reference, and how far the nearest other photo (of the fitted views) was
    (medians). Empty without reference images."""
    kind, _ = reference_kind(scene)
    if kind == "none":
        return {}
    render_size = RenderSize.parse(size)
    fitted = [v for v in scene.views if v.split == "train"]
    spread = fitted if max_views is None or len(fitted) <= max_views else [
        fitted[i] for i in np.linspace(0, len(fitted) - 1, max_views).round().astype(int)]
    held = [r for v in floor_views(scene, max_views) if (r := _neighbour_record(scene, v, render_size, kind))]
    fits = [r for v in spread if (r := _neighbour_record(scene, v, render_size, kind))]
    groups = {"held out": held, "fitted": fits}
    for low, high in NEIGHBOUR_ANGLE_BINS:
        groups[f"fitted, nearest {low:g}–{high:g}°" if high < 180 else f"fitted, nearest over {low:g}°"] = [
            r for r in fits if low <= r["degrees"] < high]
    out = {}
    for group, records in groups.items():
        if not records:
            continue
        out[group] = {"views": len(records),
                      "nearest": {k: float(np.median([r[k] for r in records]))
                                  for k in ("degrees", "reference lengths", "share brought")},
                      "rows": {name: {"psnr": float(np.mean([r["scores"][name]["psnr"] for r in records])),
                                      **{d: defined_mean([r["scores"][name][d] for r in records]) for d in DETECTORS}}
                               for name in NEIGHBOUR_ROWS},
                      "per view": records}
    return out


#: How :func:`_found_again` counts a point found again, in the order it returns them.
FOUND_AGAIN = ("one to one", "mutual", "plain")


def _found_again(a: np.ndarray, b: np.ndarray, px: float) -> tuple[float, float, float]:
    """Points ``a`` and ``b`` of one pose (identity mapping): the share found again within ``px`` one to one (the
    largest one-to-one matching over the smaller set, as the metric counts), as mutual nearest neighbours (what
    the metric counted before its ``result_version`` 2) and plainly (each point of ``a`` with a point of ``b``
    within ``px``)."""
    from scipy.spatial import cKDTree

    from pytest_n2r.metrics._matching import maximum_matching, mutual_nearest

    smaller = max(min(len(a), len(b)), 1)
    plain = float(np.mean(cKDTree(b).query(a)[0] <= px)) if len(a) and len(b) else float("nan")
    return len(maximum_matching(a, b, px)) / smaller, len(mutual_nearest(a, b, px)) / smaller, plain


def _inner_points(detect, rgb: np.ndarray, shift: int = 0, border: int = 16) -> np.ndarray:
    """The distinct points ``detect`` finds on ``rgb``, moved back by ``shift`` px along both axes, without those
    within ``border`` px of the image's edges."""
    h, w = rgb.shape[:2]
    p = np.unique(np.round(np.asarray(detect(rgb), dtype=np.float64)[:, :2], 6), axis=0) - shift
    return p[(p[:, 0] > border) & (p[:, 1] > border) & (p[:, 0] < w - 1 - border) & (p[:, 1] < h - 1 - border)]


def crowding(scene, size: str, max_views: int | None) -> dict[str, dict[str, float]]:
    """Per detector, on the held-out views: ``crowded``, the share of its points on the reference image that have
    another of its points within the repeatability metric's tolerance; and the share of points found again one to
    one, as mutual nearest neighbours and plainly (:func:`_found_again`) in the reference moved by one whole pixel
    (nothing resampled) and in the render. Where points crowd, mutual nearest neighbours pair a point that moved a
    little with a neighbour's counterpart and count both as lost. Points within 16 px of the border are left out.
    Empty without reference images."""
    from scipy.spatial import cKDTree

    kind, _ = reference_kind(scene)
    if kind == "none":
        return {}
    render_size = RenderSize.parse(size)
    suts = {name: resolve_sut(name, None) for name in DETECTORS}
    rows: dict[str, dict[str, list]] = {d: {"crowded": [], "moved": [], "render": []} for d in DETECTORS}
    for view in floor_views(scene, max_views):
        camera = render_size.apply(view.camera)
        image = np.asarray(reference_image(scene, view, camera, kind))
        images = {"moved": np.pad(image, ((1, 0), (1, 0), (0, 0)), mode="reflect")[:-1, :-1],
                  "render": scene.render(view.c2w, camera, ("rgb",)).rgb}
        for d in DETECTORS:
            px = suts[d].metrics()["repeatability"].px
            mine = _inner_points(suts[d].fn, image)
            if len(mine) > 1:
                rows[d]["crowded"].append(float(np.mean(cKDTree(mine).query(mine, k=2)[0][:, 1] <= px)))
            for name, other in images.items():
                rows[d][name].append(_found_again(mine, _inner_points(suts[d].fn, other, int(name == "moved")), px))
    def mean(values: list[float]) -> float:
        finite = [v for v in values if np.isfinite(v)]
        return float(np.mean(finite)) if finite else float("nan")

    return {d: {"crowded": mean(r["crowded"]),
                **{f"{name} {how}": mean([x[k] for x in r[name]])
                   for name in ("moved", "render") for k, how in enumerate(FOUND_AGAIN)}}
            for d, r in rows.items()}


#: ``--bands``: the Gaussian blurs (pixels) applied to both images before their PSNR.
BAND_SIGMAS = (1.0, 2.0, 4.0)


def _gain_offset_psnr(reference: np.ndarray, render: np.ndarray) -> float:
    """PSNR after the render's best per-channel gain and offset (least squares) towards the reference."""
    x, y = render.reshape(-1, 3).astype(np.float64), reference.reshape(-1, 3).astype(np.float64)
    fitted = np.stack([np.polyval(np.polyfit(x[:, c], y[:, c], 1), x[:, c]) for c in range(3)], axis=1)
    return psnr(y.reshape(reference.shape), np.clip(fitted, 0, 255).reshape(reference.shape), data_range=255.0)


def bands(scene, size: str, max_views: int | None) -> dict[str, dict]:
    """``{"held out": ..., "fitted": ...}``: the mean PSNR of the render against the reference image, plain,
    after a Gaussian blur of both (:data:`BAND_SIGMAS`) and after a per-channel gain and offset, on the held-out
    views and on as many training views spread over the capture. Empty without reference images."""
    kind, _ = reference_kind(scene)
    if kind == "none":
        return {}
    render_size = RenderSize.parse(size)
    heldout = floor_views(scene, max_views)
    train = [v for v in scene.views if v.split != "heldout" and (kind == "exact" or v.image is not None)]
    train = [train[i] for i in np.linspace(0, len(train) - 1, min(len(heldout), len(train))).round().astype(int)]
    out = {}
    for label, views in (("held out", heldout), ("fitted", train)):
        rows = []
        for view in views:
            camera = render_size.apply(view.camera)
            render = scene.render(view.c2w, camera, ("rgb",)).rgb
            image = np.asarray(reference_image(scene, view, camera, kind))
            blurred = [psnr(cv2.GaussianBlur(image.astype(np.float32), (0, 0), sigma),
                            cv2.GaussianBlur(render.astype(np.float32), (0, 0), sigma), data_range=255.0)
                       for sigma in BAND_SIGMAS]
            rows.append([psnr(image, render), *blurred, _gain_offset_psnr(image, render)])
        out[label] = {"views": len(views), "psnr": dict(zip(["plain", *map(str, BAND_SIGMAS), "gain"],
                                                                np.mean(rows, axis=0).tolist()))}
    return out


def _offset(reference: np.ndarray, render: np.ndarray) -> tuple[float, float]:
    """The render's global shift ``(du, dv)`` in pixels against the reference (phase correlation of the grey
    images under a Hann window: where the render's texture lands as a whole)."""
    grey = [cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY).astype(np.float64)
            for image in (reference, render)]
    window = cv2.createHanningWindow(grey[0].shape[::-1], cv2.CV_64F)
    (du, dv), _ = cv2.phaseCorrelate(grey[0], grey[1], window)
    return float(du), float(dv)


def _frozen_view_dependence(scene) -> np.ndarray:
    """Fold each vertex's degree-1 spherical harmonics into its constant term at the capture's mean viewing
    direction (the mean of the views' optical axes) and zero them, in place: the field's colour as seen from
    that direction, at every pose. Returns the direction (world axes)."""
    from pytest_n2r.field.kernels import SH_C0, SH_C1

    axes = np.stack([v.c2w[:3, 2] for v in scene.views])
    x, y, z = axes.mean(axis=0) / np.linalg.norm(axes.mean(axis=0))
    coeff = scene.field.values[:, 1:].view(-1, 4, 3)  # a view: the changes land in the field
    basis = torch.tensor([-SH_C1 * y, SH_C1 * z, -SH_C1 * x], dtype=coeff.dtype)
    coeff[:, 0] += torch.einsum("l,nlc->nc", basis, coeff[:, 1:]) / SH_C0
    coeff[:, 1:] = 0.0
    return np.array([x, y, z])


def _refined_pose(scene, view, camera, reference: np.ndarray) -> tuple[np.ndarray, dict]:
    """The pose near ``view``'s at which ``scene``'s render best matches ``reference``: a rigid correction in the
    camera's frame (rotation vector in milliradians, translation in thousandths of the render's median z-depth)
    found by Powell's method on the mean squared error, 8 px borders left out. Returns the refined camera-to-world
    pose and ``{"psnr": (before, after), "rotation px", "translation"}`` (the rotation's length times the focal
    length; the translation's length in thousandths of the median depth)."""
    from scipy.optimize import minimize
    from scipy.spatial.transform import Rotation

    depth = float(np.median(scene.render(view.c2w, camera, ("depth",)).depth))
    target = reference[8:-8, 8:-8].astype(np.float32)

    def pose(p: np.ndarray) -> np.ndarray:
        correction = np.eye(4)
        correction[:3, :3] = Rotation.from_rotvec(p[:3] * 1e-3).as_matrix()
        correction[:3, 3] = p[3:] * 1e-3 * depth
        return view.c2w @ correction

    def error(p: np.ndarray) -> float:
        render = scene.render(pose(p), camera, ("rgb",)).rgb[8:-8, 8:-8].astype(np.float32)
        return float(np.mean((render - target) ** 2))

    found = minimize(error, np.zeros(6), method="Powell", options={"xtol": 0.05, "ftol": 1e-4, "maxfev": 300})
    db = [10.0 * np.log10(255.0 ** 2 / e) for e in (error(np.zeros(6)), found.fun)]
    return pose(found.x), {"psnr": db, "rotation px": float(np.linalg.norm(found.x[:3]) * 1e-3 * camera.fx),
                           "translation": float(np.linalg.norm(found.x[3:]))}


def _render_with(scene, render) -> None:
    """Make ``scene`` (this object only) render through ``render(original, c2w, camera, outputs)``."""
    original = scene.render
    scene.render = lambda c2w, camera, outputs=("rgb",): render(original, np.asarray(c2w), camera, outputs)


def _supersampled(original, c2w: np.ndarray, camera, outputs) -> RenderedView:
    """The render with 2×2 rays a pixel, area-averaged (as a photo resized to ``camera`` is)."""
    fine = original(c2w, camera.resized(2 * camera.width, 2 * camera.height), outputs)
    size = (camera.width, camera.height)
    return RenderedView(camera=camera, c2w=fine.c2w, **{
        name: cv2.resize(getattr(fine, name), size, interpolation=cv2.INTER_AREA)
        for name in OUTPUTS if getattr(fine, name) is not None})


def _fidelity_row(report) -> dict:
    return {"psnr": report.mean("psnr"), "ssim": report.mean("ssim"),
            **{d: report.score(d, "repeatability") for d in DETECTORS}}


def placement(spec: str, size: str, max_views: int | None) -> dict:
    """Where a render's texture lands at the held-out poses: per view, its global shift against the reference
    image (:func:`_offset`) and the pose correction that best aligns them (:func:`_refined_pose`); the fidelity of
    the same field with its view dependence frozen (:func:`_frozen_view_dependence`), which says whether
    view-dependent colour puts detail where the reference has none; at the refined poses; and rendered with 2×2
    rays a pixel (:func:`_supersampled`). Empty without reference images."""
    scene = load(spec)
    kind, _ = reference_kind(scene)
    if kind == "none":
        return {}
    render_size = RenderSize.parse(size)
    offsets, corrections, refined = {}, {}, {}
    for view in floor_views(scene, max_views):
        camera = render_size.apply(view.camera)
        render = scene.render(view.c2w, camera, ("rgb",)).rgb
        reference = np.asarray(reference_image(scene, view, camera, kind))
        name = view.name.rsplit("/", 1)[-1]
        offsets[name] = _offset(reference, render)
        refined[view.c2w.tobytes()], corrections[name] = _refined_pose(scene, view, camera, reference)
    posed = load(spec)
    _render_with(posed, lambda render, c2w, camera, outputs: render(refined.get(c2w.tobytes(), c2w), camera, outputs))
    fine = load(spec)
    _render_with(fine, _supersampled)
    table = {"offsets": offsets, "corrections": corrections, "frozen": None,
             "refined poses": _fidelity_row(measure_fidelity(posed, size=size, max_views=max_views)),
             "2x2 rays a pixel": _fidelity_row(measure_fidelity(fine, size=size, max_views=max_views))}
    frozen = load(spec)  # a fresh field: the renderer is built on the first render, after the change
    if frozen.field.sh_degree > 0:
        direction = _frozen_view_dependence(frozen)
        table["frozen"] = {"direction": direction.round(3).tolist(),
                           **_fidelity_row(measure_fidelity(frozen, size=size, max_views=max_views))}
    return table


def print_placement(spec: str, table: dict) -> None:
    shifts = table["offsets"]
    print(f"\n{spec}: the render's global shift against the reference (phase correlation, px, u right / v down): "
          + ", ".join(f"{name} ({du:+.2f}, {dv:+.2f})" for name, (du, dv) in shifts.items())
          + f"; mean length {np.mean([np.hypot(*s) for s in shifts.values()]):.2f} px")
    print(f"{spec}: each held-out pose refined (Powell on the render's squared error; PSNR before → after, the "
          "correction's rotation in px and translation in thousandths of the median depth): "
          + ", ".join(f"{name} {c['psnr'][0]:.2f} → {c['psnr'][1]:.2f} dB ({c['rotation px']:.2f} px, "
                      f"{c['translation']:.2f})" for name, c in table["corrections"].items()))
    rows = [("at the refined poses", table["refined poses"]), ("with 2×2 rays a pixel", table["2x2 rays a pixel"])]
    if table["frozen"] is not None:
        rows.append((f"with view-dependent colour frozen at the mean viewing direction {table['frozen']['direction']}",
                     table["frozen"]))
    for label, row in rows:
        print(f"{spec} {label}: PSNR {row['psnr']:.2f} dB, SSIM {row['ssim']:.4f}, "
              + ", ".join(f"{d.upper()} rep. {row[d]:.3f}" for d in DETECTORS))


def print_bands(spec: str, table: dict[str, dict]) -> None:
    print(f"\n{spec}: PSNR dB of the render against the reference, plain, after both are blurred, and after the "
          "render's best per-channel gain and offset\n")
    print("| views | n | plain | " + " | ".join(f"blur {s:g} px" for s in BAND_SIGMAS) + " | gain and offset |")
    print("|---|---|---|" + "---|" * (len(BAND_SIGMAS) + 1))
    for label, row in table.items():
        print(f"| {label} | {row['views']} | " + " | ".join(f"{v:.2f}" for v in row["psnr"].values()) + " |")


def print_ceiling(spec: str, table: dict[str, dict]) -> None:
    print(f"\n{spec}: each detector on the reference image vs on the reference degraded (no field error)\n")
    print("| reference degraded to | PSNR dB | SSIM | " + " | ".join(f"{d.upper()} rep." for d in DETECTORS) + " |")
    print("|---|---|---|" + "---|" * len(DETECTORS))
    for name, row in table.items():
        print(f"| {name} | {row['psnr']:.2f} | {row['ssim']:.4f} | {format_repeatabilities(row, ' | ')} |")


def print_neighbours(spec: str, table: dict[str, dict]) -> None:
    print(f"\n{spec}: each detector on the reference image vs on the field's render and on the nearest other photo "
          "brought to the same pose\n")
    print("| views | n | nearest other photo (median) | image scored | PSNR dB | "
          + " | ".join(f"{d.upper()} rep." for d in DETECTORS) + " |")
    print("|---|---|---|---|---|" + "---|" * len(DETECTORS))
    for group, part in table.items():
        gap = part["nearest"]
        where = (f"{gap['degrees']:.1f}°, {gap['reference lengths']:.3f} ref. lengths, "
                 f"{100 * gap['share brought']:.0f} % of pixels brought")
        for name, row in part["rows"].items():
            print(f"| {group} | {part['views']} | {where} | {name} | {row['psnr']:.2f} | "
                  f"{format_repeatabilities(row, ' | ')} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help=".n2r file or demo:<name>-field")
    parser.add_argument("--size", default="480", help="render size: longer side in pixels or WxH (default 480)")
    parser.add_argument("--views", type=int, default=None, help="at most this many held-out views per scene")
    parser.add_argument("--targets", action="store_true", help="check issue 14's targets on every scene")
    parser.add_argument("--ceiling", action="store_true",
                        help="also score each detector on the reference image degraded (what the targets ask)")
    parser.add_argument("--bands", action="store_true",
                        help="also say where the render's error is (fine texture, shape, exposure; held out vs fitted)")
    parser.add_argument("--placement", action="store_true",
                        help="also say where the render's texture lands (global shift; view dependence frozen)")
    parser.add_argument("--neighbours", action="store_true",
                        help="also score the nearest other photo brought to each pose (a real image nearby)")
    parser.add_argument("--json", default=None, metavar="PATH", help="also write every number as JSON")
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    reports, ceilings, crowded, band_tables, placements, nearby = [], {}, {}, {}, {}, {}
    header = ("| scene | reference | views | PSNR dB | SSIM | "
              + " | ".join(f"{d.upper()} rep. | {d.upper()} spread" for d in DETECTORS) + " | seconds |")
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for spec in args.scenes:
        t0 = time.perf_counter()
        try:
            scene = load(spec)
        except N2RError as exc:  # a missing or unreadable scene file, an unknown demo scene
            parser.error(str(exc))
        report = measure_fidelity(scene, size=args.size, max_views=args.views)
        seconds = time.perf_counter() - t0
        reports.append(report)
        if args.ceiling:
            ceilings[spec] = ceiling(scene, args.size, args.views)
            crowded[spec] = crowding(scene, args.size, args.views)
        if args.bands:
            band_tables[spec] = bands(scene, args.size, args.views)
        if args.placement:
            placements[spec] = placement(spec, args.size, args.views)
        if args.neighbours:
            nearby[spec] = neighbours(scene, args.size, args.views)
        if report.reference == "none":
            print(f"| {spec} | none: {report.reason} |" + " |" * (header.count("|") - 3))
            continue
        cells = " | ".join(f"{report.score(d, 'repeatability'):.3f} | {report.score(d, 'ip_spread'):.3f}"
                           for d in DETECTORS)
        print(f"| {spec} | {report.reference} | {len(report.images)} | {report.mean('psnr'):.2f} | "
              f"{report.mean('ssim'):.4f} | {cells} | {seconds:.0f} |")
    if args.targets:
        print(f"\ntargets: held-out PSNR >= {TARGET_PSNR_DB:g} dB, repeatability >= {TARGET_REPEATABILITY:g} "
              "for each detector")
        for spec, report in zip(args.scenes, reports):
            checks = [("PSNR", report.mean("psnr"), TARGET_PSNR_DB)]
            checks += [(f"{d} rep.", report.score(d, "repeatability"), TARGET_REPEATABILITY) for d in DETECTORS]
            print(f"  {spec}: " + ", ".join(f"{name} {value:.3g} {'met' if value >= target else 'NOT met'}"
                                             for name, value, target in checks))
    for report in reports:
        for (detector, metric), floor in report.floors.items():
            per_view = ", ".join(f"{s.view.rsplit('/', 1)[-1]} {s.score:.2f}" if s.valid else f"{s.view} undefined"
                                 for s in floor.samples)
            print(f"  {report.scene} {detector} {metric}: {per_view}")
    for spec, table in ceilings.items():
        print_ceiling(spec, table)
        if crowded.get(spec):
            print("\nthe reference's points with another point of the same detector within the metric's tolerance, "
                  "and the share found again one to one (as the metric counts), as mutual nearest neighbours (as it "
                  "counted before result_version 2) and plainly (nearest within the tolerance), in the reference "
                  "moved by 1 whole pixel and in the render (same pose, 16 px borders left out)\n")
            columns = list(next(iter(crowded[spec].values())))
            print("| detector | " + " | ".join(columns) + " |")
            print("|---|" + "---|" * len(columns))
            for d, row in crowded[spec].items():
                print(f"| {d.upper()} | " + " | ".join(f"{row[c]:.3f}" for c in columns) + " |")
    for spec, table in band_tables.items():
        print_bands(spec, table)
    for spec, table in placements.items():
        if table:
            print_placement(spec, table)
    for spec, table in nearby.items():
        if table:
            print_neighbours(spec, table)
    if args.json:
        from pytest_n2r.data.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps([{**r.to_dict(), "ceiling": ceilings.get(spec),
                                                  "crowding": crowded.get(spec), "bands": band_tables.get(spec),
                                                  "placement": placements.get(spec),
                                                  "neighbours": nearby.get(spec)}
                                                 for spec, r in zip(args.scenes, reports)], indent=1))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
