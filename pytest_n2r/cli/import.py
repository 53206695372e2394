# ruff: noqa: N999  (the module is named after its subcommand, as cli/main.py COMMANDS requires)
"""``n2r import scene.ply -o scene.n2r``: pack a splat scene trained elsewhere (a 3DGS ``.ply``) with its cameras
into one scene file that ``--n2r-scene`` and ``load_scene`` read; ``n2r import fitted.n2r -o splats.n2r`` turns a
scene fitted by ``n2r fit`` into splats (:mod:`pytest_n2r.scene.splat_from_field`)."""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path
from typing import Literal

from .._validation import as_unit_rgb
from ._output import FORCE_HELP, printable

__all__ = ["add_parser", "parse_dataparser", "parse_rgb", "run"]


def parse_rgb(text: str) -> tuple[float, float, float]:
    """``"0,0,0"`` or ``"1,1,1"`` (three values in [0, 1]) → an RGB triple.

    >>> parse_rgb("1, 1, 1")
    (1.0, 1.0, 1.0)
    """
    try:
        rgb = as_unit_rgb([float(part) for part in text.split(",")])
    except ValueError:
        rgb = None
    if rgb is None:
        raise argparse.ArgumentTypeError(f"{text!r}: expected three comma-separated values in [0, 1], e.g. 1,1,1")
    return rgb


