"""The 3DGS .ply reader and writer: the reference layout, every SH degree, binary and ASCII, files written
by hand (other property orders and types, big-endian, extra elements), and a clear error for every malformed
file."""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from pytest_n2r.errors import InvalidArgument, SceneFileError
from pytest_n2r.splats import TENSORS, Gaussians, ply_properties, read_ply, write_ply

from .make_data import DATA, FILES


def random_gaussians(n: int, degree: int, seed: int = 0) -> Gaussians:
    rng = np.random.default_rng(seed)
    return Gaussians(means=rng.normal(size=(n, 3)), quats=rng.normal(size=(n, 4)), log_scales=rng.normal(-3, 1, (n, 3)),
                     opacity_logits=rng.normal(size=n), sh=rng.normal(size=(n, (degree + 1) ** 2, 3)))


def assert_same(a: Gaussians, b: Gaussians, what: str) -> None:
    for name in TENSORS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), f"{what}: {name} differs after the round trip"


@pytest.mark.parametrize("ascii", [False, True])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_write_then_read_gives_the_same_gaussians(tmp_path, degree, ascii):
    g = random_gaussians(7, degree)
    path = write_ply(tmp_path / "s.ply", g, ascii=ascii)
    back = read_ply(path)
    assert back.sh_degree == degree, f"read SH degree {back.sh_degree}, wrote {degree}"
    assert_same(g, back, f"degree {degree}, {'ascii' if ascii else 'binary'}")


def test_the_header_is_the_reference_layout(tmp_path):
    """The property list of the 3DGS reference's save_ply: x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity
    scale_0..2 rot_0..3, all float, binary little endian."""
    path = write_ply(tmp_path / "s.ply", random_gaussians(2, 3))
    header = path.read_bytes().split(b"end_header\n")[0].decode().splitlines()
    assert header[:3] == ["ply", "format binary_little_endian 1.0", "element vertex 2"], header[:3]
    names = [line.split()[2] for line in header[3:]]
    assert names == ply_properties(3), f"property order {names}"
    assert all(line.split()[1] == "float" for line in header[3:]), "every property is a float"
    assert len(path.read_bytes()) == len(b"\n".join(map(str.encode, header))) + len(b"\nend_header\n") + 2 * 62 * 4


def hand_written(tmp_path, properties: list[tuple[str, str]], rows: list[list[float]], fmt: str = "<",
                 extra: bytes = b"", before: bytes = b"") -> str:
    """A ply written with struct, independent of write_ply: ``properties`` are ``(type, name)``."""
    codes = {"float": "f", "double": "d", "uchar": "B", "int": "i"}
    kind = "binary_little_endian" if fmt == "<" else "binary_big_endian"
    header = ["ply", f"format {kind} 1.0", "comment written by hand"]
    if before:
        header += ["element camera 1", "property float fov"]
    header += [f"element vertex {len(rows)}"] + [f"property {t} {n}" for t, n in properties] + ["end_header"]
    body = b"".join(struct.pack(fmt + "".join(codes[t] for t, _ in properties), *row) for row in rows)
    path = tmp_path / "hand.ply"
    path.write_bytes(("\n".join(header) + "\n").encode() + before + body + extra)
    return str(path)


BASE = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3"]


@pytest.mark.parametrize("fmt", ["<", ">"])
def test_properties_in_any_order_and_type_are_read_by_name(tmp_path, fmt):
    props = [("double", "rot_0"), ("float", "x"), ("uchar", "red"), *[("float", n) for n in BASE if n not in
                                                                        ("rot_0", "x")]]
    row = {"rot_0": 0.5, "x": 1.25, "red": 200, "y": -2.0, "z": 3.0, "f_dc_0": 0.1, "f_dc_1": 0.2, "f_dc_2": 0.3,
           "opacity": 1.5, "scale_0": -3.0, "scale_1": -2.0, "scale_2": -1.0, "rot_1": 0.5, "rot_2": 0.25,
           "rot_3": -0.75}
    path = hand_written(tmp_path, props, [[row[n] for _, n in props]] * 2, fmt, before=struct.pack(fmt + "f", 1.0))
    with pytest.warns(UserWarning, match=r"hand\.ply: vertex property red is not read"):
        g = read_ply(path)
    assert g.means.tolist() == [[1.25, -2.0, 3.0]] * 2 and g.quats[0].tolist() == [0.5, 0.5, 0.25, -0.75]
    assert g.sh.shape == (2, 1, 3) and np.allclose(g.sh[0, 0], [0.1, 0.2, 0.3])
    assert g.log_scales[0].tolist() == [-3.0, -2.0, -1.0] and g.opacity_logits[0] == 1.5


