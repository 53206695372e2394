"""Splat render speed of several git revisions side by side, in one run (ratios survive a shared machine).

Run: ``python benchmarks/splat_compare.py main HEAD`` (any revisions; the first is the base of the ratios;
``--gaussians N``, default 300 000; ``--size WxH``, repeatable, default 480x270; ``--rounds R``, default 3;
``--smoke`` for a seconds-long run on tiny input). Each revision's ``pytest_n2r`` is exported with ``git
archive`` into a temporary folder; the same Gaussians (sampled once, by this checkout, on the exact
``object`` demo scene, as benchmarks/splat_speed.py does) and the same held-out views are rendered by each
revision in its own process, the revisions taking turns ``R`` times, so a change in the machine's load hits
every revision alike. Per process, frames/s is the median over views of 1 / (best of 3 renders after a
warm-up) on all numba threads; CPU ms per frame is the median over views of the least thread CPU time of a
render in a process with ``NUMBA_NUM_THREADS=1``. The table gives, per revision, the median over rounds, the
ratio to the first revision, and whether its outputs (RGB, depth, opacity of every view) have the same bits.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Run in a child process whose PYTHONPATH holds one revision's package: argv = data file, size, repeats.
CHILD = r"""
import hashlib, json, statistics, sys, time
import numpy as np
from pytest_n2r.geometry import Camera
from pytest_n2r.render.splat_render import SplatRenderer, SplatSettings
from pytest_n2r.splats import Gaussians
data = np.load(sys.argv[1])
w, h = (int(v) for v in sys.argv[2].split("x"))
repeats = int(sys.argv[3])
g = Gaussians(**{k: data[k] for k in ("means", "quats", "log_scales", "opacity_logits", "sh")})
renderer = SplatRenderer(g, SplatSettings(background=tuple(data["background"].tolist())))
digest, rates, cpu = hashlib.sha256(), [], []
for c2w, (vw, vh, fx, fy, cx, cy) in zip(data["c2w"], data["cameras"]):
    camera = Camera(int(vw), int(vh), fx, fy, cx, cy).resized(w, h)
    out = renderer.render(c2w, camera)
    for name in ("rgb", "depth", "opacity"):
        digest.update(out[name].tobytes())
    wall, thread = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.thread_time()
        renderer.render(c2w, camera)
        wall.append(time.perf_counter() - t0)
        thread.append(time.thread_time() - c0)
    rates.append(1.0 / min(wall))
    cpu.append(min(thread))
import pytest_n2r
print(json.dumps({"fps": statistics.median(rates), "cpu_ms": 1e3 * statistics.median(cpu),
                  "digest": digest.hexdigest(), "package": pytest_n2r.__file__}))
"""


def export(revision: str, into: Path, paths: tuple[str, ...] = ("pytest_n2r",)) -> Path:
    """``paths`` of ``revision`` (``git archive``; ``()``: the whole tree) under ``into / <commit>``; the folder to
    put on the path."""
    commit = subprocess.run(["git", "rev-parse", "--verify", f"{revision}^{{commit}}"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout.strip()
    folder = into / commit
    if not folder.exists():
        archive = subprocess.run(["git", "archive", commit, *paths], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        with tarfile.open(fileobj=BytesIO(archive)) as tar:
            tar.extractall(folder, filter="data")
    return folder


def measure(folder: Path, data: Path, size: str, repeats: int, threads: int | None) -> dict:
    env = {} if threads is None else {"NUMBA_NUM_THREADS": str(threads)}
    return run_in_export(folder, CHILD, [str(data), size, str(repeats)], env)


def run_in_export(folder: Path, child: str, args: list[str], env: dict[str, str]) -> dict:
    """Run ``child`` (Python source that prints a JSON object with the ``package`` it imported last) with
    ``args`` on the export ``folder`` of one revision (and ``env`` added); its JSON object."""
    env = dict(os.environ, PYTHONPATH=str(folder), **env)
    # run in the export: `python -c` puts the working directory first on sys.path, before PYTHONPATH
    result = subprocess.run([sys.executable, "-c", child, *args], env=env, cwd=folder, capture_output=True,
                            text=True, check=False)
    if result.returncode != 0:
        raise SystemExit(f"the render at {folder.name[:10]} failed:\n{result.stderr}")
    measured = json.loads(result.stdout.splitlines()[-1])
    if not Path(measured["package"]).resolve().is_relative_to(folder.resolve()):
        raise SystemExit(f"the render of {folder.name[:10]} imported {measured['package']}, not the export")
    return measured


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revisions", nargs="+", help="git revisions; the first is the base of the ratios")
    parser.add_argument("--gaussians", type=int, default=300_000)
    parser.add_argument("--size", action="append", help="WxH (repeatable; default 480x270)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="tiny input, to check that the script runs")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from pytest_n2r.demo import ground_truth
    from pytest_n2r.demo.splats import sample_splats

    exact = ground_truth("object")
    views = [v for v in exact.views if v.split == "heldout"]
    sizes, count, rounds, repeats = args.size or ["480x270"], args.gaussians, args.rounds, 3
    if args.smoke:
        views, sizes, count, rounds, repeats = views[:1], ["64x36"], 2_000, 1, 1
    g = sample_splats(exact, count)
    with tempfile.TemporaryDirectory(prefix="n2r-splat-compare-") as tmp:
        data = Path(tmp) / "scene.npz"
        np.savez(data, means=g.means, quats=g.quats, log_scales=g.log_scales, opacity_logits=g.opacity_logits,
                 sh=g.sh, background=np.asarray(exact.background, dtype=np.float64),
                 c2w=np.stack([v.c2w for v in views]),
                 cameras=np.array([[v.camera.width, v.camera.height, v.camera.fx, v.camera.fy, v.camera.cx,
                                    v.camera.cy] for v in views]))
        folders = {rev: export(rev, Path(tmp)) for rev in args.revisions}
        print(f"{len(g)} Gaussians on demo:object, {len(views)} held-out views, {rounds} rounds, "
              f"numba threads: {os.cpu_count()} (all) and 1\n")
        for size in sizes:
            runs = {rev: [] for rev in args.revisions}
            for _ in range(rounds):
                for rev, folder in folders.items():
                    many = measure(folder, data, size, repeats, None)
                    one = measure(folder, data, size, repeats, 1)
                    runs[rev].append((many["fps"], one["cpu_ms"], many["digest"], one["digest"]))
            print(f"| {size} | revision | frames/s, all threads | ratio | CPU ms per frame, 1 thread | ratio | "
                  "same bits as the first |")
            print("|---|---|---|---|---|---|---|")
            base = None
            for rev, folder in folders.items():
                fps = statistics.median(r[0] for r in runs[rev])
                cpu = statistics.median(r[1] for r in runs[rev])
                digests = {d for r in runs[rev] for d in r[2:]}
                base = base or (fps, cpu, digests)
                same = "yes" if digests == base[2] and len(digests) == 1 else "no"
                print(f"| {size} | {rev} ({folder.name[:10]}) | {fps:.1f} | {fps / base[0]:.2f} | {cpu:.0f} | "
                      f"{cpu / base[1]:.2f} | {same} |")
            print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
