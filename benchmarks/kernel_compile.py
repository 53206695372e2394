"""What a demo scene's first render compiles, and what each compilation costs (CPU seconds).

Run: ``python benchmarks/kernel_compile.py`` (``--scene wall|object``, default wall, the exact ray caster, or
``wall-field|object-field``, a fitted twin: the scene field's renderer; ``--size PX``, the render's longer side,
default 32: the field's adaptive sampling compiles only from 480 px; ``--fit``: instead of a render, the fit
tests' short fit (``tests/fit/conftest.py``) of the exact scene's 48×27 capture, which runs every training kernel
and the field's renderer;
``--masks-only``: compile the exact scene's blend masks alone, :meth:`~pytest_n2r.scene.base.Scene.compile_apart`,
seconds long; ``--rounds R``, default 1; ``--collector on|frozen|off``, default on: Python's cyclic garbage collector
during the render as in a plain process, on with the heap frozen after the imports as in a test session, or off as a
session's first render of a kind runs since 3 December). Each round runs in a child process with an empty numba
cache (its own temporary folder) and one numba thread, renders one view of the scene and reports, from numba's
``numba:compile`` events, every function compiled with its CPU time inclusive and exclusive of the functions it
compiled in turn, and the collector's CPU time; for the ray caster's kernel the CPU time of numba's compiler passes
(``pipeline_times``: inlining, type inference, lowering...) and of LLVM (the ``llvm_lock`` timer). A last child
renders again with the cache the first left: what a second process pays. Compilation runs on one thread: the child's
CPU time is its duration on an idle core, whatever the machine's load.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Run in a child process: argv = scene name, "masks" or "render". Prints one JSON object.
CHILD = r"""
import gc, json, sys, time
from collections import defaultdict
from numba.core import event

collector = {"s": 0.0, "full": 0, "started": 0.0}


def timed(phase, info):
    if phase == "start":
        collector["started"] = time.process_time()
    else:
        collector["s"] += time.process_time() - collector["started"]
        collector["full"] += info["generation"] == 2

stack, inclusive, exclusive, count = [], defaultdict(float), defaultdict(float), defaultdict(int)


class Compiles(event.Listener):
    def on_start(self, ev):
        stack.append([ev.data["dispatcher"].py_func.__qualname__, time.process_time(), 0.0])

    def on_end(self, ev):
        name, start, children = stack.pop()
        spent = time.process_time() - start
        inclusive[name] += spent
        exclusive[name] += spent - children
        count[name] += 1
        if stack:
            stack[-1][2] += spent


event.register("numba:compile", Compiles())
from pytest_n2r.demo import load_demo, raycast

scene = load_demo(sys.argv[1], device="cpu")
view = scene.views[0]
if sys.argv[2] == "fit":  # its capture is rendered by the exact scene: compiled here, before the count starts
    from pytest_n2r.demo.rendered_capture import capture_scene
    from pytest_n2r.fit import fit
    from tests.fit.conftest import SHORT_CONFIG, SHORT_STEPS

    capture = capture_scene(scene, size=(48, 27))
    for table in (inclusive, exclusive, count):
        table.clear()
if sys.argv[3] == "frozen":
    gc.collect()
    gc.freeze()
elif sys.argv[3] == "off":
    gc.disable()
gc.callbacks.append(timed)
start = time.process_time()
if sys.argv[2] == "masks":
    scene.compile_apart()
elif sys.argv[2] == "fit":  # the fit tests' short fit (tests/fit/conftest.py): every training kernel runs
    fit(capture, SHORT_CONFIG, max_steps=SHORT_STEPS, device="cpu")
else:
    camera = view.camera.scaled(int(sys.argv[4]) / max(view.camera.width, view.camera.height))
    scene.render(view.c2w, camera, ("rgb", "depth", "opacity"))
