"""Reading and writing 3D Gaussian Splatting ``.ply`` files (the interchange format of the reference code,
nerfstudio's splatfacto export, gsplat, Brush, Polycam, Luma, ...).

Convention
----------
One ``vertex`` element; each vertex a Gaussian with float properties (any order, any PLY scalar type):

- ``x y z``: the mean (world, scene units); ``nx ny nz`` (optional, ignored: the reference code writes 0);
- ``f_dc_0..2``: the SH DC coefficients of R, G, B;
- ``f_rest_0..M-1``: the higher SH coefficients **grouped by colour channel** (all of R's, then G's, then
  B's), ``M = 3·((d + 1)² - 1)``: 0, 9, 24 or 45 for SH degree ``d`` = 0, 1, 2, 3;
- ``opacity``: the opacity logit (pre-sigmoid); ``scale_0..2``: log standard deviations;
- ``rot_0..3``: the rotation quaternion, **w first**;
- ``filter_3D`` (optional, Mip-Splatting's ``save_ply``): the 3-D filter's standard deviation (scene units),
  baked into the scales and opacities on reading (:func:`bake_filter_3d`), so the Gaussians render as
  Mip-Splatting renders them;
- ``red green blue`` (uchar) in place of ``f_dc_0..2`` and without ``f_rest_*`` (nerfstudio's
  ``ns-export gaussian-splat --ply-color-mode rgb``): read as SH degree 0, ``f_dc = (c/255 - 0.5) / C0``.

All three of ``red green blue`` beside ``f_dc_0..2`` (a preview colour some exporters add) are not read and not
warned of:
the SH coefficients are the colour. Any other vertex property is not read, and one ``UserWarning`` names them
all.

Formats ``binary_little_endian``, ``binary_big_endian`` and ``ascii`` are read; files are written in the
reference code's layout (``binary_little_endian``, float32, the property order above, zero normals).
Reading never executes anything from the file and raises :class:`~pytest_n2r.errors.SceneFileError` naming
the file and the property for a malformed header, missing or extra SH properties, a wrong vertex count, a
truncated body, and NaN or infinite values.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np

from ..data.atomic import atomic_write_bytes
from ..errors import SceneFileError
from .gaussians import Gaussians
from .sh import SH_C0, sh_count, sh_degree_of

__all__ = ["MIP_FILTER", "bake_filter_3d", "ply_properties", "read_ply", "read_ply_with_notes", "write_ply"]

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}
_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
             "rot_0", "rot_1", "rot_2", "rot_3")
_DC = ("f_dc_0", "f_dc_1", "f_dc_2")
_RGB = ("red", "green", "blue")
_NORMALS = ("nx", "ny", "nz")
#: Mip-Splatting's per-Gaussian 3-D filter size (scene units), baked in on reading (:func:`bake_filter_3d`).
MIP_FILTER = "filter_3D"
_MAX_HEADER = 1 << 16
_MAX_COUNT_DIGITS = 15  # a larger element count cannot fit any file


def ply_properties(sh_degree: int) -> list[str]:
    """The vertex properties of the reference layout, in order, for ``sh_degree`` 0..3.

    >>> len(ply_properties(3)), ply_properties(0)[:7]
    (62, ['x', 'y', 'z', 'nx', 'ny', 'nz', 'f_dc_0'])
    """
    rest = 3 * (sh_count(sh_degree) - 1)
    return (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
            + [f"f_rest_{i}" for i in range(rest)]
            + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])


def _parse_header(raw: bytes, source: str) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]], int]:
    """``(format, elements, body offset)``; each element is ``(name, count, [(property, dtype code)])``."""
    if not raw.startswith(b"ply"):
        raise SceneFileError(f"{source}: not a PLY file; a 3DGS .ply starts with the line 'ply'")
    end = re.search(rb"(?m)^end_header[ \t]*\r?\n", raw[:_MAX_HEADER])  # the whole line: a comment may name it
    if end is None:
        raise SceneFileError(f"{source}: the PLY header has no 'end_header' line in its first {_MAX_HEADER} bytes")
    try:
        lines = raw[:end.start()].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise SceneFileError(f"{source}: the PLY header is not ASCII text") from None
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        where = f"{source}: PLY header line {number} {line.strip()!r}"
        if words[0] == "format":
            if len(words) != 3 or words[1] not in _FORMATS:
                raise SceneFileError(f"{where}: expected 'format' followed by one of {tuple(_FORMATS)} and 1.0")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise SceneFileError(f"{where}: expected 'element NAME COUNT'")
            if len(words[2]) > _MAX_COUNT_DIGITS:
                raise SceneFileError(f"{where}: the element count has {len(words[2])} digits; expected a count of "
                                     f"at most {_MAX_COUNT_DIGITS} digits")
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                raise SceneFileError(f"{where}: a property before any element")
            if len(words) >= 2 and words[1] == "list":
                if len(words) != 5 or words[2] not in _TYPES or words[3] not in _TYPES:
                    raise SceneFileError(f"{where}: expected 'property list COUNT_TYPE ITEM_TYPE NAME' with types "
                                         f"from {sorted(set(_TYPES))}")
                kind = "list"
            elif len(words) == 3 and words[1] in _TYPES:
                kind = _TYPES[words[1]]
            else:
                raise SceneFileError(f"{where}: expected 'property TYPE NAME' with TYPE one of {sorted(set(_TYPES))}")
            if words[-1] in (name for name, _ in elements[-1][2]):
                raise SceneFileError(f"{where}: property {words[-1]!r} of element {elements[-1][0]!r} "
                                     "is declared twice; expected unique property names")
            elements[-1][2].append((words[-1], kind))
        else:
            raise SceneFileError(f"{where}: unknown header keyword {words[0]!r}")
    if fmt is None:
        raise SceneFileError(f"{source}: the PLY header has no 'format' line")
    return fmt, elements, end.end()


def _vertex_element(elements, source: str):
    names = [e[0] for e in elements]
    if "chunk" in names:
        raise SceneFileError(f"{source}: a compressed splat .ply (a 'chunk' element, as SuperSplat / PlayCanvas "
                             "write); export or decompress it to the standard 3DGS .ply first")
    if "vertex" not in names:
        raise SceneFileError(f"{source}: the PLY file has no 'vertex' element (elements: {names})")
    index = names.index("vertex")
    for name, _, props in elements[:index]:
        if any(kind == "list" for _, kind in props):
            raise SceneFileError(f"{source}: element {name!r} before 'vertex' has list properties; a 3DGS .ply "
                                 "has only the vertex element")
    skip = [(count, props) for _, count, props in elements[:index]]
    return elements[index], skip


def read_ply(path: str | os.PathLike) -> Gaussians:
    """The Gaussians of the 3DGS ``.ply`` file ``path`` (see the module *Convention*)."""
    return read_ply_with_notes(path)[0]


def read_ply_with_notes(path: str | os.PathLike) -> tuple[Gaussians, tuple[str, ...]]:
    """The Gaussians of the 3DGS ``.ply`` file ``path`` and one sentence for each conversion made on reading
    (colours from ``red green blue``, a Mip-Splatting ``filter_3D`` baked in); warns once, naming them, of
    vertex properties it does not read."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise SceneFileError(f"{source}: no such .ply file")
    raw = path.read_bytes()
    fmt, elements, offset = _parse_header(raw, source)
    (_, count, props), skip = _vertex_element(elements, source)
    kinds = dict(props)
    if "list" in kinds.values():
        bad = [name for name, kind in props if kind == "list"]
        raise SceneFileError(f"{source}: vertex property {bad[0]!r} is a list; 3DGS vertex properties are scalars")
    rgb = _is_rgb_export(kinds)
    missing = [name for name in _REQUIRED if name not in kinds and not (rgb and name in _DC)]
    if missing:
        hint = (" (this looks like a point cloud, not Gaussian splats)"
                if {"red", "green", "blue"} & set(kinds) or len(missing) == len(_REQUIRED) - 3 else "")
        raise SceneFileError(f"{source}: vertex property {missing[0]!r} is missing{hint}; a 3DGS .ply has "
                             f"{', '.join(_REQUIRED)} and f_rest_*")
    rest = sorted((int(m.group(1)), name) for name in kinds if (m := re.fullmatch(r"f_rest_(\d+)", name)))
    degree = sh_degree_of(len(rest) // 3 + 1) if len(rest) % 3 == 0 else None
    if degree is None:
        raise SceneFileError(f"{source}: {len(rest)} f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0 "
                             "to 3: 3·((degree + 1)² - 1))")
    for expected, (number, name) in enumerate(rest):
        if number != expected:
            raise SceneFileError(f"{source}: vertex property 'f_rest_{expected}' is missing (found {name} "
                                 f"among {len(rest)} f_rest_* properties)")
    _warn_unread(source, [name for name, _ in props], rgb)
    columns = _read_body(raw, offset, fmt, count, props, skip, source)
    notes = []
    if rgb:
        for channel, name in zip(_RGB, _DC):
            columns[name] = ((columns[channel] / np.float32(255.0) - np.float32(0.5)) / np.float32(SH_C0))
        notes.append(f"{source}: colours read from red/green/blue (uchar, nerfstudio's --ply-color-mode rgb) as "
                     "SH degree 0, f_dc = (c/255 - 0.5)/C0; the view-dependent colour was not exported")
    for name in (*_REQUIRED, *(n for _, n in rest), *((MIP_FILTER,) if MIP_FILTER in kinds else ())):
        bad = ~np.isfinite(columns[name])
        if bad.any():
            first = int(np.argmax(bad))
            raise SceneFileError(
                f"{source}: vertex property {name!r} of vertex {first} is {float(columns[name][first])} "
                f"({int(bad.sum())} vertices have a NaN or infinite {name})")
    stack = lambda names: np.stack([columns[n] for n in names], axis=1)
    k = sh_count(degree)
    sh = np.empty((count, k, 3), dtype=np.float32)
    sh[:, 0, :] = stack(["f_dc_0", "f_dc_1", "f_dc_2"])
    if k > 1:  # file order: channel-major (R's k-1 coefficients, then G's, then B's)
        sh[:, 1:, :] = stack([n for _, n in rest]).reshape(count, 3, k - 1).transpose(0, 2, 1)
    quats = stack(["rot_0", "rot_1", "rot_2", "rot_3"])
    zero = ~(quats != 0).any(axis=1)
    if zero.any():
        raise SceneFileError(f"{source}: rot_0..rot_3 of vertex {int(np.argmax(zero))} are all 0; a rotation needs a "
                             f"non-zero quaternion ({int(zero.sum())} vertices have one)")
    log_scales, logits = stack(["scale_0", "scale_1", "scale_2"]), columns["opacity"]
    if MIP_FILTER in kinds:
        log_scales, logits = bake_filter_3d(log_scales, logits, columns[MIP_FILTER])
        notes.append(f"{source}: Mip-Splatting's 3-D filter ({MIP_FILTER}) baked in: scales sqrt(s² + f²), "
                     "opacities times sqrt(det Σ / det(Σ + f²I))")
    return (Gaussians(means=stack(["x", "y", "z"]), quats=quats, log_scales=log_scales, opacity_logits=logits, sh=sh),
            tuple(notes))


def _is_rgb_export(kinds: dict[str, str]) -> bool:
    """Whether the vertex holds ``red green blue`` in place of ``f_dc_0..2`` (nerfstudio's
    ``--ply-color-mode rgb``) besides a Gaussian's opacity, scales and rotation."""
    gaussian = ("opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")
    return (not any(name in kinds for name in _DC) and all(name in kinds for name in (*_RGB, *gaussian))
            and not any(name.startswith("f_rest_") for name in kinds))


def _warn_unread(source: str, names: list[str], rgb: bool) -> None:
    """One warning naming the vertex properties that are neither read nor known and ignored (the normals, and
    all three of ``red green blue`` beside ``f_dc_*``: a preview colour). ``rgb``: the colours are read from them."""
    preview = all(name in names for name in (*_DC, *_RGB))
    read = {*_REQUIRED, *_NORMALS, MIP_FILTER, *(_RGB if rgb or preview else ())}
    unread = [n for n in names if n not in read and not re.fullmatch(r"f_rest_\d+", n)]
    if unread:
        noun = "property" if len(unread) == 1 else "properties"
        verb = "is" if len(unread) == 1 else "are"
        warnings.warn(f"{source}: vertex {noun} {', '.join(unread)} {verb} not read (this 3DGS .ply reader uses "
                      f"{', '.join(_REQUIRED)}, f_rest_* and Mip-Splatting's {MIP_FILTER}, and ignores normals "
                      "and a preview red/green/blue); the splats are rendered without them", UserWarning,
                      stacklevel=4)


def bake_filter_3d(log_scales: np.ndarray, opacity_logits: np.ndarray,
                   filter_3d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mip-Splatting's 3-D smoothing filter folded into plain 3DGS parameters: ``(log_scales, opacity_logits)``.

    Convention
    ----------
    Mip-Splatting renders each Gaussian with covariance ``Σ + f²·I`` (``f`` = ``filter_3D``, scene units) and
    peak opacity ``o · sqrt(det Σ / det(Σ + f²I))``; as ``Σ = R S² Rᵀ`` that is, per axis,
    ``s' = sqrt(s² + f²)`` and ``o' = o · Π s / Π s'``. Scales are log standard deviations, opacities logits.
    Computed in float64 and in logs, ``logit' = log o' − log(1 − o')`` with ``1 − o' = σ(−l) + σ(l)·(1 − r)``
    (``l`` the logit, ``r = Π s / Π s'``), so a saturated logit (±800) stays finite and ``f = 0`` returns it
    unchanged; returned as float32.

    >>> ls, lo = bake_filter_3d(np.log([[3.0, 3.0, 3.0]]), np.array([0.0]), np.array([4.0]))
    >>> np.round(np.exp(ls), 4).tolist(), round(float(1 / (1 + np.exp(-lo[0]))), 4)
    ([[5.0, 5.0, 5.0]], 0.108)
    """
    s2 = np.exp(2.0 * np.asarray(log_scales, np.float64))
    f2 = np.square(np.asarray(filter_3d, np.float64)).reshape(-1, 1)
    after = s2 + f2
    log_ratio = 0.5 * (np.log(s2).sum(axis=1) - np.log(after).sum(axis=1))  # log sqrt(det Σ / det Σ')
    logit = np.asarray(opacity_logits, np.float64)
    log_p, log_q = -np.logaddexp(0.0, -logit), -np.logaddexp(0.0, logit)  # log σ(l), log σ(−l)
    log_not_o = np.logaddexp(log_q, log_p + _log1mexp(log_ratio))  # log(1 − σ(l)·r), no cancellation
    new_logit = log_p + log_ratio - log_not_o
    return (0.5 * np.log(after)).astype(np.float32), new_logit.astype(np.float32)


def _log1mexp(x: np.ndarray) -> np.ndarray:
    """``log(1 − exp(x))`` for ``x ≤ 0`` (``-inf`` at 0), accurate at both ends (Mächler 2012)."""
    x = np.minimum(x, 0.0)
    with np.errstate(divide="ignore"):
        return np.where(x < -np.log(2.0), np.log1p(-np.exp(x)), np.log(-np.expm1(x)))


def _read_body(raw: bytes, offset: int, fmt: str, count: int, props, skip, source: str) -> dict[str, np.ndarray]:
    """Every vertex property's column (float32), by name."""
    endian = _FORMATS[fmt]
    if endian is None:
        lines = raw[offset:].decode("ascii", errors="replace").split("\n")
        for before, _ in skip:
            lines = lines[before:]
        rows = [line.split() for line in lines if line.strip()][:count]
        if len(rows) < count:
            raise SceneFileError(f"{source}: element vertex declares {count} vertices; the ASCII body has {len(rows)}")
        wrong = next((i for i, r in enumerate(rows) if len(r) != len(props)), None)
        if wrong is not None:
            raise SceneFileError(f"{source}: vertex {wrong} has {len(rows[wrong])} values; the header declares "
                                 f"{len(props)} properties")
        try:
            table = np.array(rows, dtype=np.float64).reshape(count, len(props))
        except ValueError as exc:
            raise SceneFileError(f"{source}: the ASCII body has a value that is not a number ({exc})") from None
        return {name: table[:, j].astype(np.float32) for j, (name, _) in enumerate(props)}
    for before, before_props in skip:
        offset += before * int(np.dtype([(n, endian + k) for n, k in before_props]).itemsize)
    dtype = np.dtype([(name, endian + kind) for name, kind in props])
    need = count * dtype.itemsize
    have = len(raw) - offset
    if have < need:
        raise SceneFileError(f"{source}: truncated: element vertex declares {count} vertices of {dtype.itemsize} bytes "
                             f"({need} bytes); the file has {max(have, 0)} bytes after the header "
                             f"({max(have, 0) // dtype.itemsize} whole vertices)")
    table = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
    return {name: table[name].astype(np.float32) for name, _ in props}


def write_ply(path: str | os.PathLike, gaussians: Gaussians, *, ascii: bool = False) -> Path:
    """Write ``gaussians`` as a 3DGS ``.ply`` in the reference layout (atomically); return the path.

    ``ascii=True`` writes the same properties as text (``repr`` of each float32, so values round-trip).
    """
    g = gaussians
    k = g.sh.shape[1]
    names = ply_properties(g.sh_degree)
    n = len(g)
    columns = [g.means, np.zeros((n, 3), np.float32), g.sh[:, 0, :],
               g.sh[:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1)), g.opacity_logits[:, None],
               g.log_scales, g.quats]
    table = np.ascontiguousarray(np.concatenate(columns, axis=1), dtype=np.float32)
    header = "\n".join(["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0", f"element vertex {n}",
                        *(f"property float {name}" for name in names), "end_header"]) + "\n"
    if ascii:
        body = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in table).encode("ascii")
    else:
        body = table.astype("<f4").tobytes()
    return atomic_write_bytes(path, header.encode("ascii") + body)
