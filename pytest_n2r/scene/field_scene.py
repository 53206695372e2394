"""A fitted scene: a scene file's field rendered at any camera and pose (the scenes users test on)."""

from __future__ import annotations

import functools
import hashlib
import json

import numpy as np
import torch

from ..field.device import resolve_device
from ..field.grid import SceneField
from ..geometry import Camera
from ..render.field_render import RENDER_VERSION, FieldRenderer, RenderSettings
from .base import Scene, hash_views
from .file import SceneFile

__all__ = ["FieldScene", "RENDER_VERSION"]


class FieldScene(Scene):
    """The scene of a ``.n2r`` file (:func:`pytest_n2r.scene.load_scene` builds one).

    Renders RGB, z-depth and opacity through one :class:`~pytest_n2r.render.field_render.FieldRenderer`
    with ``settings``, on ``device`` (``"auto"``: CUDA when available). ``views`` are the captured views
    (with their photos when the file stores them and they were loaded); ``report`` is the fit report.
    """

    is_exact = False

    def __init__(self, file: SceneFile, *, device: str | torch.device = "auto",
                 settings: RenderSettings | None = None, name: str | None = None) -> None:
        self.file = file
        self.name = name or file.path.stem
        self.views = file.views
        self.reference_length = file.reference_length
        self.metres_per_unit = file.metres_per_unit
        self.device = resolve_device(device)
        self.settings = settings or RenderSettings()
        self._backend = self.settings.backend_on(self.device)  # a bad backend is an error now, not at a render
        self._hash: str | None = None

    @functools.cached_property
    def field(self) -> SceneField:
        """The scene field on :attr:`device` (decoded on first use when the file was read with
        ``lazy_field=True``: a run whose renders all come from the render cache decodes none)."""
        return self.file.field.to(self.device)

    @functools.cached_property
    def _renderer(self) -> FieldRenderer:
        """The renderer, prepared on the first render (its marching grid takes seconds on a large field; a run
        whose renders all come from the render cache needs none)."""
        return FieldRenderer(self.field, self.settings)

    @property
    def report(self) -> dict:
        """The fit report stored in the file (held-out PSNR/SSIM, time, device, versions)."""
        return self.file.report

    @property
    def backend(self) -> str:
        """The render backend in use (``"compiled"`` on the CPU, ``"torch"`` on CUDA)."""
        return self._backend

    @property
    def content_hash(self) -> str:
        """SHA-256 of the stored field member, the views, the render settings and backend (the torch backend with
        its device, torch's version and the GPU: its kernels' round-off differs between them), and
        :data:`RENDER_VERSION`: anything that can change a rendered pixel."""
        if self._hash is None:
            backend = self.backend if self.backend != "torch" else f"torch/{_torch_platform(self.device)}"
            h = hashlib.sha256(f"FieldScene/{RENDER_VERSION}/{backend}/{self.file.field_digest}".encode())
            background = self.settings.background if self.settings.background is not None else self.file.background
            settings = {**self.settings.to_dict(), "background": list(background)}
            h.update(json.dumps(settings, sort_keys=True).encode())
            h.update(np.asarray([self.reference_length, self.metres_per_unit or 0.0]).tobytes())
            hash_views(h, self.views)
            self._hash = h.hexdigest()
        return self._hash

    def with_settings(self, settings: RenderSettings) -> FieldScene:
        """The same scene rendered with other ``settings`` (a new content hash; the field is shared)."""
        return FieldScene(self.file, device=self.device, settings=settings, name=self.name)

    def _render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        return self._renderer.render(c2w, camera, outputs)

    def __repr__(self) -> str:
        return (f"<FieldScene {self.name!r}: {len(self.views)} views, {self.field.resolution}³ grid on "
                f"{self.device}, {self.backend} backend>")


def _torch_platform(device: torch.device) -> str:
    """What the torch backend's pixels depend on besides the scene: the device's kind, torch's version, on the CPU
    the vector instructions its kernels use, on CUDA the CUDA version and the GPU's name (renders of one field
    differ in the last bits between them)."""
    if device.type != "cuda":  # the CPU kernels torch dispatches to: AVX512, AVX2, ... (its AVX2 ones differ)
        return f"{device.type}/{torch.__version__}/{torch.backends.cpu.get_cpu_capability()}"
    return f"cuda/{torch.__version__}/{torch.version.cuda}/{torch.cuda.get_device_name(device)}"
