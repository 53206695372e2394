"""``n2r demo``: the built-in demo scenes (list them, export their ground truth, build their fitted fields)."""

from __future__ import annotations

import argparse


def _size(text: str) -> int | tuple[int, int]:
    """``480`` (longer side) or ``480x270`` (width x height), in pixels."""
    try:
        if "x" in text:
            w, h = text.lower().split("x")
            return int(w), int(h)
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT (480x270) or the longer side (480)")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo", help="built-in demo scenes with exact ground truth",
        description="Built-in procedural scenes (wall: AUV wall inspection; object: UAV vehicle inspection).",
    )
    sub = parser.add_subparsers(dest="demo_command", metavar="ACTION", required=True)
    p = sub.add_parser("list", help="list the demo scenes")
    p.set_defaults(func=run_list)
    p = sub.add_parser("export", help="write a demo scene's ground-truth images and transforms.json")
    p.add_argument("name", help="scene name (see `n2r demo list`)")
    p.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("--size", type=_size, default=(480, 270), metavar="WxH",
                   help="image size, WIDTHxHEIGHT or the longer side (default: 480x270)")
    p.set_defaults(func=run_export)


def run_list(args: argparse.Namespace) -> int:
    from ..demo import demo_scene_names, ground_truth

    for name in demo_scene_names():
        scene = ground_truth(name)
        n_held = sum(v.split == "heldout" for v in scene.views)
        cam = scene.views[0].camera
        print(f"{name:8s} {len(scene.views)} views ({n_held} held out), {cam.width}x{cam.height}, "
              f"reference length {scene.reference_length:.3f} m, hash {scene.content_hash[:12]}")
    return 0


def run_export(args: argparse.Namespace) -> int:
    from ..demo import export

    path = export(args.name, args.out, args.size)
    print(f"wrote {path} and {path.parent / 'images'}")
    return 0