def test_f_rest_is_grouped_by_colour_channel(tmp_path):
    """f_rest_0..8 of degree 1 are R's three coefficients, then G's, then B's (the reference's transpose)."""
    props = [("float", n) for n in BASE] + [("float", f"f_rest_{i}") for i in range(9)]
    values = {n: 0.0 for n in BASE} | {"rot_0": 1.0} | {f"f_rest_{i}": float(10 + i) for i in range(9)}
    g = read_ply(hand_written(tmp_path, props, [[values[n] for _, n in props]]))
    assert g.sh[0, 1:, 0].tolist() == [10, 11, 12] and g.sh[0, 1:, 1].tolist() == [13, 14, 15], g.sh[0]
    assert g.sh[0, 1:, 2].tolist() == [16, 17, 18], g.sh[0]


def ascii_ply(tmp_path, header_props: list[str], rows: list[str], count: int | None = None) -> str:
    lines = ["ply", "format ascii 1.0", f"element vertex {len(rows) if count is None else count}",
             *(f"property float {p}" for p in header_props), "end_header", *rows]
    path = tmp_path / "a.ply"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


GOOD_ROW = "0 1 2 0.1 0.2 0.3 1.0 -3 -3 -3 1 0 0 0"


@pytest.mark.parametrize("case, expected", [
    ("missing", "vertex property 'opacity' is missing"),
    ("point_cloud", "looks like a point cloud"),
    ("rest_count", "10 f_rest_* properties; expected 0, 9, 24 or 45"),
    ("rest_gap", "vertex property 'f_rest_4' is missing"),
    ("nan", "vertex property 'scale_1' of vertex 1 is nan"),
    ("inf", "vertex property 'x' of vertex 0 is inf"),
    ("count", "declares 3 vertices; the ASCII body has 2"),
    ("columns", "vertex 1 has 13 values; the header declares 14"),
    ("zero_quat", "rot_0..rot_3 of vertex 0 are all 0"),
    ("not_number", "a value that is not a number"),
])
def test_malformed_ascii_files_get_an_error_naming_the_problem(tmp_path, case, expected):
    props, rows, count = list(BASE), [GOOD_ROW, GOOD_ROW], None
    if case == "missing":
        props.remove("opacity")
        rows = [" ".join(GOOD_ROW.split()[:6] + GOOD_ROW.split()[7:])] * 2
    elif case == "point_cloud":
        props, rows = ["x", "y", "z", "red", "green", "blue"], ["0 0 0 1 2 3"]
    elif case == "rest_count":
        props += [f"f_rest_{i}" for i in range(10)]
        rows = [GOOD_ROW + " 0" * 10] * 2
    elif case == "rest_gap":
        props += [f"f_rest_{i}" for i in range(10) if i != 4]
        rows = [GOOD_ROW + " 0" * 9] * 2
    elif case == "nan":
        rows = [GOOD_ROW, GOOD_ROW.replace("-3 -3 -3", "-3 nan -3")]
    elif case == "inf":
        rows = [GOOD_ROW.replace("0 1 2", "inf 1 2", 1), GOOD_ROW]
    elif case == "count":
        count = 3
    elif case == "columns":
        rows = [GOOD_ROW, GOOD_ROW.rsplit(" ", 1)[0]]
    elif case == "zero_quat":
        rows = [GOOD_ROW.replace("1 0 0 0", "0 0 0 0"), GOOD_ROW]
    elif case == "not_number":
        rows = [GOOD_ROW.replace("0.1", "abc"), GOOD_ROW]
    path = ascii_ply(tmp_path, props, rows, count)
    with pytest.raises(SceneFileError) as info:
        read_ply(path)
    assert expected in str(info.value) and path in str(info.value), f"message: {info.value}"


def test_a_truncated_binary_file_says_how_many_bytes_are_missing(tmp_path):
    path = write_ply(tmp_path / "s.ply", random_gaussians(10, 1))
    path.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(SceneFileError,
                       match=r"truncated: element vertex declares 10 vertices of 104 bytes \(1040 bytes\)"
                             r"; the file has 1033 bytes after the header \(9 whole vertices\)"):
        read_ply(path)


