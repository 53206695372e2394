"""3-D Gaussian splats: the representation of scenes trained elsewhere (3D Gaussian Splatting, nerfstudio's
splatfacto, gsplat, ...), their ``.ply`` files and their spherical-harmonics colours.

Rendering them is :mod:`pytest_n2r.render.splat_render`; a splat scene is :class:`pytest_n2r.scene.SplatScene`.
"""

from .gaussians import TENSORS, Gaussians
from .ply import ply_properties, read_ply, write_ply
from .sh import SH_C0, rgb_to_sh, sh_count, view_colours

__all__ = [
           "SH_C0",
           "TENSORS",
           "Gaussians",
           "ply_properties",
           "read_ply",
           "rgb_to_sh",
           "sh_count",
           "view_colours",
           "write_ply",
]
