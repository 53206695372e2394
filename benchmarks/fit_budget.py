"""What a longer fit and a finer grid buy: phone captures of the demo scenes (and the fox), a validation split
for choosing, held-out views for reporting.

Run: ``python benchmarks/fit_budget.py [--scenes wall object] [--size 160] [--steps 1000]
[--ladder default=48,96,160@0.1,0.35 --ladder planned=48,96,160,256@0.025,0.0875,0.25] [--fox 10m] [--json out.json]``,
or, to compare other settings of the fit at the same steps, ``--base default --variant base
--variant tv tv=1e-4 --variant half-rays batch_rays=2048 steps=4000`` (each variant: a name, then
``FieldConfig`` settings as ``n2r fit --config`` takes them; ``steps=N`` overrides ``--steps`` for it).

Each demo scene is photographed like a phone does (:func:`pytest_n2r.demo.phone_capture.write_phone_capture`:
mixed orientation, exposure and white balance, blur, JPEG), read with its poses, and fitted once per
(ladder, steps) with the same config and seed. Every 8th training photo (from the 4th) is a **validation**
view: it is not fitted, and it is where variants are compared and chosen. The demo's held-out views are
never fitted and never used for choosing: they are what is reported. Both are scored against the exact
render at the same pose: PSNR, SSIM and ORB repeatability (1000 points, 2 px) between the exact image and
the field's. ``pixels/voxel``: how many training pixels one voxel of the finest grid spans where the
cameras look closely (:mod:`pytest_n2r.fit.detail`; 1 would match the photos).

``--fox 10m`` also fits the fox (``../shared/scenes/fox``, 1/4 resolution, every 8th photo held out, every
8th of the rest from the 4th for validation) once per ladder within that time budget, scored against the
photos. Fit times are wall-clock seconds on whatever machine runs this; compare ladders at equal steps.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from pytest_n2r.cli.fit import parse_config_override, parse_duration
from pytest_n2r.data import ingest
from pytest_n2r.data.capture import Capture
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit import evaluate_views, fit
from pytest_n2r.fit.detail import capture_detail
from pytest_n2r.metrics import repeatability
from pytest_n2r.metrics.image_quality import psnr, ssim
from pytest_n2r.render.field_render import FieldRenderer
from pytest_n2r.study.suts import resolve_sut

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"
#: The phone benchmark's field settings (benchmarks/phone_capture.py); only the grid ladder varies here.
CONFIG = FieldConfig(resolutions=(48, 96, 160), stage_fractions=(0.1, 0.35), sh_degree=0, batch_rays=4096,
                     tv=1e-4, seed=0)
LADDERS = ("default=48,96,160@0.1,0.35", "planned=48,96,160,256@0.025,0.0875,0.25")
#: The base configs ``--base`` names: the phone benchmark's, and the library's defaults (what the fox is fitted
#: with).
BASES = {"phone": CONFIG, "default": FieldConfig()}


def parse_ladder(text: str) -> tuple[str, tuple[int, ...], tuple[float, ...]]:
    """``name=r1,r2,...@f1,f2,...`` → (name, resolutions, stage fractions)."""
    try:
        name, rest = text.split("=", 1)
        res, fractions = rest.split("@", 1) if "@" in rest else (rest, "")
        resolutions = tuple(int(r) for r in res.split(","))
        stage = tuple(float(f) for f in fractions.split(",")) if fractions else ()
        FieldConfig(resolutions=resolutions, stage_fractions=stage)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--ladder {text!r}: expected name=48,96,160@0.1,0.35 ({exc})") from None
    return name, resolutions, stage


def parse_variant(words: list[str]) -> tuple[str, dict, int | None]:
    """``[name, key=value, ...]`` of ``--variant`` → (name, FieldConfig changes, steps or None)."""
    if not words or "=" in words[0]:
        raise argparse.ArgumentTypeError(f"--variant {' '.join(words)}: expected a name, then key=value settings")
    changes, steps = {}, None
    for word in words[1:]:
        key, value = parse_config_override(word)
        if key == "steps":
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise argparse.ArgumentTypeError(f"--variant {words[0]}: steps={value!r}: expected an integer >= 1")
            steps = value
        else:
            default = getattr(FieldConfig(), key, None)
            changes[key] = (value,) if isinstance(default, tuple) and not isinstance(value, tuple) else value
    try:
        CONFIG.replace(**changes)
    except (TypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"--variant {words[0]}: {exc}") from None
    return words[0], changes, steps


def split_validation(capture: Capture, every: int = 8, first: int = 4) -> tuple[Capture, list, list]:
    """(the capture to fit: training views minus validation, no held-out ones; validation views; held-out
    views)."""
    train = capture.train_views
    validation = [v for k, v in enumerate(train) if k % every == first]
    fitted = [v for k, v in enumerate(train) if k % every != first]
    return replace(capture, views=fitted), validation, capture.heldout_views


def score_exact(scene, field, views) -> dict:
    """Mean PSNR, SSIM and ORB repeatability of the field's renders against the exact ones at ``views``."""
    renderer, orb, rep = FieldRenderer(field), resolve_sut("orb", None).fn, repeatability(px=2)
    rows = []
    for view in views:
        want = scene.render(view.c2w, view.camera, ("rgb", "depth", "opacity"))
        got = renderer.render(view.c2w, view.camera, ("rgb",))["rgb"]
        r = rep.compute(orb(want.rgb), orb(got), want, replace(want, rgb=got))
        rows.append((psnr(want.rgb, got), ssim(want.rgb, got), r.score if r.valid else np.nan))
    table = np.asarray(rows, dtype=np.float64)
    defined = table[np.isfinite(table[:, 2]), 2]  # ORB finds nothing on tiny images: no score, not 0
    return {"psnr": round(float(table[:, 0].mean()), 2), "ssim": round(float(table[:, 1].mean()), 4),
            "orb": round(float(defined.mean()), 3) if len(defined) else float("nan"), "n": len(rows)}


