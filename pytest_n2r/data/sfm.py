"""Structure from motion on a folder of photos with pycolmap (4.x API).

Pipeline
--------
1. Read every image directly in the folder (EXIF orientation applied, so a phone's portrait photo is portrait;
   unreadable files skipped with a warning; a photo with the same pixels as one read before it, a copy or a link,
   skipped: held out, it would score a copy of a training photo; fewer than 3 readable, different images is an error
   naming each unreadable file with its reason, and the subfolders that hold images, which are not read).
2. Write upright copies downscaled to at most ``max_size`` pixels into a temporary folder, one subfolder
   per upright image size: a phone capture mixing portrait and landscape photos (or two cameras) gets one
   camera per size and orientation.
3. SIFT feature extraction (one ``SIMPLE_RADIAL`` camera per subfolder, CPU).
4. Matching: exhaustive for up to :data:`EXHAUSTIVE_MAX_IMAGES` images, otherwise sequential (ordered
   video frames; each image with the next 10 and quadratically spaced ones).
5. Incremental mapping; the model with the most registered images is kept; images it did not register
   are reported in ``skipped``.
6. The registered photos' up axes are compared (:mod:`.upright`): a photo upside down against the others was put
   half a turn wrong (symmetric or repeated structure) and is reported in ``skipped``; more than
   :data:`~.upright.UPSIDE_DOWN_SHARE` of them upside down is an error, the reconstruction as a whole being
   doubtful. ``report["upright"]`` holds the check (``dropped``: whether photos were skipped for it).
   ``upright=False`` (photos not all taken upright: looking straight down, or a camera on a robot arm or a drone
   that rolls) keeps every registered photo and only reports. The sparse points kept are those at least two of the
   kept photos see.
7. Fewer than :data:`MIN_KEPT_SHARE` of the readable photos kept, or images in subfolders of the folder (not read),
   is warned of (:func:`warnings.warn`, and ``report["warnings"]``, which ``n2r poses`` and ``n2r fit`` print).

The same photos and ``seed`` give the same reconstruction, bit for bit, whatever the threads' timing: the photos
are numbered in name order before extraction's threads start (they numbered them in the order they finished),
matching runs one matcher thread with a seeded RANSAC, and mapping's threads keep to its seed.

Each camera is scaled back to its full-resolution images with :meth:`Camera.resized` (radial distortion
coefficients act on normalized coordinates, so they do not change). ``report["cameras"]`` lists the
cameras: upright size, number of photos, and how many of them registered and were kept (step 6).
"""

from __future__ import annotations

import filecmp
import hashlib
import os
import tempfile
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import IngestError, InvalidType
from ..geometry import invert_pose, orthonormalize
from .colmap import PYCOLMAP_ERRORS, camera_from_colmap
from .colour import PhotoColourWarning
from .images import iter_readable, read_image, resize_image
from .listing import list_images, other_files, subfolder_hint
from .poses import PoseSet, SourceFrame
from .upright import check_upright

__all__ = ["run_sfm", "partial_registration", "EXHAUSTIVE_MAX_IMAGES", "MATCHERS", "MIN_KEPT_SHARE"]

#: Fewer of the readable photos registered and kept than this share is warned of (not refused): the reconstruction
#: may be folded or split. Measured (docs/ingestion.md, docs/scene-field-log.md, and a review's phone-style capture of
#: the demo object): right reconstructions keep all or nearly all their photos (the fox 50 of 50, the demo wall 48 of
#: 48 or 46 once 2 upside-down photos are dropped, the object at 960 px 48 of 48, the textured corner of the tests 10 of
#: 10, the review's 120-frame video 115); the poor ones keep fewer (the object at 320 px, focal length 23 % off: 31, 33,
#: 34 and 41 of 48, 65-85 %; the review's photos, folded, rotations 60-104° off the truth: 31 of 48). 90 % lies between
#: the two. A count cannot see every wrong reconstruction: the object at 480 px kept 44 of 48 (92 %) with about half of
#: them half a turn wrong.
MIN_KEPT_SHARE = 0.9
#: When fewer than 3 photos register and all are under this many pixels a side, the error gives the largest's size
#: (SIFT finds too few features on them: three 32x24 photos register none).
SMALL_PHOTO_SIDE = 200
#: ``matcher="auto"`` matches exhaustively up to this many images, sequentially beyond.
EXHAUSTIVE_MAX_IMAGES = 100
MATCHERS = ("auto", "exhaustive", "sequential")
#: Photos are told apart by a digest of every ``SAMPLE_STEP``-th row and column of their pixels (2 ms for 12 MP,
#: against 39 ms for all of them); only photos whose samples agree are compared in full (:func:`_same_pixels`).
SAMPLE_STEP = 7


