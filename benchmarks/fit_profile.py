"""Where a training step's time goes: milliseconds per step by phase and grid, and steps per CPU second, on
1 and on 2 threads.

Run: ``python benchmarks/fit_profile.py [--steps 600] [--threads 1 2] [--config key=value ...] [--capture wall]``

Fits the fox (``../shared/scenes/fox``, 1/4 resolution, every 8th photo held out) for ``--steps`` steps once
per thread count, each in a fresh process (numba's thread count is fixed when its pool starts), with the same
config and seed, so every run does the same arithmetic. ``--capture wall`` (or ``object``) fits a phone
capture of that demo scene instead (no download). Phases (``FitResult.report["step_ms"]``): ``rays`` (draw
the batch), ``march`` (occupied samples), ``corners`` (sample positions, corner rows, the step's distinct
rows), ``forward`` (interpolate, shade, composite, loss), ``backward``, ``update`` (priors and Adam on the
touched rows), ``prune`` (occupancy refresh, every ``prune_every`` steps, averaged over all steps) and
``refine`` (moving to the next grid). Wall-clock milliseconds: run under ``flock /tmp/n2r-cpu.lock`` and
compare runs made side by side. Results: docs/performance.md ("Fitting the fox capture").
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pytest_n2r.field.config import FieldConfig

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"
PHASES = ("rays", "march", "corners", "forward", "backward", "update", "prune", "refine")


def load_capture(name: str, folder: str):
    """The fox (``name`` 'fox') or a phone capture of a demo scene written to ``folder``."""
    from pytest_n2r.data import ingest

    if name == "fox":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
            return ingest(FOX, downscale=0.25)
    from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture

    write_phone_capture(name, folder, PhoneSettings(size=160))
    return ingest(folder)


def child(args: argparse.Namespace, config: FieldConfig) -> int:
    """One fit of ``config`` in this process; prints its report as one JSON line."""
    import torch

    from pytest_n2r.fit import fit

    torch.set_num_threads(args.child)
    with tempfile.TemporaryDirectory(prefix="n2r-profile-") as tmp:
        capture = load_capture(args.capture, tmp)
        # compile (or load from numba's cache) every kernel first, so the first grid is not charged for it
        fit(capture, config.replace(resolutions=(16, 24), stage_fractions=(0.5,)), max_steps=30, device="cpu")
        c0, t0 = time.process_time(), time.perf_counter()
        result = fit(capture, config, max_steps=args.steps, device="cpu")
        cpu_s, wall_s = time.process_time() - c0, time.perf_counter() - t0
    report = result.report
    print(json.dumps({"threads": args.child, "steps": report["steps"], "train_s": report["train_seconds"],
                      "cpu_s": round(cpu_s - report["eval_seconds"], 2), "wall_s": round(wall_s, 2),
                      "psnr": report["psnr"], "step_ms": report["step_ms"]}))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="steps of each fit")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="thread counts to compare")
    parser.add_argument("--capture", default="fox", choices=["fox", "wall", "object"])
    parser.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE", help="FieldConfig overrides")
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.capture == "fox" and not FOX.exists():
        print(f"skipped: {FOX} is absent (the fox capture lives in ../shared beside the checkout)")
        return 0
    from _arguments import field_config

    config, _ = field_config(parser, args.config)  # a bad setting stops here, before any child starts
    if args.child is not None:
        return child(args, config)
    runs = []
    for threads in args.threads:
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
        command = [sys.executable, __file__, "--child", str(threads), "--steps", str(args.steps),
                   "--capture", args.capture, "--config", *args.config]
        out = subprocess.run(command, check=False, env=env, capture_output=True, text=True)
        if out.returncode != 0:
            print(out.stderr, file=sys.stderr)
            return out.returncode
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(f"{args.capture}, {args.steps} steps, config {' '.join(args.config) or 'default'}")
    for kind in ("cpu_ms", "wall_ms"):
        print(f"\n{'CPU' if kind == 'cpu_ms' else 'wall'} milliseconds per step")
        print("| threads | grid | steps | " + " | ".join(PHASES) + " | total |")
        print("|---|---|---|" + "---|" * (len(PHASES) + 1))
        for run in runs:
            for grid, row in run["step_ms"].items():
                ms = row[kind]
                print(f"| {run['threads']} | {grid} | {row['steps']} | " + " | ".join(f"{ms[p]:.1f}" for p in PHASES)
                      + f" | {sum(ms.values()):.1f} |")
    print("\n| threads | steps | training s | CPU s | steps per CPU s | steps per s | held-out PSNR |")
    print("|---|---|---|---|---|---|---|")
    for run in runs:
        print(f"| {run['threads']} | {run['steps']} | {run['train_s']} | {run['cpu_s']} | "
              f"{run['steps'] / run['cpu_s']:.2f} | {run['steps'] / run['train_s']:.2f} | {run['psnr']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
