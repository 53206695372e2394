"""A cold main job's time line, process by process: who compiles what when, who waits for whom, when tests run.

Run: ``python benchmarks/cold_timeline.py main`` (any revision; trailing ``-- ARGS`` go to pytest, e.g. ``-- -n 2``).
The revision is exported and run as ``main_job_compare.py`` runs its cold run (an export with its own empty render,
numba and bytecode caches; ``python -m pytest ex -p no:cacheprovider -q``), with a probe in every Python process of
the run: a ``sitecustomize`` module first on ``PYTHONPATH`` (so the kernel helper and the pytest-xdist workers load it
too) records numba's ``numba:compile`` events and the process's CPU time, and a pytest plugin (``PYTEST_PLUGINS``)
each test's start and end and each wait for a kernel lock (:mod:`pytest_n2r.scene.first_render`). Printed: one table
row per process (seconds from the run's start), then every compile of over 0.3 s and every wait of over 0.2 s. The
probe replaces any ``sitecustomize`` of the environment for the run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from main_job_compare import _environment, check_export_imported, export_tree

#: Loaded by every Python process of the run: its life, CPU time and numba's compiles, one JSON line an event.
SITECUSTOMIZE = r'''
import json, os, sys, time
_f = open(os.path.join(os.environ["N2R_TIMELINE_DIR"], f"{os.getpid()}.jsonl"), "a", buffering=1)


def emit(kind, **fields):
    t = os.times()
    _f.write(json.dumps(dict(fields, k=kind, t=time.time(), user=t.user, sys=t.system)) + "\n")


emit("start", argv=sys.argv[:3])
sys.modules["_n2r_timeline"] = type(sys)("_n2r_timeline")
sys.modules["_n2r_timeline"].emit = emit


class _NumbaHook:  # registers the listener at the first import after numba's dispatcher is loaded
    done = False

    def find_spec(self, name, path=None, target=None):
        if not _NumbaHook.done and "numba.core.dispatcher" in sys.modules:
            _NumbaHook.done = True
            from numba.core import event

            class Compiles(event.Listener):
                def on_start(self, ev):
                    emit("compile", fn=ev.data["dispatcher"].py_func.__qualname__)

                def on_end(self, ev):
                    emit("compiled", fn=ev.data["dispatcher"].py_func.__qualname__)

            event.register("numba:compile", Compiles())
        return None


sys.meta_path.insert(0, _NumbaHook())
import atexit
atexit.register(lambda: emit("exit"))
'''

#: The pytest side: tests and kernel-lock waits.
PLUGIN = r'''
import time
from _n2r_timeline import emit


def pytest_configure(config):
    emit("configure", worker=getattr(config, "workerinput", {}).get("workerid"))
    from pytest_n2r.scene import first_render

    acquire = first_render._acquire

    def timed(fd, wait_s, *meanwhile):  # any revision's signature (a meanwhile callback since 3 December)
        start = time.time()
        held = acquire(fd, wait_s, *meanwhile)
        emit("waited", s=time.time() - start)
        return held

    first_render._acquire = timed


def pytest_runtest_logstart(nodeid, location):
    emit("test", id=nodeid)


def pytest_runtest_logfinish(nodeid, location):
    emit("tested", id=nodeid)
'''


def read_events(folder: Path) -> dict[int, list[dict]]:
    """Each process's events (by pid), in order."""
    return {int(p.stem): [json.loads(line) for line in p.read_text().splitlines() if line]
            for p in sorted(folder.glob("*.jsonl"))}


def role(events: list[dict]) -> str:
    """``pytest`` (the session, or the xdist controller), ``gwN`` (a worker) or ``helper`` (the kernel helper)."""
    configured = next((e for e in events if e["k"] == "configure"), None)
    if configured is None:
        return "helper"
    return configured["worker"] or "pytest"