def score_photos(field, views) -> dict:
    rows = evaluate_views(field, views)
    return {"psnr": round(float(np.mean([r["psnr"] for r in rows])), 2),
            "ssim": round(float(np.mean([r["ssim"] for r in rows])), 4), "orb": float("nan"), "n": len(rows)}


def pixels_per_voxel(capture: Capture, resolution: int) -> float:
    centers = np.stack([v.c2w[:3, 3] for v in capture.views])
    detail = capture_detail(capture, SceneSpace.around(capture.bounds, centers, shell=CONFIG.shell))
    return float("nan") if detail is None else detail.pixels_per_voxel(resolution)


def _progress(info: dict) -> None:
    if info["step"] % 250 < 5:  # about every 250 steps, so a long run's log shows where it is
        print(f"  step {info['step']}, {info['resolution']}³, {info['elapsed_s']:.0f} s", file=sys.stderr, flush=True)


def run_fit(capture: Capture, config: FieldConfig, **limits) -> tuple[object, dict]:
    t0, c0 = time.perf_counter(), time.process_time()
    result = fit(capture, config, device="cpu", progress=_progress, **limits)
    info = {"steps": result.report["steps"], "fit_s": round(time.perf_counter() - t0, 1),
            "cpu_s": round(time.process_time() - c0, 1),
            "pixels_per_voxel": round(pixels_per_voxel(capture, config.resolutions[-1]), 2)}
    return result.field, info


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["wall", "object"])
    parser.add_argument("--size", type=int, default=160, help="longer side of the phone photos, pixels")
    parser.add_argument("--steps", type=int, nargs="+", default=[1000], help="optimization steps per fit")
    parser.add_argument("--ladder", type=parse_ladder, action="append", default=None, metavar="NAME=RES@FRACTIONS",
                        help=f"grid ladder to compare (repeatable; default: {' '.join(LADDERS)})")
    parser.add_argument("--base", choices=sorted(BASES), default="phone",
                        help="the config ladders and variants change (default: phone, the phone benchmark's)")
    parser.add_argument("--variant", nargs="+", action="append", default=None, metavar="NAME [KEY=VALUE ...]",
                        help="compare these settings instead of ladders (repeatable)")
    parser.add_argument("--fox", type=parse_duration, default=None, metavar="DURATION",
                        help="also fit the fox once per ladder within this time budget")
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args(argv)
    base = BASES[args.base]
    if args.variant:
        try:
            variants = [parse_variant(words) for words in args.variant]
        except argparse.ArgumentTypeError as exc:
            parser.error(str(exc))
    else:
        variants = [(name, {"resolutions": res, "stage_fractions": stage}, None)
                    for name, res, stage in (args.ladder or [parse_ladder(text) for text in LADDERS])]
    torch.set_num_threads(2)
    rows = []
    print("| scene | ladder / variant | steps | fit s | CPU s | pixels/voxel | validation PSNR / SSIM / ORB "
          "| held-out PSNR / SSIM / ORB |")
    print("|---|---|---|---|---|---|---|---|")

    def report(row: dict) -> None:
        rows.append(row)
        v, h = row["validation"], row["heldout"]
        print(f"| {row['scene']} | {row['ladder']} | {row['steps']} | {row['fit_s']} | {row['cpu_s']} | "
              f"{row['pixels_per_voxel']} | "
              f"{v['psnr']:.2f} / {v['ssim']:.3f} / {v['orb']:.3f} ({v['n']}) | "
              f"{h['psnr']:.2f} / {h['ssim']:.3f} / {h['orb']:.3f} ({h['n']}) |", flush=True)

    for name in args.scenes:
        scene = ground_truth(name)
        with tempfile.TemporaryDirectory(prefix="n2r-budget-") as tmp:
            write_phone_capture(name, tmp, PhoneSettings(size=args.size))
            capture, validation, heldout = split_validation(ingest(tmp))
        for steps in args.steps:
            for variant, changes, own_steps in variants:
                field, info = run_fit(capture, base.replace(**changes), max_steps=own_steps or steps)
                report({"scene": name, "ladder": variant, **info, "validation": score_exact(scene, field, validation),
                        "heldout": score_exact(scene, field, heldout)})
    if args.fox is not None:
        if not FOX.exists():
            print(f"fox skipped: {FOX} is absent (the fox capture lives in ../shared beside the checkout)")
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
                capture, validation, heldout = split_validation(ingest(FOX, downscale=0.25))
            for variant, changes, _ in variants:
                config = FieldConfig().replace(**changes)
                field, info = run_fit(capture, config, time_budget_s=args.fox)
                report({"scene": "fox", "ladder": variant, **info, "validation": score_photos(field, validation),
                        "heldout": score_photos(field, heldout)})
    if args.json:
        from pytest_n2r.data.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
