"""The README's main job (``python -m pytest example_project``) at several git revisions side by side, in one run:
one cold run each, then warm runs taking turns (ratios survive a shared machine; a warm run's spread is ~2 s).

Run: ``python benchmarks/main_job_compare.py a5c3b54 main`` (any revisions; the first is the base of the ratios;
``--warm N``, default 3; ``--no-bytecode`` sets ``PYTHONDONTWRITEBYTECODE=1`` and no prefix, so every run reads the
installed packages' own bytecode and compiles the export's modules; trailing ``-- ARGS`` go to pytest,
e.g. ``-- -k orb``). Each revision is exported whole with ``git archive`` into a temporary folder, its example
project copied to ``ex`` there, and run as a user runs it: ``python -m pytest ex -p no:cacheprovider -q -rA`` from
the export's root with the export first on ``PYTHONPATH``, its own empty render cache (``N2R_CACHE_DIR``), numba
cache (``NUMBA_CACHE_DIR``) and bytecode prefix (``PYTHONPYCACHEPREFIX``: the cold run compiles every module it
imports, torch's included, into it, so a cold run here is longer than a user's first run). A warm run is the same
command again with those caches filled. Wall times are the child process's, start to exit; CPU seconds are the
user and system time of the whole process tree the run waited for (pytest, its kernel helper, xdist's workers:
``getrusage(RUSAGE_CHILDREN)`` around the run), which a cold run that keeps both cores busy is bound by, and which
does not count the time a shared host runs other machines' work; the split is the plugin's summary line (render /
SUT / metric). The verdict lines (``-rA``'s PASSED / FAILED / SKIPPED) of every run
are compared with the base's cold run: a speed change must not change a verdict.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from splat_compare import export

#: The session's split in the plugin's time line (each verdict line has its own relation's split, not this one).
_SPLIT = re.compile(r"relations [\d.]+ s = render (?P<render>[\d.]+) s / SUT (?P<sut>[\d.]+) s / metric "
                    r"(?P<metric>[\d.]+) s / validity (?P<validity>[\d.]+) s / field floors (?P<floors>[\d.]+) s")
_VERDICT = re.compile(r"^(PASSED|FAILED|SKIPPED|ERROR) ")


def export_tree(revision: str, into: Path) -> tuple[str, Path]:
    """The whole tree of ``revision`` (``git archive``) under ``into / <commit>``, its example project copied to
    ``ex`` beside it; the short commit and the folder."""
    folder = export(revision, into, paths=())
    shutil.copytree(folder / "example_project", folder / "ex")
    return folder.name[:7], folder


def _environment(folder: Path, no_bytecode: bool) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(folder), str(folder / "example_project")]),
               N2R_CACHE_DIR=str(folder / ".n2r"), NUMBA_CACHE_DIR=str(folder / ".numba"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.pop("PYTHONPYCACHEPREFIX", None)
    if no_bytecode:  # the installed packages' own __pycache__ is read; an empty prefix would compile torch every run
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    else:
        env["PYTHONPYCACHEPREFIX"] = str(folder / ".pyc")
    return env


def check_export_imported(folder: Path, env: dict[str, str]) -> None:
    """Stop unless ``import pytest_n2r`` in the runs' environment finds the export (not an installed copy)."""
    found = subprocess.run([sys.executable, "-c", "import pytest_n2r; print(pytest_n2r.__file__)"], cwd=folder,
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    if not Path(found).resolve().is_relative_to(folder.resolve()):
        raise SystemExit(f"the main job of {folder.name[:10]} would import {found}, not the export")


def run_once(folder: Path, env: dict[str, str], pytest_args: list[str]) -> dict:
    """One run of the main job in ``folder``: wall seconds, CPU seconds of its process tree, the plugin's split,
    pytest's last line, the verdicts."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "pytest", "ex", "-p", "no:cacheprovider", "-q", "-rA",
                             *pytest_args], cwd=folder, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = result.stdout.splitlines()
    if result.returncode not in (0, 1) or not lines:
        raise SystemExit(f"the main job in {folder.name[:10]} ended with {result.returncode}:\n"
                         f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    split = next((m.groupdict() for m in map(_SPLIT.search, lines) if m), {})
    verdicts = sorted(line.split("; time ")[0] for line in lines if _VERDICT.match(line))  # times vary
    return {"wall": wall, "cpu": cpu, "split": {k: float(v) for k, v in split.items()}, "last": lines[-1].strip("= "),
            "verdicts": verdicts}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    pytest_args = argv[argv.index("--") + 1:] if "--" in argv else []
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revisions", nargs="+", help="git revisions; the first is the base of the ratios")
    parser.add_argument("--warm", type=int, default=3, help="warm runs of each revision, taking turns")
    parser.add_argument("--no-bytecode", action="store_true", help="PYTHONDONTWRITEBYTECODE=1 in every run")
    args = parser.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    if args.warm < 1:
        parser.error(f"--warm must be at least 1, got {args.warm}")
    with tempfile.TemporaryDirectory(prefix="n2r-main-job-") as tmp:
        trees = [export_tree(revision, Path(tmp) / str(i)) for i, revision in enumerate(args.revisions)]
        envs = [_environment(folder, args.no_bytecode) for _, folder in trees]
        for (_, folder), env in zip(trees, envs, strict=True):
            check_export_imported(folder, env)
        runs: list[dict[str, list[dict]]] = [{"cold": [], "warm": []} for _ in trees]
        for i, ((_, folder), env) in enumerate(zip(trees, envs, strict=True)):
            runs[i]["cold"].append(run_once(folder, env, pytest_args))
        for _ in range(args.warm):
            for i, ((_, folder), env) in enumerate(zip(trees, envs, strict=True)):
                runs[i]["warm"].append(run_once(folder, env, pytest_args))
    base_verdicts = runs[0]["cold"][0]["verdicts"]
    print(f"main job, cold once then {args.warm} warm runs each, taking turns; bytecode "
          f"{'not written' if args.no_bytecode else 'kept'}; pytest args {' '.join(pytest_args) or '(none)'}\n")
    print("| revision | cold wall s | cold CPU s | cold field floors s | warm wall s | warm median s | ratio to base | "
          "warm CPU s (median) | warm SUT s (median) | warm metric s (median) | verdicts as the base's | "
          "pytest's last line (cold) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    base_median = statistics.median(r["wall"] for r in runs[0]["warm"])
    for (name, _), revision, measured in zip(trees, args.revisions, runs, strict=True):
        warm = [r["wall"] for r in measured["warm"]]
        median = statistics.median(warm)

        def split(key: str, measured: dict = measured, kind: str = "warm") -> str:
            values = [r["split"][key] for r in measured[kind] if key in r["split"]]
            return f"{statistics.median(values):.2f}" if values else "—"

        same = all(r["verdicts"] == base_verdicts for r in measured["cold"] + measured["warm"])
        warm_cpu = statistics.median(r["cpu"] for r in measured["warm"])
        print(f"| {revision} ({name}) | {measured['cold'][0]['wall']:.2f} | {measured['cold'][0]['cpu']:.1f} | "
              f"{split('floors', kind='cold')} | {' / '.join(f'{w:.2f}' for w in warm)} | "
              f"{median:.2f} | {median / base_median:.2f} | {warm_cpu:.1f} | {split('sut')} | {split('metric')} | "
              f"{'yes' if same else 'NO'} ({len(base_verdicts)} lines) | {measured['cold'][0]['last']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
