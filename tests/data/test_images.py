"""Image listing and decoding: EXIF orientation, HEIF photos, gray/RGBA/16-bit conversion, unreadable files."""

from __future__ import annotations

import cv2
import numpy as np
import pillow_heif
import pytest
from PIL import Image, ImageOps

from pytest_n2r.data.images import (
    images_in_subfolders,
    iter_readable,
    list_images,
    other_files,
    read_image,
    read_image_size,
    read_turn,
    subfolder_hint,
    to_rgb8,
)
from pytest_n2r.errors import IngestError


def _pattern() -> np.ndarray:
    """6 rows x 4 columns RGB with a red top-left pixel and a blue bottom-left pixel."""
    img = np.full((6, 4, 3), 128, np.uint8)
    img[0, 0] = (255, 0, 0)
    img[5, 0] = (0, 0, 255)
    return img


def test_rgb_order_is_rgb(tmp_path):
    Image.fromarray(_pattern()).save(tmp_path / "a.png")
    img = read_image(tmp_path / "a.png")
    assert img.dtype == np.uint8 and img.shape == (6, 4, 3)
    assert img[0, 0].tolist() == [255, 0, 0], "channels are not in RGB order"


@pytest.mark.parametrize(
    ("orientation", "corner"),
    [(1, (0, 0)), (3, (5, 3)), (6, (0, 5)), (8, (3, 0))],  # where the red top-left pixel ends up (row, col)
)
def test_exif_orientation_is_applied(tmp_path, orientation, corner):
    big = cv2.resize(_pattern(), (40, 60), interpolation=cv2.INTER_NEAREST)
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(big).save(tmp_path / "a.jpg", exif=exif, quality=100)
    img = read_image(tmp_path / "a.jpg")
    rotated = orientation in (6, 8)
    assert img.shape[:2] == ((40, 60) if rotated else (60, 40))
    assert read_image_size(tmp_path / "a.jpg") == (img.shape[1], img.shape[0])
    r, c = corner
    r, c = r * 10 + 5, c * 10 + 5
    assert img[r, c, 0] > 200 and img[r, c, 2] < 60, f"orientation {orientation}: red pixel not at {corner}"


#: how each format is saved losslessly (JPEG as near as it gets)
_FORMATS = {"jpg": {"quality": 100}, "png": {}, "tif": {}, "webp": {"lossless": True}}


@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("suffix", list(_FORMATS))
def test_every_format_reads_upright_or_as_stored_and_its_size_is_the_upright_one(tmp_path, suffix, orientation):
    """read_image's upright pixels match Pillow's exif_transpose, read_image(oriented=False) gives the stored pixels
    (as COLMAP reads them), and read_image_size says the size read_image decodes (a TIFF's was swapped twice)."""
    stored = cv2.resize(_pattern(), (40, 60), interpolation=cv2.INTER_NEAREST)
    exif = Image.Exif()
    exif[0x0112] = orientation
    path = tmp_path / f"a.{suffix}"
    Image.fromarray(stored).save(path, exif=exif, **_FORMATS[suffix])
    Image.fromarray(stored).save(tmp_path / "ref.png", exif=exif)
    expected = np.asarray(ImageOps.exif_transpose(Image.open(tmp_path / "ref.png")))
    upright = read_image(path)
    assert read_image_size(path) == (upright.shape[1], upright.shape[0]), \
        f"{suffix}, orientation {orientation}: read_image_size says {read_image_size(path)}, read_image decodes " \
        f"{upright.shape[1]}x{upright.shape[0]}"
    as_stored = read_image(path, oriented=False)
    for got, want, what in ((upright, expected, "upright"), (as_stored, stored, "as stored")):
        assert got.shape == want.shape, \
            f"{suffix}, orientation {orientation}: read {what} as {got.shape}, not {want.shape}"
        error = np.abs(got.astype(int) - want).mean()
        assert error < 2.0, f"{suffix}, orientation {orientation}: the pixels read {what} differ by {error:.1f} on mean"


