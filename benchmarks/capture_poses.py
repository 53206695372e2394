"""How wrong poses show in a capture, on phone-style captures of the exact demo scenes (whose true poses are known).

Run: ``python benchmarks/capture_poses.py sfm [--scenes wall object] [--size 320] [--matcher auto] [--runs 1]`` or
``python benchmarks/capture_poses.py perturb [--scene wall] [--size 160] [--steps 400] [--degrees 1 3 10]``

``sfm``: structure from motion (:func:`pytest_n2r.data.sfm.run_sfm`, the call ``n2r fit photos/`` makes) on the
photos of :func:`~pytest_n2r.demo.phone_capture.write_phone_capture` written without their poses, scored against
the true poses. A reconstruction is right up to a similarity of the world, so each photo's world rotation
``R_true · R_estᵀ`` is the same rotation for every photo of a right one: the photos whose rotation lies within
5° of the one most photos agree with are *consistent*. Rotation errors are against the mean of the consistent
photos' rotations; centre errors (% of the trajectory's extent) after the best similarity of the consistent
photos' centres (Umeyama); both for the consistent photos and, apart, for the others. Printed with the photos
registered, the models and the focal length found against the true one, and the up check
(:mod:`pytest_n2r.data.upright`) on every registered photo: how many it finds upside down, how many of those the
truth calls inconsistent, the others' largest angle from their consensus, and what ``n2r fit`` then does (keeps
all, drops the upside-down photos, or refuses the reconstruction).

``perturb``: the capture written with its true poses, fitted (:data:`CONFIG`, ``--steps``) after
the poses of some training photos were turned about their camera's vertical axis by ``--degrees``; printed:
each turned photo's PSNR (the field's render at its given pose against the photo), beside the other fitted
photos' median and lowest, and the held-out photos' range. Whether a fit exposes a photo whose pose is wrong.
Results: docs/scene-field-log.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pytest_n2r.data import ingest
from pytest_n2r.data.atomic import atomic_write_text
from pytest_n2r.data.compare import compare_poses
from pytest_n2r.data.poses import PoseSet, SourceFrame
from pytest_n2r.data.sfm import MATCHERS, run_sfm
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.errors import IngestError, InvalidArgument
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.fit import evaluate_views, fit
from pytest_n2r.geometry import Camera, rotation_angle_deg

#: The settings ``perturb`` fits with: the phone benchmark's recipe when its results in docs/scene-field-log.md were
#: measured (4 December; ``benchmarks/phone_capture.py`` has fitted the library's defaults since 6 December).
CONFIG = FieldConfig(resolutions=(32, 96, 160), stage_fractions=(0.15, 0.4), sh_degree=0, batch_rays=4096,
                     lr_density=0.2, lr_color=0.1, tv=1e-4, seed=0)
#: A photo whose world rotation lies within this many degrees of the consensus is consistent with it.
CONSISTENT_DEG = 5.0
#: A placeholder camera for the pose sets compared (the comparison reads poses only).
CAMERA = Camera(2, 2, 1.0, 1.0, 0.5, 0.5)


def _mean_rotation(rotations: list[np.ndarray]) -> np.ndarray:
    """The rotation nearest (chordally) to the mean of ``rotations``."""
    u, _, vt = np.linalg.svd(np.sum(rotations, axis=0))
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def score_poses(estimated: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> dict:
    """Score estimated camera-to-world poses (by photo name) against the true ones (see the module docstring)."""
    names = sorted(estimated)
    world = [truth[n][:3, :3] @ estimated[n][:3, :3].T for n in names]
    agree = [[j for j in range(len(names)) if rotation_angle_deg(world[i], world[j]) < CONSISTENT_DEG]
             for i in range(len(names))]
    consistent = max(agree, key=len)
    consensus = _mean_rotation([world[j] for j in consistent])
    others = [rotation_angle_deg(consensus, world[j]) for j in range(len(names)) if j not in consistent]
    row = {"consistent": len(consistent), "others_rotation_deg": float(np.median(others)) if others else None,
           "rotation_deg": None, "centre_pct": None,
           "inconsistent": [names[j] for j in range(len(names)) if j not in consistent]}
    if len(consistent) >= 3:  # fewer cannot be aligned

        def pose_set(poses: dict[str, np.ndarray]) -> PoseSet:
            return PoseSet([SourceFrame(names[j], None, CAMERA, poses[names[j]]) for j in consistent])

        errors = compare_poses(pose_set(estimated), pose_set(truth))
        row["rotation_deg"] = [float(np.median(errors.rotation_deg)), float(errors.rotation_deg.max())]
        row["centre_pct"] = [float(np.median(errors.centre_error) * 100), float(errors.centre_error.max() * 100)]
    return row


def sfm_row(name: str, size: int, matcher: str, folder: Path) -> dict:
    """Structure from motion on ``name``'s phone capture at ``size`` px, without its poses, scored."""
    photos = write_phone_capture(name, folder, PhoneSettings(size=size), poses=False)
    row = {"scene": name, "size": size, "matcher": matcher, "photos": len(photos)}
    start = time.perf_counter()
    try:
        poses = run_sfm(folder, matcher=matcher, upright=False)  # every registered photo, to score the check
    except IngestError as error:
        return {**row, "error": str(error), "seconds": round(time.perf_counter() - start, 1)}
    truth = {p.path.name: p.c2w for p in photos}
    fx = {p.path.name: p.camera.fx for p in photos}
    focal = [f.camera.fx / fx[f.name] - 1.0 for f in poses.frames]
    scored = score_poses({f.name: f.c2w for f in poses.frames}, truth)
    upright = poses.report["upright"]
    turned = set(upright["upside_down"])
    default = "refused" if upright["doubtful"] else f"drops {len(turned)}" if turned else "keeps all"
    return {**row, "seconds": round(time.perf_counter() - start, 1), "registered": len(poses.frames),
            "models": poses.report["models"], "focal_error_pct": float(np.max(np.abs(focal)) * 100.0), **scored,
            "upside_down": len(turned), "upside_down_inconsistent": len(turned & set(scored["inconsistent"])),
            "largest_upright_deg": upright["largest_upright_deg"], "default": default}


