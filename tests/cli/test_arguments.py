"""Each command takes the boundary values its help promises (``--max-frames 1``, ``--max-size 64``, ``--size 8``,
views of 11 pixels, ``--heldout-every 0``) and refuses what it cannot use (``--eps nan``); a bare ``--sut-kind`` applies
to imported SUTs only; the fit's progress clock pads its seconds."""

from __future__ import annotations

import argparse

import pytest


def _poses_args(tmp_path, **kw):
    args = {"source": str(tmp_path), "compare": None, "max_size": 960, "max_frames": 120, "output": None,
            "force": False, "frames_dir": None}
    return argparse.Namespace(**{**args, **kw})


def test_poses_takes_max_frames_1_and_max_size_64(tmp_path):
    from pytest_n2r.cli.poses import check_arguments

    check_arguments(_poses_args(tmp_path, max_frames=1))
    check_arguments(_poses_args(tmp_path, max_size=64))


def test_study_refuses_eps_nan():
    from pytest_n2r.cli.study import _eps_list

    with pytest.raises(argparse.ArgumentTypeError):
        _eps_list("0.1,nan")


def test_a_bare_sut_kind_applies_to_imported_suts_only():
    from pytest_n2r.cli.study import _kinds

    assert _kinds(["orb", "m:f"], [(None, "classifier")]) == {"m:f": "classifier"}
    assert _kinds(["m:f"], [("m:f", "detector"), ("m:f", "classifier")]) == {"m:f": "classifier"}


def test_demo_export_takes_8_pixels():
    from pytest_n2r.cli.demo import _size

    assert _size("8") == 8 and _size("8x8") == (8, 8)


def test_views_of_exactly_11_pixels_may_be_fitted():
    from types import SimpleNamespace

    from pytest_n2r.cli.fit import MIN_VIEW_SIDE, check_view_sizes
    from pytest_n2r.errors import InvalidArgument

    def view(w, h):
        return SimpleNamespace(name=f"{w}x{h}", camera=SimpleNamespace(width=w, height=h))

    check_view_sizes([view(40, 30), view(MIN_VIEW_SIDE, 20)], 4.0)
    with pytest.raises(InvalidArgument, match="'10x20'"):
        check_view_sizes([view(40, 30), view(10, 20), view(64, 64)], 4.0)


def test_the_progress_clock_pads_seconds():
    from pytest_n2r.cli.fit import _clock

    assert (_clock(65), _clock(600), _clock(59.6)) == ("1:05", "10:00", "1:00")
