"""A photo's colours: an embedded colour profile converted to sRGB, transparent pixels warned of."""

from __future__ import annotations

import io
import struct
import warnings

import cv2
import numpy as np
import pillow_heif
import pytest
from PIL import Image, ImageCms

from pytest_n2r.data.images import read_image


def _display_p3() -> bytes:
    """An ICC v2 matrix profile with Display P3's primaries (D50-adapted) and a 2.2 gamma, as an iPhone's photos carry
    (Pillow can build sRGB, not P3)."""
    def s15(x: float) -> bytes:
        return struct.pack(">i", round(x * 65536))

    def xyz(x: float, y: float, z: float) -> bytes:
        return b"XYZ \0\0\0\0" + s15(x) + s15(y) + s15(z)

    text = b"Display P3 (test)\0"
    desc = b"desc\0\0\0\0" + struct.pack(">I", len(text)) + text + b"\0" * 79
    curve = b"curv\0\0\0\0" + struct.pack(">IH", 1, 0x0233) + b"\0\0"
    tags = [(b"desc", desc), (b"wtpt", xyz(0.9642, 1.0, 0.8249)), (b"rXYZ", xyz(0.5151, 0.2412, -0.0011)),
            (b"gXYZ", xyz(0.2920, 0.6922, 0.0419)), (b"bXYZ", xyz(0.1571, 0.0666, 0.7841)), (b"rTRC", curve),
            (b"gTRC", curve), (b"bTRC", curve), (b"cprt", b"text\0\0\0\0none\0")]
    offset, table, data = 128 + 4 + 12 * len(tags), b"", b""
    for signature, payload in tags:
        payload += b"\0" * (-len(payload) % 4)
        table += signature + struct.pack(">II", offset + len(data), len(payload))
        data += payload
    body = struct.pack(">I", len(tags)) + table + data
    header = (struct.pack(">I", 128 + len(body)) + b"lcms" + bytes([2, 0x10, 0, 0]) + b"mntrRGB XYZ " + b"\0" * 12
              + b"acsp" + b"APPL" + b"\0" * 24 + s15(0.9642) + s15(1.0) + s15(0.8249) + b"\0" * 48)
    return header + body


def _two_colours() -> np.ndarray:
    image = np.zeros((8, 16, 3), np.uint8)
    image[:, :8], image[:, 8:] = (200, 100, 80), (60, 170, 90)
    return image


def _managed(path, icc: bytes) -> np.ndarray:
    """The photo at ``path`` as a colour-managed viewer shows it: from ``icc`` to sRGB."""
    source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
    with Image.open(path) as im:
        return np.asarray(ImageCms.profileToProfile(im.convert("RGB"), source, ImageCms.createProfile("sRGB")))


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".tif", ".webp"])
def test_a_display_p3_photo_is_converted_to_srgb(tmp_path, suffix):
    """An iPhone's photos are Display P3: their pixels were read as sRGB, the red (200, 100, 80) as itself, not the
    (217, 92, 72) a colour-managed viewer shows."""
    icc = _display_p3()
    path = tmp_path / f"p3{suffix}"
    options = {".jpg": {"quality": 100, "subsampling": 0}, ".webp": {"lossless": True}}.get(suffix, {})
    Image.fromarray(_two_colours()).save(path, icc_profile=icc, **options)
    out = read_image(path)
    expected = _managed(path, icc)
    assert np.abs(out.astype(int) - expected).max() <= 1, (out[0, 0], out[0, -1], expected[0, 0], expected[0, -1])
    assert np.abs(out.astype(int) - _two_colours()).max() >= 10, "the pixels were read as sRGB"


def test_a_display_p3_heif_photo_is_converted_to_srgb(tmp_path):
    icc = _display_p3()
    pillow_heif.register_heif_opener()
    Image.fromarray(_two_colours()).save(tmp_path / "p3.heic", quality=-1, icc_profile=icc)
    stored = np.asarray(pillow_heif.open_heif(tmp_path / "p3.heic"))
    source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
    expected = np.asarray(ImageCms.profileToProfile(Image.fromarray(stored), source, ImageCms.createProfile("sRGB")))
    out = read_image(tmp_path / "p3.heic")
    assert np.abs(out.astype(int) - expected).max() <= 1
    assert np.abs(out.astype(int) - stored).max() >= 10, "the pixels were read as sRGB"


