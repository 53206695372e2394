"""Fitting speed and quality on the fox capture: held-out PSNR / SSIM after 1, 3, 6 and 10 minutes.

Run: ``python benchmarks/field_fit.py [--budget 10m | --steps 6500] [--eval-at 10m,20m] [--out /tmp/fox.n2r]
[--config key=value ...] [--sfm] [--appearance auto|on|off]``.
``--steps N`` fits N steps instead of a time budget: the same fit on a loaded machine as on an idle one (the
default recipe reached 6 051-6 582 steps in 10 minutes on the idle AVX-512 2-core host of 2 December; the AVX2
host of 3 December takes 12 min 52 s for 6 500: docs/performance.md), with the CPU seconds it took printed
beside.
Fox at 1/4 resolution (270×480 training images), every 8th image held out, as issue 3 specifies. The poses are the
ones the fox was published with (its ``transforms.json``), or with ``--sfm`` those our structure from motion finds
from the photos alone, as ``n2r fit photos/`` fits a user's capture (the same photos held out). Evaluation time is
not counted as training time. A ``--budget`` trains what ``n2r fit --time-budget`` does for it
(:func:`pytest_n2r.fit.budget.budget_config`: from 20 minutes SH degree 2 and a 256³ last grid, from 30 a finer
end), keeping each setting ``--config`` gives (before 6 December 14:30 UTC it trained its config as given for any
budget); a ``--steps`` fit keeps the defaults. The fitted scene is written to ``--out`` so that
``benchmarks/render_speed.py`` can measure the same field. Needs ``../shared/scenes/fox`` (research-use-only data,
never copied into this repository). Results: docs/performance.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import torch
from _arguments import field_config

from pytest_n2r.cli.fit import APPEARANCE, parse_duration, parse_durations
from pytest_n2r.cli.info import format_exposure
from pytest_n2r.data import ingest
from pytest_n2r.fit import fit
from pytest_n2r.fit.appearance import decide_appearance
from pytest_n2r.fit.budget import budget_config
from pytest_n2r.scene import save_scene

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=parse_duration, default="10m", metavar="DURATION",
                        help="training time (e.g. 90s, 10m)")
    parser.add_argument("--steps", type=int, default=None, help="fit this many steps instead of --budget")
    parser.add_argument("--eval-at", type=parse_durations, default=None, metavar="DURATIONS",
                        help="training times at which the held-out views are scored, within the budget "
                             "(default 1m,3m,6m,10m)")
    parser.add_argument("--out", default="/tmp/n2r-bench-fox.n2r", help="where to write the fitted scene")
    parser.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE", help="FieldConfig overrides")
    parser.add_argument("--sfm", action="store_true",
                        help="poses from our structure from motion on the photos, not the published transforms.json")
    parser.add_argument("--appearance", choices=sorted(APPEARANCE), default="auto",
                        help="a colour gain per photo, as n2r fit --appearance decides it (default auto: measured "
                             "from the photos; the fox's is off)")
    args = parser.parse_args(argv)
    budget = args.budget
    if args.eval_at is not None and args.steps is not None:
        parser.error("--eval-at: scores at training times within --budget; a fit of --steps takes none")
    if args.eval_at is not None and args.eval_at[-1] >= budget:
        parser.error(f"--eval-at {args.eval_at[-1]:g} s: expected training times below --budget {budget:g} s "
                     "(the end of the fit is always scored)")
    given, keys = field_config(parser, args.config)
    config = budget_config(given, budget, max_steps=args.steps, fixed=keys)  # a --steps fit keeps its config
    if not FOX.exists():
        print(f"skipped: {FOX} is absent (the fox capture lives in ../shared beside the checkout)")
        return 0
    torch.set_num_threads(2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
        t0 = time.perf_counter()
        capture = ingest(FOX.parent / "images" if args.sfm else FOX, downscale=0.25)
    height, width = capture.views[0].image.shape[:2]
    print(f"ingest ({'structure from motion' if args.sfm else 'transforms.json'}): {time.perf_counter() - t0:.1f} s, "
          f"{len(capture.train_views)} train / "
          f"{len(capture.heldout_views)} held-out views of {width}×{height}")
    if config != given:
        grids = " → ".join(f"{r}³" for r in config.resolutions)
        print(f"recipe for {budget / 60:g} minutes (as n2r fit --time-budget): SH degree {config.sh_degree}, grids "
              f"{grids}, max_pixels_per_voxel {config.max_pixels_per_voxel:g}")
    defaults = [m for m in (60.0, 180.0, 360.0, 600.0) if m < budget] if args.steps is None else []
    marks = defaults if args.eval_at is None else list(args.eval_at)
    appearance, exposure = decide_appearance(capture, APPEARANCE[args.appearance])  # before the CPU clock
    if exposure is not None:
        print(format_exposure(exposure))
    c0 = time.process_time()
    if args.steps is None:
        result = fit(capture, config, time_budget_s=budget, eval_at_s=marks, appearance=appearance)
    else:
        result = fit(capture, config, max_steps=args.steps, appearance=appearance)
        budget = result.report["train_seconds"]
    report = result.report
    print(f"\n{'train time':>10} {'steps':>6} {'PSNR dB':>8} {'SSIM':>6}")
    final = {"seconds": budget, "step": report["steps"], "psnr": report["psnr"], "ssim": report["ssim"]}
    for row in [*report["history"], final]:
        print(f"{row['seconds'] / 60:>8.1f} m {row['step']:>6} {row['psnr']:>8.2f} {row['ssim']:>6.3f}")
    print(f"\nfield: {json.dumps(report['field'])}; {report['steps'] / report['train_seconds']:.2f} steps/s, "
          f"{time.process_time() - c0:.0f} CPU s (training and evaluation); "
          f"{report['compile_seconds']:.1f} s compiling the training kernels (not training time)")
    print("held-out views:", ", ".join(f"{r['view']} {r['psnr']:.2f} dB" for r in report["heldout"]))
    save_scene(args.out, result.field, result.config, capture, {**report, **({} if exposure is None else
                                                                             {"exposure": exposure})})
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
