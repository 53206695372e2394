"""``n2r fit SOURCE -o scene.n2r``: ingest a capture, fit a scene field, write the scene file and its report.

Checkpoints are written (atomically) to the output path while fitting, so a crash leaves the last good scene
there; the first Ctrl-C ends the fit after its step and saves the field trained so far (before the first
checkpoint, nothing); the final file replaces them when the fit ends.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import math
import re
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TextIO

from ._output import FORCE_HELP, printable
from .poses import ANY_ROLL_HELP, add_frames_dir_argument

if TYPE_CHECKING:
    from collections.abc import Sequence

    from ..data.capture import CapturedView
    from ..field.config import FieldConfig

__all__ = ["add_parser", "run", "parse_duration", "parse_durations", "parse_config_override", "APPEARANCE"]

#: ``--appearance`` as ``fit(appearance=...)`` takes it.
APPEARANCE: dict[str, bool | Literal["auto"]] = {"auto": "auto", "on": True, "off": False}
#: The fewest pixels a view may have on a side after ``--downscale``: the fit scores its held-out views with SSIM,
#: whose window is 11×11 pixels (:func:`pytest_n2r.metrics.image_quality.ssim`).
MIN_VIEW_SIDE = 11
_DURATION = re.compile(r"(?:(\d+(?:\.\d*)?)h)?(?:(\d+(?:\.\d*)?)m)?(?:(\d+(?:\.\d*)?)s?)?")


def parse_duration(text: str) -> float:
    """``"10m"``, ``"90s"``, ``"1h30m"``, ``"1m30"`` or ``"600"`` (seconds) → seconds (> 0).

    >>> parse_duration("10m"), parse_duration("1h30m"), parse_duration("45")
    (600.0, 5400.0, 45.0)
    """
    m = _DURATION.fullmatch(text.strip().lower())
    if not text.strip() or m is None or not any(m.groups()):
        raise argparse.ArgumentTypeError(f"{text!r} is not a duration; expected e.g. 10m, 90s, 1h30m or seconds (600)")
    h, mins, s = (float(g) if g else 0.0 for g in m.groups())
    seconds = 3600.0 * h + 60.0 * mins + s
    if seconds <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a duration > 0")
    return seconds


def parse_durations(text: str) -> tuple[float, ...]:
    """Comma-separated durations (``"1m,3m,6m"``) → seconds, ascending."""
    return tuple(sorted(parse_duration(part) for part in text.split(",")))


def parse_config_override(text: str) -> tuple[str, object]:
    """``"key=value"`` of ``--config`` → ``(key, value)``; the value is a Python literal (``0.2``, ``1e-3``,
    ``64,128`` for a tuple), read with :func:`ast.literal_eval` (no code runs)."""
    key, sep, value = (s.strip() for s in text.partition("="))
    if not sep or not key or not value:
        raise argparse.ArgumentTypeError(f"--config {text!r}: expected key=value, e.g. resolutions=48,96,160")
    try:
        return key, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        raise argparse.ArgumentTypeError(f"--config {text!r}: {value!r} is not a number, True/False or a "
                                         "comma-separated list of numbers") from None


def build_config(overrides: list[tuple[str, object]]) -> FieldConfig:
    """The default :class:`~pytest_n2r.field.config.FieldConfig` with ``overrides`` applied (a scalar for a
    tuple setting becomes a one-element tuple); unknown keys and bad values raise naming them."""
    from dataclasses import asdict

    from ..errors import InvalidArgument
    from ..field.config import FieldConfig

    base = asdict(FieldConfig())  # every setting (the stored form leaves some out at their defaults)
    changes = {}
    for key, value in overrides:
        if key not in base:
            raise InvalidArgument(f"--config {key}=...: unknown setting {key!r}; known: {sorted(base)}")
        changes[key] = (value,) if isinstance(base[key], tuple) and not isinstance(value, (tuple, list)) else value
    try:
        return FieldConfig.from_dict({**base, **changes})
    except InvalidArgument as exc:
        raise InvalidArgument(f"--config: {exc}") from None


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fit", help="fit a scene field to a capture and write a .n2r scene file",
        description="Ingest SOURCE (a transforms.json, a COLMAP model folder, a folder of photos or a video), fit "
                    "a scene field within the time budget, and write the scene file: field, cameras, poses, "
                    "split, optional JPEG copies of the photos and the fit report (held-out PSNR/SSIM per "
                    "view and how far each is from a fitted view, training views' scores, the photos skipped and "
                    "why, time, device, versions), which is also printed. A checkpoint is written to the "
                    "output about every minute, so a crash leaves the last good scene; Ctrl-C ends the fit "
                    "after its step and saves the field trained so far (before the first checkpoint it "
                    "writes nothing; a second Ctrl-C quits at once, keeping the last checkpoint), exit "
                    "status 130; SIGTERM (timeout, docker stop) is handled as Ctrl-C, exit status 143.",
    )
    p.add_argument("source", metavar="SOURCE", help="transforms.json, COLMAP model folder, images folder or video")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="PATH", help="the scene file to write (.n2r)")
    p.add_argument("--downscale", type=float, default=4.0, metavar="F",
                   help="divide the image width and height by F before fitting (default: 4)")
    p.add_argument("--time-budget", type=parse_duration, default=None, metavar="DURATION",
                   help="training time, e.g. 10m, 90s, 1h (default: 10m unless --max-steps is given); from 20m on, "
                        "without --max-steps, the colour takes SH degree 2 (unless --config sh_degree is given) "
                        "and the grids end on 256³ (unless --config resolutions or stage_fractions is given); "
                        "from 30m on, a finer grid is added for the end where the last one's voxel spans more than "
                        "3.5 of the photos' pixels, not 6 (unless --config max_pixels_per_voxel is given)")
    p.add_argument("--max-steps", type=int, default=None, metavar="N",
                   help="stop after N steps (with no time budget, the fit is reproducible bit for bit)")
    p.add_argument("--device", default="auto", metavar="DEVICE", help="auto, cpu or cuda[:N] (default: auto)")
    p.add_argument("--config", type=parse_config_override, action="append", default=[], metavar="KEY=VALUE",
                   help="change a field setting (repeatable), e.g. --config resolutions=48,96 "
                        "--config stage_fractions=0.2 (the fields of pytest_n2r.field.config.FieldConfig)")
    p.add_argument("--appearance", choices=tuple(APPEARANCE), default="auto",
                   help="a colour gain per photo (exposure, white balance) in the fit, for captures whose exposure "
                        "varies as a phone's does; renders keep the capture's average. auto (the default) measures "
                        "how much neighbouring photos' colours differ where they see the same points and fits the "
                        "gains above 5 %%; on always fits them, off never (see docs/scene-field.md)")
    p.add_argument("--any-roll", action="store_true", help=ANY_ROLL_HELP)
    add_frames_dir_argument(p)
    p.add_argument("--no-images", dest="images", action="store_false",
                   help="do not store JPEG copies of the photos in the scene file")
    p.add_argument("--metres-per-unit", type=float, default=None, metavar="M",
                   help="metres per scene unit when the capture's scale is known (enables --units metres)")
    p.add_argument("--eval-at", type=parse_durations, default=(), metavar="DURATIONS",
                   help="also score the held-out views at these training times, e.g. 1m,3m,6m (stored in the "
                        "report's history; evaluation time is not training time)")
    p.add_argument("--checkpoint-every", type=float, default=60.0, metavar="SECONDS",
                   help="write a checkpoint to the output this often (default: 60)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=run)


class _Progress:
    """A tqdm bar over steps (``max_steps``) or training seconds (time budget) showing loss, PSNR and ETA; drawn on
    a terminal only (a log would get a line of carriage returns), and never where stderr is closed (``2>&-``)."""

    def __init__(self, max_steps: int | None, time_budget_s: float | None):
        from tqdm import tqdm

        self.by_steps = max_steps is not None
        if max_steps is not None:
            total = max_steps
        else:
            assert time_budget_s is not None, "run() gives a fit without --max-steps a time budget (600 s by default)"
            total = round(time_budget_s)
        self.bar = tqdm(total=total, desc="starting", dynamic_ncols=True, file=sys.stderr,
                        disable=None if sys.stderr is not None else True,
                        bar_format="fit {percentage:3.0f}%|{bar}| {desc}")

    def __call__(self, info: dict) -> None:
        done = info["step"] if self.by_steps else min(round(info["elapsed_s"]), self.bar.total)
        self.bar.update(done - self.bar.n)
        eta = info["eta_s"]
        self.bar.set_description_str(
            f"step {info['step']}, {info['resolution']}³ grid, loss {info['loss']:.4f}, PSNR {info['psnr']:.2f} dB, "
            f"elapsed {_clock(info['elapsed_s'])}, ETA {'?' if math.isnan(eta) else _clock(eta)}", refresh=True)

    def close(self) -> None:
        self.bar.close()

    @contextlib.contextmanager
    def showing_memory_limits(self) -> Iterator[None]:
        """Print a fit's :class:`~pytest_n2r.fit.memory.GridMemoryLimit` warnings as a line above the bar, not
        as a warning with a source line through it (other warnings are shown as before)."""
        from ..fit.memory import GridMemoryLimit

        with warnings.catch_warnings():
            shown = warnings.showwarning

            def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                     file: TextIO | None = None, line: str | None = None) -> None:
                if issubclass(category, GridMemoryLimit):
                    self.bar.write(f"n2r fit: memory: {message}", file=sys.stderr)
                else:
                    shown(message, category, filename, lineno, file, line)

            warnings.showwarning = show
            yield


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}"


def run(args: argparse.Namespace) -> int:
    from collections import Counter

    from .. import fit as fitting
    from ..data import ingest
    from ..fit.appearance import decide_appearance
    from ..fit.budget import FINE_BUDGET_S, LONG_BUDGET_S, budget_config
    from ..fit.detail import DETAIL_STAGE_AT
    from ..scene.file import read_scene_file, save_scene
    from ._interrupt import first_ctrl_c_deferred, interrupt_name, interrupted, sigterm_kept_from_pycolmap
    from ._output import SCENE, check_output
    from .info import format_exposure, format_info
    from .poses import (
        forces_frames_dir,
        format_frames,
        format_skipped,
        format_upright,
        format_warnings,
        skipped_records,
    )

    check_arguments(args)
    sigterm_kept_from_pycolmap()  # SIGTERM as Ctrl-C, also while structure from motion runs
    time_budget = args.time_budget
    if time_budget is None and args.max_steps is None:
        time_budget = 600.0
    given = build_config(args.config)
    config = budget_config(given, time_budget, max_steps=args.max_steps, fixed={key for key, _ in args.config})
    output = check_output(args.output, SCENE, inputs=[Path(args.source)], force=args.force)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # every skipped file is listed below
        capture = ingest(args.source, downscale=1.0 / args.downscale, upright=not args.any_roll,
                         frames_dir=args.frames_dir, force_frames_dir=forces_frames_dir(args))
    check_view_sizes(capture.views, args.downscale)
    ingest_s = time.perf_counter() - start
    sizes = Counter(f"{v.camera.width}x{v.camera.height}" for v in capture.views)
    shown = ", ".join(f"{size} ({n} views)" for size, n in sizes.most_common()) if len(sizes) > 1 else next(iter(sizes))
    lines = [(f"ingested    {args.source}: {len(capture.train_views)} training views, {len(capture.heldout_views)} "
              f"held out, {shown} ({ingest_s:.1f} s)"),
             *format_frames(capture.report), *format_skipped(capture.skipped), *format_upright(capture.report),
             *format_warnings(capture.report, "fit")]
    if config.sh_degree != given.sh_degree:
        lines.append(f"colour      SH degree {config.sh_degree}: it fits better than {given.sh_degree} from a "
                     f"{LONG_BUDGET_S / 60:.0f}-minute budget on (docs/scene-field.md); "
                     f"--config sh_degree={given.sh_degree} keeps {given.sh_degree}")
    if config.resolutions != given.resolutions:
        kept = ",".join(map(str, given.resolutions))
        lines.append(f"grid        {' → '.join(f'{r}³' for r in config.resolutions)}: a finer last grid fits better "
                     f"from a {LONG_BUDGET_S / 60:.0f}-minute budget on (docs/scene-field.md; photos finer than "
                     f"its voxel add one more for the end); --config resolutions={kept} keeps the default grids")
    if config.max_pixels_per_voxel != given.max_pixels_per_voxel:
        was, end = f"{given.max_pixels_per_voxel:g}", round(100 * (1 - DETAIL_STAGE_AT))
        lines.append(f"detail      a finer grid for the last {end} % where a voxel spans more than "
                     f"{config.max_pixels_per_voxel:g} of the photos' pixels, not {was}: it fits better from a "
                     f"{FINE_BUDGET_S / 60:.0f}-minute budget on (docs/scene-field.md); "
                     f"--config max_pixels_per_voxel={was} keeps {was}")
    appearance, exposure = decide_appearance(capture, APPEARANCE[args.appearance])
    if exposure is not None:
        lines.append(format_exposure(exposure))
    print(printable("\n".join(lines)), file=sys.stderr)
    context = {"source": str(args.source), "downscale": args.downscale, "ingest_seconds": round(ingest_s, 2),
               "skipped": skipped_records(capture.skipped), "warnings": list(capture.report.get("warnings", [])),
               **({} if exposure is None else {"exposure": exposure})}
    last: dict = {}

    def save(result: fitting.FitResult, report: dict) -> None:
        save_scene(output, result.field, result.config, capture, {**context, **report}, images=args.images,
                   metres_per_unit=args.metres_per_unit)

    def checkpoint(result: fitting.FitResult) -> None:
        save(result, {**result.report, "complete": False})
        last.update(result.report)

    progress = _Progress(args.max_steps, time_budget)
    try:
        with first_ctrl_c_deferred() as pressed:  # the first press is read here, the second raises at once

            def stop() -> bool:
                """The first Ctrl-C, read after a step: before the first checkpoint it abandons the fit (the
                output untouched); after it, the fit ends there and the field trained so far is saved."""
                if not pressed():
                    return False
                if not last:
                    raise KeyboardInterrupt
                progress.close()
                print(f"n2r fit: {interrupt_name()}: stopping here, then evaluating and saving the field trained so "
                      f"far (Ctrl-C again to quit at once, keeping the checkpoint of step {last['steps']})",
                      file=sys.stderr)
                return True

            with progress.showing_memory_limits():
                result = fitting.fit(capture, config, time_budget_s=time_budget, max_steps=args.max_steps,
                                     device=args.device, progress=progress, checkpoint=checkpoint,
                                     checkpoint_every_s=args.checkpoint_every, eval_at_s=args.eval_at,
                                     appearance=appearance, stop=stop)
            progress.close()
            save(result, {**result.report, "complete": True})
            late = pressed() and not result.report["stopped"]  # pressed after the last step: the field is complete
    except BaseException as exc:
        progress.close()
        if interrupted(exc):  # Ctrl-C, also when a compiled kernel wrapped it in a SystemError
            print(f"n2r fit: interrupted; {_kept(output, last)}", file=sys.stderr)
            return 130
        print(f"n2r fit: the fit failed; {_kept(output, last)}", file=sys.stderr)
        raise
    print(printable(format_info(read_scene_file(output, images=False))))
    if result.report["stopped"]:
        print(f"n2r fit: interrupted; the field at step {result.report['steps']} "
              f"({result.report['train_seconds']:.0f} s of training) is saved in {printable(output)}", file=sys.stderr)
        return 130
    if late:
        print(f"n2r fit: interrupted after training had ended; the complete field is saved in {printable(output)}",
              file=sys.stderr)
        return 130
    return 0


def check_arguments(args: argparse.Namespace) -> None:
    """Every number and the device, checked before the capture is read (so a typo costs no fit)."""
    from ..errors import InvalidArgument
    from ..field.device import resolve_device
    from .poses import check_frames_dir

    if not (math.isfinite(args.downscale) and args.downscale >= 1):
        raise InvalidArgument(f"--downscale {args.downscale}: expected a finite factor >= 1 (4: a quarter of "
                              "the width)")
    if args.max_steps is not None and args.max_steps < 1:
        raise InvalidArgument(f"--max-steps {args.max_steps}: expected an integer >= 1")
    if not (math.isfinite(args.checkpoint_every) and args.checkpoint_every > 0):
        raise InvalidArgument(f"--checkpoint-every {args.checkpoint_every}: expected a finite number of seconds > 0")
    mpu = args.metres_per_unit
    if mpu is not None and not (math.isfinite(mpu) and mpu > 0):
        raise InvalidArgument(f"--metres-per-unit {mpu}: expected the finite number of metres per scene unit, > 0 "
                              "(leave it out when the capture's scale is unknown)")
    if not Path(args.source).exists():
        raise InvalidArgument(f"SOURCE {args.source}: does not exist; expected a transforms.json, a COLMAP "
                              "model folder, a folder of photos or a video")
    check_frames_dir(args.frames_dir, args.force)
    resolve_device(args.device)


def check_view_sizes(views: Sequence[CapturedView], downscale: float) -> None:
    """Every view downscaled by ``downscale`` must keep :data:`MIN_VIEW_SIDE` pixels a side: checked once the capture
    is read, before any step is fitted (a fit of 1×1 views would run its whole budget, then fail to score them)."""
    from ..errors import InvalidArgument

    small = min(views, key=lambda view: min(view.camera.width, view.camera.height))
    if min(small.camera.width, small.camera.height) < MIN_VIEW_SIDE:
        raise InvalidArgument(
            f"--downscale {downscale:g}: the photo {small.name!r} would be {small.camera.width}x{small.camera.height} "
            f"pixels; expected views of at least {MIN_VIEW_SIDE} pixels a side (the held-out views are scored with "
            f"SSIM's {MIN_VIEW_SIDE}x{MIN_VIEW_SIDE} window): a smaller factor (4: a quarter of the width)")


def _kept(output: Path, last: dict) -> str:
    if not last:
        return f"no checkpoint was written yet, so {printable(output)} was not touched"
    return (f"the last checkpoint (step {last['steps']}, {last['train_seconds']:.0f} s of training) is kept in "
            f"{printable(output)}")