def test_an_srgb_photo_is_read_bit_for_bit(tmp_path):
    """Tagged sRGB or untagged, the pixels are those stored: no round trip through a colour transform."""
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (16, 24, 3), np.uint8)
    srgb = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    Image.fromarray(image).save(tmp_path / "tagged.png", icc_profile=srgb)
    Image.fromarray(image).save(tmp_path / "plain.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(read_image(tmp_path / "tagged.png"), image)
        assert np.array_equal(read_image(tmp_path / "plain.png"), image)


def test_a_colour_profile_that_cannot_be_read_is_warned_of_and_the_pixels_kept(tmp_path):
    Image.fromarray(_two_colours()).save(tmp_path / "odd.png", icc_profile=b"not a colour profile at all" * 8)
    with pytest.warns(UserWarning, match=r"odd\.png'?: its colour profile cannot be read .*taken as sRGB"):
        out = read_image(tmp_path / "odd.png")
    assert np.array_equal(out, _two_colours())


@pytest.mark.parametrize("mode", ["RGBA", "LA", "P"])
def test_transparent_pixels_are_warned_of_naming_the_file(tmp_path, mode):
    """A cut-out's alpha was dropped without a word: the background stored under transparent pixels came back."""
    rgba = np.zeros((8, 16, 4), np.uint8)
    rgba[..., :3], rgba[..., 3] = (30, 160, 40), 255
    rgba[:, 8:, 3] = 0
    image = Image.fromarray(rgba, "RGBA")
    if mode == "LA":
        image = image.convert("LA")
    if mode == "P":
        image = image.convert("RGB").quantize(2)
        image.info["transparency"] = 0
    image.save(tmp_path / "cut.png", **({"transparency": 0} if mode == "P" else {}))
    with pytest.warns(UserWarning, match=r"cut\.png' has transparent pixels: its alpha is dropped and the colour "
                                         r"stored under them is read"):
        assert read_image(tmp_path / "cut.png").shape == (8, 16, 3)


def test_a_transparent_heif_photo_is_warned_of(tmp_path):
    rgba = np.full((8, 16, 4), 255, np.uint8)
    rgba[:, 8:, 3] = 0
    pillow_heif.from_bytes("RGBA", (16, 8), rgba.tobytes()).save(tmp_path / "cut.heic", quality=-1)
    with pytest.warns(UserWarning, match=r"cut\.heic' has transparent pixels"):
        read_image(tmp_path / "cut.heic")


def test_an_opaque_alpha_channel_is_not_warned_of(tmp_path):
    rgba = np.full((8, 16, 4), 255, np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "opaque.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_image(tmp_path / "opaque.png")


def _with_alpha(path, mode: str) -> np.ndarray:
    """Save a 6 x 8 photo with a transparent pixel at ``path`` as ``mode`` (``RGBA16``: 16-bit RGBA; ``RGB+tRNS``,
    ``P+tRNS``: a transparent colour or palette entry); return the RGB colour stored under the alpha."""
    rgba = np.random.default_rng(4).integers(0, 256, (6, 8, 4), dtype=np.uint8)
    rgba[..., 3], rgba[0, 0, 3] = 255, 0
    if mode == "RGBA16":
        bgra = np.random.default_rng(5).integers(0, 65536, (6, 8, 4), dtype=np.uint16)
        bgra[..., 3], bgra[0, 0, 3] = 65535, 0
        cv2.imwrite(str(path), bgra)
        return ((bgra[..., 2::-1].astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    image = Image.fromarray(rgba, "RGBA")
    if mode == "LA":
        image = image.convert("LA")
    elif mode == "RGB+tRNS":
        image = image.convert("RGB")
        image.info["transparency"] = tuple(int(v) for v in rgba[0, 0, :3])
    elif mode == "P+tRNS":
        image = image.convert("RGB").quantize(4)
        image.info["transparency"] = int(np.asarray(image)[0, 0])
    image.save(path, **({"transparency": image.info["transparency"]} if "tRNS" in mode else {}))
    with Image.open(path) as saved:
        return np.asarray(saved.convert("RGBA"))[..., :3]  # Pillow drops an alpha without blending


@pytest.mark.parametrize("mode", ["RGBA", "RGBA16", "LA", "RGB+tRNS", "P+tRNS"])
def test_the_colour_stored_under_an_alpha_channel_is_read_and_the_photo_decoded_once(tmp_path, mode, monkeypatch):
    """The transparency check decoded an RGBA PNG a second time with Pillow (12 MP: 0.65 s to read became 1.0 s);
    OpenCV's decode, with the alpha, is tested instead. The colours read are those stored, as before."""
    from PIL import PngImagePlugin

    expected = _with_alpha(tmp_path / "cut.png", mode)

    def decoded(*args, **kwargs):
        raise AssertionError("Pillow decoded the pixels of a PNG that OpenCV decodes")

    monkeypatch.setattr(PngImagePlugin.PngImageFile, "load", decoded)
    with pytest.warns(UserWarning, match=r"cut\.png' has transparent pixels"):
        out = read_image(tmp_path / "cut.png")
    assert out.dtype == np.uint8 and np.array_equal(out, expected)