def _turned(c2w: list[list[float]], degrees: float) -> list[list[float]]:
    """A transforms.json pose turned by ``degrees`` about its camera's own y axis (vertical in either axis
    convention)."""
    a = np.radians(degrees)
    turn = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    out = np.array(c2w, dtype=np.float64)
    out[:3, :3] = out[:3, :3] @ turn
    return out.tolist()


def perturb_rows(name: str, size: int, steps: int, degrees: list[float], folder: Path) -> dict:
    """Fit ``name``'s phone capture with some training photos' poses turned (see the module docstring)."""
    write_phone_capture(name, folder, PhoneSettings(size=size))
    transforms = json.loads((folder / "transforms.json").read_text())
    heldout = set(transforms["val_filenames"])
    frames = [f for f in transforms["frames"] if Path(f["file_path"]).name not in heldout]
    picks = np.linspace(0, len(frames) - 1, len(degrees) + 2).round().astype(int)[1:-1]
    turned = {}
    for k, angle in zip(picks, degrees):
        frames[k]["transform_matrix"] = _turned(frames[k]["transform_matrix"], angle)
        turned[Path(frames[k]["file_path"]).name] = angle
    (folder / "transforms.json").write_text(json.dumps(transforms))
    capture = ingest(folder)
    start = time.perf_counter()
    result = fit(capture, CONFIG, max_steps=steps, device="cpu")
    seconds = time.perf_counter() - start
    fitted = {r["view"].rsplit("/", 1)[-1]: r["psnr"]
              for r in evaluate_views(result.field, [v for v in capture.views if v.split != "heldout"])}
    others = [p for n, p in fitted.items() if n not in turned]
    held = [r["psnr"] for r in result.report["heldout"]]
    return {"scene": name, "size": size, "steps": steps, "fit_s": round(seconds, 1),
            "turned": {n: {"degrees": a, "psnr": fitted[n]} for n, a in turned.items()},
            "others": {"n": len(others), "median": float(np.median(others)), "lowest": float(np.min(others))},
            "heldout": [float(np.min(held)), float(np.max(held))] if held else None}


