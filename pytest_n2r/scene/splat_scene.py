"""A splat scene: 3-D Gaussians trained elsewhere (a 3DGS ``.ply``), rendered on the CPU at any camera and pose.

With the capture's cameras (a 3DGS ``cameras.json``, a ``transforms.json`` or a COLMAP model) it has
views, a train / held-out split, a reference length and the validity checks like a fitted scene. Without
them it still renders at poses the caller gives, and every use that needs them says so.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from .._validation import as_unit_rgb, check_choice, check_positive, check_range, repeated_name
from ..data.capture import split_frames
from ..data.poses import PoseSet
from ..errors import IngestError, InvalidArgument, InvalidType
from ..geometry import Camera, Units
from ..render.size import MAX_SIDE
from ..render.splat_render import SPLAT_RENDER_VERSION, SplatRenderer, SplatSettings
from ..splats.gaussians import Gaussians
from .base import Scene, SceneView, hash_views

__all__ = ["MIN_COVERAGE", "SplatScene", "load_splat_scene", "measure_coverage", "measure_reference_length",
           "splat_views"]

#: Training views rendered (at most) to measure the reference length, and their longer side in pixels.
REFERENCE_VIEWS, REFERENCE_SIZE = 16, 64
#: The least share of the training views' pixels the Gaussians must cover (mean opacity of the reference
#: renders) for ``load_splat_scene`` to accept a ply and its cameras as one scene. Measured (7 December 2026,
#: ``tests/scene/test_splat_pairing.py`` pins the cases): paired right, the shipped demo splats cover 0.82
#: (object-sh0), 0.91 (wall-sh3) and 0.81 (object-rotated), a 3000-Gaussian blob under the fox's 67 cameras
#: 0.43; paired with the capture's cameras while in nerfstudio's normalized frame, the blob covers 0.034 and
#: object-rotated 0.062 (refused), wall-sh3 0.17 and object-sh0 0.30 (not caught: a check of coverage only
#: catches a gross mismatch). The share of Gaussians whose centre is in front of and inside some view was 1.0
#: in all eight cases (a cloud shrunk about the origin stays in view), so it cannot tell them apart.
MIN_COVERAGE = 0.10


class SplatScene(Scene):
    """Gaussians rendered by :class:`~pytest_n2r.render.splat_render.SplatRenderer` (see the module docstring).

    Parameters
    ----------
    gaussians:
        The scene, in the world frame of ``views``.
    views:
        The captured views (cameras and poses; no photos), or none.
    name:
        Short name for test ids and reports.
    reference_length:
        The median z-depth of the surface seen from the training views (scene units); ``None`` measures it
        (:func:`measure_reference_length`) when there are views.
    background:
        RGB in [0, 1] shown where the Gaussians leave transmittance (the colour the scene was trained over;
        3DGS's default is black).
    settings:
        Render settings (:class:`~pytest_n2r.render.splat_render.SplatSettings`).
    metres_per_unit:
        Metres per scene unit when the capture's scale is known.
    no_cameras:
        Why there are no views (``None`` when there are).
    notes:
        What the loader converted on the way (read from a red/green/blue ply, a Mip-Splatting filter baked in,
        cameras moved into the splats' frame), one sentence each, for reports.
    """

    is_exact = False
    device = "cpu"
    backend = "compiled"

    def __init__(self, gaussians: Gaussians, views: Sequence[SceneView] = (), *, name: str = "splats",
                 reference_length: float | None = None, background: Sequence[float] = (0.0, 0.0, 0.0),
                 settings: SplatSettings | None = None, metres_per_unit: float | None = None,
                 no_cameras: str | None = None, notes: Sequence[str] = ()) -> None:
        if not isinstance(gaussians, Gaussians):
            raise InvalidType(f"gaussians must be a pytest_n2r.splats.Gaussians, got {type(gaussians).__name__}")
        if settings is not None and not isinstance(settings, SplatSettings):
            raise InvalidType(f"settings must be a SplatSettings for a splat scene, got {type(settings).__name__}")
        bg = as_unit_rgb(background)
        if bg is None:
            raise InvalidArgument(f"background={background!r}; expected three values in [0, 1]")
        if reference_length is not None:
            reference_length = check_positive("reference_length", reference_length)
        self.gaussians = gaussians
        self.name = name
        self.views = tuple(views)  # Scene refuses two views of one name
        self.background = bg
        self.settings = settings or SplatSettings()
        self.metres_per_unit = metres_per_unit
        self.no_views_reason = no_cameras if not self.views else None
        self.notes = tuple(notes)
        self._renderer = SplatRenderer(gaussians, self.settings, bg)
        if reference_length is None and self.views:
            reference_length = measure_reference_length(self, self.views)
        self._reference_length = None if reference_length is None else float(reference_length)
        self._hash: str | None = None

    @property
    def reference_length(self) -> float:  # type: ignore[override]
        """The median z-depth of the surface seen from the training views (scene units)."""
        __tracebackhide__ = True
        if self._reference_length is None:
            raise InvalidArgument(f"splat scene {self.name!r} has no reference length: {self.no_views_reason} "
                                  "Translate in units='scene' instead.")
        return self._reference_length

    def length_scale(self, units: Units | str = Units.REFERENCE) -> float:
        __tracebackhide__ = True
        if check_choice("units", units, Units, "a unit") is Units.REFERENCE:
            return self.reference_length
        return super().length_scale(units)

    @property
    def renderer(self) -> SplatRenderer:
        """The renderer (its ``stage_seconds`` time the last render's stages)."""
        return self._renderer

    @property
    def content_hash(self) -> str:
        """SHA-256 of the Gaussians, the render settings and background, the views, the reference length and
        :data:`~pytest_n2r.render.splat_render.SPLAT_RENDER_VERSION`."""
        if self._hash is None:
            h = hashlib.sha256(f"SplatScene/{SPLAT_RENDER_VERSION}/{self.gaussians.digest()}".encode())
            h.update(json.dumps({**self.settings.to_dict(), "background": list(self._renderer.background)},
                                sort_keys=True).encode())
            h.update(np.asarray([self._reference_length or 0.0, self.metres_per_unit or 0.0]).tobytes())
            hash_views(h, self.views)
            self._hash = h.hexdigest()
        return self._hash

    def with_settings(self, settings: SplatSettings) -> SplatScene:
        """The same scene rendered with other ``settings`` (a new content hash)."""
        return SplatScene(self.gaussians, self.views, name=self.name, reference_length=self._reference_length,
                          background=self.background, settings=settings, metres_per_unit=self.metres_per_unit,
                          no_cameras=self.no_views_reason, notes=self.notes)

    def _render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        return self._renderer.render(c2w, camera, outputs)

    def __repr__(self) -> str:
        cams = f"{len(self.views)} views" if self.views else "no cameras"
        return (f"<SplatScene {self.name!r}: {len(self.gaussians)} Gaussians "
                f"(SH degree {self.gaussians.sh_degree}), {cams}>")


def _reference_renders(scene: Scene, views: Sequence[SceneView]) -> tuple[int, np.ndarray, float]:
    """``(views rendered, z-depths of the pixels of opacity >= 0.5, mean opacity)`` of up to
    :data:`REFERENCE_VIEWS` training views (evenly spread; all views when none is marked ``train``), rendered
    :data:`REFERENCE_SIZE` pixels on the longer side."""
    train = [v for v in views if v.split == "train"] or list(views)
    picked = [train[i] for i in np.linspace(0, len(train) - 1, min(REFERENCE_VIEWS, len(train))).round().astype(int)]
    depths, covered = [], []
    for view in picked:
        out = scene.render(view.c2w, view.camera.fit_within(REFERENCE_SIZE), ("depth", "opacity"))
        depth, opacity = out.output("depth"), out.output("opacity")
        depths.append(depth[opacity >= 0.5])
        covered.append(float(opacity.mean()))
    return len(picked), np.concatenate(depths), float(np.mean(covered))


def measure_coverage(scene: Scene, views: Sequence[SceneView]) -> float:
    """The share of the training views' pixels the scene covers: the mean opacity, in [0, 1], of the renders
    :func:`measure_reference_length` makes."""
    return _reference_renders(scene, views)[2]


def measure_reference_length(scene: Scene, views: Sequence[SceneView]) -> float:
    """The median z-depth of the surface (opacity >= 0.5) that up to :data:`REFERENCE_VIEWS` training
    views (evenly spread; all views when none is marked ``train``) see, rendered :data:`REFERENCE_SIZE`
    pixels on the longer side (scene units)."""
    count, seen, _ = _reference_renders(scene, views)
    return _median_depth(scene, count, seen)


def _median_depth(scene: Scene, count: int, seen: np.ndarray) -> float:
    if not seen.size:
        raise IngestError(f"scene {scene.name!r}: none of {count} training views sees a surface (opacity >= 0.5) "
                          "at its camera; the cameras do not look at these Gaussians (a different world frame?)")
    return float(np.median(seen))


def splat_views(poses: PoseSet, heldout_every: int | None = None) -> list[SceneView]:
    """Views of a pose set, sorted by name, with ideal pinhole cameras (distortion dropped, ``K`` and the size
    kept: a warning says so when a camera had distortion). Held out: the source's own split (a
    transforms.json's ``val_filenames``) when ``heldout_every`` is ``None`` and it has one, else every
    ``heldout_every``-th (default 8, from the first: the 3DGS reference's ``--eval`` split, ``llffhold`` 8;
    nerfstudio's default differs, see docs/splat-scenes.md); 0 holds none out.

    Raises :class:`IngestError` naming the source and the frame for two frames of one name or a camera side
    that is not a whole number of pixels in 1..:data:`~pytest_n2r.render.size.MAX_SIDE`."""
    repeat = repeated_name(f.name for f in poses.frames)
    if repeat is not None:
        raise IngestError(f"{poses.source}: frames [{repeat[0]}] and [{repeat[1]}] are both named {repeat[2]!r}; "
                          "expected one frame a name")
    for i, f in enumerate(poses.frames):
        for key in ("width", "height"):
            side = getattr(f.camera, key)
            if not 1 <= side <= MAX_SIDE:
                raise IngestError(f"{poses.source}: frame [{i}] {f.name!r}: camera {key}={side!r}; expected a whole "
                                  f"number of pixels in 1..{MAX_SIDE}")
    distorted = sum(bool(f.camera.distortion) for f in poses.frames)
    if distorted:
        warnings.warn(f"{poses.source}: {distorted} of {len(poses.frames)} cameras have lens distortion; the views "
                      "drop it and keep its K and size, while nerfstudio and gsplat train on images undistorted to "
                      "cv2.getOptimalNewCameraMatrix(K, dist, (w, h), 0) cropped to its ROI (the 3DGS reference: "
                      "COLMAP's image_undistorter), so the views' field of view differs slightly from the "
                      "trained one; give the undistorted cameras (e.g. the undistorted COLMAP model) for exact views",
                      UserWarning, stacklevel=3)
    frames = sorted(poses.frames, key=lambda f: f.name)
    splits = split_frames([f.name for f in frames], poses.heldout, heldout_every)
    return [SceneView(i, f.name, f.camera.undistorted(), f.c2w, split)
            for i, (f, split) in enumerate(zip(frames, splits))]


def load_splat_scene(path: str | os.PathLike, *, cameras: str | os.PathLike | None = None,
                     dataparser_transforms: str | os.PathLike | Literal[False] | None = None,
                     heldout_every: int | None = None, background: Sequence[float] = (0.0, 0.0, 0.0),
                     settings: SplatSettings | None = None, name: str | None = None,
                     min_coverage: float = MIN_COVERAGE) -> SplatScene:
    """The splat scene of the 3DGS ``.ply`` file ``path``.

    ``cameras`` is a 3DGS ``cameras.json``, a ``transforms.json`` or a COLMAP model (folder); ``None`` looks
    for one beside the ply (:func:`~pytest_n2r.data.camera_sources.find_cameras`), and without one the scene
    has no views. ``dataparser_transforms`` is nerfstudio's ``dataparser_transforms.json`` of the run that
    trained the ply: the cameras are moved into the splats' frame by it (:mod:`~pytest_n2r.data.trainer_frame`),
    and ``notes`` says so; ``None`` uses one in the ply's folder or up to two above it, if any; ``False`` uses
    none (a ply already in the capture's frame beside such a file). ``heldout_every`` chooses the split
    (:func:`splat_views`); ``background`` is the colour the scene was trained over (3DGS: black unless trained
    with ``--white_background``).

    Raises :class:`IngestError` naming both files when the Gaussians cover less than ``min_coverage`` (in
    [0, 1], default :data:`MIN_COVERAGE`; 0 turns the check off) of the training views' pixels: the ply and the
    cameras are then not in one frame (when a transform found beside the ply caused it, the message says so).
    """
    from ..data.camera_sources import find_cameras, read_cameras
    from ..data.trainer_frame import find_dataparser_transforms, read_dataparser_transforms
    from ..splats.ply import read_ply_with_notes

    min_coverage = check_range("min_coverage", min_coverage, 0.0, 1.0)
    if not (dataparser_transforms is None or dataparser_transforms is False
            or isinstance(dataparser_transforms, (str, os.PathLike))):
        raise InvalidArgument(f"dataparser_transforms={dataparser_transforms!r}; expected a path, None (look for one "
                              "beside the ply) or False (use none)")
    path = Path(path)
    gaussians, ply_notes = read_ply_with_notes(path)
    notes = list(ply_notes)
    found = Path(cameras) if cameras is not None else find_cameras(path)
    views: list[SceneView] = []
    reason = None
    length = None
    if found is None and dataparser_transforms:
        raise InvalidArgument(f"dataparser_transforms={str(dataparser_transforms)!r} moves cameras, and {path} has "
                              "none (none given, none found beside it); pass cameras=... too")
    if found is None:
        reason = (f"no cameras were given and none were found beside {path} (a cameras.json, transforms.json or "
                  "COLMAP model in its folder or up to two folders above), so it has no captured views, no "
                  "train / held-out split, no reference length and no validity checks; it renders at the poses "
                  "you give. Pass cameras=... to load_scene (or `n2r import --cameras`) to have them.")
    else:
        captured = read_cameras(found)
        given = dataparser_transforms is not None
        if dataparser_transforms is not None:
            frame = None if dataparser_transforms is False else Path(dataparser_transforms)
        else:
            frame = find_dataparser_transforms(path)
        poses = captured
        if frame is not None:
            poses, note = read_dataparser_transforms(frame).apply(captured)
            notes.append(note)
        views = splat_views(poses, heldout_every)
        probe = SplatScene(gaussians, (), name=name or path.stem, background=background, settings=settings)
        count, depths, coverage = _reference_renders(probe, views)
        if coverage < min_coverage:
            without = None
            if frame is not None and not given:  # a file found beside the ply: would the cameras fit without it?
                without = _reference_renders(probe, splat_views(captured, heldout_every))[2]
            raise IngestError(_not_paired(path, found, frame, count, coverage, min_coverage,
                                          without if without is not None and without >= min_coverage else None))
        length = _median_depth(probe, count, depths)
    return SplatScene(gaussians, views, name=name or path.stem, reference_length=length, background=background,
                      settings=settings, no_cameras=reason, notes=notes)


def _not_paired(ply: Path, cameras: Path, frame: Path | None, count: int, coverage: float, least: float,
                without: float | None) -> str:
    """The message of a ply whose Gaussians its cameras barely see; ``without``: the coverage without the
    dataparser transform ``frame`` found beside the ply, when that is enough."""
    moved = f" moved by {frame}" if frame is not None else ""
    if without is not None:
        cause = (f"{frame} was found beside the ply and applied; without it the cameras cover {without:.1%}, so "
                 "the ply is likely in the capture's frame already: pass dataparser_transforms=False "
                 "(n2r import --dataparser-transforms none) to use no transform")
    elif frame is not None:
        cause = "the transform does not belong to this ply and these cameras"
    else:
        cause = ("the ply is likely in a trainer's normalized frame (nerfstudio's splatfacto orients, centres and "
                 "scales the capture before training, and ns-export writes the Gaussians in that frame): pass that "
                 "run's dataparser_transforms.json (dataparser_transforms=... / n2r import --dataparser-transforms "
                 "PATH; for gsplat's normalize_world_space, which records nothing, export in the capture's frame)")
    skip = (f"If they do belong together (the object just small in the views), lower or skip the check: "
            f"min_coverage=0 to load_scene / load_splat_scene, `n2r import {ply} --min-coverage 0 -o scene.n2r` "
            "(the .n2r then loads anywhere, --n2r-scene included), or a --n2r-scene / n2r_scenes entry "
            f"'module:function' whose function returns load_scene({str(ply)!r}, min_coverage=0)")
    return (f"{ply} with the cameras of {cameras}{moved}: the Gaussians cover {coverage:.1%} of the pixels of "
            f"{count} training views (mean opacity at {REFERENCE_SIZE} pixels); expected at least {least:.0%} for "
            f"a ply and its cameras in one frame. {cause[0].upper()}{cause[1:]}. {skip}.")
