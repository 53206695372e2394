"""A demo scene photographed the way a phone does it: a folder of photos to ingest like a real capture.

What a phone capture does that :mod:`.rendered_capture` does not, each drawn per photo from a seeded
generator (:class:`PhoneSettings`):

- **orientation**: every ``portrait_every``-th photo is taken in portrait: the phone rolled 90° about its optical
  axis, so the photo, viewed upright, is taller than wide and the world's up is still at its top (the same pose,
  the sensor's width and height swapped). Of those, every other one is stored as the phone stores it: the
  sensor's landscape pixels, which show the world on its side, with the EXIF orientation tag 6 ("rotate 90°
  clockwise to view"; in a HEIC, the container's rotation box ``irot`` as well, as an iPhone writes it); the
  others are stored upright;
- **exposure and white balance**: a gain of ``2 ** u`` stops, ``u`` uniform in ``±exposure_stops``, and a
  per-channel gain uniform in ``1 ± white_balance``, applied to linear light (sRGB decoded with gamma 2.2);
- **slight blur**: a Gaussian of sigma uniform in ``[0, blur_px]`` pixels (hand shake, focus);
- **shaken photos** (off by default): with probability ``shaken``, a photo is also smeared along a straight streak of
  ``shake_px`` pixels at an angle uniform in ``[0°, 180°)``, in linear light, as a phone moved during the exposure
  records it (drawn from a generator of its own, so a capture with shaken photos differs from the same capture
  without them in those photos alone);
- **JPEG**, or **HEIC** as iPhones store photos (``file_format``), at ``jpeg_quality``.

The ground truth of every photo (its camera-to-world pose, OpenCV axes, world frame of the demo scene; its
upright camera; the drawn degradations) is returned with the folder, so a test can align what structure from
motion recovers to the truth and score a fitted field against the exact scene.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InvalidArgument, InvalidType
from ..geometry import Camera
from .rendered_capture import check_size

__all__ = ["PhonePhoto", "PhoneSettings", "streak_kernel", "write_phone_capture"]

#: EXIF tag number of the orientation, and the value meaning "rotate 90° clockwise to view".
EXIF_ORIENTATION = 0x0112
ROTATE_90_CW = 6
#: The photo files a phone writes, by :attr:`PhoneSettings.file_format`: suffix and Pillow's format name.
FILE_FORMATS = {"jpeg": (".jpg", "JPEG"), "heic": (".heic", "HEIF")}
#: The name of a photo :func:`write_phone_capture` writes, of either format (an earlier call's are replaced).
PHOTO_NAME = re.compile(r"photo_\d{3,}(" + "|".join(re.escape(s) for s, _ in FILE_FORMATS.values()) + ")")
#: The smallest :attr:`PhoneSettings.size` (longer side, pixels): a photo is at least 8x8 pixels (a scene whose
#: shorter side is under this size's aspect needs more: :func:`write_phone_capture` says so before writing).
MIN_SIZE = 8


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True)
class PhoneSettings:
    """How the phone photographs (see the module docstring); ``size`` is the longer side in pixels;
    ``jpeg_quality`` is the quality of either codec of :data:`FILE_FORMATS`."""

    size: int = 480
    portrait_every: int = 3
    exposure_stops: float = 0.5
    white_balance: float = 0.08
    blur_px: float = 0.8
    shaken: float = 0.0
    shake_px: float = 6.0
    jpeg_quality: int = 90
    seed: int = 0
    file_format: str = "jpeg"

    def __post_init__(self) -> None:
        for name in ("size", "portrait_every", "jpeg_quality", "seed"):
            if not _is_int(getattr(self, name)):
                raise InvalidType(f"PhoneSettings.{name}={getattr(self, name)!r}: expected an int, not "
                                  f"{type(getattr(self, name)).__name__}")
        if self.size < MIN_SIZE:
            raise InvalidArgument(f"PhoneSettings.size={self.size!r}: expected the photos' longer side in pixels, "
                                  f">= {MIN_SIZE}")
        if self.file_format not in FILE_FORMATS:
            raise InvalidArgument(
                f"PhoneSettings.file_format={self.file_format!r}: expected one of {list(FILE_FORMATS)}")
        if not 1 <= self.jpeg_quality <= 100:
            raise InvalidArgument(f"PhoneSettings.jpeg_quality={self.jpeg_quality!r}: expected 1..100")
        for name in ("exposure_stops", "white_balance", "blur_px", "shake_px", "shaken"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise InvalidType(f"PhoneSettings.{name}={value!r}: expected a number, not {type(value).__name__}")
            if name != "shaken" and not 0 <= value < float("inf"):  # shaken: a probability, below
                raise InvalidArgument(f"PhoneSettings.{name}={value!r}: expected a finite number >= 0")
        if self.white_balance >= 1:
            raise InvalidArgument(f"PhoneSettings.white_balance={self.white_balance!r}: expected less than 1")
        if not 0 <= self.shaken <= 1:
            raise InvalidArgument(f"PhoneSettings.shaken={self.shaken!r}: expected a probability in [0, 1]")
        if self.seed < 0:
            raise InvalidArgument(f"PhoneSettings.seed={self.seed!r}: expected an int >= 0")
        if self.portrait_every < 0:
            raise InvalidArgument(f"PhoneSettings.portrait_every={self.portrait_every!r}: expected >= 0 (0: none)")


@dataclass(frozen=True)
class PhonePhoto:
    """One photo of a phone capture and its truth: the file, the camera and camera-to-world pose of the photo
    viewed upright (OpenCV axes, the demo scene's world frame), whether it was taken in portrait and stored with an EXIF
    rotation, the drawn exposure gain, white-balance gains (R, G, B) and blur sigma (pixels), and the streak of a
    shaken photo: its length (pixels; 0 for a photo not shaken) and angle (degrees from the image's x axis towards
    its y axis, as the photo is viewed upright)."""

    path: Path
    camera: Camera
    c2w: np.ndarray
    portrait: bool
    exif_rotated: bool
    gain: float
    white_balance: tuple[float, float, float]
    blur_px: float
    shake_px: float = 0.0
    shake_deg: float = 0.0


def _portrait_camera(camera: Camera) -> Camera:
    """The upright camera of the landscape ``camera``'s sensor turned to portrait: width and height swapped, the
    principal point turned with the sensor (90° clockwise, as the photo is viewed), square pixels kept."""
    return Camera(camera.height, camera.width, camera.fy, camera.fx, camera.height - 1 - camera.cy, camera.cx)


def streak_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """The normalized kernel of a straight motion streak ``length_px`` pixels long at ``angle_deg`` (from the x axis
    towards y, image axes), centred: the segment sampled every 1/8 pixel, each sample spread bilinearly.

    >>> k = streak_kernel(4.0, 0.0)
    >>> k.shape, round(float(k.sum()), 6), bool(k[k.shape[0] // 2].sum() > 0.99)
    ((7, 7), 1.0, True)
    """
    half = length_px / 2
    size = 2 * int(np.ceil(half)) + 3
    c = size // 2
    t = np.linspace(-half, half, max(2, int(np.ceil(length_px * 8)) + 1))
    x = c + t * np.cos(np.radians(angle_deg))
    y = c + t * np.sin(np.radians(angle_deg))
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    kernel = np.zeros((size, size))
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            np.add.at(kernel, (y0 + dy, x0 + dx), wy * wx)
    return kernel / kernel.sum()


def _degrade(rgb: np.ndarray, gain: float, wb: np.ndarray, sigma: float, streak: np.ndarray | None) -> np.ndarray:
    import cv2

    linear = (rgb.astype(np.float32) / 255.0) ** 2.2 * (gain * wb.astype(np.float32))
    if streak is not None:  # the sensor integrates light while the phone moves: a smear in linear light
        linear = cv2.filter2D(linear, -1, streak.astype(np.float32), borderType=cv2.BORDER_REFLECT)
    out: np.ndarray = np.clip(linear, 0.0, 1.0) ** (1 / 2.2) * 255.0
    if sigma > 0.05:
        out = cv2.GaussianBlur(out, (0, 0), sigma)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _check_views(views: Sequence[int] | None, count: int) -> list[int]:
    """``views`` as a list of distinct indices into a trajectory of ``count`` views (all of them for ``None``), or
    raise naming ``views``."""
    if views is None:
        return list(range(count))
    try:
        indices = list(views)
    except TypeError:
        raise InvalidType(f"views={views!r}: expected a sequence of view indices, not {type(views).__name__}") from None
    for k, index in enumerate(indices):
        if not _is_int(index):
            raise InvalidType(f"views[{k}]={index!r}: expected an int index, not {type(index).__name__}")
    if not indices:
        raise InvalidArgument("views is empty: expected at least one view index (None: every view)")
    outside = [int(i) for i in indices if not 0 <= i < count]
    if outside:
        raise InvalidArgument(f"views holds {outside}: expected indices in 0..{count - 1} (the trajectory's views)")
    repeated = sorted({int(i) for k, i in enumerate(indices) if i in indices[:k]})
    if repeated:
        raise InvalidArgument(f"views holds {repeated} more than once: expected distinct indices (one photo each)")
    return [int(i) for i in indices]


def write_phone_capture(name: str, out_dir: str | os.PathLike, settings: PhoneSettings = PhoneSettings(), *,
                        views: Sequence[int] | None = None, poses: bool = True) -> list[PhonePhoto]:
    """Photograph the exact demo scene ``name`` at its trajectory's poses (``views``: distinct indices into the
    trajectory, default all) into ``out_dir`` as ``photo_<index>.jpg`` (or ``.heic``) files; return each photo's
    truth.

    With ``poses``, also write ``out_dir/transforms.json`` (nerfstudio; one camera per photo, as the photo
    is viewed upright; the demo trajectory's train / held-out split), so ``n2r fit out_dir`` fits it
    without structure from motion, in the demo scene's world frame. Without it, ``n2r fit`` runs
    structure from motion on the folder.

    ``out_dir`` then holds this capture alone, as ``n2r fit`` reads the whole folder: an earlier call's photos
    (``photo_<index>`` files of either format) that this one does not write are removed, and so is an earlier
    ``transforms.json`` (before any photo is written; with ``poses`` a new one is written last). Other files are
    left alone. The arguments are checked before anything is written.
    """
    from PIL import Image

    from ..data.poses import SourceFrame
    from ..data.transforms_json import write_transforms_json
    from . import ground_truth

    if settings.file_format == "heic":
        import pillow_heif

        pillow_heif.register_heif_opener()  # Pillow's "HEIF" format, which writes the EXIF orientation as irot
    scene = ground_truth(name)
    indices = _check_views(views, len(scene.views))
    cameras: dict[int, Camera] = {}
    for index in indices:
        try:
            cameras[index] = check_size(settings.size, scene.views[index].camera)
        except InvalidArgument as exc:
            raise InvalidArgument(
                f"PhoneSettings.size={settings.size!r} is too small for scene {name!r}: {exc}") from None
    suffix, codec = FILE_FORMATS[settings.file_format]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {f"photo_{index:03d}{suffix}" for index in indices}
    for stale in out.iterdir():  # an earlier capture's poses and photos: ingestion would read them with these
        if stale.is_file() and (stale.name == "transforms.json" or (PHOTO_NAME.fullmatch(stale.name)
                                                                    and stale.name not in written)):
            stale.unlink()
    rng = np.random.default_rng(settings.seed)
    shaking = np.random.default_rng([settings.seed, 1])  # a stream of its own: the other draws do not depend on it
    photos: list[PhonePhoto] = []
    train: list[str] = []
    heldout: list[str] = []
    for k, index in enumerate(indices):
        view = scene.views[index]
        camera = cameras[index]
        portrait = settings.portrait_every > 0 and k % settings.portrait_every == settings.portrait_every - 1
        exif_rotated = portrait and (k // settings.portrait_every) % 2 == 0
        c2w = view.c2w.copy()  # viewed upright, a portrait photo keeps the landscape one's pose
        camera = _portrait_camera(camera) if portrait else camera
        gain = float(2.0 ** rng.uniform(-settings.exposure_stops, settings.exposure_stops))
        wb = rng.uniform(1 - settings.white_balance, 1 + settings.white_balance, 3)
        sigma = float(rng.uniform(0.0, settings.blur_px))
        shake_px = shake_deg = 0.0
        if settings.shaken > 0:
            draw, angle = shaking.uniform(size=2)
            if draw < settings.shaken:
                shake_px, shake_deg = settings.shake_px, 180.0 * float(angle)
        streak = streak_kernel(shake_px, shake_deg) if shake_px > 0 else None
        rgb = scene.render(c2w, camera, ("rgb",)).output("rgb")
        upright = _degrade(rgb, gain, wb, sigma, streak)
        path = out / f"photo_{index:03d}{suffix}"
        exif = Image.Exif()
        if exif_rotated:  # the phone keeps the sensor's landscape pixels and says how to turn them
            exif[EXIF_ORIENTATION] = ROTATE_90_CW
            stored = np.rot90(upright, k=1)  # 90° counter-clockwise; the viewer turns it back clockwise
        else:
            stored = upright
        tmp = path.with_suffix(".tmp")
        Image.fromarray(np.ascontiguousarray(stored)).save(tmp, format=codec, quality=settings.jpeg_quality,
                                                           exif=exif.tobytes())
        os.replace(tmp, path)
        photos.append(PhonePhoto(path, camera, c2w, portrait, exif_rotated, gain,
                                 (float(wb[0]), float(wb[1]), float(wb[2])), sigma, shake_px, shake_deg))
        (train if view.split == "train" else heldout).append(path.name)
    if poses:
        frames = [SourceFrame(name=p.path.name, path=p.path, camera=p.camera, c2w=p.c2w) for p in photos]
        write_transforms_json(out / "transforms.json", frames, extra={
            "train_filenames": train, "val_filenames": heldout, "n2r_scene": name,
            "n2r_content_hash": scene.content_hash, "n2r_reference_length": scene.reference_length})
    return photos
