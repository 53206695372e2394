"""``n2r study``: the N2R-Tester paper's evaluation (RQ1 realness, RQ2 diversity, RQ3 efficiency)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from ._output import printable
from ._scene import SCENE_HELP

if TYPE_CHECKING:
    from ..study.suts import Kind


def _eps_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--eps {text!r}: expected numbers separated by commas (0.1,0.2,0.5)") from None
    if not values or any(not v >= 0 for v in values):
        raise argparse.ArgumentTypeError(f"--eps {text!r}: expected one or more numbers >= 0")
    return values


def _wxh(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT, e.g. 480x270") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"size {text!r}: width and height must be 1..8192 pixels")
    return w, h


def _sut_kind(text: str) -> tuple[str | None, Kind]:
    """``SUT=KIND`` (one ``--sut``) or ``KIND`` (every imported ``--sut``) as ``(sut or None, kind)``."""
    from ..study.suts import KINDS

    sut, _, kind = text.rpartition("=")
    if kind not in KINDS:
        raise argparse.ArgumentTypeError(f"--sut-kind {text!r}: expected {' or '.join(KINDS)}, or "
                                         f"{' / '.join(f'SUT={k}' for k in KINDS)} for one --sut")
    return sut or None, kind


def _kinds(suts: list[str], given: list[tuple[str | None, Kind]]) -> dict[str, Kind]:
    """The kind given for each ``--sut`` (``SUT=KIND`` wins over a bare ``KIND``, which applies to the imported
    ones: a built-in's kind is known)."""
    from ..errors import InvalidArgument
    from ..study.suts import BUILTIN_SUTS

    kinds: dict[str, Kind] = {}
    for sut, kind in given:
        if sut is not None and sut not in suts:
            raise InvalidArgument(f"--sut-kind {sut}={kind}: {sut!r} is not one of the --sut given "
                                  f"({', '.join(suts)})")
    for spec in suts:
        named = [kind for sut, kind in given if sut == spec] or [
            kind for sut, kind in given if sut is None and spec not in BUILTIN_SUTS]
        if named:
            kinds[spec] = named[-1]
    return kinds


def check_render_size(scenes: list, size: int) -> None:
    """Every scene's test renders at ``--size`` (the longer side, never above a view's own) must keep
    :data:`~pytest_n2r.cli.fit.MIN_VIEW_SIDE` pixels a side, for SSIM's window: checked before anything is rendered
    (``--size 16`` used to fail after the renders, a 16:9 view being 16x9 pixels)."""
    from ..errors import InvalidArgument
    from .fit import MIN_VIEW_SIDE

    for scene in scenes:
        for view in scene.views:
            camera = view.camera.fit_within(size)
            if min(camera.width, camera.height) >= MIN_VIEW_SIDE:
                continue
            own = view.camera
            needed = next((s for s in range(size, max(own.width, own.height) + 1)
                           if min(own.fit_within(s).width, own.fit_within(s).height) >= MIN_VIEW_SIDE), None)
            fix = (f"--size {needed} or more" if needed is not None and needed <= 4096 else
                   f"a scene with larger views (its own are {own.width}x{own.height})")
            raise InvalidArgument(
                f"--size {size}: view {view.name!r} of {scene.name} would render {camera.width}x{camera.height} "
                f"pixels; the study scores renders with SSIM, which needs at least {MIN_VIEW_SIDE} pixels a side: "
                f"{fix}")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "study", help="characterize SUTs on scenes as the N2R-Tester paper did (RQ1-RQ3)",
        description="Render τ0 (captured poses), τ1–τ6 and the mutations m1–m3, run every SUT, and write CSV "
                    "and Markdown tables and PNG plots: realness (PSNR/SSIM/LPIPS), inconsistencies per SUT, "
                    "metric and eps, and render frames/s.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE",
                        help=SCENE_HELP + " (globs allowed)")
    parser.add_argument("--sut", action="append", required=True, metavar="SUT",
                        help="orb, sift, akaze, or 'module:callable' (repeatable)")
    parser.add_argument("--sut-kind", type=_sut_kind, action="append", default=[], metavar="[SUT=]KIND",
                        help="detector or classifier: what an imported --sut returns, where its output cannot say "
                             "(shape (1, K): one keypoint, or a batch of one score vector); SUT=KIND for one --sut "
                             "(repeatable), KIND for every imported one")
    parser.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder (created if missing)")
    parser.add_argument("--force", action="store_true", help="write into a folder that holds other files")
    parser.add_argument("--examples", type=int, default=5, metavar="N",
                        help="draws per transform family, source view and scene (default: 5)")
    parser.add_argument("--views", type=int, default=3, metavar="N",
                        help="held-out source views per scene, spread over the trajectory (default: 3)")
    parser.add_argument("--points", type=int, default=100, metavar="N",
                        help="keypoints each built-in detector (orb, sift, akaze) keeps per image: the N of largest "
                             "response (default: 100, the paper's setting; imported SUTs run as given)")
    parser.add_argument("--size", type=int, default=480, metavar="PX",
                        help="longer side of the test renders in pixels (default: 480; the paper rendered 960x540)")
    parser.add_argument("--eps", type=_eps_list, default=(0.1, 0.2, 0.5), metavar="E1,E2,...",
                        help="thresholds at which inconsistencies are counted (default: 0.1,0.2,0.5)")
    parser.add_argument("--fps-size", type=_wxh, action="append", metavar="WxH", dest="fps_sizes",
                        help="render size timed for RQ3, landscape (portrait scenes swap it); repeatable "
                             "(default: 480x270, 960x540, 1920x1080 as in the paper)")
    parser.add_argument("--fps-frames", type=int, default=3, metavar="N", help="frames timed per size (default: 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every draw (default: 0)")
    parser.add_argument("--device", default="auto", metavar="DEVICE",
                        help="render device: auto, cpu or cuda[:N] (default: auto)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tqdm import tqdm

    from ..demo.scene_specs import load_scene_spec
    from ..errors import InvalidArgument
    from ..field.device import resolve_device
    from ..study import StudyConfig, resolve_sut, run_study, write_study
    from ..study.suts import check_points
    from ._output import check_output_dir
    from ._scene import scene_arguments

    for option, value in (("--examples", args.examples), ("--views", args.views), ("--fps-frames", args.fps_frames)):
        if value < 1:
            raise InvalidArgument(f"{option} {value}: expected an integer >= 1")
    if not 16 <= args.size <= 4096:
        raise InvalidArgument(f"--size {args.size}: expected the longer side of the test renders in 16..4096 pixels")
    check_points(args.points)
    resolve_device(args.device)  # as n2r render and n2r fit do: cuda without CUDA is an error, not the CPU
    kinds = _kinds(args.sut, args.sut_kind)  # checked before any work
    check_output_dir(Path(args.out), lambda folder: (folder / "study.md").is_file(), "the study's tables and plots",
                     force=args.force)
    config = StudyConfig(examples=args.examples, max_views=args.views, size=args.size, eps=args.eps,
                         fps_frames=args.fps_frames, seed=args.seed,
                         **({"fps_sizes": tuple(args.fps_sizes)} if args.fps_sizes else {}))
    scenes = [load_scene_spec(spec, args.device) for spec in scene_arguments(args.scenes)]
    check_render_size(scenes, args.size)
    view = scenes[0].views[0]
    probe = scenes[0].render(view.c2w, view.camera.fit_within(args.size), ("rgb",)).output("rgb")
    suts = [resolve_sut(spec, probe, kinds.get(spec), points=args.points) for spec in args.sut]
    with tqdm(desc="n2r study", unit="step", file=sys.stderr, disable=None) as bar:
        def progress(message: str) -> None:
            bar.set_postfix_str(message)
            bar.update()

        result = run_study(scenes, suts, config, progress)
    paths = write_study(result, args.out)
    print(printable(Path(args.out) / "study.md"))
    print(f"wrote {len(paths)} files to {printable(args.out)}")
    for note in result.notes:
        print(f"note: {printable(note)}")
    return 0
