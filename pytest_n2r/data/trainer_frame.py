"""The normalized world frame a trainer fitted its splats in, and the capture's cameras moved into it.

nerfstudio (splatfacto) orients, centres and scales the capture's poses before it trains, and
``ns-export gaussian-splat`` writes the Gaussians as trained, in that frame. It records the map in
``dataparser_transforms.json`` beside the run's ``config.yml``. gsplat's ``normalize_world_space`` records
nothing, so its frame cannot be recovered from files (export in the capture's frame instead).

Convention
----------
``dataparser_transforms.json`` is ``{"transform": [[3x4]], "scale": s}`` with ``transform = [T_R | T_t]``
(``T_R`` a rotation): a point ``x`` of the frame the map starts from goes to ``x' = s · (T_R · x + T_t)``; a
camera-to-world pose (of either camera-axis convention: the map acts on the world side) to
``R' = T_R · R`` and centre ``c' = s · (T_R · c + T_t)``. Units: ``s`` is trained units per capture unit.

The map starts from the capture's *original* world: nerfstudio composes a transforms.json's
``applied_transform`` ``A`` (3x4, the original (COLMAP) world to the transforms.json world, which
``ns-process-data`` writes) into ``transform`` and multiplies ``scale`` by its ``applied_scale``. So the
cameras of a transforms.json holding ``A`` move by ``T · A⁻¹`` and ``s / applied_scale``; the cameras of a
COLMAP model or of a transforms.json without ``A`` move by ``T`` and ``s``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .._validation import is_finite
from ..errors import IngestError
from ..geometry import apply_similarity_to_pose, rotation_angle_deg
from .json_file import read_json_file
from .poses import PoseSet

__all__ = ["DATAPARSER_FILE", "FrameTransform", "find_dataparser_transforms", "read_dataparser_transforms"]

#: The file nerfstudio writes with the map from the capture's frame to the trained one.
DATAPARSER_FILE = "dataparser_transforms.json"
_ORTHO_TOL = 1e-4  # nerfstudio stores float32 matrices


@dataclass(frozen=True)
class FrameTransform:
    """A similarity ``x -> scale · (rotation · x + translation)`` from a capture's world to a trainer's
    (see the module *Convention*); ``source`` is the file it was read from."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    source: str

    def for_cameras(self, poses: PoseSet) -> tuple[FrameTransform, str]:
        """The map of ``poses``' world (undoing a transforms.json's ``applied_transform`` already composed
        into this one) and a note of what was composed."""
        applied = _applied_transform(poses)
        if applied is None:
            return self, ""
        (a_rot, a_t), a_scale = applied
        rotation = self.rotation @ a_rot.T
        return (replace(self, scale=self.scale / a_scale, rotation=rotation,
                        translation=self.translation - rotation @ a_t),
                f", its applied_transform of {Path(poses.source).name} undone first")

    def apply(self, poses: PoseSet) -> tuple[PoseSet, str]:
        """``poses`` moved into the trainer's frame, and a sentence saying how (for reports)."""
        move, composed = self.for_cameras(poses)
        frames = [replace(f, c2w=apply_similarity_to_pose(f.c2w, move.scale, move.rotation,
                                                          move.scale * move.translation)) for f in poses.frames]
        angle = rotation_angle_deg(np.eye(3), move.rotation)
        shift = ", ".join(f"{v:.4g}" for v in move.scale * move.translation)
        note = (f"cameras moved into the splats' frame by {self.source} (nerfstudio's dataparser transform"
                f"{composed}): scale {move.scale:.6g}, rotation {angle:.2f}°, translation ({shift}) scene units")
        return replace(poses, frames=frames, points=_moved(poses.points, move)), note


def _moved(points: np.ndarray, move: FrameTransform) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return move.scale * (points @ move.rotation.T + move.translation)


def _matrix(value: object, rows: int, where: str) -> np.ndarray:
    """A finite ``rows``x4 float64 matrix, or :class:`IngestError` naming ``where``."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != (rows, 4) or not np.isfinite(m).all():
        shape = "?" if m is None else "x".join(map(str, m.shape))
        raise IngestError(f"{where}: expected {rows} rows of 4 finite numbers ([[T_R | T_t]]), got shape {shape}")
    return m


def _rotation(m: np.ndarray, where: str) -> np.ndarray:
    """The nearest rotation to ``m`` (3x3), which must be one within :data:`_ORTHO_TOL`."""
    off = float(np.abs(m.T @ m - np.eye(3)).max())
    if off > _ORTHO_TOL or np.linalg.det(m) <= 0:
        raise IngestError(f"{where}: its 3x3 part is not a rotation (|RᵀR - I| up to {off:.3g}, det "
                          f"{np.linalg.det(m):.4g}); expected an orthonormal matrix of determinant +1")
    u, _, vt = np.linalg.svd(m)
    return u @ vt


def read_dataparser_transforms(path: str | os.PathLike) -> FrameTransform:
    """The map of nerfstudio's ``dataparser_transforms.json`` at ``path`` (see the module *Convention*).

    Raises :class:`IngestError` naming the file and the field for anything else.
    """
    path = Path(path)
    data = read_json_file(path, DATAPARSER_FILE)
    if not isinstance(data, dict) or "transform" not in data or "scale" not in data:
        raise IngestError(f"{path}: expected a JSON object with 'transform' (3x4) and 'scale', as nerfstudio's "
                          f"{DATAPARSER_FILE} holds")
    m = _matrix(data["transform"], 3, f"{path}: 'transform'")
    scale = _scale(data["scale"], f"{path}: 'scale'")
    return FrameTransform(scale, _rotation(m[:, :3], f"{path}: 'transform'"), m[:, 3].copy(), str(path))


def _scale(value: object, where: str) -> float:
    """A JSON scale as a finite float > 0, or :class:`IngestError` naming ``where`` (an integer too large for a
    float, ``10**400``, is not finite)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (is_finite(value) and value > 0):
        shown = repr(value) if len(repr(value)) <= 40 else f"{repr(value)[:12]}… ({len(repr(value))} characters)"
        raise IngestError(f"{where} is {shown}; expected a finite number > 0")
    return float(value)


def _applied_transform(poses: PoseSet) -> tuple[tuple[np.ndarray, np.ndarray], float] | None:
    """A transforms.json's ``((A_R, A_t), applied_scale)``, or ``None`` when it has no ``applied_transform``."""
    if poses.kind != "transforms.json":
        return None
    source = Path(poses.source)
    try:
        data = read_json_file(source, "transforms")
    except IngestError:
        return None  # it was read moments ago; its reader names what is wrong
    if not isinstance(data, dict) or "applied_transform" not in data:
        return None
    m = _matrix(data["applied_transform"], 3, f"{source}: 'applied_transform'")
    scale = _scale(data.get("applied_scale", 1.0), f"{source}: 'applied_scale'")
    return (_rotation(m[:, :3], f"{source}: 'applied_transform'"), m[:, 3].copy()), scale


def find_dataparser_transforms(ply: str | os.PathLike) -> Path | None:
    """nerfstudio's ``dataparser_transforms.json`` in the ply's folder or up to two folders above it (where
    ``ns-export --output-dir`` inside the run's folder puts the ply); ``None`` when there is none."""
    ply = Path(ply).resolve()
    for folder in list(ply.parents)[:3]:
        if (folder / DATAPARSER_FILE).is_file():
            return folder / DATAPARSER_FILE
    return None
