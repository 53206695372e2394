"""A HEIF photo's nclx colour box (H.273 primaries and transfer, no ICC profile): read as a colour-managed viewer
shows it, checked against the colour-science formulas, not against the ICC profile the reader builds."""

from __future__ import annotations

import warnings

import numpy as np
import pillow_heif
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.data.colour import PhotoColourWarning, to_srgb
from pytest_n2r.data.images import read_image
from pytest_n2r.data.nclx import SRGB_CHROMATICITIES, bradford_adaptation, nclx_icc, rgb_to_xyz

#: H.273 primaries code → chromaticities (x, y) of red, green, blue, white
PRIMARIES = {
    12: ((0.680, 0.320), (0.265, 0.690), (0.150, 0.060), (0.3127, 0.3290)),  # Display P3 (SMPTE EG 432-1)
    9: ((0.708, 0.292), (0.170, 0.797), (0.131, 0.046), (0.3127, 0.3290)),  # BT.2020
    11: ((0.680, 0.320), (0.265, 0.690), (0.150, 0.060), (0.314, 0.351)),  # DCI-P3, its greenish white
    1: SRGB_CHROMATICITIES,
}


def _srgb_decode(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _srgb_encode(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * np.clip(v, 0.0031308, None) ** (1 / 2.4) - 0.055)


#: H.273 transfer code → the curve from code values to linear light
DECODE = {13: _srgb_decode, 1: _srgb_decode, 4: lambda v: v ** 2.2, 8: lambda v: v}


def _expected(stored: np.ndarray, primaries: int, transfer: int) -> np.ndarray:
    """The photo in sRGB by the formulas: linear light, the primaries' XYZ adapted (Bradford) to sRGB's D65 white,
    sRGB's primaries, clipped to its gamut, the sRGB curve."""
    source = PRIMARIES[primaries]
    white = np.array([source[3][0] / source[3][1], 1.0, (1 - sum(source[3])) / source[3][1]])
    d65 = rgb_to_xyz(SRGB_CHROMATICITIES) @ np.ones(3)
    to_srgb_linear = np.linalg.inv(rgb_to_xyz(SRGB_CHROMATICITIES)) @ bradford_adaptation(white, d65) \
        @ rgb_to_xyz(source)
    linear = DECODE[transfer](stored / 255.0) @ to_srgb_linear.T
    return np.round(255 * _srgb_encode(np.clip(linear, 0.0, 1.0))).astype(int)


def _photo() -> np.ndarray:
    """Saturated and pale colours, dark and bright: every grey level of each channel against the others'."""
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (32, 48, 3), dtype=np.uint8)
    image[:4, :8] = (200, 100, 80)
    image[4:8, :8] = 255
    image[8:12, :8] = 0
    return image


def _save(path, primaries: int, transfer: int) -> np.ndarray:
    """Save the test photo as a HEIF with an nclx box and no ICC profile; return its pixels as libheif decodes them."""
    heif = pillow_heif.from_bytes("RGB", (48, 32), _photo().tobytes())
    heif.save(path, quality=-1, nclx_profile={"color_primaries": primaries, "transfer_characteristics": transfer,
                                              "matrix_coefficients": 6, "full_range_flag": 1})
    info = pillow_heif.open_heif(path).info
    assert info.get("icc_profile") is None and info["nclx_profile"]["color_primaries"] == primaries, info
    return np.asarray(pillow_heif.open_heif(path)).astype(int)


@pytest.mark.parametrize(("primaries", "transfer"), [(12, 13), (12, 1), (9, 13), (11, 13), (1, 4), (1, 8)])
def test_an_nclx_heif_photo_is_converted_to_srgb(tmp_path, primaries, transfer):
    """A HEIF photo with an nclx box (an Android phone's) was read as sRGB whatever primaries and curve it stated."""
    stored = _save(tmp_path / "nclx.heic", primaries, transfer)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = read_image(tmp_path / "nclx.heic").astype(int)
    expected = _expected(stored, primaries, transfer)
    worst = np.unravel_index(np.abs(out - expected).argmax(), out.shape)[:2]
    assert np.abs(out - expected).max() <= 1, \
        f"stored {stored[worst]} read as {out[worst]}, the formulas give {expected[worst]}"
    assert np.abs(out - stored).max() >= 5, "the pixels were read as sRGB"  # gamma 2.2's are 9 levels off at most


@pytest.mark.parametrize(("primaries", "transfer"), [(1, 13), (1, 1), (2, 2), (1, 6), (2, 13)])
def test_an_nclx_box_stating_srgb_changes_no_pixel(tmp_path, primaries, transfer):
    stored = _save(tmp_path / "srgb.heic", primaries, transfer)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(read_image(tmp_path / "srgb.heic"), stored), "an sRGB photo's pixels moved"


@pytest.mark.parametrize(("transfer", "said"), [(16, r"HDR colours \(transfer 16, PQ"), (18, r"HDR .*HLG"),
                                                (7, "transfer code 7, which this reader does not convert")])
def test_an_nclx_curve_that_is_not_converted_is_warned_of_naming_the_file(tmp_path, transfer, said):
    stored = _save(tmp_path / "hdr.heic", 12, transfer)
    with pytest.warns(PhotoColourWarning, match=rf"hdr\.heic'?: its nclx colour box states {said}.*taken as sRGB"):
        out = read_image(tmp_path / "hdr.heic")
    assert np.array_equal(out, stored), "pixels of a curve that is not converted were changed"


def test_nclx_primaries_that_span_no_colour_space_are_warned_of():
    flat = {"transfer_characteristics": 13, **{f"color_primary_{c}_{a}": v for c in ("red", "green", "blue")
                                               for a, v in (("x", 0.3), ("y", 0.3))},
            "color_primary_white_x": 0.3127, "color_primary_white_y": 0.329}
    with pytest.warns(PhotoColourWarning, match=r"'odd\.heic': its nclx colour box states primaries that span no "
                                                r"colour space \(red \(0\.3, 0\.3\)"):
        assert nclx_icc(flat, "odd.heic") is None


def _chromaticity(x: float, y: float, spread: float) -> st.SearchStrategy[tuple[float, float]]:
    return st.tuples(st.floats(x - spread, x + spread), st.floats(y - spread, y + spread))


@settings(max_examples=40, deadline=None)
@given(red=_chromaticity(0.67, 0.32, 0.04), green=_chromaticity(0.25, 0.67, 0.06),
       blue=_chromaticity(0.14, 0.06, 0.01), white=_chromaticity(0.32, 0.34, 0.02),
       transfer=st.sampled_from([13, 4, 8]))
def test_white_stays_white_and_black_black_whatever_the_primaries(red, green, blue, white, transfer):
    """Relative colorimetric, as a viewer converts: the photo's white is the display's white (the adaptation from
    the stated white to D50 and back to sRGB's D65 cancels), its black the display's black."""
    names = ("red", "green", "blue", "white")
    nclx = {"transfer_characteristics": transfer, **{f"color_primary_{n}_{a}": v for n, xy in
                                                    zip(names, (red, green, blue, white)) for a, v in zip("xy", xy)}}
    icc = nclx_icc(nclx, "drawn.heic")
    assert icc is not None, "primaries other than sRGB's gave no profile"
    image = np.zeros((1, 2, 3), np.uint8)
    image[0, 0] = 255
    out = to_srgb(image, icc, "drawn.heic").astype(int)
    assert np.abs(out[0, 0] - 255).max() <= 1 and out[0, 1].max() <= 1, f"white read as {out[0, 0]}, black {out[0, 1]}"