def _save_heic(image: np.ndarray, path, orientation: int = 1) -> None:
    """Save as an iPhone does: the pixels as given, the EXIF orientation written into the container as irot/imir."""
    pillow_heif.register_heif_opener()
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(image).save(path, format="HEIF", exif=exif.tobytes(), quality=100)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_heif_photo_is_upright_as_the_same_jpeg(tmp_path, orientation):
    big = cv2.resize(_pattern(), (40, 60), interpolation=cv2.INTER_NEAREST)
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(big).save(tmp_path / "a.jpg", exif=exif, quality=100)
    _save_heic(big, tmp_path / "a.heic", orientation)
    boxes = {box for box in (b"irot", b"imir") if box in (tmp_path / "a.heic").read_bytes()}
    assert boxes if orientation > 1 else not boxes, \
        f"orientation {orientation}: the HEIC holds {boxes or 'no'} transformation boxes; the test would not " \
        "exercise libheif's transformations as an iPhone's photo does"
    jpeg, heif = read_image(tmp_path / "a.jpg"), read_image(tmp_path / "a.heic")
    assert heif.shape == jpeg.shape, f"orientation {orientation}: HEIF read as {heif.shape}, the JPEG as {jpeg.shape}"
    assert read_image_size(tmp_path / "a.heic") == (heif.shape[1], heif.shape[0])
    # 4:2:0 chroma smears the colour blocks' edges; away from them the two codecs agree
    difference = np.abs(heif.astype(int) - jpeg).mean()
    assert difference < 2.0, f"orientation {orientation}: HEIF and JPEG differ by {difference:.2f} grey levels on mean"


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_heif_photo_as_stored_has_its_rotation_and_mirror_undone(tmp_path, orientation):
    """COLMAP reads a HEIF photo without its irot / imir (OpenImageIO's oiio:reorient=0): oriented=False does too."""
    stored = cv2.resize(_pattern(), (40, 60), interpolation=cv2.INTER_NEAREST)
    _save_heic(stored, tmp_path / "a.heic", orientation)
    got = read_image(tmp_path / "a.heic", oriented=False)
    assert got.shape == stored.shape, f"orientation {orientation}: the HEIF read as stored is {got.shape}"
    error = np.abs(got.astype(int) - stored).mean()
    assert error < 2.0, f"orientation {orientation}: the HEIF read as stored differs from its pixels by {error:.1f}"


@pytest.mark.parametrize("orientation", range(1, 9))
def test_read_turn_says_how_a_photo_is_shown_against_its_stored_pixels(tmp_path, orientation):
    """A HEIF photo's turn is its irot / imir (its EXIF tag only describes them): read_turn took the tag alone, so a
    transforms.json of turned HEIC photos was read as if none were turned."""
    stored = cv2.resize(_pattern(), (40, 60), interpolation=cv2.INTER_NEAREST)
    _save_heic(stored, tmp_path / "a.heic", orientation)
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(stored).save(tmp_path / "a.jpg", exif=exif, quality=100)
    for name in ("a.heic", "a.jpg"):
        turned, swapped = read_turn(tmp_path / name)
        shown = read_image(tmp_path / name)
        assert turned == (orientation != 1), f"{name}, orientation {orientation}: turned={turned}"
        assert swapped == (shown.shape[:2] != stored.shape[:2]), f"{name}, orientation {orientation}: swapped={swapped}"


def test_a_heif_photo_is_read_by_its_content_whatever_its_name(tmp_path):
    _save_heic(_pattern().repeat(10, 0).repeat(10, 1), tmp_path / "IMG_0001.HEIC")
    (tmp_path / "IMG_0001.HEIC").rename(tmp_path / "renamed.jpg")
    img = read_image(tmp_path / "renamed.jpg")
    assert img.shape == (60, 40, 3) and img[5, 5, 0] > 200 and img[55, 5, 2] > 200, "red or blue cell misplaced"
    assert read_image_size(tmp_path / "renamed.jpg") == (40, 60)


