""".ply files of trainers other than the 3DGS reference: Mip-Splatting's ``filter_3D`` baked in, nerfstudio's
``--ply-color-mode rgb`` export read as SH degree 0, and one warning naming the vertex properties not read."""

from __future__ import annotations

import math
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.splats import SH_C0, read_ply, write_ply
from pytest_n2r.splats.ply import bake_filter_3d, read_ply_with_notes

from .test_ply import random_gaussians

GAUSSIAN = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def write(path: Path, names: list[str], rows: list[list[float]], types: list[str] | None = None) -> Path:
    """A binary little-endian .ply with one vertex element of ``names`` (float unless ``types`` says)."""
    types = types or ["float"] * len(names)
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(rows)}",
            *(f"property {t} {n}" for t, n in zip(types, names)), "end_header"]
    fmt = "<" + "".join({"float": "f", "uchar": "B"}[t] for t in types)
    path.write_bytes(("\n".join(head) + "\n").encode() + b"".join(struct.pack(fmt, *r) for r in rows))
    return path


def sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def test_a_mip_splatting_filter_is_baked_into_scales_and_opacity(tmp_path):
    """Mip-Splatting renders Σ + f²I and o·sqrt(det Σ / det Σ'): a tiny Gaussian under a wide filter is nearly
    invisible (the reader used to ignore filter_3D and render it opaque)."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", *GAUSSIAN, "filter_3D"]
    s, f = math.exp(-6), 0.2
    path = write(tmp_path / "point_cloud.ply", names, [[0, 0, 0, 0, 0, 0, 1.5, 1.5, 1.5, 8, -6, -6, -6, 1, 0, 0, 0, f]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # filter_3D is read: no warning
        g, notes = read_ply_with_notes(path)
    np.testing.assert_allclose(np.exp(g.log_scales[0]), [math.sqrt(s * s + f * f)] * 3, rtol=1e-6)
    expected = sigmoid(8.0) * (s * s / (s * s + f * f)) ** 1.5
    assert sigmoid(float(g.opacity_logits[0])) == pytest.approx(expected, rel=1e-5), "peak opacity"
    assert len(notes) == 1 and "filter_3D" in notes[0] and str(path) in notes[0], notes


@settings(max_examples=200, deadline=None)
@given(log_s=st.lists(st.floats(-12, 3), min_size=3, max_size=3), logit=st.floats(-8, 12), f=st.floats(0, 2))
def test_baking_the_filter_matches_mip_splattings_formula(log_s, logit, f):
    ls, lo = bake_filter_3d(np.array([log_s]), np.array([logit]), np.array([f]))
    s2 = np.exp(2 * np.array(log_s))
    np.testing.assert_allclose(np.exp(2 * ls[0].astype(np.float64)), s2 + f * f, rtol=1e-5)
    coef = math.sqrt(np.prod(s2) / np.prod(s2 + f * f))
    assert sigmoid(float(lo[0])) == pytest.approx(sigmoid(logit) * coef, rel=1e-4, abs=1e-30)


def test_a_nerfstudio_rgb_export_is_read_as_degree_0(tmp_path):
    """``ns-export gaussian-splat --ply-color-mode rgb`` writes red/green/blue bytes instead of f_dc_*: read
    as DC = (c/255 - 0.5)/C0 (it used to be refused as "a point cloud")."""
    names = ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", *GAUSSIAN]
    types = ["float"] * 6 + ["uchar"] * 3 + ["float"] * 8
    path = write(tmp_path / "splat.ply", names, [[1, 2, 3, 0, 0, 0, 200, 100, 50, 3, -1, -2, -3, 1, 0, 0, 0]], types)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g, notes = read_ply_with_notes(path)
    assert g.sh_degree == 0
    np.testing.assert_allclose(g.sh[0, 0], (np.array([200, 100, 50]) / 255 - 0.5) / SH_C0, rtol=1e-6)
    np.testing.assert_array_equal(g.log_scales[0], [-1, -2, -3])
    assert g.opacity_logits[0] == 3 and notes and "red/green/blue" in notes[0], notes


def test_a_point_cloud_is_still_refused_as_one(tmp_path):
    path = write(tmp_path / "cloud.ply", ["x", "y", "z", "red", "green", "blue"], [[0, 0, 0, 1, 2, 3]],
                 ["float"] * 3 + ["uchar"] * 3)
    with pytest.raises(Exception, match=r"this looks like a point cloud"):
        read_ply(path)


def test_one_warning_names_the_file_and_every_property_not_read(tmp_path):
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", *GAUSSIAN, "semantic_id", "confidence"]
    path = write(tmp_path / "extra.ply", names, [[0.0] * 9 + [1, 0, 0, 0, 1, 0, 0, 0, 7, 0.5]])
    with pytest.warns(UserWarning) as record:
        read_ply(path)
    mine = [str(w.message) for w in record if "not read" in str(w.message)]
    assert len(mine) == 1, mine
    assert str(path) in mine[0] and "semantic_id, confidence" in mine[0] and "nx" not in mine[0], mine[0]


def test_the_reference_layout_reads_without_a_warning(tmp_path):
    path = write_ply(tmp_path / "s.ply", random_gaussians(3, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g, notes = read_ply_with_notes(path)
    assert notes == () and len(g) == 3


def test_a_preview_colour_beside_the_sh_is_known_and_not_warned_of(tmp_path):
    """Some exporters add uchar red/green/blue beside f_dc_*: the SH are the colour, the preview is ignored
    without a warning (it used to be named as 'not read')."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "red", "green", "blue", *GAUSSIAN]
    types = ["float"] * 9 + ["uchar"] * 3 + ["float"] * len(GAUSSIAN)
    path = write(tmp_path / "preview.ply", names, [[0.0] * 6 + [0.25, 0.5, 0.75, 10, 20, 30, 1, 0, 0, 0, 1, 0, 0, 0]],
                 types)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g, notes = read_ply_with_notes(path)
    assert notes == () and g.sh_degree == 0
    np.testing.assert_allclose(g.sh[0, 0], [0.25, 0.5, 0.75])


@pytest.mark.parametrize("logit", [800.0, -800.0, 40.0, -40.0, 0.0])
def test_baking_keeps_saturated_opacities_finite(logit):
    """A saturated logit (800: sigmoid is 1.0 in float64) used to bake to +inf with a divide warning; f = 0
    returns it unchanged, f > 0 gives the formula's finite logit."""
    log_s = np.log([[0.01, 0.02, 0.03]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, same = bake_filter_3d(log_s, np.array([logit]), np.array([0.0]))
        _, baked = bake_filter_3d(log_s, np.array([logit]), np.array([0.02]))
    assert same[0] == pytest.approx(logit, abs=1e-5)
    s = np.exp(log_s[0])
    ratio = math.prod(s) / math.prod(np.sqrt(s ** 2 + 0.02 ** 2))
    log_p = math.log(ratio) + (-math.log1p(math.exp(-logit)) if logit > -700 else logit)
    expected = log_p - math.log1p(-math.exp(log_p))
    assert math.isfinite(float(baked[0])) and float(baked[0]) == pytest.approx(expected, rel=1e-5, abs=1e-4)
