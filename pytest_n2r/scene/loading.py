"""Loading a scene file as a renderable scene: a fitted field or packed splats (``.n2r``), or a 3DGS ``.ply``."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from ..errors import InvalidArgument, InvalidType

if TYPE_CHECKING:
    import torch

    from ..render.field_render import RenderSettings
    from ..render.splat_render import SplatSettings
    from .base import Scene

__all__ = ["load_scene"]


def load_scene(path: str | os.PathLike, device: str | torch.device = "auto", *, images: bool = True,
               settings: RenderSettings | SplatSettings | None = None,
               cameras: str | os.PathLike | None = None,
               dataparser_transforms: str | os.PathLike | Literal[False] | None = None,
               min_coverage: float | None = None) -> Scene:
    """The scene of ``path``, ready to render.

    - A ``.n2r`` file of a fitted field (``n2r fit``): a :class:`~pytest_n2r.scene.field_scene.FieldScene` on
      ``device`` (``"auto"``: CUDA when available, else CPU) with ``settings``
      (:class:`~pytest_n2r.render.field_render.RenderSettings`); ``images=False`` skips decoding the stored
      photos (``scene.views[i].image`` is then ``None``).
    - A ``.n2r`` file of packed splats (``n2r import``) or a 3DGS ``.ply``: a
      :class:`~pytest_n2r.scene.splat_scene.SplatScene`, rendered on the CPU whatever ``device``, with
      ``settings`` (:class:`~pytest_n2r.render.splat_render.SplatSettings`). A ply's ``cameras`` (a 3DGS
      ``cameras.json``, a ``transforms.json`` or a COLMAP model) are looked for beside it when not given, and
      so is nerfstudio's ``dataparser_transforms.json`` (``dataparser_transforms``: a path, ``None`` to look for
      one, ``False`` for none); ``min_coverage`` (in [0, 1]; ``None``: the default 0.10, 0 skips the check) is the
      least share of the training views the Gaussians must cover
      (:func:`~pytest_n2r.scene.splat_scene.load_splat_scene`).

    Raises :class:`~pytest_n2r.errors.SceneFileError` saying what is wrong with a bad file.
    """
    from ..render.splat_render import SplatSettings

    is_ply = Path(path).suffix.lower() == ".ply"
    for key, value in (("cameras", cameras), ("dataparser_transforms", dataparser_transforms),
                       ("min_coverage", min_coverage)):
        if value is not None and not is_ply:
            raise InvalidArgument(f"{key}={value if isinstance(value, (bool, float, int)) else str(value)!r} "
                                  f"applies to a .ply only; {path} is a scene file with its own cameras")
    from .splat_file import is_splat_file

    if is_ply or is_splat_file(path):
        if settings is not None and not isinstance(settings, SplatSettings):
            raise InvalidType(f"settings must be a SplatSettings for the splat scene {path}, got "
                              f"{type(settings).__name__}")
        if is_ply:
            from .splat_scene import MIN_COVERAGE, load_splat_scene

            coverage = MIN_COVERAGE if min_coverage is None else min_coverage
            return load_splat_scene(path, cameras=cameras, dataparser_transforms=dataparser_transforms,
                                    settings=settings, min_coverage=coverage)
        from .splat_file import read_splat_file

        return read_splat_file(path, settings=settings)
    if isinstance(settings, SplatSettings):
        raise InvalidType(f"settings is a SplatSettings, but {path} holds a fitted field (use RenderSettings)")
    from .field_scene import FieldScene
    from .file import read_scene_file

    return FieldScene(read_scene_file(path, images=images), device=device, settings=settings)
