"""Shaken photos in a phone capture: is the field better fitted with them or without them?

Run: ``python benchmarks/shaken_photos.py [--scenes wall object] [--size 480] [--shaken 0.15] [--shake-px 6]
[--steps 6000] [--config KEY=VALUE ...] [--json out.json]``

For each demo scene, :func:`pytest_n2r.demo.phone_capture.write_phone_capture` photographs the trajectory as
``phone_capture.py`` does (portraits, ±0.5 stops, ±8 % white balance, blur up to 0.8 px, JPEG 90), and smears a
share ``--shaken`` of the photos along a streak of ``--shake-px`` pixels at a random angle
(:attr:`~pytest_n2r.demo.phone_capture.PhoneSettings.shaken`; drawn apart, so the capture differs from the one
without shaken photos in those photos alone). Three fields, with the same settings, seed and number of steps (the
library's defaults and what a 10-minute budget chooses, the per-photo appearance correction on):

- ``every photo``: the shaken capture as ``n2r fit`` takes it;
- ``shaken left out``: the same capture without its shaken photos, as a screen that dropped them would fit it;
- ``none shaken``: the capture without shaken photos (the same photos, sharp): what the shake costs.

Each is scored against the **exact** scene at the held-out poses whose photo is not shaken, and at those poses
moved by τ1 and τ3 (drawn from a seeded generator): PSNR, SSIM and the repeatability (2 px) of ORB, SIFT and AKAZE
between the exact image and the field's. A fixed ``--steps`` keeps the fields independent of the machine's load.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace

import numpy as np
import torch
from _arguments import field_config
from _scoring import format_repeatabilities, score_exact

from pytest_n2r.data import ingest
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.fit import fit
from pytest_n2r.fit.budget import budget_config
from pytest_n2r.study.sampling import sample_transform

#: The budget whose settings the fields take (the grids of a 10-minute fit); the length is ``--steps``.
BUDGET_S = 600.0


def run(name: str, settings: PhoneSettings, config, steps: int) -> dict:
    """Photograph ``name`` with and without shaken photos, fit the three fields, score them (module docstring)."""
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="n2r-shaken-") as shaken_dir, \
            tempfile.TemporaryDirectory(prefix="n2r-steady-") as steady_dir:
        photos = write_phone_capture(name, shaken_dir, settings)
        write_phone_capture(name, steady_dir, replace(settings, shaken=0.0))
        shaken = {p.path.name for p in photos if p.shake_px > 0}
        capture, steady = ingest(shaken_dir), ingest(steady_dir)
        out["shaken"] = sorted(shaken)
        out["shaken_fitted"] = sum(v.name in shaken for v in capture.train_views)
        scene = ground_truth(name)
        rng = np.random.default_rng(0)
        heldout = [(v.c2w, v.camera) for v in capture.heldout_views if v.name not in shaken]
        poses = {"held out": heldout,
                 "moved": [(sample_transform(f, rng).apply(c2w, capture.reference_length), cam)
                           for c2w, cam in heldout for f in ("tau1", "tau3")]}
        variants = {"every photo": capture,
                    "shaken left out": replace(capture, views=[v for v in capture.views if v.name not in shaken]),
                    "none shaken": steady}
        for label, fitted in variants.items():
            result = fit(fitted, config, max_steps=steps, device="cpu", appearance=True)
            entry = {where: score_exact(scene, result.field, at) for where, at in poses.items()}
            entry.update(steps=result.report["steps"], train_s=result.report["train_seconds"],
                         photos=len(fitted.train_views))
            out[label] = entry
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["wall", "object"])
    parser.add_argument("--size", type=int, default=480, help="longer side of the photos, pixels")
    parser.add_argument("--shaken", type=float, default=0.15, help="share of the photos shaken (default %(default)g)")
    parser.add_argument("--shake-px", type=float, default=6.0, help="length of a shaken photo's streak, pixels")
    parser.add_argument("--steps", type=int, default=6000, help="training steps of each field (default %(default)d)")
    parser.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE",
                        help="FieldConfig settings, as n2r fit --config takes them")
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args(argv)
    given, keys = field_config(parser, args.config)
    config = budget_config(given, BUDGET_S, max_steps=args.steps, fixed=keys)
    settings = PhoneSettings(size=args.size, shaken=args.shaken, shake_px=args.shake_px)
    torch.set_num_threads(2)
    results = {}
    print("| scene | fit | photos fitted | steps | train s | poses | PSNR dB (vs exact) | SSIM | ORB rep. | "
          "SIFT rep. | AKAZE rep. |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        results[name] = r = run(name, settings, config, args.steps)
        for label in ("every photo", "shaken left out", "none shaken"):
            e = r[label]
            for where in ("held out", "moved"):
                s = e[where]
                print(f"| {name} | {label} | {e['photos']} | {e['steps']} | {e['train_s']:.0f} | {where} ({s['n']}) | "
                      f"{s['psnr']:.2f} | {s['ssim']:.4f} | {format_repeatabilities(s, ' | ')} |", flush=True)
        print(f"{name}: {len(r['shaken'])} photos shaken ({r['shaken_fitted']} of them fitted): "
              f"{', '.join(r['shaken'])}", flush=True)
    if args.json:
        from pytest_n2r.data.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
