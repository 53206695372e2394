"""SIGTERM (``timeout``, ``docker stop``, a cancelled CI job) takes every command's Ctrl-C path: its clean-up runs,
the fit's first one saves the field trained so far, and the exit status is 143 (130 for Ctrl-C)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import pytest_n2r.cli.render
from pytest_n2r.cli import _interrupt
from pytest_n2r.cli.main import main


class NotHandled(Exception):
    pass


@pytest.fixture
def sigterm_not_handled():
    """A SIGTERM handler that says the command left SIGTERM to the process's own (its default kills the process, and
    with it pytest: this one raises instead)."""

    def unhandled(_signum: int, _frame: object) -> None:
        raise NotHandled("SIGTERM reached the handler from before the command: the command does not handle it")

    previous = signal.signal(signal.SIGTERM, unhandled)
    yield unhandled
    signal.signal(signal.SIGTERM, previous)


def test_sigterm_runs_the_commands_cleanup_and_exits_143(monkeypatch, capsys, sigterm_not_handled):
    """`n2r poses` killed by `timeout` left its $TMPDIR/n2r-sfm-* folder: SIGTERM skipped the clean-up Ctrl-C runs."""
    left: list[Path] = []

    def run(_args: object) -> int:
        with tempfile.TemporaryDirectory(prefix="n2r-sfm-") as tmp:
            left.append(Path(tmp))
            os.kill(os.getpid(), signal.SIGTERM)
        return 0

    monkeypatch.setattr(pytest_n2r.cli.render, "run", run)
    assert main(["render", "demo:wall", "-o", "x.png"]) == 143, "SIGTERM's exit status is 128 + 15"
    assert left and not left[0].exists(), f"the command's temporary folder {left} was left behind"
    assert "n2r render: interrupted (SIGTERM)" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is sigterm_not_handled, "the previous SIGTERM handler was not restored"


def test_ctrl_c_still_exits_130_after_a_command_ended_by_sigterm(monkeypatch, capsys, sigterm_not_handled):
    def run(_args: object) -> int:
        raise KeyboardInterrupt

    monkeypatch.setattr(pytest_n2r.cli.render, "run", run)
    assert main(["render", "demo:wall", "-o", "x.png"]) == 130
    assert capsys.readouterr().err.strip() == "n2r render: interrupted"


def test_the_fits_first_sigterm_is_remembered_like_its_first_ctrl_c(sigterm_not_handled):
    """`n2r fit` killed during a checkpoint write left `.c2.n2r.XXXX.tmp` and did not save the field trained so far:
    the first SIGTERM must only be remembered (the step, the write, finish), as the first Ctrl-C is."""
    with _interrupt.first_ctrl_c_deferred() as pressed:
        os.kill(os.getpid(), signal.SIGTERM)
        assert pressed(), "the fit's loop was not told of the SIGTERM"
        assert (_interrupt.interrupt_name(), _interrupt.exit_status()) == ("SIGTERM", 143)
        with pytest.raises(KeyboardInterrupt):  # a second one quits at once, as a second Ctrl-C does
            os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) is sigterm_not_handled


POSES_KILLED = """
import importlib, os, signal, sys
from pytest_n2r.cli.main import main

ingest = importlib.import_module("pytest_n2r.data.ingest")  # the module (pytest_n2r.data.ingest is also a function)

def load_poses(*args, **kw):
    import pycolmap  # noqa: F401 - what structure from motion imports; its logging takes SIGTERM over
    os.kill(os.getpid(), signal.SIGTERM)
    raise AssertionError("SIGTERM was not raised")

ingest.load_poses = load_poses
sys.exit(main(["poses", sys.argv[1]]))
"""


def test_sigterm_during_structure_from_motion_is_handled_as_ctrl_c(tmp_path):
    """pycolmap's logging installs its own SIGTERM handler on import (a stack trace, then death by the signal): `n2r
    poses` under `timeout` left $TMPDIR/n2r-sfm-*. A real process, since that handler kills it."""
    pytest.importorskip("pycolmap")
    done = subprocess.run([sys.executable, "-c", POSES_KILLED, str(tmp_path)], check=False, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 143, f"rc {done.returncode}, expected 143 (SIGTERM handled):\n{done.stderr[-2000:]}"
    assert done.stderr.strip().endswith("n2r poses: interrupted (SIGTERM)"), done.stderr[-2000:]