@pytest.mark.parametrize("content, expected", [
    (b"solid cube\n", "not a PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n", "no 'end_header' line"),
    (b"ply\nformat weird 1.0\nend_header\n", "expected 'format' followed by"),
    (b"ply\nformat ascii 1.0\nelement chunk 2\nproperty float min_x\nend_header\n", "compressed splat .ply"),
    (b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
     "no 'vertex' element"),
    (b"ply\nelement vertex 1\nproperty float x\nend_header\n", "no 'format' line"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n", "expected 'property TYPE NAME'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty\nend_header\n",
     "PLY header line 4 'property': expected 'property TYPE NAME'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float\nend_header\n",
     "PLY header line 4 'property float': expected 'property TYPE NAME'"),
    (b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar\nend_header\n",
     "PLY header line 4 'property list uchar': expected 'property list COUNT_TYPE ITEM_TYPE NAME'"),
    (b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar half vertex_indices\nend_header\n",
     "expected 'property list COUNT_TYPE ITEM_TYPE NAME' with types from"),
    (b"ply\nformat ascii 1.0\nelement vertex " + b"9" * 5000 + b"\nproperty float x\nend_header\n",
     "PLY header line 3 'element vertex 999"),
    (b"ply\nformat binary_little_endian 1.0\nelement face 1\nproperty float a\nproperty float a\n"
     b"element vertex 1\nproperty float x\nend_header\n" + bytes(12),
     "PLY header line 5 'property float a': property 'a' of element 'face' is declared twice"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty uchar x\nend_header\n1 2\n",
     "PLY header line 5 'property uchar x': property 'x' of element 'vertex' is declared twice"),
])
def test_broken_headers_get_an_error(tmp_path, content, expected):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(SceneFileError) as info:
        read_ply(path)
    assert expected in str(info.value) and str(path) in str(info.value), f"{info.value}; expected {expected!r}"


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(SceneFileError, match="no such .ply file"):
        read_ply(tmp_path / "nothing.ply")


@pytest.mark.parametrize("change, expected", [
    ({"means": np.full((2, 3), np.nan)}, "Gaussians.means of Gaussian 0 is"),
    ({"quats": np.zeros((2, 4))}, "Gaussians.quats of Gaussian 0 is (0, 0, 0, 0)"),
    ({"sh": np.zeros((2, 5, 3))}, "5 coefficients per channel"),
    ({"log_scales": np.zeros((3, 3))}, "Gaussians.log_scales has shape (3, 3); expected (N, 3) with N = 2"),
])
def test_gaussians_check_their_arrays(change, expected):
    arrays = random_gaussians(2, 0).tensors() | change
    with pytest.raises((InvalidArgument, TypeError)) as info:
        Gaussians(**arrays)
    assert expected in str(info.value), f"message: {info.value}"


#: A number in a camera file (JSON or COLMAP text): the pieces between two are compared as text.
NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def _assert_same_text_and_numbers(shipped: Path, built: Path, rel: float) -> None:
    """``shipped`` reads as ``built``: the same text between numbers, and each number within ``rel``."""
    a, b = shipped.read_text(), built.read_text()
    assert NUMBER.split(a) == NUMBER.split(b), f"{shipped}: its text differs from what make_data builds"
    for x, y in zip(NUMBER.findall(a), NUMBER.findall(b), strict=True):
        assert math.isclose(float(x), float(y), rel_tol=rel, abs_tol=rel), (
            f"{shipped}: {x} where make_data builds {y}")


def test_the_shipped_files_are_what_make_data_builds(tmp_path):
    """tests/splats/data is what make_data.build writes: the cameras' text, and their numbers to 1e-13 relative
    (the COLMAP model's poses go through matrix products, which OpenBLAS sums with fused multiply-adds or without
    by CPU: on an AVX2 AMD EPYC 98 of its 499 numbers came out up to 4.7e-15 apart from the AVX-512 machine that
    built them, and ``OPENBLAS_CORETYPE=Prescott`` moves them on any x86 machine); the Gaussians to 1e-5 (the exact
    demo renderer they are sampled from may change in the last bits: its relief solver changed the wall's by
    5e-7)."""
    from .make_data import build

    for path in build(tmp_path):
        shipped = DATA / path.relative_to(tmp_path)
        if path.suffix != ".ply":
            _assert_same_text_and_numbers(shipped, path, rel=1e-13)
            continue
        built, kept = read_ply(path), read_ply(shipped)
        for name in TENSORS:
            np.testing.assert_allclose(getattr(kept, name), getattr(built, name), rtol=0, atol=1e-5,
                                       err_msg=f"{shipped}: {name} differs from what make_data builds")


