"""What a phone capture of a known scene gives with ``n2r fit``'s defaults, with and without the per-photo
appearance (exposure / white balance) correction, scored against the exact scene.

Run: ``python benchmarks/phone_capture.py [--scenes wall object] [--size 480] [--budget 10m | --steps N]
[--exposure-stops 0.5] [--white-balance 0.08] [--config KEY=VALUE ...] [--json out.json]``

For each demo scene: :func:`pytest_n2r.demo.phone_capture.write_phone_capture` photographs the trajectory
(every third photo in portrait, half of those EXIF-rotated; ±0.5 stops of exposure, ±8 % white balance unless
``--exposure-stops`` and ``--white-balance`` say otherwise,
blur up to 0.8 px, JPEG 90) with its poses in a transforms.json; :func:`pytest_n2r.data.ingest` reads it at
full size; the field is fitted twice with the same settings and seed, as ``n2r fit DIR --downscale 1
--appearance off`` and ``--appearance on`` fit it (what the default, ``auto``, decides from the photos is printed
beside): the library's defaults, what the time budget chooses
(:func:`pytest_n2r.fit.budget.budget_config`) and the finer grid for the end where the photos are finer than
the voxel (:mod:`pytest_n2r.fit.detail`); ``--config`` changes a setting as ``n2r fit --config`` does.

Scored against the **exact** render at the same pose: at the demo's held-out poses (never fitted), at those
poses moved by τ1 and τ3 (drawn from a seeded generator), and at every 7th fitted pose; PSNR; the share of a
view's pixels whose surface no fitted photo sees (``unseen``: outside their images or hidden) and the PSNR over the
other pixels (``seen``: the field's error where the capture showed it what to render); SSIM, and the
repeatability (2 px) of ORB, SIFT and AKAZE between the exact image and the field's (a view where a detector
finds nothing to compare is counted apart: ``0.41 (4 of 6)``, or ``n/a`` when no view has anything). Nothing
here was tuned on these views: the defaults were chosen on validation views (``benchmarks/fit_budget.py``).
A time budget is wall-clock training on whatever machine runs this; ``--steps`` fixes the fields instead.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from _arguments import field_config
from _scoring import FittedPhotos, format_repeatabilities, score_exact

from pytest_n2r.cli.fit import parse_duration
from pytest_n2r.cli.info import format_exposure
from pytest_n2r.data import ingest
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.fit import fit
from pytest_n2r.fit.appearance import measured_appearance
from pytest_n2r.fit.budget import budget_config
from pytest_n2r.study.sampling import sample_transform

#: Which fitted poses are scored: every 7th training view (6 of the 42 a 48-photo capture fits).
FITTED_EVERY = 7


def run(name: str, settings: PhoneSettings, folder: Path, config: FieldConfig, *, time_budget_s: float | None,
        max_steps: int | None) -> dict:
    """Photograph ``name`` with ``settings`` into ``folder``, fit it plainly and with the appearance correction,
    and score both fields against the exact scene (see the module docstring)."""
    write_phone_capture(name, folder, settings)
    capture = ingest(folder)
    scene = ground_truth(name)
    rng = np.random.default_rng(0)
    heldout = [(v.c2w, v.camera) for v in capture.heldout_views]
    poses = {"held out": heldout,
             "moved": [(sample_transform(f, rng).apply(c2w, capture.reference_length), cam)
                       for c2w, cam in heldout for f in ("tau1", "tau3")],
             "fitted": [(v.c2w, v.camera) for v in capture.train_views[::FITTED_EVERY]]}
    fitted = FittedPhotos(scene, [(v.c2w, v.camera) for v in capture.train_views])
    out = {"exposure": measured_appearance(capture)}  # what n2r fit's default (--appearance auto) decides
    for appearance in (False, True):
        result = fit(capture, config, time_budget_s=time_budget_s, max_steps=max_steps, device="cpu",
                     appearance=appearance)
        report = result.report
        detail = report["detail"] or {}
        entry = {where: score_exact(scene, result.field, at, fitted=fitted) for where, at in poses.items()}
        entry.update(steps=report["steps"], train_s=report["train_seconds"],
                     grids=list(result.config.resolutions), pixels_per_voxel=detail.get("pixels_per_voxel"))
        if appearance:
            gains = np.asarray(list(report["appearance"].values()))
            entry["gain_range"] = [float(gains.min()), float(gains.max())]
        out["corrected" if appearance else "plain"] = entry
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["wall", "object"])
    parser.add_argument("--size", type=int, default=480, help="longer side of the photos, pixels")
    parser.add_argument("--exposure-stops", type=float, default=PhoneSettings.exposure_stops, metavar="STOPS",
                        help="each photo's exposure drawn in ±STOPS (default %(default)g)")
    parser.add_argument("--white-balance", type=float, default=PhoneSettings.white_balance, metavar="FRACTION",
                        help="each photo's gain per channel drawn in 1 ± FRACTION (default %(default)g)")
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--budget", type=parse_duration, default=None, metavar="DURATION",
                        help="training time of each fit, as n2r fit --time-budget (default 10m)")
    length.add_argument("--steps", type=int, default=None, help="fit this many steps instead of a time budget")
    parser.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE",
                        help="FieldConfig settings, as n2r fit --config takes them")
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args(argv)
    budget = 600.0 if args.budget is None and args.steps is None else args.budget
    given, keys = field_config(parser, args.config)
    config = budget_config(given, budget, max_steps=args.steps, fixed=keys)
    settings = PhoneSettings(size=args.size, exposure_stops=args.exposure_stops, white_balance=args.white_balance)
    torch.set_num_threads(2)
    results = {}
    print("| scene | fit | steps | train s | grids | pixels/voxel | poses | PSNR dB (vs exact) | unseen | "
          "PSNR dB seen | SSIM | ORB rep. | SIFT rep. | AKAZE rep. |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        with tempfile.TemporaryDirectory(prefix="n2r-phone-") as tmp:
            results[name] = run(name, settings, Path(tmp), config, time_budget_s=budget, max_steps=args.steps)
        for key, r in results[name].items():
            if key == "exposure":
                continue
            grids = "→".join(f"{g}³" for g in r["grids"])
            ppv = "n/a" if r["pixels_per_voxel"] is None else f"{r['pixels_per_voxel']:.1f}"
            for where in ("held out", "moved", "fitted"):
                s = r[where]
                seen = "n/a" if s["psnr_seen"] is None else f"{s['psnr_seen']:.2f}"
                print(f"| {name} | {key} | {r['steps']} | {r['train_s']:.0f} | {grids} | {ppv} | {where} ({s['n']}) "
                      f"| {s['psnr']:.2f} | {s['unseen']:.1%} | {seen} | {s['ssim']:.4f} "
                      f"| {format_repeatabilities(s, ' | ')} |", flush=True)
        print(f"{name}: {format_exposure(results[name]['exposure'])}", flush=True)
    if args.json:
        from pytest_n2r.data.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