def run_sfm(
    images_dir: str | os.PathLike, *, max_size: int = 960, matcher: str = "auto", max_features: int = 2048,
    num_threads: int = -1, seed: int = 0, upright: bool = True, files: Sequence[str | os.PathLike] | None = None,
) -> PoseSet:
    """Recover cameras, poses and sparse points of the photos in ``images_dir`` (see the module docstring), or of
    only those ``files`` there (a video's frames, whatever else their folder holds).

    Returns a :class:`PoseSet` whose frames are the registered images sorted by file name, with the
    full-resolution camera. ``report["time_s"]`` holds seconds per stage (``read``, ``features``,
    ``matching``, ``mapping``); ``report["other_files"]`` counts the files of the folder left alone (not images by
    their suffix; 0 when ``files`` are given). Raises :class:`IngestError` naming the folder or files on bad input and
    when fewer than 3 images register.
    """
    import cv2
    import pycolmap

    if matcher not in MATCHERS:
        raise IngestError(f"matcher={matcher!r} is not one of {MATCHERS}")
    if isinstance(max_size, bool) or not isinstance(max_size, int) or max_size < 64:
        raise IngestError(f"max_size={max_size!r} must be an int >= 64 (pixels)")
    if not isinstance(upright, bool):
        raise InvalidType(f"upright={upright!r} must be True (photos taken upright) or False (a camera that rolls)")
    images_dir = Path(images_dir)
    given = files
    files = list_images(images_dir) if given is None else [Path(f) for f in given]
    times: dict[str, float] = {}
    skipped: list[tuple[str, str]] = []
    twins: list[tuple[Path, str]] = []  # (a copy, the work name of the photo with its pixels): skipped
    seen: dict[bytes, list[str]] = {}  # digest of a sample of the decoded pixels -> work names of the photos kept
    full: dict[str, bytes] = {}  # work name -> digest of all its pixels, computed when its sample's is met again
    colour_notes: list[str] = []

    start = time.perf_counter()
    sizes: dict[tuple[int, int], list[str]] = {}
    with tempfile.TemporaryDirectory(prefix="n2r-sfm-") as tmp:
        work = Path(tmp)
        (work / "images").mkdir()
        names: dict[str, Path] = {}  # work file name (size folder / index) -> original file
        full_size: dict[str, tuple[int, int]] = {}  # work file name -> upright (width, height)
        for k, (file, image) in enumerate(_colour_noted(iter_readable(files, skipped), colour_notes)):
            h, w = image.shape[:2]
            key = _pixels_key(image, step=SAMPLE_STEP)
            twin, digest = _same_pixels(image, file, seen.get(key, []), names, full)
            if twin is not None:  # the same work copy: keep the name of the original, not of its copy
                if _original(file) < _original(names[twin]):
                    names[twin], file = file, names[twin]
                twins.append((file, twin))
                continue
            scale = min(1.0, max_size / max(w, h))
            small = resize_image(image, max(1, round(w * scale)), max(1, round(h * scale)))
            (work / "images" / f"{w}x{h}").mkdir(exist_ok=True)
            work_name = f"{w}x{h}/{k:06d}.png"
            if not cv2.imwrite(str(work / "images" / work_name), cv2.cvtColor(small, cv2.COLOR_RGB2BGR)):
                raise IngestError(f"cannot write a downscaled copy of {str(file)!r} to the temporary folder {tmp!r}")
            names[work_name] = file
            full_size[work_name] = (w, h)
            sizes.setdefault((w, h), []).append(work_name)
            seen.setdefault(key, []).append(work_name)
            if digest:  # computed: another photo's sample digest is the same
                full[work_name] = digest
        # named after the loop: a copy read first gives way to its original read later, which its other copies name
        copies = [(copy.name, f"the same pixels as {names[twin].name} (a copy or a link to it)")
                  for copy, twin in twins]
        if len(names) < 3:
            raise IngestError(_too_few(images_dir, files, skipped, copies, listed=given is None))
        skipped += copies
        times["read"] = time.perf_counter() - start

        db = work / "database.db"
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = "SIMPLE_RADIAL"
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.num_threads = num_threads
        extraction.sift.max_num_features = max_features
        extraction.sift.first_octave = 0  # no 2x upsampling: 3-4x faster, enough features at <= 960 px
        with _stage("features", images_dir, times):
            # numbered in name order first: extraction's threads would number them in the order they finish, and
            # the numbering orders the pairs matched and the mapper's choices (another reconstruction each run)
            pycolmap.Database.open(str(db)).close()
            pycolmap.import_images(db, work / "images", camera_mode=pycolmap.CameraMode.PER_FOLDER, options=reader)
            pycolmap.extract_features(
                db, work / "images", camera_mode=pycolmap.CameraMode.PER_FOLDER, reader_options=reader,
                extraction_options=extraction, device=pycolmap.Device.cpu,
            )

        matching = pycolmap.FeatureMatchingOptions()
        # one matcher thread, its RANSAC seeded: with two, 1 run in 24 of the suite's capture registered other poses
        # (seeded or not); pycolmap still keeps both cores busy within it (the fox: 18.4 CPU s in 9.9 s of wall time,
        # against 9.1 s with two matcher threads; 7 December)
        matching.num_threads = 1
        verification = pycolmap.TwoViewGeometryOptions()
        verification.ransac.random_seed = seed
        used = matcher if matcher != "auto" else ("exhaustive" if len(names) <= EXHAUSTIVE_MAX_IMAGES else "sequential")
        with _stage("matching", images_dir, times):
            if used == "exhaustive":
                pycolmap.match_exhaustive(db, matching_options=matching, verification_options=verification,
                                          device=pycolmap.Device.cpu)
            else:
                pycolmap.match_sequential(db, matching_options=matching, verification_options=verification,
                                          device=pycolmap.Device.cpu)

        options = pycolmap.IncrementalPipelineOptions()
        options.num_threads = num_threads
        options.random_seed = seed
        options.mapper.random_seed = seed
        options.triangulation.random_seed = seed
        options.extract_colors = False
        with _stage("mapping", images_dir, times):
            models = pycolmap.incremental_mapping(db, work / "images", work / "sparse", options=options)

    if not models:
        raise IngestError(f"structure from motion on {str(images_dir)!r} registered no images (too little overlap or "
                          f"texture?){_small(sizes)}")
    rec = max(models.values(), key=lambda r: r.num_reg_images())
    frames: list[SourceFrame] = []
    for image in rec.images.values():
        if not image.has_pose:
            continue
        cam = rec.cameras[image.camera_id]
        camera = camera_from_colmap(cam.model.name, cam.width, cam.height, cam.params, where="SfM camera")
        w2c = np.eye(4)
        w2c[:3] = np.asarray(image.cam_from_world().matrix(), dtype=np.float64)
        w2c[:3, :3] = orthonormalize(w2c[:3, :3])
        original = names[image.name]
        frames.append(SourceFrame(
            name=original.name, path=original, camera=camera.resized(*full_size[image.name]), c2w=invert_pose(w2c)
        ))
    frames.sort(key=lambda f: f.name)
    registered = {f.name for f in frames}
    elsewhere = {names[image.name].name: other.num_reg_images() for other in models.values() if other is not rec
                 for image in other.images.values() if image.has_pose}
    skipped += [(f.name, "not registered by structure from motion" + (
                 f" (it formed a separate model of {elsewhere[f.name]} images that shares too few matches with "
                 f"the kept one of {len(frames)}; more photos bridging the two would join them)"
                 if f.name in elsewhere else " (too few features matched with the other photos)"))
                for f in names.values() if f.name not in registered]
    if len(frames) < 3:
        raise IngestError(
            f"structure from motion on {str(images_dir)!r} registered only {len(frames)} of {len(names)} images; "
            f"at least 3 are needed (more overlap between photos helps){_small(sizes)}"
        )
    up_record = check_upright([f.name for f in frames], [f.c2w for f in frames]).as_report()
    turned = up_record["upside_down"] if upright else {}
    if upright and up_record["doubtful"]:
        raise IngestError(
            f"structure from motion on {str(images_dir)!r} registered {len(turned)} of {len(frames)} photos upside "
            "down against the others: it has likely taken symmetric or repeated structure (a brick wall, an object's "
            "two alike sides) for the same view, and its poses cannot be trusted; give the poses from elsewhere "
            "(a transforms.json or a COLMAP model), or add photos that also see something asymmetric. Photos not all "
            "taken upright (looking straight down, or from a camera that rolls) are kept by --any-roll "
            "(n2r fit, n2r poses) or upright=False"
        )
    frames = [f for f in frames if f.name not in turned]
    skipped += [(name, (f"registered upside down against the other photos ({angle:.0f}° from their up): "
                        "structure from motion has likely put it half a turn wrong on symmetric or repeated structure"))
                for name, angle in turned.items()]
    # the points at least two kept photos see (all of them, unless photos were skipped as upside down)
    kept = {image_id for image_id, image in rec.images.items() if names[image.name].name not in turned}
    points = np.array([p.xyz for _, p in sorted(rec.points3D.items())
                       if sum(el.image_id in kept for el in p.track.elements) >= 2], dtype=np.float64).reshape(-1, 3)
    notes = colour_notes + [note for note in (partial_registration(len(frames), len(names)),
                               subfolder_hint(images_dir, len(files)) if given is None else "") if note]
    for note in notes[len(colour_notes):]:
        warnings.warn(f"structure from motion on {str(images_dir)!r}: {note}", stacklevel=2)
    registered_sizes = [(f.camera.width, f.camera.height) for f in frames]
    cameras = [{"width": w, "height": h, "photos": len(listed), "registered": registered_sizes.count((w, h))}
               for (w, h), listed in sorted(sizes.items(), key=lambda kv: -len(kv[1]))]
    report = {
        "images": len(files), "other_files": other_files(images_dir) if given is None else 0, "matcher": used,
        "models": len(models), "sfm_max_size": max_size, "cameras": cameras,
        "time_s": times, "points_method": "structure from motion",
        "upright": {**up_record, "dropped": bool(turned)}, "warnings": notes,
    }
    return PoseSet(frames=frames, points=points, source=str(images_dir), kind="images", skipped=skipped,
                   report=report)


