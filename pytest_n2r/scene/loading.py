"""Loading a scene file as a renderable scene."""

from __future__ import annotations

import os

import torch

from ..render.field_render import RenderSettings
from .field_scene import FieldScene
from .file import read_scene_file

__all__ = ["load_scene"]


def load_scene(path: str | os.PathLike, device: str | torch.device = "auto", *, images: bool = True,
               settings: RenderSettings | None = None) -> FieldScene:
    """The scene of the ``.n2r`` file ``path``, ready to render on ``device`` (``"auto"``: CUDA when
    available, else CPU) with ``settings`` (default :class:`~pytest_n2r.render.field_render.RenderSettings`).

    ``images=False`` skips decoding the stored photos (``scene.views[i].image`` is then ``None``).
    Raises :class:`~pytest_n2r.errors.SceneFileError` saying what is wrong with a bad file.
    """
    return FieldScene(read_scene_file(path, images=images), device=device, settings=settings)