def parse_dataparser(text: str) -> Path | Literal[False]:
    """``--dataparser-transforms``: a path, or ``none`` (any case) for no transform.

    >>> parse_dataparser("none"), parse_dataparser("run/dataparser_transforms.json").name
    (False, 'dataparser_transforms.json')
    """
    return False if text.strip().lower() == "none" else Path(text)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "import", help="pack a 3D Gaussian Splatting .ply and its cameras into a .n2r scene file (or turn a fitted "
                       ".n2r into splats)",
        description="Read a 3DGS .ply (SH degree 0-3, as the reference code, nerfstudio's splatfacto export, gsplat "
                    "and others write it) and its cameras (a 3DGS cameras.json, a transforms.json or a COLMAP "
                    "model; looked for beside the ply when --cameras is not given), measure the reference length "
                    "and write one scene file. Given a scene file fitted by n2r fit (.n2r) instead, write its field "
                    "as splats, one Gaussian per occupied voxel, with the same views (--size, --path).",
    )
    p.add_argument("ply", type=Path, metavar="SOURCE",
                   help="the trained splats (.ply), or a scene file fitted by n2r fit (.n2r) to turn into splats")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="PATH", help="the scene file to write (.n2r)")
    p.add_argument("--cameras", type=Path, metavar="PATH",
                   help="cameras.json, transforms.json or COLMAP model folder (default: found beside the ply)")
    p.add_argument("--dataparser-transforms", type=parse_dataparser, metavar="PATH",
                   help="nerfstudio's dataparser_transforms.json of the run that trained the ply (splatfacto exports "
                        "are in its normalized frame): the cameras are moved into that frame (default: one found "
                        "in the ply's folder or up to two folders above, else none); 'none': use none (a ply in "
                        "the capture's frame beside such a file; ./none names a file called none)")
    p.add_argument("--min-coverage", type=float, metavar="FRACTION",
                   help="the least share, in [0, 1], of the training views' pixels the Gaussians must cover for the "
                        "ply and its cameras to count as one frame (default 0.10); 0 skips the check (an object "
                        "small in a background-free capture)")
    p.add_argument("--heldout-every", type=int, metavar="N",
                   help="hold out every N-th view by name from the first (default: the source's own split, else 8: "
                        "the --eval split of 3DGS, not nerfstudio's 90 %% fraction); 0 holds none")
    p.add_argument("--background", type=parse_rgb, metavar="R,G,B",
                   help="the colour the scene was trained over, in [0, 1] (default: 0,0,0, 3DGS's; 1,1,1 for "
                        "--white_background)")
    p.add_argument("--size", type=float, metavar="VOXELS",
                   help="fitted .n2r only: each Gaussian's standard deviation in voxel sides (default 0.4)")
    p.add_argument("--path", type=float, metavar="VOXELS",
                   help="fitted .n2r only: the voxels of density a Gaussian's peak opacity stands for (default 0.8)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import __version__
    from ..data.camera_sources import find_cameras
    from ..errors import InvalidArgument
    from ..scene.splat_file import save_splat_scene
    from ..scene.splat_scene import load_splat_scene
    from ._output import SCENE, check_output

    if args.ply.suffix.lower() == ".n2r":
        return _from_field(args)
    knobs = [name for name, value in (("--size", args.size), ("--path", args.path)) if value is not None]
    if knobs:
        raise InvalidArgument(f"{', '.join(knobs)}: only for a fitted scene file (.n2r); a .ply holds its Gaussians")
    if args.heldout_every is not None and args.heldout_every < 0:
        raise InvalidArgument(f"--heldout-every {args.heldout_every}: expected an int >= 0")
    if args.min_coverage is not None and not 0.0 <= args.min_coverage <= 1.0:  # NaN fails both
        raise InvalidArgument(f"--min-coverage {args.min_coverage}: expected a number in [0, 1] (a share of the "
                              "training views' pixels; 0 skips the check)")
    dataparser = args.dataparser_transforms or None  # False ('none') is no file
    for option, path in (("PLY", args.ply), ("--cameras", args.cameras), ("--dataparser-transforms", dataparser)):
        if path is not None and not path.exists():
            raise InvalidArgument(f"{option} {path}: does not exist")
    inputs = [p for p in (args.ply, args.cameras, dataparser) if p is not None]
    check_output(args.output, SCENE, inputs=inputs, force=args.force)
    start = time.perf_counter()
    cameras = args.cameras if args.cameras is not None else find_cameras(args.ply)
    if cameras is None:
        raise InvalidArgument(f"{args.ply}: no cameras found beside it (a cameras.json, transforms.json or COLMAP "
                              "model in its folder or up to two folders above); pass --cameras PATH")
    scene = load_splat_scene(args.ply, cameras=cameras, dataparser_transforms=args.dataparser_transforms,
                             heldout_every=args.heldout_every, background=args.background or (0.0, 0.0, 0.0),
                             name=args.output.stem,
                             **({} if args.min_coverage is None else {"min_coverage": args.min_coverage}))
    report = {"source": str(args.ply), "source_sha256": hashlib.sha256(args.ply.read_bytes()).hexdigest(),
              "cameras": str(cameras), "imported_by": f"pytest-n2r {__version__}",
              "import_s": round(time.perf_counter() - start, 3)}
    if scene.notes:
        report["notes"] = list(scene.notes)
    path = save_splat_scene(args.output, scene, report)
    held = sum(v.split == "heldout" for v in scene.views)
    g = scene.gaussians
    print(f"read        {printable(args.ply)}: {len(g)} Gaussians, SH degree {g.sh_degree}", file=sys.stderr)
    for note in scene.notes:
        print(f"  note      {printable(note)}", file=sys.stderr)
    print(f"cameras     {printable(cameras)}: {len(scene.views)} views ({held} held out); reference length "
          f"{scene.reference_length:.4g} scene units", file=sys.stderr)
    print(f"wrote       {printable(path)} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0


def _from_field(args: argparse.Namespace) -> int:
    """``n2r import fitted.n2r -o splats.n2r``: the fitted field as splats, with the file's views."""
    from .. import __version__
    from ..errors import InvalidArgument
    from ..scene import load_scene
    from ..scene.field_scene import FieldScene
    from ..scene.splat_file import save_splat_scene
    from ..scene.splat_from_field import DEFAULT_PATH, DEFAULT_SIZE, check_voxels, splat_scene_from_field
    from ._output import SCENE, check_output

    size = DEFAULT_SIZE if args.size is None else args.size
    path_voxels = DEFAULT_PATH if args.path is None else args.path
    given = [name for name, value in (("--cameras", args.cameras), ("--heldout-every", args.heldout_every),
                                      ("--dataparser-transforms", args.dataparser_transforms),
                                      ("--min-coverage", args.min_coverage),
                                      ("--background", args.background)) if value is not None]
    if given:
        raise InvalidArgument(f"{', '.join(given)}: only for a .ply; a fitted scene file {args.ply} brings its own "
                              "views, split and background")
    for option, value in (("--size", size), ("--path", path_voxels)):
        check_voxels(value, f"{option} {value}:")  # before the fitted scene is loaded
    if not args.ply.exists():
        raise InvalidArgument(f"SOURCE {args.ply}: does not exist")
    check_output(args.output, SCENE, inputs=[args.ply], force=args.force)
    start = time.perf_counter()
    fitted = load_scene(args.ply, device="cpu", images=False)
    if not isinstance(fitted, FieldScene):
        raise InvalidArgument(f"SOURCE {args.ply}: is already a splat scene file; expected a scene fitted by n2r fit")
    scene = splat_scene_from_field(fitted, size=size, path=path_voxels)
    report = {"source": str(args.ply), "source_sha256": hashlib.sha256(args.ply.read_bytes()).hexdigest(),
              "from_field": {"size": size, "path": path_voxels, "resolution": fitted.field.resolution,
                             "fit": {k: fitted.report.get(k) for k in ("train_seconds", "psnr") if k in fitted.report}},
              "imported_by": f"pytest-n2r {__version__}", "import_s": round(time.perf_counter() - start, 3)}
    path = save_splat_scene(args.output, scene, report)
    g = scene.gaussians
    print(f"read        {printable(args.ply)}: a {fitted.field.resolution}³ field, "
          f"{int(fitted.field.occupancy.sum())} occupied voxels -> {len(g)} Gaussians, SH degree {g.sh_degree}",
          file=sys.stderr)
    print(f"wrote       {printable(path)} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0