def partial_registration(kept: int, readable: int) -> str:
    """The warning for a reconstruction that keeps ``kept`` of the ``readable`` photos, when that is fewer than
    :data:`MIN_KEPT_SHARE` of them (``""`` otherwise)."""
    if readable <= 0 or kept >= MIN_KEPT_SHARE * readable:
        return ""
    return (f"only {kept} of the {readable} readable photos registered and were kept ({100 * kept / readable:.0f} %, "
            f"under {100 * MIN_KEPT_SHARE:.0f} %): a reconstruction of part of a capture is often folded or put "
            "together wrong. Check the poses before trusting a fit: n2r poses SOURCE --compare OTHER against poses "
            "from elsewhere, or render a training view of the fitted scene (n2r render SCENE --view NAME) and set it "
            "beside its photo")


def _too_few(images_dir: Path, files: list[Path], skipped: list[tuple[str, str]], copies: list[tuple[str, str]],
             listed: bool) -> str:
    """Why fewer than 3 of ``files`` could be used: each unreadable file with its reason, each copy of another, and
    the images in subfolders (when the folder was ``listed``, not given as ``files``)."""
    readable = len(files) - len(skipped) - len(copies)
    if skipped or copies:
        which = "readable" if not copies else "readable and different" if skipped else "different"
        text = (f"images folder {str(images_dir)!r}: only {readable} of {len(files)} images are {which}; structure "
                "from motion needs at least 3")
        text += ". Unreadable: " + "; ".join(reason for _, reason in skipped) if skipped else ""
        text += ". Copies: " + "; ".join(f"{name} has {reason}" for name, reason in copies) if copies else ""
    else:
        text = (f"images folder {str(images_dir)!r} holds only {readable} image{'s' * (readable != 1)} "
                f"({', '.join(f.name for f in files)}); structure from motion needs at least 3")
    hint = subfolder_hint(images_dir, len(files)) if listed else ""
    return f"{text}; {hint}" if hint else text


