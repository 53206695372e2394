"""``n2r demo``: the built-in demo scenes (list them, export their ground truth, build their fitted fields)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._output import FORCE_HELP, printable


def _size(text: str) -> int | tuple[int, int]:
    """``480`` (longer side) or ``480x270`` (width x height), in pixels (each 8..4096)."""
    try:
        if "x" in text.lower():
            w, h = text.lower().split("x")
            size: int | tuple[int, int] = (int(w), int(h))
        else:
            size = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT (480x270) or the longer side "
                                         "(480)") from None
    if not all(8 <= v <= 4096 for v in (size if isinstance(size, tuple) else (size,))):
        raise argparse.ArgumentTypeError(f"size {text!r}: width and height must be 8..4096 pixels")
    return size


def _is_export(folder: Path) -> bool:
    """Whether ``folder`` holds an earlier ``n2r demo export`` (its transforms.json names the demo scene)."""
    from ._output import _json_object

    path = folder / "transforms.json"
    return path.is_file() and "n2r_scene" in (_json_object(path) or {})


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo", help="built-in demo scenes with exact ground truth, and their fitted fields",
        description="Built-in procedural scenes (wall: AUV wall inspection; object: UAV vehicle inspection) and "
                    "the scene fields fitted to them (wall-field, object-field).",
    )
    sub = parser.add_subparsers(dest="demo_command", metavar="ACTION", required=True)
    p = sub.add_parser("list", help="list the demo scenes")
    p.set_defaults(func=run_list)
    p = sub.add_parser("export", help="write a demo scene's ground-truth images and transforms.json")
    p.add_argument("name", help="scene name (see `n2r demo list`)")
    p.add_argument("-o", "--out", required=True, type=Path, metavar="DIR",
                   help="output folder (created if missing)")
    p.add_argument("--size", type=_size, default=(480, 270), metavar="WxH",
                   help="image size, WIDTHxHEIGHT or the longer side (default: 480x270)")
    p.add_argument("--force", action="store_true", help="write into a folder that holds other files")
    p.set_defaults(func=run_export)
    p = sub.add_parser(
        "build", help="fit the fitted demo scenes by their recipes (package data, or a folder)",
        description="Fit each named demo scene (default: all) by its fixed recipe (capture size, field settings, "
                    "steps, seed, CPU threads) and write NAME.n2r. Two builds on the same machine and library "
                    "versions give byte-identical files.",
    )
    p.add_argument("names", nargs="*", metavar="NAME", help="exact scene names (default: every demo scene)")
    p.add_argument("-o", "--out", type=Path, default=None, metavar="DIR",
                   help="output folder (default: the package's own pytest_n2r/demo/data, shipped with it)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=run_build)


def run_list(args: argparse.Namespace) -> int:
    from ..demo import demo_scene_names, ground_truth
    from ..demo.fitted import DATA_DIR, FIELD_SUFFIX, RECIPES, find_fitted

    print("exact scenes (ground truth at any pose), --n2r-scene demo:NAME")
    for name in demo_scene_names():
        scene = ground_truth(name)
        n_held = sum(v.split == "heldout" for v in scene.views)
        cam = scene.views[0].camera
        print(f"  {name:14s} {len(scene.views)} views ({n_held} held out), {cam.width}x{cam.height}, "
              f"reference length {scene.reference_length:.3f} m, hash {scene.content_hash[:12]}")
    print("fitted scene fields of them, --n2r-scene demo:NAME")
    for name in demo_scene_names():
        recipe = RECIPES[name]
        found, cached = find_fitted(name)
        if found is None:
            where = f"not built: fitted into {cached} on first use (`n2r demo build` ships it)"
        else:
            where = (f"{'shipped' if found.parent == DATA_DIR else 'cached'} {found} "
                     f"({found.stat().st_size / 2**20:.1f} MiB)")
        w, h = recipe.size
        print(f"  {name + FIELD_SUFFIX:14s} {w}x{h}, {recipe.max_steps} steps, grid "
              f"{'/'.join(map(str, recipe.config.resolutions))}, recipe {recipe.digest[:12]}: {where}")
    return 0


def run_export(args: argparse.Namespace) -> int:
    from ..demo import demo_scene_names, export
    from ..errors import InvalidArgument
    from ._output import check_output_dir

    if args.name not in demo_scene_names():
        raise InvalidArgument(f"NAME {args.name!r}: no such demo scene; expected one of {demo_scene_names()} "
                              "(`n2r demo list`)")
    check_output_dir(args.out, _is_export, "the export (transforms.json and images/)", force=args.force)
    path = export(args.name, args.out, args.size)
    print(f"wrote {printable(path)} and {printable(path.parent / 'images')}")
    return 0


def run_build(args: argparse.Namespace) -> int:
    from ..demo import demo_scene_names
    from ..demo.fitted import DATA_DIR, RECIPES, build_fitted
    from ..errors import InvalidArgument
    from ..scene.file import read_scene_file
    from ._output import SCENE, check_output
    from .fit import _Progress

    names = args.names or list(demo_scene_names())
    unknown = [n for n in names if n not in RECIPES]
    if unknown:
        raise InvalidArgument(f"no fitted recipe for {unknown}; expected scene names from {tuple(RECIPES)}")
    out = args.out if args.out is not None else DATA_DIR
    if out.exists() and not out.is_dir():
        raise InvalidArgument(f"-o {out}: is a file; expected a folder for the scene files")
    for name in names:
        check_output(out / f"{name}.n2r", SCENE, force=args.force)
    for name in names:
        bar = _Progress(RECIPES[name].max_steps, None)
        try:
            path, timings = build_fitted(name, out / f"{name}.n2r", progress=bar)
        finally:
            bar.close()
        report = read_scene_file(path, images=False).report
        print(f"wrote {printable(path)} ({path.stat().st_size / 2**20:.2f} MiB): held-out PSNR "
              f"{report['psnr']:.2f} dB, SSIM {report['ssim']:.4f}; fit {timings['fit_s']:.1f} s, total "
              f"{timings['total_s']:.1f} s")
    return 0