total = time.process_time() - start
gc.enable()
gc.callbacks.remove(timed)
passes, llvm = {}, None
for compiled in raycast._render_kernel.overloads.values():
    if compiled.metadata is None:  # loaded from numba's cache: nothing was compiled
        continue
    llvm = compiled.metadata["timers"]["llvm_lock"]
    for pipeline in compiled.metadata["pipeline_times"].values():
        for name, t in pipeline.items():
            passes[name.split("_", 1)[1]] = t.init + t.run + t.finalize
print(json.dumps({"total": total, "inclusive": inclusive, "exclusive": exclusive, "count": count, "passes": passes,
                  "llvm": llvm, "collector": collector["s"], "full": collector["full"]}))
"""


def run_child(scene: str, what: str, cache: Path, collector: str = "on", size: int = 32) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", CHILD, scene, what, collector, str(size)], env=env,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"the child failed:\n{done.stderr}")
    return json.loads(done.stdout.splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="wall", choices=["wall", "object", "wall-field", "object-field"],
                        help="a demo scene: exact, or its fitted twin (the scene field's renderer)")
    parser.add_argument("--size", type=int, default=32,
                        help="longer side of the render (pixels); the field's adaptive sampling compiles from 480")
    parser.add_argument("--masks-only", action="store_true", help="compile the scene's blend masks alone")
    parser.add_argument("--fit", action="store_true",
                        help="instead of a render, the fit tests' short fit of the scene's 48x27 capture (the training "
                             "kernels)")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--collector", default="on", choices=["on", "frozen", "off"],
                        help="the cyclic garbage collector during the render: on, on with the heap frozen, off")
    args = parser.parse_args(argv)
    if (args.masks_only or args.fit) and args.scene.endswith("-field"):
        parser.error(f"--masks-only, --fit: {args.scene} is a fitted twin; expected --scene wall or object")
    if args.size < 1:
        parser.error(f"--size {args.size}: expected a positive number of pixels")
    what = "masks" if args.masks_only else "fit" if args.fit else "render"
    with tempfile.TemporaryDirectory(prefix="n2r-kernel-compile-") as tmp:
        runs = [run_child(args.scene, what, Path(tmp) / f"numba-{r}", args.collector, args.size)
                for r in range(args.rounds)]
        again = run_child(args.scene, what, Path(tmp) / f"numba-{args.rounds - 1}", args.collector, args.size)
    median = statistics.median
    done = {"masks": "blend masks alone", "fit": "the fit tests' short fit of its 48x27 capture",
            "render": f"first render ({args.size} px)"}[what]
    print(f"demo:{args.scene}, {done}, empty numba cache, one thread, collector {args.collector}, {args.rounds} "
          f"round(s), medians; load average at the end {os.getloadavg()[0]:.1f}\n")
    print(f"CPU seconds: {median(r['total'] for r in runs):.2f} with an empty cache (in the collector "
          f"{median(r['collector'] for r in runs):.2f}, {median(r['full'] for r in runs)} full collections), "
          f"{again['total']:.2f} with the cache the first process left\n")
    print("| function compiled | times | CPU s, inclusive | CPU s, exclusive |")
    print("|---|---|---|---|")
    names = sorted(runs[0]["exclusive"], key=lambda n: -runs[0]["exclusive"][n])
    for name in names[:15]:
        print(f"| {name} | {runs[0]['count'][name]} | {median(r['inclusive'].get(name, 0.0) for r in runs):.2f} | "
              f"{median(r['exclusive'].get(name, 0.0) for r in runs):.2f} |")
    if runs[0]["passes"]:
        print("\nThe ray caster's kernel (`_render_kernel`): numba's compiler passes (seconds of wall time on one "
              f"thread), and LLVM {median(r['llvm'] for r in runs):.2f} s\n")
        print("| pass | s |")
        print("|---|---|")
        passes = runs[0]["passes"]
        for name in sorted(passes, key=lambda n: -passes[n])[:8]:
            print(f"| {name} | {median(r['passes'].get(name, 0.0) for r in runs):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