def _pixels_key(image: np.ndarray, step: int = 1) -> bytes:
    """A digest of the decoded pixels (every ``step``-th row and column of them), their shape and type: two photos
    with the same full one (``step=1``) are copies of each other."""
    digest = hashlib.blake2b(f"{image.shape} {image.dtype} {step}".encode(), digest_size=16)
    digest.update(np.ascontiguousarray(image[::step, ::step]).data)
    return digest.digest()


def _same_pixels(image: np.ndarray, file: Path, candidates: list[str], names: dict[str, Path],
                 full: dict[str, bytes]) -> tuple[str | None, bytes]:
    """The work name of the photo among ``candidates`` (those whose sample digest is ``image``'s, read from ``file``)
    with all of ``image``'s pixels (``None`` when none has them), and the digest of all ``image``'s pixels when it was
    computed (else ``b""``). A file with the same bytes (a copy, a link) has them; otherwise the digests of all the
    pixels are compared, the candidates' kept in ``full``, a photo read again (its warnings silenced) when its digest
    is first needed: a photo saved again, or one that differs only between the pixels sampled."""
    digest = b""
    for work_name in candidates:
        if _same_bytes(file, names[work_name]):
            return work_name, digest
        digest = digest or _pixels_key(image)
        if work_name not in full:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    full[work_name] = _pixels_key(read_image(names[work_name]))
                except IngestError:  # gone or changed since it was read: not a copy of it
                    full[work_name] = b""
        if full[work_name] == digest:
            return work_name, digest
    return None, digest


