"""Fitted demo scenes: the exact demo scenes as a scene field would see them, fitted by a fixed recipe.

A fitted demo scene is what a user's own scene is (a :class:`~pytest_n2r.scene.FieldScene` rendered from
a ``.n2r`` file), but its true image at any pose is known, so the field's own error can be measured
(``benchmarks/demo_accuracy.py``, docs/demo-scenes.md).

Where the file comes from (:func:`fitted_path`)
    1. The file shipped with the package, ``pytest_n2r/demo/data/<name>.n2r``, when its stored recipe digest
       is the current recipe's (no wait, no download).
    2. Otherwise the user cache, ``<cache dir>/<name>-<digest[:16]>.n2r``, fitted there on first use (a few
       minutes on a laptop CPU; a warning says so). The cache dir is ``$N2R_CACHE_DIR`` when set, else the
       platform's user cache dir (``~/.cache/pytest-n2r`` on Linux). A file lock makes concurrent pytest-xdist
       workers fit once.

Reproducibility
    A recipe fixes the capture size, the :class:`~pytest_n2r.field.config.FieldConfig` (seed included), the
    number of steps and the CPU thread count; the fit runs on the CPU. The report stored in the file holds no
    timings, so two builds on the same machine and library versions give byte-identical files
    (``n2r demo build``; tested). Another CPU or library version may round differently: the bytes can
    differ, the recipe digest (the scene's poses are the same bits everywhere: :mod:`.portable_math`) and
    the fit's quality do not.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import numbers
import os
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import __version__
from ..errors import InvalidArgument, SceneFileError
from ..field.config import FieldConfig
from .scenes import SCENES
from .user_cache import cache_dir

if TYPE_CHECKING:
    from ..scene.field_scene import FieldScene

__all__ = [
    "FittedRecipe", "RECIPES", "DEMO_CONFIG", "FIELD_SUFFIX", "build_fitted", "fitted_scene", "fitted_path",
    "packaged_path", "cache_dir", "read_recipe_digest", "find_fitted",
]

#: A fitted scene's spec name is the exact scene's name plus this suffix (``demo:object-field``).
FIELD_SUFFIX = "-field"

#: The folder of the shipped fitted scenes (package data).
DATA_DIR = Path(__file__).resolve().parent / "data"

#: Field settings for the demo scenes. Their colours are view-independent (Lambertian shading under one
#: light), so spherical harmonics of degree 0 lose nothing and store a quarter of the values. The finest
#: grid, 384³, makes a voxel about three capture pixels wide on the wall; the total-variation prior on the
#: colour keeps the vertices few rays see from noise. Chosen by measurement (docs/demo-scenes.md). The learning
#: rates are the ones the shipped twins were fitted with (the library's defaults doubled later): a recipe that
#: changed with the defaults would make the shipped files stale.
DEMO_CONFIG = FieldConfig(resolutions=(32, 96, 192, 384), stage_fractions=(0.1, 0.25, 0.5), sh_degree=0,
                          batch_rays=4096, lr_density=0.2, lr_color=0.1, tv=1e-4, seed=0)


@dataclass(frozen=True)
class FittedRecipe:
    """Everything that determines a fitted demo scene's file.

    ``scene``: the exact demo scene fitted; ``size``: the capture's ``(width, height)`` in pixels (the
    fitted scene's views, and so its default render size, have this size); ``config``: the field settings,
    seed included; ``max_steps``: optimization steps (no time budget, so the fit is reproducible);
    ``threads``: CPU threads of the fit (a thread count can change the rounding of parallel sums).
    """

    scene: str
    size: tuple[int, int]
    config: FieldConfig = DEMO_CONFIG
    max_steps: int = 3000
    threads: int = 2

    def __post_init__(self) -> None:
        if self.scene not in SCENES:
            raise InvalidArgument(f"FittedRecipe.scene={self.scene!r}: expected one of {tuple(SCENES)}")
        try:  # whole numbers: a fraction was truncated without a word
            w, h = self.size
            if any(isinstance(v, bool) or int(v) != v for v in (w, h)):
                raise ValueError
            w, h = int(w), int(h)
        except (TypeError, ValueError, OverflowError):
            raise InvalidArgument(
                f"FittedRecipe.size={self.size!r}: expected a (width, height) pair of whole pixels") from None
        if w < 8 or h < 8:
            raise InvalidArgument(f"FittedRecipe.size={self.size!r}: expected at least 8x8 pixels")
        object.__setattr__(self, "size", (w, h))
        for name in ("max_steps", "threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise InvalidArgument(f"FittedRecipe.{name}={value!r}: expected an integer >= 1")
            object.__setattr__(self, name, int(value))
        if not isinstance(self.config, FieldConfig):
            raise InvalidArgument(f"FittedRecipe.config must be a FieldConfig, got {type(self.config).__name__}")

    def to_dict(self) -> dict[str, Any]:
        """The recipe as plain JSON values (stored in the fitted file's report as ``demo_recipe``)."""
        return {"scene": self.scene, "size": list(self.size), "config": self.config.to_dict(),
                "max_steps": self.max_steps, "threads": self.threads}

    @property
    def digest(self) -> str:
        """Hex SHA-256 of the recipe, the exact scene's content hash and the pytest-n2r version: a file built
        with another digest is stale."""
        from . import ground_truth

        spec = {"recipe": self.to_dict(), "scene_hash": ground_truth(self.scene).content_hash,
                "pytest_n2r": __version__}
        return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()

    def replace(self, **changes: Any) -> FittedRecipe:
        """A copy with ``changes`` (e.g. a tiny variant for a test: ``replace(size=(48, 27), max_steps=30)``)."""
        return replace(self, **changes)


#: The recipe of each fitted demo scene, by exact scene name.
RECIPES: dict[str, FittedRecipe] = {
    # The prior on the density: at 1e-4 on the object it thinned the grass, seen only at grazing angles,
    # until haze pruning cut holes in it (24.2 dB held out); without it a floater stayed in one view's sky
    # (27.9 dB); at 2e-5, 28.7 dB. The wall, seen face on, takes 1e-4.
    "wall": FittedRecipe("wall", (240, 135), DEMO_CONFIG.replace(tv_density=1e-4)),
    "object": FittedRecipe("object", (240, 135), DEMO_CONFIG.replace(tv_density=2e-5)),
}


def _recipe(name: str) -> FittedRecipe:
    if name not in RECIPES:
        raise InvalidArgument(f"fitted demo scene {name!r} does not exist; expected one of {tuple(RECIPES)}")
    return RECIPES[name]


@contextlib.contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` torch and numba threads (numba: at most its configured maximum), then
    restore both."""
    import numba
    import torch

    before_torch, before_numba = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(n)
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]  # set at run time
    try:
        yield
    finally:
        torch.set_num_threads(before_torch)
        numba.set_num_threads(before_numba)


#: Report keys that hold timings: left out of a fitted demo file so that rebuilding it gives the same bytes.
_TIMING_KEYS = ("train_seconds", "eval_seconds", "compile_seconds", "history", "time_budget_s", "step_ms")


def build_fitted(
    name: str, out_path: str | os.PathLike, *, recipe: FittedRecipe | None = None,
    progress: Callable[[dict], None] | None = None,
) -> tuple[Path, dict]:
    """Fit the demo scene ``name`` by ``recipe`` (default :data:`RECIPES` ``[name]``) and write the scene
    file ``out_path`` atomically; return the path and the build's timings (seconds: ``capture_s``, ``fit_s``
    of training, ``eval_s``, ``total_s``).

    The stored report is the fit report without timings, plus ``demo_recipe`` (:meth:`FittedRecipe.to_dict`)
    and ``recipe_digest``; no photos are stored (the exact scene renders them). ``progress`` receives the
    fit's progress dicts (see :func:`pytest_n2r.fit.fit`).
    """
    from ..fit import fit
    from ..scene.file import save_scene
    from . import capture

    recipe = recipe or _recipe(name)
    if recipe.scene != name:
        raise InvalidArgument(f"build_fitted: recipe is for scene {recipe.scene!r}, not {name!r}")
    t0 = time.perf_counter()
    cap = capture(name, recipe.size)
    capture_s = time.perf_counter() - t0
    with _torch_threads(recipe.threads):
        result = fit(cap, recipe.config, max_steps=recipe.max_steps, device="cpu", progress=progress)
    report = {k: v for k, v in result.report.items() if k not in _TIMING_KEYS}
    report.update(source=f"demo:{name}", demo_recipe=recipe.to_dict(), recipe_digest=recipe.digest)
    path = save_scene(out_path, result.field, result.config, cap, report, images=False,
                      metres_per_unit=1.0)
    timings = {"capture_s": round(capture_s, 2), "fit_s": result.report["train_seconds"],
               "eval_s": result.report["eval_seconds"], "total_s": round(time.perf_counter() - t0, 2)}
    return path, timings


def read_recipe_digest(path: str | os.PathLike) -> str | None:
    """The ``recipe_digest`` stored in the scene file ``path`` (``None`` when it has none); reads only
    ``scene.json``."""
    import zipfile
    import zlib

    # a file cut short or garbled: no zip, a bad entry, not JSON (ValueError), JSON but not an object (AttributeError)
    try:
        with zipfile.ZipFile(path) as archive:
            report = json.loads(archive.read("scene.json")).get("report") or {}
        digest = report.get("recipe_digest")
    except (OSError, EOFError, KeyError, ValueError, AttributeError, zipfile.BadZipFile, zlib.error) as exc:
        raise SceneFileError(f"{path}: cannot read its scene.json ({exc})") from None
    return digest if isinstance(digest, str) else None


def packaged_path(name: str) -> Path:
    """Where the shipped fitted file of demo scene ``name`` lives (it may be absent in a source checkout)."""
    _recipe(name)
    return DATA_DIR / f"{name}.n2r"


def _holds(path: Path, digest: str) -> bool:
    """Whether the scene file ``path`` exists and holds the fit of the recipe ``digest`` (a file that cannot be
    read, such as one cut short by a full disk or a killed copy, does not)."""
    if not path.is_file():
        return False
    try:
        return read_recipe_digest(path) == digest
    except SceneFileError:
        return False


def find_fitted(name: str) -> tuple[Path | None, Path]:
    """``(found, cached)``: the file holding the current recipe's fit of demo scene ``name`` (the shipped one
    first, then the cached one; ``None`` when neither holds it: absent, stale or unreadable) and the cache path a
    build on first use writes."""
    digest = _recipe(name).digest
    shipped = packaged_path(name)
    cached = cache_dir() / f"{name}-{digest[:16]}.n2r"
    if _holds(shipped, digest):
        return shipped, cached
    return (cached if _holds(cached, digest) else None), cached


def fitted_path(name: str, *, build: bool = True) -> Path:
    """The fitted scene file of demo scene ``name``: the shipped one when it matches the current recipe,
    else the cached one, fitted on first use when ``build`` (otherwise :class:`SceneFileError` when absent).
    A cached file that cannot be read (cut short, say) is fitted again in its place, as an absent one is."""
    found, cached = find_fitted(name)
    if found is not None:
        return found
    recipe, shipped = _recipe(name), packaged_path(name)
    if not build:
        broken = f" ({cached} is unreadable: delete it)" if cached.is_file() else ""
        raise SceneFileError(f"fitted demo scene {name!r}: neither {shipped} nor {cached} holds the current "
                             f"recipe's fit{broken}; `n2r demo build {name}` writes it")
    import filelock

    cached.parent.mkdir(parents=True, exist_ok=True)
    with filelock.FileLock(str(cached) + ".lock"):
        if not _holds(cached, recipe.digest):  # another process may have built it while this one waited
            reason = "is stale (another recipe or pytest-n2r version)" if shipped.is_file() else "is not installed"
            if cached.is_file():
                reason += f", and the cached {cached.name} is unreadable (cut short?)"
            warnings.warn(f"fitted demo scene {name!r}: the shipped {shipped.name} {reason}; fitting it into "
                          f"{cached} ({recipe.max_steps} steps, minutes on a CPU; once)", stacklevel=2)
            build_fitted(name, cached, recipe=recipe)  # written atomically: it replaces an unreadable file
    return cached


def fitted_scene(name: str, device: str = "auto") -> FieldScene:
    """The fitted demo scene ``name`` (``"wall"`` or ``"object"``) as a :class:`~pytest_n2r.scene.FieldScene`
    named ``<name>-field``, rendered on ``device`` (see :func:`fitted_path` for where the file comes from)."""
    from ..scene.field_scene import FieldScene
    from ..scene.file import read_scene_file

    # the field decoded on first use: a run that takes every render of the twin from the cache needs none
    return FieldScene(read_scene_file(fitted_path(name), lazy_field=True), device=device, name=name + FIELD_SUFFIX)
