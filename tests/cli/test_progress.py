"""The progress bar of `n2r fit` and `n2r demo build`: on a terminal only, and never a failure."""

from __future__ import annotations

from pytest_n2r.cli.fit import _Progress

INFO = {"step": 3, "elapsed_s": 1.0, "eta_s": 2.0, "resolution": 48, "loss": 0.1, "psnr": 20.0}


def test_no_bar_is_drawn_into_a_log(capsys):
    """A 10-minute fit wrote ~1,200 carriage-return updates into a non-TTY log (pytest's stderr is not a TTY)."""
    progress = _Progress(10, None)
    progress(INFO)
    progress.close()
    assert progress.bar.disable, "the bar is drawn where stderr is not a terminal"
    assert "\r" not in capsys.readouterr().err


def test_a_closed_stderr_does_not_fail_the_fit(monkeypatch):
    """`n2r fit ... 2>&-` failed silently with rc 1: the bar wrote to sys.stderr, which Python sets to None."""
    monkeypatch.setattr("sys.stderr", None)
    progress = _Progress(None, 60.0)
    progress(INFO)
    progress.close()