def _same_bytes(a: Path, b: Path) -> bool:
    """Whether the files at ``a`` and ``b`` hold the same bytes (``False`` when one cannot be read)."""
    try:
        return filecmp.cmp(a, b, shallow=False)
    except OSError:
        return False


def _original(file: Path) -> tuple[bool, int, str]:
    """Sorts the original of photos with the same pixels first: a file before a link to it, then the shorter name
    (``IMG_0001.JPG`` before ``IMG_0001 (1).JPG``), then the name."""
    return file.is_symlink(), len(file.name), file.name


def _small(sizes: dict[tuple[int, int], list[str]]) -> str:
    """``"; the largest photo is WxH pixels: ..."`` when every photo is under :data:`SMALL_PHOTO_SIDE` pixels a side
    (SIFT finds too few features on them), else ``""``."""
    w, h = max(sizes, key=max, default=(0, 0))
    if not sizes or max(w, h) >= SMALL_PHOTO_SIDE:
        return ""
    return (f"; the largest photo is {w}x{h} pixels, too small to find enough features in: photos of a few hundred "
            "pixels a side or more are needed")


def _colour_noted(pairs: Iterator[tuple[Path, np.ndarray]], notes: list[str]) -> Iterator[tuple[Path, np.ndarray]]:
    """``pairs``, each :class:`~.colour.PhotoColourWarning` of their reading added to ``notes`` (what the report's
    ``warnings`` list, which ``n2r poses`` and ``n2r fit`` print) and warned again."""
    while True:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PhotoColourWarning)
            pair = next(pairs, None)
        for w in caught:
            if issubclass(w.category, PhotoColourWarning):
                notes.append(str(w.message))
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if pair is None:
            return
        yield pair


@contextmanager
def _stage(name: str, images_dir: Path, times: dict[str, float]) -> Iterator[None]:
    """Time a pycolmap stage into ``times[name]``, keep COLMAP's INFO and WARNING log off stderr (our
    report says what happened; errors still show), and turn its exceptions into :class:`IngestError`."""
    import pycolmap

    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 2
    start = time.perf_counter()
    try:
        yield
    except IngestError:
        raise
    except PYCOLMAP_ERRORS as exc:  # plain RuntimeError/ValueError carrying C++ check messages
        raise IngestError(f"structure from motion on {str(images_dir)!r} failed during {name}: {exc}") from None
    finally:
        pycolmap.logging.minloglevel = level
        times[name] = time.perf_counter() - start