def _pair(values: list[float] | None) -> str:
    return "—" if values is None else f"{values[0]:.2f} / {values[1]:.2f}"


def run(args: argparse.Namespace) -> list[dict]:
    """Run the chosen mode and print its table; the rows."""
    with tempfile.TemporaryDirectory(prefix="n2r-capture-poses-") as tmp:
        if args.mode == "perturb":
            row = perturb_rows(args.scene, args.size, args.steps, args.degrees, Path(tmp) / "capture")
            print_perturb(row)
            return [row]
        rows = [sfm_row(name, size, args.matcher, Path(tmp) / f"{name}-{size}-{run}")
                for name in args.scenes for size in args.size for run in range(args.runs)]
    print(f"structure from motion on phone-style demo captures (no poses given), matcher {args.matcher}; "
          f"consistent: world rotation within {CONSISTENT_DEG:g}° of the consensus\n")
    print("| scene | px | registered | models | consistent | their rotation error, median / max ° "
          "| their centre error, median / max % of the camera spread | the others' rotation error, median ° "
          "| focal error, max % | upside down (of them not consistent) | the others' up, largest ° "
          "| `n2r fit` | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['scene']} | {r['size']} | 0 of {r['photos']} |" + " — |" * 9 + f" {r['seconds']} |"
                  f"\n\n{r['scene']}: {r['error']}\n")
            continue
        print(f"| {r['scene']} | {r['size']} | {r['registered']} of {r['photos']} | {r['models']} | "
              f"{r['consistent']} | {_pair(r['rotation_deg'])} | {_pair(r['centre_pct'])} | "
              + ("—" if r["others_rotation_deg"] is None else f"{r['others_rotation_deg']:.1f}")
              + f" | {r['focal_error_pct']:.1f} | {r['upside_down']} ({r['upside_down_inconsistent']}) | "
              f"{r['largest_upright_deg']:.1f} | {r['default']} | {r['seconds']} |")
    return rows


def print_perturb(r: dict) -> None:
    print(f"{r['scene']} phone capture at {r['size']} px, {r['steps']} steps ({r['fit_s']} s): PSNR dB of "
          "the field's render at each photo's given pose against the photo\n")
    print("| photo | pose turned by | PSNR dB |")
    print("|---|---|---|")
    for photo, t in r["turned"].items():
        print(f"| {photo} | {t['degrees']:g}° | {t['psnr']:.2f} |")
    print(f"| the other {r['others']['n']} fitted photos | 0° | median {r['others']['median']:.2f}, "
          f"lowest {r['others']['lowest']:.2f} |")
    if r["heldout"] is not None:
        print(f"| held-out photos (never fitted) | 0° | {r['heldout'][0]:.2f} to {r['heldout'][1]:.2f} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    modes = parser.add_subparsers(dest="mode", required=True)
    sfm = modes.add_parser("sfm", help="structure from motion on a capture without poses, scored")
    sfm.add_argument("--scenes", nargs="+", default=["wall", "object"], choices=["wall", "object"])
    sfm.add_argument("--size", type=int, nargs="+", default=[320], help="the photos' longer side, pixels")
    sfm.add_argument("--matcher", default="auto", choices=MATCHERS)
    sfm.add_argument("--runs", type=int, default=1, help="structure from motion runs a capture (it is not "
                     "deterministic on several threads)")
    turn = modes.add_parser("perturb", help="a fit with some photos' poses turned")
    turn.add_argument("--scene", default="wall", choices=["wall", "object"])
    turn.add_argument("--size", type=int, default=160)
    turn.add_argument("--steps", type=int, default=400)
    turn.add_argument("--degrees", type=float, nargs="+", default=[1.0, 3.0, 10.0])
    for sub in (sfm, turn):
        sub.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args(argv)
    try:
        rows = run(args)
    except InvalidArgument as error:  # a size or step count the library refuses: say which, without a traceback
        parser.error(str(error))
    if args.json is not None:
        atomic_write_text(args.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
