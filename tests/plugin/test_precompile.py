"""Which scenes the kernel helper loads: one of each family the session reaches after its first render, never
a ``module:function`` scene (the helper runs no user code)."""

from __future__ import annotations

import pytest

from pytest_n2r.plugin.precompile import (
    HELPER_KIND,
    LOG_NAME,
    apart_specs,
    compile_apart_meanwhile,
    family,
    helper_specs,
    open_log,
    run_job,
)
from pytest_n2r.plugin.scenes import SceneSpec

WALL, OBJECT = SceneSpec("wall", "demo", "demo:wall"), SceneSpec("object", "demo", "demo:object")
WALL_FIELD = SceneSpec("wall-field", "demo", "demo:wall-field")
OBJECT_FIELD = SceneSpec("object-field", "demo", "demo:object-field")
FOX, SPLATS = SceneSpec("fox", "file", "/s/fox.n2r"), SceneSpec("room", "file", "/s/room.PLY")
USER = SceneSpec("mine", "python", "mymodule:scene")


def test_families_follow_the_spec():
    assert [family(s) for s in (WALL, OBJECT, WALL_FIELD, FOX, SPLATS, USER)] == \
        ["demo", "demo", "demo-field", "file.n2r", "file.ply", None]


def test_the_helper_gets_one_scene_of_each_other_family_in_order():
    planned = [WALL, OBJECT, WALL_FIELD, OBJECT_FIELD, USER, FOX, SPLATS]
    assert helper_specs(planned, WALL) == [WALL_FIELD, FOX, SPLATS]
    assert helper_specs(planned, FOX) == [WALL, WALL_FIELD, SPLATS]
    assert helper_specs(planned, None) == [WALL, WALL_FIELD, FOX, SPLATS]


def test_nothing_for_the_helper_when_every_scene_shares_the_first_family():
    assert helper_specs([WALL, OBJECT], WALL) == []
    assert helper_specs([USER], USER) == []
    assert helper_specs([], None) == []


def test_the_helper_compiles_apart_the_scenes_of_the_first_family_when_it_can():
    planned = [WALL, WALL_FIELD, OBJECT, USER, FOX]
    assert apart_specs(planned, WALL) == [WALL, OBJECT], "the exact demo scenes' masks were not left to the helper"
    assert apart_specs(planned, WALL_FIELD) == [], "a fitted twin was loaded for nothing"
    assert apart_specs(planned, FOX) == [] and apart_specs(planned, USER) == [] and apart_specs(planned, None) == []


@pytest.mark.parametrize(("value", "starts"), [("yes", True), ("no", False)])
def test_precompile_no_leaves_the_session_without_a_helper(pytester, value, starts):
    from pytest_n2r.plugin import _build_session

    session = _build_session(pytester.parseconfig("--n2r-precompile", value))
    assert (session.on_first_render is not None) == starts, \
        f"--n2r-precompile {value}: the session {'would not' if starts else 'would'} start the kernel helper"
    assert (session.while_waiting is not None) == starts, \
        f"--n2r-precompile {value}: the session {'would not' if starts else 'would'} compile pieces while it waits"


def test_a_waiting_first_render_compiles_apart_the_planned_scenes_of_the_apart_families(monkeypatch):
    from pytest_n2r.demo.exact import GroundTruthScene
    from pytest_n2r.plugin.session import N2RSession

    compiled: list[str] = []
    monkeypatch.setattr(GroundTruthScene, "compile_apart", lambda self: compiled.append(self.name) or True)
    session = N2RSession(planned=[WALL_FIELD, WALL, OBJECT_FIELD, OBJECT])
    compile_apart_meanwhile(session, session.load(WALL_FIELD))
    assert compiled == ["wall", "object"], f"compiled apart {compiled}, not the exact demo scenes in order"


def _job(cache_dir) -> dict:
    return {"scenes": [], "apart": [], "skip": "none", "cache_dir": str(cache_dir), "device": "cpu",
            "render_scale": 1.0}


def test_a_second_helper_adds_to_the_log_instead_of_erasing_the_first_ones(tmp_path):
    with open_log(tmp_path) as first:
        first.write("first helper's line\n")
        first.flush()
        with open_log(tmp_path) as second:
            second.write("second helper's line\n")
    text = (tmp_path / "kernel-locks" / LOG_NAME).read_text()
    assert text == "first helper's line\nsecond helper's line\n", f"one helper's lines were lost: {text!r}"


def test_the_helper_holding_the_lock_starts_the_log_afresh_and_one_without_it_leaves_it(tmp_path, capsys):
    from pytest_n2r.scene.first_render import claim_kind

    with open_log(tmp_path) as log:
        log.write("the previous session's helper\n")
    path = tmp_path / "kernel-locks" / LOG_NAME
    with claim_kind(tmp_path, HELPER_KIND, wait=False) as held:
        assert held
        assert run_job(_job(tmp_path)) == []
        assert path.read_text() == "the previous session's helper\n", "a helper without the lock emptied the log"
        assert "another helper is compiling" in capsys.readouterr().out
    assert run_job(_job(tmp_path)) == []
    assert path.read_text() == "", "the helper holding the lock kept the previous session's lines"
    assert "started at" in capsys.readouterr().out


def test_the_log_is_never_written_or_emptied_through_a_link(tmp_path):
    from pytest_n2r.plugin.precompile import _restart_log

    victim = tmp_path / "notes.txt"
    victim.write_text("important notes\n")
    cache = tmp_path / "cache"
    (cache / "kernel-locks").mkdir(parents=True)
    link = cache / "kernel-locks" / LOG_NAME
    link.symlink_to(victim)
    _restart_log(cache)  # a link in place of the log: left as it is, its target untouched
    assert victim.read_text() == "important notes\n"
    with open_log(cache) as log:  # the link is replaced by the log itself
        log.write("helper line\n")
    assert victim.read_text() == "important notes\n"
    assert not link.is_symlink() and link.read_text() == "helper line\n"
    _restart_log(cache)
    assert link.read_text() == "" and victim.read_text() == "important notes\n"


def test_close_ends_a_running_kernel_helper():
    """The session's close ends a helper that still runs (else it outlives pytest)."""
    import subprocess
    import sys

    from pytest_n2r.plugin.session import N2RSession

    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        session = N2RSession()
        session.helper = proc
        session.close()
        assert proc.poll() is not None, "the helper still runs after close()"
        assert session.helper is None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_waiting_first_render_leaves_out_the_scenes_this_process_released(monkeypatch):
    """A released scene loaded again for its pieces would be kept to the end of the session, for nothing."""
    from pytest_n2r.demo.exact import GroundTruthScene
    from pytest_n2r.plugin.session import N2RSession

    compiled: list[str] = []
    monkeypatch.setattr(GroundTruthScene, "compile_apart", lambda self: compiled.append(self.name) or True)
    session = N2RSession(planned=[WALL, WALL_FIELD, OBJECT], released={WALL.source})
    compile_apart_meanwhile(session, session.load(WALL_FIELD))
    assert compiled == ["object"], f"compiled apart {compiled}: the released wall was loaded again"
    assert WALL.source not in session._loaded, "the released scene is held again"