def spans(events: list[dict], start: str, end: str, key: str) -> list[tuple[float, float, str]]:
    """Outermost (start, end, name) spans of paired events (nested compiles are inside their caller's)."""
    out, stack = [], []
    for e in events:
        if e["k"] == start:
            stack.append(e)
        elif e["k"] == end and stack:
            began = stack.pop()
            if not stack:
                out.append((began["t"], e["t"], began[key]))
    return out


def report(events: dict[int, list[dict]]) -> list[str]:
    """The printed time line (markdown)."""
    t0 = min(ev[0]["t"] for ev in events.values())
    lines = ["| process | pid | start s | end s | CPU user / sys s | tests | first test s | last test ends s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    notes = []
    workers = any(role(ev).startswith("gw") for ev in events.values())
    for pid, ev in sorted(events.items(), key=lambda kv: kv[1][0]["t"]):
        name = role(ev)
        # an xdist controller hears of its workers' tests, interleaved: their own rows say when they ran
        tests = [] if workers and name == "pytest" else spans(ev, "test", "tested", "id")
        first = f"{tests[0][0] - t0:.1f}" if tests else "—"
        last = f"{tests[-1][1] - t0:.1f}" if tests else "—"
        lines.append(f"| {name} | {pid} | {ev[0]['t'] - t0:.1f} | {ev[-1]['t'] - t0:.1f} | "
                     f"{ev[-1]['user']:.1f} / {ev[-1]['sys']:.1f} | {len(tests)} | {first} | {last} |")
        for a, b, fn in spans(ev, "compile", "compiled", "fn"):
            if b - a > 0.3:
                notes.append(f"- {name} compiles `{fn}` {a - t0:.1f} → {b - t0:.1f} s ({b - a:.1f} s)")
        for e in ev:
            if e["k"] == "waited" and e["s"] > 0.2:
                notes.append(f"- {name} waits {e['s']:.1f} s for a kernel lock, until {e['t'] - t0:.1f} s")
        slow = sorted(tests, key=lambda s: s[0] - s[1])[:3]
        for a, b, nodeid in sorted(slow):
            notes.append(f"- {name} runs `{nodeid.split('::')[-1]}` {a - t0:.1f} → {b - t0:.1f} s ({b - a:.1f} s)")
    return lines + [""] + notes


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    pytest_args = argv[argv.index("--") + 1:] if "--" in argv else []
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revision", help="git revision to export and run cold")
    args = parser.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    with tempfile.TemporaryDirectory(prefix="n2r-cold-timeline-") as tmp:
        name, folder = export_tree(args.revision, Path(tmp) / "tree")
        probe, events = Path(tmp) / "probe", Path(tmp) / "events"
        probe.mkdir()
        events.mkdir()
        (probe / "sitecustomize.py").write_text(SITECUSTOMIZE)
        (probe / "n2r_timeline_probe.py").write_text(PLUGIN)
        env = _environment(folder, no_bytecode=False)
        check_export_imported(folder, env)
        env.update(PYTHONPATH=f"{probe}:{env['PYTHONPATH']}", N2R_TIMELINE_DIR=str(events),
                   PYTEST_PLUGINS="n2r_timeline_probe", PYTEST_DEBUG_TEMPROOT=str(Path(tmp) / "pytest-tmp"))
        (Path(tmp) / "pytest-tmp").mkdir()
        start = time.perf_counter()
        result = subprocess.run([sys.executable, "-m", "pytest", "ex", "-p", "no:cacheprovider", "-q", *pytest_args],
                                cwd=folder, env=env, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
        if result.returncode not in (0, 1):
            raise SystemExit(f"the main job ended with {result.returncode}:\n{result.stdout[-3000:]}\n"
                             f"{result.stderr[-3000:]}")
        last = result.stdout.strip().splitlines()[-1].strip("= ")
        print(f"cold main job at {args.revision} ({name}), pytest args {' '.join(pytest_args) or '(none)'}: "
              f"{wall:.2f} s wall; {last}\n")
        print("\n".join(report(read_events(events))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
