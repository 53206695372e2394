"""Scene specs of the plugin: how a user names the scenes to test on (``--n2r-scene``, ``n2r_scenes``).

An entry is a ``.n2r`` scene file or a 3DGS ``.ply`` (globs allowed), ``demo:<name>`` for a built-in demo
scene, or ``module:callable`` returning a :class:`~pytest_n2r.Scene`. The resolver lives below the plugin in
:mod:`pytest_n2r.demo.scene_specs`, which the command line (``n2r render``, ``n2r info``, ``n2r study``) uses
too without importing pytest; this module adds what only the plugin says.
"""

from __future__ import annotations

from ..demo.scene_specs import DEMO_PREFIX, SceneSpec, default_scene_specs, load_scene_spec, parse_scene_specs

__all__ = ["SceneSpec", "parse_scene_specs", "default_scene_specs", "load_scene_spec", "DEMO_PREFIX",
           "NO_SCENE_MESSAGE"]

NO_SCENE_MESSAGE = (
    "no scene configured for pytest-n2r: pass --n2r-scene PATH (a .n2r file from `n2r fit`, "
    "'demo:<name>', or 'module:function'), or set n2r_scenes in the ini file"
)
