"""What a longer fit and a finer grid buy: phone captures of the demo scenes (and the fox), a validation split
for choosing, held-out views for reporting.

Run: ``python benchmarks/fit_budget.py [--scenes wall object] [--size 160] [--steps 1000 | --time 3m]
[--ladder default=48,96,160@0.1,0.35 --ladder planned=48,96,160,256@0.025,0.0875,0.25] [--fox 10m] [--json out.json]``,
or, to compare other settings of the fit at the same steps, ``--base default --variant base
--variant tv tv=1e-4 --variant half-rays batch_rays=2048 steps=4000`` (each variant: a name, then
``FieldConfig`` settings as ``n2r fit --config`` takes them; ``steps=N`` overrides ``--steps`` for it;
``appearance=True`` fits a colour gain per photo, as ``n2r fit --appearance`` does).

Each demo scene is photographed like a phone does (:func:`pytest_n2r.demo.phone_capture.write_phone_capture`: mixed
orientation, exposure and white balance, blur, JPEG), read with its poses, and fitted once per (ladder, steps) with
the same config and seed, as given: what a long ``n2r fit --time-budget`` would choose
(:func:`pytest_n2r.fit.budget.budget_config`) is not applied, so a long screen names its settings. Every 8th
training photo (from the 4th) is a **validation** view: it is not fitted, and it is where variants are compared and
chosen. The demo's held-out views are never fitted and never used for choosing: they are what is reported. Both are
scored against the exact render at the same pose: PSNR, SSIM and the repeatability (2 px) of ORB, SIFT and AKAZE
between the exact image and the field's (a view where a detector has nothing to compare is counted apart).
``pixels/voxel``: how many training pixels one voxel of the finest grid spans where the cameras look closely
(:mod:`pytest_n2r.fit.detail`; 1 would match the photos).

``--fox-steps N`` (or ``--fox 10m``, a time budget) also fits the fox (``../shared/scenes/fox``, 1/4
resolution, every 8th photo held out, every 8th of the rest from the 4th for validation) once per ladder or
variant (library defaults plus its settings), and scores it on the **validation** views only, as
``benchmarks/fidelity.py`` scores a scene (photos; repeatability photo vs render at 480 px): the fox's
held-out views are reported only for the recipe chosen, with ``benchmarks/field_fit.py`` and
``benchmarks/fidelity.py``. Fit times are wall-clock seconds on whatever machine runs this; compare at equal
steps.
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
from _scoring import defined_mean, format_repeatabilities, score_exact

from pytest_n2r.cli.fit import parse_config_override, parse_duration
from pytest_n2r.data import ingest
from pytest_n2r.data.capture import Capture
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit import fit
from pytest_n2r.fit.detail import capture_detail

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"
#: The phone recipe: the settings the first phone-capture tables were measured at (1–2 December, before the
#: library's defaults fitted those captures 3.3 dB better); ``--base phone``, the default, keeps the commands in
#: docs/scene-field-log.md reproducible. Only the grid ladder varies here.
CONFIG = FieldConfig(resolutions=(48, 96, 160), stage_fractions=(0.1, 0.35), sh_degree=0, batch_rays=4096,
                     lr_density=0.2, lr_color=0.1, tv=1e-4, seed=0)  # the rates its tables were measured at
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


def parse_variant(words: list[str]) -> tuple[str, dict, dict]:
    """``[name, key=value, ...]`` of ``--variant`` → (name, FieldConfig changes, options of the fit: ``max_steps``
    from ``steps=N``, ``appearance`` from ``appearance=True``)."""
    if not words or "=" in words[0]:
        raise argparse.ArgumentTypeError(f"--variant {' '.join(words)}: expected a name, then key=value settings")
    changes, options = {}, {}
    for word in words[1:]:
        key, value = parse_config_override(word)
        if key == "steps":
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise argparse.ArgumentTypeError(f"--variant {words[0]}: steps={value!r}: expected an integer >= 1")
            options["max_steps"] = value
        elif key == "appearance":
            if not isinstance(value, bool):
                raise argparse.ArgumentTypeError(f"--variant {words[0]}: appearance={value!r}: expected True or False")
            options["appearance"] = value
        else:
            default = getattr(FieldConfig(), key, None)
            changes[key] = (value,) if isinstance(default, tuple) and not isinstance(value, tuple) else value
    try:
        CONFIG.replace(**changes)
    except (TypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"--variant {words[0]}: {exc}") from None
    return words[0], changes, options


def split_validation(capture: Capture, every: int = 8, first: int = 4) -> tuple[Capture, list, list]:
    """(the capture to fit: training views minus validation, no held-out ones; validation views; held-out
    views)."""
    train = capture.train_views
    validation = [v for k, v in enumerate(train) if k % every == first]
    fitted = [v for k, v in enumerate(train) if k % every != first]
    return replace(capture, views=fitted), validation, capture.heldout_views


def score_fox(field, config: FieldConfig, capture: Capture, validation: list, path: Path) -> dict:
    """Validation scores of a fox field as :func:`pytest_n2r.study.fidelity.measure_fidelity` measures a scene
    (PSNR / SSIM against the photos, each detector's repeatability photo vs render at 480 px): the field is
    stored at ``path`` (a /tmp path: fox fields never go into the repository) with the validation views as its
    held-out ones, and the real held-out views left out, so nothing here can be tuned on them."""
    from pytest_n2r.scene import load_scene, save_scene
    from pytest_n2r.study.fidelity import DETECTORS, measure_fidelity

    marked = [replace(v, split="heldout") for v in validation]
    save_scene(path, field, config, replace(capture, views=[*capture.views, *marked]), {})
    report = measure_fidelity(load_scene(path, device="cpu"), size=480)
    return {"psnr": round(report.mean("psnr"), 2), "ssim": round(report.mean("ssim"), 4), "n": len(report.images),
            **{d: defined_mean([s.score if s.valid else float("nan")
                                for s in report.floors[d, "repeatability"].samples]) for d in DETECTORS}}


def poses(views: list) -> list:
    return [(v.c2w, v.camera) for v in views]


def pixels_per_voxel(capture: Capture, resolution: int) -> float:
    centers = np.stack([v.c2w[:3, 3] for v in capture.views])
    detail = capture_detail(capture, SceneSpace.around(capture.bounds, centers, shell=CONFIG.shell))
    return float("nan") if detail is None else detail.pixels_per_voxel(resolution)


def _progress(info: dict) -> None:
    if info["step"] % 250 < 5:  # about every 250 steps, so a long run's log shows where it is
        print(f"  step {info['step']}, {info['resolution']}³, {info['elapsed_s']:.0f} s", file=sys.stderr, flush=True)


def run_fit(capture: Capture, config: FieldConfig, **options) -> tuple[object, dict]:
    """Fit ``capture`` on the CPU with ``options`` (:func:`pytest_n2r.fit.fit`'s ``max_steps`` or
    ``time_budget_s``, ``appearance``): the field and the fit's steps, wall and CPU seconds and detail."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = fit(capture, config, device="cpu", progress=_progress, **options)
    info = {"steps": result.report["steps"], "fit_s": round(time.perf_counter() - t0, 1),
            "cpu_s": round(time.process_time() - c0, 1),
            "pixels_per_voxel": round(pixels_per_voxel(capture, config.resolutions[-1]), 2)}
    return result.field, info


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["wall", "object"])
    parser.add_argument("--size", type=int, default=160, help="longer side of the phone photos, pixels")
    parser.add_argument("--steps", type=int, nargs="+", default=[1000], help="optimization steps per fit")
    parser.add_argument("--time", type=parse_duration, default=None, metavar="DURATION",
                        help="fit each demo scene within this training time instead of --steps (variants at "
                             "equal time: compare their CPU s and steps)")
    parser.add_argument("--ladder", type=parse_ladder, action="append", default=None, metavar="NAME=RES@FRACTIONS",
                        help=f"grid ladder to compare (repeatable; default: {' '.join(LADDERS)})")
    parser.add_argument("--base", choices=sorted(BASES), default="phone",
                        help="the config ladders and variants change (default: phone, the phone benchmark's)")
    parser.add_argument("--variant", nargs="+", action="append", default=None, metavar="NAME [KEY=VALUE ...]",
                        help="compare these settings instead of ladders (repeatable)")
    parser.add_argument("--fox", type=parse_duration, default=None, metavar="DURATION",
                        help="also fit the fox once per ladder within this time budget")
    parser.add_argument("--fox-steps", type=int, default=None, metavar="N",
                        help="also fit the fox's validation split once per ladder / variant for N steps")
    parser.add_argument("--fox-dir", default=None, metavar="DIR",
                        help="keep the fox fields (validation views as held-out ones) here; a /tmp folder")
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args(argv)
    base = BASES[args.base]
    if args.variant:
        try:
            variants = [parse_variant(words) for words in args.variant]
        except argparse.ArgumentTypeError as exc:
            parser.error(str(exc))
        timed = [name for name, _, options in variants if "max_steps" in options and args.time]
        if timed:
            parser.error(f"--variant {timed[0]}: steps=N with --time (the demo scenes' fits stop at the time; "
                         "leave steps out, or use --steps)")
    else:
        variants = [(name, {"resolutions": res, "stage_fractions": stage}, {})
                    for name, res, stage in (args.ladder or [parse_ladder(text) for text in LADDERS])]
    torch.set_num_threads(2)
    rows = []
    print("| scene | ladder / variant | steps | fit s | CPU s | pixels/voxel | validation PSNR / SSIM | "
          "ORB / SIFT / AKAZE rep. | held-out PSNR / SSIM | ORB / SIFT / AKAZE rep. |")
    print("|---|---|---|---|---|---|---|---|---|---|")

    def cells(score: dict | None) -> str:
        if score is None:
            return "not scored | "
        reps = format_repeatabilities(score, " / ")
        return f"{score['psnr']:.2f} / {score['ssim']:.3f} ({score['n']}) | {reps}"

    def report(row: dict) -> None:
        rows.append(row)
        print(f"| {row['scene']} | {row['ladder']} | {row['steps']} | {row['fit_s']} | {row['cpu_s']} | "
              f"{row['pixels_per_voxel']} | {cells(row['validation'])} | {cells(row['heldout'])} |", flush=True)

    for name in args.scenes:
        scene = ground_truth(name)
        with tempfile.TemporaryDirectory(prefix="n2r-budget-") as tmp:
            write_phone_capture(name, tmp, PhoneSettings(size=args.size))
            capture, validation, heldout = split_validation(ingest(tmp))
        for steps in [None] if args.time else args.steps:
            for variant, changes, options in variants:
                limits = {"time_budget_s": args.time} if args.time else {"max_steps": steps}
                field, info = run_fit(capture, base.replace(**changes), **{**limits, **options})
                report({"scene": name, "ladder": variant, **info,
                        "validation": score_exact(scene, field, poses(validation)),
                        "heldout": score_exact(scene, field, poses(heldout))})
    if args.fox is not None or args.fox_steps is not None:
        if not FOX.exists():
            print(f"fox skipped: {FOX} is absent (the fox capture lives in ../shared beside the checkout)")
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
                capture, validation, _ = split_validation(ingest(FOX, downscale=0.25))
            keep = Path(args.fox_dir or tempfile.mkdtemp(prefix="n2r-budget-fox-"))
            keep.mkdir(parents=True, exist_ok=True)
            for variant, changes, options in variants:
                config = FieldConfig().replace(**changes)
                limits = ({"max_steps": options.get("max_steps", args.fox_steps)} if args.fox_steps is not None
                          else {"time_budget_s": args.fox})
                field, info = run_fit(capture, config, **limits, appearance=options.get("appearance", False))
                report({"scene": "fox", "ladder": variant, **info,
                        "validation": score_fox(field, config, capture, validation, keep / f"{variant}.n2r"),
                        "heldout": None})
    if args.json:
        from pytest_n2r.data.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