@pytest.mark.parametrize("name, count, degree", [("object-sh0", 4000, 0), ("wall-sh3", 1500, 3),
                                                 ("object-rotated", 1500, 0)])
def test_the_shipped_files_read(name, count, degree):
    g = read_ply(DATA / FILES[name][0])
    assert (len(g), g.sh_degree) == (count, degree), f"{name}: {len(g)} Gaussians of SH degree {g.sh_degree}"


def test_end_header_in_a_comment_does_not_end_the_header(tmp_path):
    """A comment naming end_header ended the header there: the body was read from inside the header (garbage)."""
    gaussians = read_ply(DATA / FILES["wall-sh3"][0])
    path = tmp_path / "commented.ply"
    write_ply(path, gaussians)
    header, body = path.read_bytes().split(b"end_header\n", 1)
    commented = header.replace(b"element vertex", b"comment exported by tool X; see end_header\nelement vertex", 1)
    path.write_bytes(commented + b"end_header\n" + body)
    again = read_ply(path)
    assert len(again) == len(gaussians) and np.array_equal(again.means, gaussians.means), \
        f"a comment containing 'end_header' shifted the body: means {again.means[:2].tolist()}"


def test_a_nan_higher_sh_coefficient_is_a_scene_file_error_naming_the_file_and_property(tmp_path):
    """A NaN among f_rest_* is refused like one among the other properties: a SceneFileError naming the file, the
    property and the vertex (not an InvalidArgument from Gaussians that names neither the file nor the property)."""
    props = BASE + [f"f_rest_{i}" for i in range(9)]
    rest = ["0"] * 9
    rest[4] = "nan"
    path = ascii_ply(tmp_path, props, [GOOD_ROW + " 0" * 9, GOOD_ROW + " " + " ".join(rest)])
    with pytest.raises(SceneFileError) as info:
        read_ply(path)
    message = str(info.value)
    assert path in message and "vertex property 'f_rest_4' of vertex 1 is nan" in message, (
        f"a NaN f_rest_4 of vertex 1: {message}")


@pytest.mark.parametrize("name", list(TENSORS))
def test_the_digest_changes_when_any_array_changes(name):
    """A splat scene's render cache is keyed by the digest: a change in any array must change it."""
    arrays = random_gaussians(3, 1).tensors()
    before = Gaussians(**arrays).digest()
    changed = arrays | {name: arrays[name] + np.float32(0.5)}
    assert Gaussians(**changed).digest() != before, f"changing {name} leaves the digest {before[:16]}… unchanged"
    assert Gaussians(**arrays).digest() == before, "the same arrays give another digest"


def test_a_list_element_before_the_vertices_is_refused_naming_it(tmp_path):
    """A binary body cannot be skipped past a list element of unknown length: refused naming the element (without
    the check the reader failed on a numpy dtype, not with a SceneFileError)."""
    header = ["ply", "format binary_little_endian 1.0", "element face 1", "property list uchar int vertex_indices",
              "element vertex 1", *(f"property float {n}" for n in BASE), "end_header"]
    face = struct.pack("<Biii", 3, 0, 1, 2)
    vertex = struct.pack("<14f", 0, 1, 2, 0.1, 0.2, 0.3, 1.0, -3, -3, -3, 1, 0, 0, 0)
    path = tmp_path / "faces_first.ply"
    path.write_bytes(("\n".join(header) + "\n").encode() + face + vertex)
    with pytest.raises(SceneFileError) as info:
        read_ply(path)
    assert str(path) in str(info.value) and "element 'face' before 'vertex' has list properties" in str(info.value), (
        f"a list element before the vertices: {info.value}")


def test_an_ascii_file_with_an_element_before_the_vertices_skips_its_lines(tmp_path):
    """The rows of an element declared before 'vertex' (a camera, as some exporters write) are not vertices."""
    lines = ["ply", "format ascii 1.0", "element camera 1", "property float fov", "property float aspect",
             "element vertex 2", *(f"property float {p}" for p in BASE), "end_header", "50.0 1.5",
             GOOD_ROW, GOOD_ROW.replace("0 1 2", "3 4 5", 1)]
    path = tmp_path / "camera_first.ply"
    path.write_text("\n".join(lines) + "\n")
    g = read_ply(path)
    assert g.means.tolist() == [[0, 1, 2], [3, 4, 5]], f"the vertices read from after a camera element: {g.means}"
