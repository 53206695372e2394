"""``n2r study``: the N2R-Tester paper's evaluation (RQ1 realness, RQ2 diversity, RQ3 efficiency) as rows.

Every result is a plain ``dict`` row (written as CSV and Markdown by :mod:`pytest_n2r.study.output`):

- ``realness``: per scene, view and source (τ0 = the scene's render at the captured pose, m1–m3 = the
  mutated real photo): PSNR (dB), SSIM and LPIPS (when available) against the real photo.
- ``domain_shift``: per scene, view, SUT (with ``points``, the keypoints a built-in detector kept per image; empty
  for an imported SUT) and metric: the metric between the SUT's output on the real
  photo and on the τ0 render (RQ1's "SUT performance under the reality-to-field shift").
- ``examples``: per scene, view, SUT (with ``points``), metric and drawn transform / mutation: score and deviation.
  RQ2's mutations m1–m3 mutate the τ0 render, the source every τ follow-up is compared with (the paper mutated
  real photos), so motions and mutations share one source image.
- ``inconsistencies``: ``examples`` counted per scene, SUT, metric and family at each eps (RQ2); NaN where no
  example of the family is valid (nothing was compared: not zero inconsistencies).
- ``correlations``: per SUT, metric and image quality metric: Spearman's rank correlation between τ0's image
  quality and the SUT's score under the reality-to-field shift, over the views (:mod:`pytest_n2r.study.correlation`).
- ``fps``: per scene and render size: frames per second of RGB renders (RQ3).

"Real photo" is the view's stored image (``SceneView.image``); for an exact demo scene without stored
images it is the exact render at the captured pose, and for a fitted demo scene the exact twin's render
(:mod:`pytest_n2r.relation.floor` measures the same shift for the plugin's field floor). Scenes with neither skip
RQ1.

Each scene's draws come from two streams spawned from ``seed`` (:func:`_streams`), one for RQ1's mutations of the
photo and one for RQ2's transforms and mutations, so RQ2 draws the same with or without a real photo.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from ..errors import InvalidArgument, MetricUndefined, N2RError
from ..geometry import Camera
from ..metrics.image_quality import lpips, lpips_unavailable_reason, psnr, ssim
from ..relation.floor import exact_twin, reference_image, shift_sample
from ..relation.outputs import sut_image
from ..relation.validity import Validity
from ..render.view import RenderedView
from ..scene.base import Scene, SceneView
from .correlation import rank_correlations
from .sampling import MUTATION_FAMILIES, TRANSFORM_FAMILIES, sample_mutation, sample_transform
from .suts import SUT

__all__ = ["StudyConfig", "StudyResult", "run_study"]

#: Render sizes of RQ3 (width, height), as in the paper's FPS table; portrait scenes swap them.
FPS_SIZES = ((480, 270), (960, 540), (1920, 1080))


@dataclass(frozen=True)
class StudyConfig:
    """What the study draws: ``examples`` transforms / mutations per family, source view and SUT; at most
    ``max_views`` held-out views per scene; renders ``size`` pixels on the longer side; counts
    inconsistencies at every ``eps``; ``fps_frames`` frames per size for RQ3; ``seed`` for every draw."""

    examples: int = 5
    max_views: int = 3
    size: int = 480
    eps: tuple[float, ...] = (0.1, 0.2, 0.5)
    families: tuple[str, ...] = TRANSFORM_FAMILIES + MUTATION_FAMILIES
    fps_frames: int = 3
    fps_sizes: tuple[tuple[int, int], ...] = FPS_SIZES
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("examples", "max_views", "size", "fps_frames"):
            if int(getattr(self, name)) < 1:
                raise InvalidArgument(f"{name}={getattr(self, name)!r} must be >= 1")
        unknown = set(self.families) - set(TRANSFORM_FAMILIES + MUTATION_FAMILIES)
        if unknown:
            raise InvalidArgument(
                f"families {sorted(unknown)} unknown; expected {TRANSFORM_FAMILIES + MUTATION_FAMILIES}")


@dataclass
class StudyResult:
    realness: list[dict] = field(default_factory=list)
    domain_shift: list[dict] = field(default_factory=list)
    examples: list[dict] = field(default_factory=list)
    fps: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    eps: tuple[float, ...] = ()

    @property
    def inconsistencies(self) -> list[dict]:
        """``examples`` counted per (scene, SUT, metric, family): valid examples and failures per eps; NaN
        failures (written ``—``) where no example is valid, which tested nothing rather than found nothing."""
        groups: dict[tuple, list[dict]] = {}
        for row in self.examples:
            groups.setdefault((row["scene"], row["sut"], row["metric"], row["family"]), []).append(row)
        out = []
        for (scene, sut, metric, family), rows in sorted(groups.items()):
            valid = [r for r in rows if r["valid"]]
            row = {"scene": scene, "sut": sut, "metric": metric, "family": family,
                   "kind": "n2r" if family.startswith("tau") else "mutation",
                   "drawn": len(rows), "valid": len(valid)}
            for eps in self.eps:
                row[f"inc@{eps:g}"] = sum(r["deviation"] > eps for r in valid) if valid else math.nan
            out.append(row)
        return out

    @property
    def correlations(self) -> list[dict]:
        """Image quality against the SUT metrics under the reality-to-field shift, one row per combination
        (:func:`~pytest_n2r.study.correlation.rank_correlations`)."""
        return rank_correlations(self.realness, self.domain_shift)


def _reference_image(scene: Scene, view: SceneView, camera: Camera) -> np.ndarray | None:
    """The view's stored photo, else the exact render (an exact scene, or a fitted demo scene's exact twin)."""
    if view.image is not None:
        return reference_image(scene, view, camera, "photo")
    if getattr(scene, "is_exact", False) or exact_twin(scene) is not None:
        return reference_image(scene, view, camera, "exact")
    return None


def _source_views(scene: Scene, max_views: int) -> list[SceneView]:
    views = [v for v in scene.views if v.split == "heldout"] or list(scene.views)
    if len(views) > max_views:  # spread over the trajectory rather than the first few
        views = [views[i] for i in np.linspace(0, len(views) - 1, max_views).round().astype(int)]
    return views


def _score(
    metric: Any, out_s: Any, out_f: Any, source: RenderedView, follow: RenderedView
) -> tuple[float, float, bool]:
    try:
        result = metric.compute(out_s, out_f, source, follow)
    except MetricUndefined:
        return float("nan"), float("nan"), False
    return float(result.score), float(result.deviation), bool(result.valid)


def _streams(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """The generators of one scene's RQ1 and RQ2 draws: two independent children of ``seed``'s
    :class:`numpy.random.SeedSequence`, so whether RQ1 runs (a real photo or not) leaves RQ2's draws as they are."""
    rq1, rq2 = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(rq1), np.random.default_rng(rq2)