def test_a_truncated_heif_photo_names_the_file(tmp_path):
    _save_heic(np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8), tmp_path / "a.heic")
    data = (tmp_path / "a.heic").read_bytes()
    (tmp_path / "cut.heic").write_bytes(data[: len(data) // 2])
    with pytest.raises(IngestError, match=r"cut\.heic.*cannot be decoded as a HEIF photo"):
        read_image(tmp_path / "cut.heic")
    (tmp_path / "box.heic").write_bytes(b"\0\0\0\x18ftypheic" + bytes(12))  # a container with nothing in it
    with pytest.raises(IngestError, match=r"box\.heic.*cannot be decoded as a HEIF photo"):
        read_image(tmp_path / "box.heic")
    with pytest.raises(IngestError, match=r"box\.heic.*cannot be decoded as a HEIF photo"):
        read_image_size(tmp_path / "box.heic")


@pytest.mark.parametrize("error", [ValueError, RuntimeError, OSError, EOFError, SyntaxError, IndexError])
def test_every_error_pillow_heif_raises_names_the_file(tmp_path, monkeypatch, error):
    _save_heic(_pattern(), tmp_path / "a.heic")

    def fails(*args, **kwargs):
        raise error("as libheif says it")

    monkeypatch.setattr(pillow_heif, "open_heif", fails)
    with pytest.raises(IngestError, match=r"a\.heic.*cannot be decoded as a HEIF photo.*as libheif says it"):
        read_image(tmp_path / "a.heic")
    with pytest.raises(IngestError, match=r"a\.heic.*cannot be decoded as a HEIF photo"):
        read_image_size(tmp_path / "a.heic")


def test_a_heif_photo_is_an_array_of_its_own(tmp_path):
    _save_heic(_pattern(), tmp_path / "a.heic")
    img = read_image(tmp_path / "a.heic")
    assert img.flags.writeable, "the decoded photo is pillow-heif's read-only buffer"
    img[0, 0] = 0  # as a caller may, on a JPEG's as well


def test_gray_rgba_and_16_bit(tmp_path):
    Image.fromarray(np.full((5, 7), 77, np.uint8)).save(tmp_path / "g.png")
    assert read_image(tmp_path / "g.png").tolist() == np.full((5, 7, 3), 77).tolist()
    rgba = np.zeros((5, 7, 4), np.uint8)
    rgba[..., 0], rgba[..., 3] = 200, 10
    Image.fromarray(rgba).save(tmp_path / "a.png")
    with pytest.warns(UserWarning, match="transparent pixels"):  # tests/data/test_colour.py
        out = read_image(tmp_path / "a.png")
    assert out.shape == (5, 7, 3) and out[0, 0].tolist() == [200, 0, 0]
    deep = np.zeros((5, 7, 3), np.uint16)
    deep[..., 2] = 65535
    deep[..., 1] = 257 * 100
    cv2.imwrite(str(tmp_path / "d.png"), deep)  # OpenCV writes BGR: channel 2 is red
    out = read_image(tmp_path / "d.png")
    assert out.dtype == np.uint8 and out[0, 0].tolist() == [255, 100, 0]
    gray16 = np.full((5, 7), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "g16.png"), gray16)
    assert read_image(tmp_path / "g16.png")[0, 0].tolist() == [255, 255, 255]


def test_float_images_are_clipped_and_scaled():
    out = to_rgb8(np.array([[[0.5, -1.0, 2.0]]], np.float32), bgr=False)
    assert out.tolist() == [[[128, 0, 255]]]


def test_a_32_bit_integer_tiff_is_refused_naming_the_file_and_its_type(tmp_path):
    """Pillow's mode I (32-bit signed) was scaled by 255 / 2^31: an image of values up to 70 000 read all black."""
    Image.fromarray(np.arange(24, dtype=np.int32).reshape(4, 6) * 3000).save(tmp_path / "deep.tif")
    with pytest.raises(IngestError, match=r"deep\.tif'?: image of dtype int32 cannot be converted to 8-bit RGB; "
                                          r"expected 8- or 16-bit integers, or floating point in \[0, 1\]"):
        read_image(tmp_path / "deep.tif")


def test_corrupt_and_missing_files_name_the_file(tmp_path):
    (tmp_path / "bad.jpg").write_bytes(b"not a jpeg at all")
    with pytest.raises(IngestError, match=r"bad\.jpg.*cannot be decoded"):
        read_image(tmp_path / "bad.jpg")
    with pytest.raises(IngestError, match=r"nope\.png.*does not exist"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(IngestError, match="empty.png"):
        read_image(tmp_path / "empty.png")


def test_a_file_that_cannot_be_read_names_the_file(tmp_path, monkeypatch):
    Image.fromarray(_pattern()).save(tmp_path / "locked.png")

    def denied(*args, **kwargs):  # as reading a file without permission does (CI runs as root, who reads anything)
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(np, "fromfile", denied)
    with pytest.raises(IngestError, match=r"locked\.png.*cannot be read: Permission denied"):
        read_image(tmp_path / "locked.png")


def test_list_images_sorted_and_filtered(tmp_path):
    for name in ("b.JPG", "a.png", ".hidden.png", "notes.txt", "c.tiff", "d.HEIC", "e.heif", "f.mov", "g.jfif",
                 "h.JPE"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "sub.png").mkdir()
    assert [p.name for p in list_images(tmp_path)] == ["a.png", "b.JPG", "c.tiff", "d.HEIC", "e.heif", "g.jfif",
                                                       "h.JPE"]
    assert other_files(tmp_path) == 2  # notes.txt, f.mov: the hidden file and the folder are not counted


def test_a_jfif_photo_reads_as_the_jpeg_it_is(tmp_path):
    """Chrome and Windows save JPEGs as .jfif (and some tools as .jpe): they were left out of the capture."""
    cv2.imwrite(str(tmp_path / "a.jpg"), _pattern()[:, :, ::-1])
    (tmp_path / "saved.jfif").write_bytes((tmp_path / "a.jpg").read_bytes())
    assert np.array_equal(read_image(tmp_path / "saved.jfif"), read_image(tmp_path / "a.jpg"))


def test_list_images_errors(tmp_path):
    with pytest.raises(IngestError, match="does not exist"):
        list_images(tmp_path / "missing")
    with pytest.raises(IngestError, match="holds no images"):
        list_images(tmp_path)
    (tmp_path / "f.png").write_bytes(b"x")
    with pytest.raises(IngestError, match="is not a folder"):
        list_images(tmp_path / "f.png")


def test_an_empty_or_cut_short_photo_says_which(tmp_path):
    """A phone capture copied off the device: a cloud photo not downloaded is 0 bytes, an interrupted copy a JPEG
    cut short; each is named with what it looks like, not only "corrupt"."""
    (tmp_path / "IMG_0001.JPG").write_bytes(b"")
    with pytest.raises(IngestError, match=r"IMG_0001\.JPG' is empty \(0 bytes: a copy that did not finish, or a cloud"):
        read_image(tmp_path / "IMG_0001.JPG")
    cv2.imwrite(str(tmp_path / "whole.jpg"), np.random.default_rng(0).integers(0, 256, (64, 64, 3), np.uint8))
    data = (tmp_path / "whole.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(data[:len(data) // 8])
    with pytest.raises(IngestError, match=r"cut\.jpg' cannot be decoded as an image \(a JPEG cut short: an interr"):
        read_image(tmp_path / "cut.jpg")


@pytest.mark.parametrize(("suffix", "kind"), [(".png", "PNG"), (".webp", "WebP")])
def test_a_png_or_webp_cut_short_says_so(tmp_path, suffix, kind):
    """Only a JPEG was called cut short; a PNG or WebP copy interrupted was "corrupt or not an image"."""
    cv2.imwrite(str(tmp_path / f"whole{suffix}"), np.random.default_rng(0).integers(0, 256, (64, 64, 3), np.uint8))
    data = (tmp_path / f"whole{suffix}").read_bytes()
    (tmp_path / f"cut{suffix}").write_bytes(data[:len(data) * 2 // 3])
    with pytest.raises(IngestError, match=rf"cut\{suffix}' cannot be decoded as an image \(a {kind} cut short: an "
                                          r"interrupted copy\?\)"):
        read_image(tmp_path / f"cut{suffix}")


@pytest.mark.filterwarnings("ignore:Corrupt EXIF data:UserWarning")  # Pillow on the cut header: not ours to say
@pytest.mark.skipif(not hasattr(cv2.utils, "logging"), reason="OpenCV before 4.13 has no log level to set")
def test_a_broken_tiff_leaves_stderr_to_the_error(tmp_path, capfd):
    """OpenCV's TIFF decoder logged four lines of its own ([ WARN:0@0.046] global grfmt_tiff.cpp ...) beside the
    error that names the file."""
    cv2.imwrite(str(tmp_path / "whole.tif"), np.random.default_rng(0).integers(0, 256, (256, 256, 3), np.uint8))
    data = (tmp_path / "whole.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[:len(data) * 2 // 3])
    level = cv2.utils.logging.getLogLevel()
    with pytest.raises(IngestError, match=r"cut\.tif' cannot be decoded"):
        read_image(tmp_path / "cut.tif")
    assert capfd.readouterr().err == ""
    assert cv2.utils.logging.getLogLevel() == level, "OpenCV's log level was not restored"


def test_a_folder_whose_photos_are_in_subfolders_names_them(tmp_path):
    """An iPhone's photos copied as they are stored: ``DCIM/100APPLE/``; the folder above holds none itself."""
    camera = tmp_path / "phone"
    (camera / "DCIM" / "100APPLE").mkdir(parents=True)
    (camera / "DCIM" / ".thumbs").mkdir()
    for k in range(3):
        (camera / "DCIM" / "100APPLE" / f"IMG_{k:04d}.JPG").write_bytes(b"x")
        (camera / "DCIM" / ".thumbs" / f"IMG_{k:04d}.JPG").write_bytes(b"x")
    (camera / "notes.txt").write_text("not a photo")
    with pytest.raises(IngestError, match=r"images folder '.*phone' holds no images itself; its subfolder "
                                          r"DCIM/100APPLE holds 3 images: pass that folder$"):
        list_images(camera)
    (camera / "DCIM" / "101APPLE").mkdir()
    (camera / "DCIM" / "101APPLE" / "IMG_0100.HEIC").write_bytes(b"x")
    assert images_in_subfolders(camera) == [("DCIM/100APPLE", 3), ("DCIM/101APPLE", 1)]
    assert subfolder_hint(camera) == ("its subfolders hold images: DCIM/100APPLE (3), DCIM/101APPLE (1): pass the "
                                      "folder of one capture")
    assert subfolder_hint(camera / "DCIM" / "101APPLE") == ""


def test_a_link_back_to_the_folder_is_not_a_subfolder_of_photos(tmp_path):
    """``alias -> .`` made the scan count the folder's own photos as 'alias', 'alias/alias', ... (a false warning
    stored in the fit report after a run that read them all)."""
    for k in range(3):
        (tmp_path / f"IMG_{k:04d}.JPG").write_bytes(b"x")
    (tmp_path / "alias").symlink_to(tmp_path, target_is_directory=True)
    assert images_in_subfolders(tmp_path) == [] and subfolder_hint(tmp_path, 3) == ""


def test_unreadable_files_are_skipped_with_a_warning_naming_them(tmp_path):
    Image.fromarray(_pattern()).save(tmp_path / "a.png")
    (tmp_path / "b.png").write_bytes(b"garbage")
    Image.fromarray(_pattern()).save(tmp_path / "c.png")
    skipped: list = []
    with pytest.warns(UserWarning, match=r"skipping .*b\.png"):
        read = list(iter_readable(list_images(tmp_path), skipped))
    assert [p.name for p, _ in read] == ["a.png", "c.png"]
    assert skipped[0][0] == "b.png" and "cannot be decoded" in skipped[0][1]


def _png_header_only(path, width: int, height: int) -> None:
    """A PNG whose header claims ``width x height`` RGB pixels but whose data is one row (a decompression bomb's
    header: reading its size must not decode it)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    raw = zlib.compress(b"\0" + bytes(width * 3), 9)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", raw) + chunk(b"IEND", b""))


@pytest.mark.parametrize("width, height, expected", [
    (20000, 20000, "is 20000x20000 pixels; expected at most 16384 pixels a side"),  # past Pillow's 179 MP
    (30000, 30000, "too large to read"),  # past even the lifted limit: Pillow refuses the header
    (20000, 1, "is 20000x1 pixels; expected at most 16384 pixels a side"),
    (1, 16385, "is 1x16385 pixels; expected at most 16384 pixels a side"),
])
@pytest.mark.parametrize("read", [read_image_size, read_image])
def test_an_image_claiming_too_many_pixels_is_refused_naming_it(tmp_path, width, height, expected, read):
    path = tmp_path / "big.png"
    _png_header_only(path, width, height)
    with pytest.raises(IngestError) as info:
        read(path)
    assert expected in str(info.value) and str(path) in str(info.value)


@pytest.mark.parametrize("width, height", [(16320, 12240), (12240, 16320), (16384, 16384)])
def test_a_200_megapixel_photo_within_the_side_cap_is_read(tmp_path, width, height):
    """Pillow's own limit (about 179 MP) refused a 200 MP phone photo's header, though its sides are within the cap;
    the process-wide limit is put back afterwards."""
    from PIL import Image

    path = tmp_path / "big.png"
    _png_header_only(path, width, height)
    limit = Image.MAX_IMAGE_PIXELS
    assert read_image_size(path) == (width, height), f"{width}x{height} header read as {read_image_size(path)}"
    assert Image.MAX_IMAGE_PIXELS == limit, f"Pillow's limit left at {Image.MAX_IMAGE_PIXELS}, was {limit}"


def test_the_image_side_cap_is_the_render_cap():
    from pytest_n2r.data.images import MAX_IMAGE_SIDE
    from pytest_n2r.render.size import MAX_SIDE

    assert MAX_IMAGE_SIDE == MAX_SIDE


def test_two_exif_segments_give_one_orientation_to_the_size_and_the_pixels(tmp_path):
    """Pillow reads the first EXIF segment, OpenCV's decoder another: orientation 6 then 1 gave the size 48x64 while
    read_image decoded 64x48 (docs/ingestion.md promises they agree)."""
    import struct

    encoded = cv2.imencode(".jpg", np.zeros((48, 64, 3), np.uint8))[1].tobytes()

    def app1(orientation: int) -> bytes:
        exif = Image.Exif()
        exif[0x0112] = orientation
        payload = b"Exif\0\0" + exif.tobytes()
        return b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload

    for first, second in ((6, 1), (1, 6)):
        path = tmp_path / f"two_{first}{second}.jpg"
        path.write_bytes(encoded[:2] + app1(first) + app1(second) + encoded[2:])
        image = read_image(path)
        assert read_image_size(path) == (image.shape[1], image.shape[0]), \
            f"EXIF orientations {first}, {second}: read_image_size says {read_image_size(path)}, read_image " \
            f"decodes {image.shape[1]}x{image.shape[0]}"
        assert image.shape[:2] == ((64, 48) if first == 6 else (48, 64)), "not the first segment's orientation"
        assert read_image(path, oriented=False).shape[:2] == (48, 64), "the stored pixels are turned"


def _exif_after_pixels(png: bytes) -> bytes:
    """The PNG ``png`` with its ``eXIf`` chunk moved after its pixels (``IDAT``), where the PNG standard allows it."""
    chunks, at = [], 8
    while at < len(png):
        end = at + 12 + int.from_bytes(png[at:at + 4], "big")
        chunks.append(png[at:end])
        at = end
    exif = [c for c in chunks if c[4:8] == b"eXIf"]
    rest = [c for c in chunks if c[4:8] not in (b"eXIf", b"IEND")]
    return png[:8] + b"".join(rest + exif + [c for c in chunks if c[4:8] == b"IEND"])


def test_a_png_orientation_is_read_without_decoding_its_pixels_unless_exif_may_follow_them(tmp_path, monkeypatch):
    """Pillow decodes a PNG's pixels to look for EXIF after them: every PNG was decoded twice by read_image (0.1 s of
    0.24 for 12 MP) and read_image_size decoded it."""
    from PIL import PngImagePlugin

    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(_pattern()).save(tmp_path / "before.png", exif=exif)
    (tmp_path / "after.png").write_bytes(_exif_after_pixels((tmp_path / "before.png").read_bytes()))
    upright = np.rot90(_pattern(), -1)
    assert np.array_equal(read_image(tmp_path / "after.png"), upright)  # found after the pixels: decoded to look
    assert read_image_size(tmp_path / "after.png") == (6, 4)

    def decoded(*args, **kwargs):
        raise AssertionError("Pillow decoded the pixels of a PNG")

    monkeypatch.setattr(PngImagePlugin.PngImageFile, "load", decoded)
    assert read_image_size(tmp_path / "before.png") == (6, 4)
    assert np.array_equal(read_image(tmp_path / "before.png"), upright)
    assert np.array_equal(read_image(tmp_path / "before.png", oriented=False), _pattern())
    Image.fromarray(_pattern()).save(tmp_path / "plain.png")
    assert read_image_size(tmp_path / "plain.png") == (4, 6)
