"""``n2r render SCENE --view N -o out.png``: render a captured view of a scene (a scene file, ``demo:<name>``,
``module:function``), optionally moved by a transform, as PNG images (RGB; z-depth as a colour-mapped preview
plus the raw float32 ``.npy``; opacity as grey)."""

from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

import numpy as np

from ._output import FORCE_HELP, printable
from ._scene import SCENE_HELP

__all__ = ["add_parser", "run", "depth_preview", "output_paths"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "render", help="render a view of a scene (a .n2r scene file, demo:<name>, ...) to PNG",
        description="Render captured view N (or NAME) of SCENE, moved by --transform (in the view's own camera "
                    "frame: yaw/pitch/roll in degrees, x right, y down, z forward in --units), and write the "
                    "RGB image to OUT; --depth also writes OUT's stem + .depth.png (colour-mapped, near = "
                    "warm, black where opacity < 0.5) and .depth.npy (float32 z-depth in scene units); "
                    "--opacity writes .opacity.png (white = opaque).",
    )
    p.add_argument("scene", metavar="SCENE", help=SCENE_HELP)
    p.add_argument("--view", default=None, metavar="N|NAME",
                   help="captured view index or image name (default: the first held-out view)")
    p.add_argument("--transform", default="identity", metavar="TAU",
                   help="pose change, e.g. yaw=10,x=0.1 (default: none)")
    p.add_argument("--units", choices=("reference", "scene", "metres"), default="reference",
                   help="units of the transform's x, y, z (default: reference lengths)")
    p.add_argument("--size", default=None, metavar="WxH",
                   help="render size: WxH, a box the view fits in with its aspect kept, or the longer side (default: "
                        "the view's own size)")
    p.add_argument("--depth", action="store_true", help="also write the z-depth (.depth.png and .depth.npy)")
    p.add_argument("--opacity", action="store_true", help="also write the opacity (.opacity.png)")
    p.add_argument("--device", default="auto", metavar="DEVICE", help="auto, cpu or cuda[:N] (default: auto)")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="OUT", help="the RGB image to write (.png)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=run)


def output_paths(output: Path) -> dict[str, Path]:
    """Where each output goes: ``rgb`` at ``output``, the others beside it with ``.depth.png``,
    ``.depth.npy`` and ``.opacity.png`` appended to its name less ``.png`` (``view.depth.png`` →
    ``view.depth.depth.png``: never the RGB image's own name)."""
    stem = output.name[:-len(output.suffix)] if output.suffix else output.name
    return {"rgb": output, **{key: output.with_name(stem + ending) for key, ending in
                              (("depth", ".depth.png"), ("depth_raw", ".depth.npy"), ("opacity", ".opacity.png"))}}


def depth_preview(depth: np.ndarray, opacity: np.ndarray) -> np.ndarray:
    """H×W×3 uint8 RGB picture of ``depth`` (turbo colour map from the 1st to the 99th percentile of the depth
    of pixels with opacity ≥ 0.5, near = red, far = blue; black where opacity < 0.5)."""
    import cv2

    solid = opacity >= 0.5
    if not solid.any():
        return np.zeros((*depth.shape, 3), dtype=np.uint8)
    near, far = np.percentile(depth[solid], [1.0, 99.0])
    scaled = np.clip((far - depth) / max(far - near, 1e-12), 0.0, 1.0)
    bgr = cv2.applyColorMap(np.rint(scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    bgr[~solid] = 0
    return np.ascontiguousarray(bgr[:, :, ::-1])


def _png(image: np.ndarray) -> bytes:
    import cv2

    if image.ndim == 3:
        image = np.ascontiguousarray(image[:, :, ::-1])  # OpenCV writes BGR
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError("OpenCV could not encode the PNG")
    return encoded.tobytes()


def run(args: argparse.Namespace) -> int:
    from ..data.atomic import atomic_write_bytes
    from ..demo.scene_specs import load_scene_spec
    from ..errors import InvalidArgument
    from ..field.device import check_device
    from ..geometry import Transform
    from ..render.size import RenderSize
    from ._output import NPY, PNG, check_output
    from ._scene import scene_argument, scene_inputs

    tau = Transform.parse(args.transform, name="--transform")
    size = None if args.size is None else RenderSize.parse(args.size, name="--size")
    check_device(args.device)  # torch imported only to check a CUDA device
    spec = scene_argument(args.scene)
    inputs = scene_inputs(spec)
    paths = output_paths(check_output(args.output, PNG, inputs=inputs, force=args.force))
    for key in (["depth", "depth_raw"] if args.depth else []) + (["opacity"] if args.opacity else []):
        check_output(paths[key], NPY if key == "depth_raw" else PNG, option=f"-o (its {key.replace('_raw', '')} "
                     "file beside it)", inputs=inputs, force=args.force)
    scene = load_scene_spec(spec, args.device, images=False)
    if not scene.views:
        raise InvalidArgument(f"SCENE {args.scene!r} has no views to render"
                              + (f" ({scene.no_views_reason})" if getattr(scene, "no_views_reason", "") else "")
                              + "; render its splats at poses of your own with load_scene(...).render(c2w, camera)")
    if args.view is None:
        view = next((v for v in scene.views if v.split == "heldout"), scene.views[0])
    else:
        view = scene.view(int(args.view) if args.view.lstrip("-").isdigit() else args.view)
    camera = view.camera if size is None else size.apply(view.camera)
    outputs = ("rgb",) + (("depth",) if args.depth else ()) + (("opacity",) if args.depth or args.opacity else ())
    c2w = tau.apply(view.c2w, scene.length_scale(args.units))
    try:
        scene.check_camera_position(c2w)
    except InvalidArgument as exc:
        raise InvalidArgument(f"--transform {args.transform!r} moves the camera too far: {exc}") from None
    start = time.perf_counter()
    rendered = scene.render(c2w, camera, outputs)
    seconds = time.perf_counter() - start
    images = {name: rendered.output(name) for name in outputs}
    encoded = {"rgb": _png(images["rgb"])}
    if args.depth:
        raw = io.BytesIO()
        np.save(raw, images["depth"])
        encoded["depth"] = _png(depth_preview(images["depth"], images["opacity"]))
        encoded["depth_raw"] = raw.getvalue()
    if args.opacity:
        encoded["opacity"] = _png(np.rint(images["opacity"] * 255).astype(np.uint8))
    written = [atomic_write_bytes(paths[key], data) for key, data in encoded.items()]
    device, backend = getattr(scene, "device", None), getattr(scene, "backend", None)  # a Scene need not say
    where = f" on {device}" if device is not None else ""
    where += f" ({backend})" if backend is not None else ""
    print(f"rendered    view {view.index} {view.name!r} ({view.split}), {tau.describe(args.units)}, "
          f"{camera.width}x{camera.height} in {seconds:.2f} s{where}", file=sys.stderr)
    for path in written:
        print(f"wrote       {printable(path)}")
    return 0