def _points_notes(suts: Sequence[SUT]) -> list[str]:
    """What the built-in detectors kept: one note per ``points`` value (the paper's detectors kept 100)."""
    by_points: dict[int, list[str]] = {}
    for sut in suts:
        if sut.points is not None:
            by_points.setdefault(sut.points, []).append(sut.name)
    orb = " (ORB as configured for {n} points: its pyramid levels share them)"
    return [f"detectors {', '.join(names)} kept at most the {n} highest-response points of each image"
            f"{orb.format(n=n) if 'orb' in names else ''} (--points {n}; the paper's detectors kept 100)"
            for n, names in sorted(by_points.items())]


def run_study(scenes: Sequence[Scene], suts: Sequence[SUT], config: StudyConfig = StudyConfig(),
              progress: Callable[[str], None] | None = None) -> StudyResult:
    """Run RQ1–RQ3 on every scene for every SUT; see the module docstring for the rows produced."""
    result = StudyResult(eps=tuple(config.eps), notes=_points_notes(suts))
    validity = Validity()
    say = progress or (lambda _msg: None)
    for scene in scenes:
        rq1_rng, rng = _streams(config.seed)
        outputs = ("rgb", "depth", "opacity")
        for view in _source_views(scene, config.max_views):
            camera = view.camera.fit_within(config.size)
            say(f"{scene.name} / {view.name}")
            source = scene.render(view.c2w, camera, outputs)
            real = _reference_image(scene, view, camera)
            if real is not None:
                _rq1(result, scene, view, source, real, suts, rq1_rng)
            elif not any("RQ1" in n and scene.name in n for n in result.notes):
                result.notes.append(f"RQ1 skipped for {scene.name}: its views store no real photos")
            sut_source = {sut.name: sut.fn(sut_image(source, "source")) for sut in suts}
            for family in config.families:
                for _ in range(config.examples):
                    if family.startswith("tau"):
                        tau = sample_transform(family, rng)
                        follow = tau.follow_view(source, scene, partial(scene.render, camera=camera, outputs=outputs))
                        valid = validity.check(follow, scene, source).valid
                        drawn = tau.describe()
                    else:
                        mutation = sample_mutation(family, rng)
                        follow = mutation.apply_to_view(source)
                        valid, drawn = True, repr(mutation)
                    for sut in suts:
                        out_f = sut.fn(sut_image(follow, "follow-up")) if valid else None
                        for name, metric in sut.metrics().items():
                            score, dev, ok = (_score(metric, sut_source[sut.name], out_f, source, follow)
                                              if valid else (float("nan"), float("nan"), False))
                            result.examples.append({
                                "scene": scene.name, "view": view.name, "family": family, "drawn": drawn,
                                "sut": sut.name, "points": sut.points, "metric": name, "score": score,
                                "deviation": dev,
                                "valid": bool(valid and ok),
                            })
        _rq3(result, scene, config, say)
    return result


def _rq1(result: StudyResult, scene: Scene, view: SceneView, source: RenderedView, real: np.ndarray,
         suts: Sequence[SUT], rng: np.random.Generator) -> None:
    images = {"tau0": sut_image(source, "source")}
    images.update({f: sample_mutation(f, rng).apply(real) for f in MUTATION_FAMILIES})
    for name, img in images.items():
        perceptual = lpips(real, img)
        if perceptual is None and not any(n.startswith("LPIPS skipped") for n in result.notes):
            result.notes.append(f"LPIPS skipped (column empty): {lpips_unavailable_reason()}")
        result.realness.append({
            "scene": scene.name, "view": view.name, "source": name, "psnr": psnr(real, img),
            "ssim": ssim(real, img), "lpips": perceptual,
        })
    real_view = RenderedView(source.camera, source.c2w, rgb=real, depth=source.depth, opacity=source.opacity)
    for sut in suts:
        out_real, out_field = sut.fn(real), sut.fn(images["tau0"])
        for name, metric in sut.same_pose_metrics().items():
            sample = shift_sample(metric, out_real, out_field, real_view, source, view.name)
            result.domain_shift.append({"scene": scene.name, "view": view.name, "sut": sut.name,
                                        "points": sut.points, "metric": name,
                                        "score": sample.score, "deviation": sample.deviation,
                                        "valid": sample.valid})


def _rq3(result: StudyResult, scene: Scene, config: StudyConfig, say: Callable[[str], None]) -> None:
    view = scene.views[0]
    portrait = view.camera.height > view.camera.width
    for w, h in config.fps_sizes:
        size = (h, w) if portrait else (w, h)
        camera = view.camera.resized(*size)
        say(f"{scene.name}: frames/s at {size[0]}x{size[1]}")
        try:
            scene.render(view.c2w, camera, ("rgb",))  # warm-up (compilation, caches)
            start = time.perf_counter()
            for _ in range(config.fps_frames):
                scene.render(view.c2w, camera, ("rgb",))
            seconds = (time.perf_counter() - start) / config.fps_frames
        except (N2RError, MemoryError) as exc:
            result.notes.append(f"RQ3 {scene.name} at {size[0]}x{size[1]}: {exc}")
            continue
        result.fps.append({"scene": scene.name, "width": size[0], "height": size[1],
                           "fps": 1.0 / seconds, "seconds_per_frame": seconds})
