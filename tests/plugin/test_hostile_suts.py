"""SUTs that hang or are not deterministic: each example ends once, with a message that says what happened."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest
import torch

from pytest_n2r.relation.determinism import same_output, show_output

PLANE = "tests.plugin.fakescene:plane"


def test_a_hanging_sut_ends_after_one_time_out_not_after_hypothesis_retries(n2r_project):
    n2r_project.write("""
import time


def hangs(rgb):
    with open("sut_calls.log", "a") as log:  # the inner run's working directory is the project's
        log.write("call\\n")
    try:
        time.sleep(30)
    except Exception:  # a SUT that swallows every error must not swallow the time limit
        return 0.0


@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=10)
def test_hang(n2r_scene):
    return hangs
""")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-timeout", "2")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([("*the system under test on the source view (*) did not finish within 2 s "
                                  "(--n2r-timeout / ini n2r_timeout)*")])
    text = result.stdout.str()
    assert "Traceback" not in text and "FlakyFailure" not in text, text
    # one time-out of 2 s: the SUT entered once. Hypothesis retrying and shrinking the failing example entered it
    # again for every retry (27 s for a 5 s limit); counted, not timed, so a loaded machine cannot fail it
    calls = (n2r_project.pytester.path / "sut_calls.log").read_text().splitlines()
    assert len(calls) == 1, f"the time-out was retried: the SUT was entered {len(calls)} times for one example"
    assert result.duration < 20, f"the 2 s limit did not stop the 30 s hang: {result.duration:.1f} s"


@pytest.mark.parametrize(("scene", "fails"), [("slow_first_render", False), ("slow_later_renders", True)])
def test_the_time_limit_spares_a_renderers_first_render_only(n2r_project, monkeypatch, scene, fails):
    """A renderer kind's first render in a process compiles its kernels (or waits for another process's): not a
    hang, whatever the limit; a later render as slow is one."""
    from pytest_n2r.scene import first_render

    monkeypatch.setattr(first_render, "_RENDERED", set())  # the inner run is in this process: no kind rendered
    n2r_project.write("""
# eps 255: no example fails the metric; what passes or fails here is the time limit
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=2), examples=2)
def test_slow(n2r_scene):
    return lambda rgb: float(rgb.mean())
""")
    result = n2r_project.run("--n2r-scene", f"tests.plugin.fakescene:{scene}", "--n2r-timeout", "1",
                             "--n2r-cache-dir", "none")
    result.assert_outcomes(failed=int(fails), passed=int(not fails))
    if fails:
        result.stdout.fnmatch_lines(["*rendering the * view of * did not finish within 1 s*"])


def test_a_non_deterministic_sut_is_named_with_both_outputs(n2r_project):
    n2r_project.write("""
_rng = np.random.default_rng()


def noisy(rgb):
    return float(rgb.mean()) + float(_rng.normal(0.0, 30.0))


@metamorphic(AbsDifference(), eps=1, transform=transforms(yaw=4), examples=20)
def test_noisy(n2r_scene):
    return noisy
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "the system under test is not deterministic: called twice on the same" in text, text
    assert re.search(r"first:\s+-?\d", text) and re.search(r"second:\s+-?\d", text), text
    assert "seed its random generators" in text, text
    assert "FlakyFailure" not in text and "Traceback" not in text, text


ONCE = """
calls = []


def once(rgb):
    calls.append(1)
    if len(calls) == 3:  # the third call only: Hypothesis's replay of that example does not do it again
        {misbehave}
    return float(rgb.mean())


@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=2), examples=20)
def test_once(n2r_scene):
    return once
"""


def _run_once(n2r_project, misbehave: str) -> Any:
    """Run the relation whose SUT misbehaves (``misbehave``) on its first call only; it must fail, and not be
    reported as a flaky relation verdict."""
    n2r_project.write(ONCE.format(misbehave=misbehave))
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-cache-dir", "none")
    result.assert_outcomes(failed=1)
    assert "the relation failed on an example and passed when Hypothesis replayed it" not in result.stdout.str(), (
        f"an SUT misbehaving once ({misbehave}) was reported as a flaky relation verdict:\n{result.stdout.str()}")
    return result


def test_a_sut_that_raises_once_is_named_with_its_error_not_as_a_flaky_relation(n2r_project):
    result = _run_once(n2r_project, 'raise RuntimeError("intermittent crash")')
    text = result.stdout.str()
    result.stdout.fnmatch_lines([("*SUTError: the system under test raised RuntimeError: intermittent crash on an "
                                  "example and not when it was replayed: it fails intermittently*")])
    assert re.search(r"^E\s+RuntimeError: intermittent crash$", text, re.MULTILINE), (
        f"the SUT's own exception should be chained, with its traceback:\n{text}")
    assert 'raise RuntimeError("intermittent crash")' in text, f"the traceback should reach the SUT's code:\n{text}"


def test_a_sut_that_returns_none_once_is_named_with_its_output_not_as_a_flaky_relation(n2r_project):
    result = _run_once(n2r_project, "return None")
    result.stdout.fnmatch_lines([("*SUTOutputError: the system under test gave an output it cannot use on an example "
                                  "and not when it was replayed: it fails intermittently*the first time: the system "
                                  "under test returned None on the * view*")])


def test_a_deterministic_sut_returning_tensors_fails_on_its_deviation_not_as_noise(n2r_project):
    """The determinism check compared two multi-valued tensors with ``==`` (ambiguous in torch): its error ended
    the search in Hypothesis's flaky path, and a real inconsistency was reported as a non-deterministic SUT."""
    n2r_project.write("""
import torch
from pytest_n2r.metrics import l2_norm


def embed(rgb):
    return torch.tensor([float(rgb[..., 0].mean()), float(rgb[..., 1].mean()), 1.0])


@metamorphic(l2_norm("raw"), eps=1e-9, transform=transforms(yaw=(5, 15)), examples=10)
def test_embedding(n2r_scene):
    return embed
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "not deterministic" not in text and "Flaky" not in text, text
    assert "metamorphic relation violated: l2_norm(inputs='raw') deviates" in text, text


def test_a_raising_sut_shows_its_own_traceback_not_the_engines(n2r_project):
    """A SUT's error walked through the engine's frames (search, evaluate, run_sut) with their source, and
    Hypothesis's note printed every field of the view (its arrays and full-size camera) and of the pose change."""
    n2r_project.write("""
def raising(rgb):
    raise ValueError("boom inside my detector")


@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=5)
def test_raises(n2r_scene):
    return raising
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert 'raise ValueError("boom inside my detector")' in text, f"the SUT's own frame is missing:\n{text}"
    for internal in ("relation/engine.py", "def run_sut", "def search"):
        assert internal not in text, f"the engine's frames are shown ({internal}):\n{text}"
    assert re.search(r"view=SceneView\(index=\d+, name='[^']+', split='\w+'\)", text), text
    assert "c2w=array" not in text and "COMPONENTS" not in text, f"the example note is not compact:\n{text}"


@pytest.mark.parametrize(("a", "b", "same"), [
    (np.array([[1.0, np.nan]]), np.array([[1.0, np.nan]]), True),
    (np.array([[1.0, 2.0]]), np.array([[1.0, 2.5]]), False),
    (np.array([1, 2]), np.array([1, 2, 3]), False),
    (3, 3, True),
    ("cat", "dog", False),
    ([np.zeros(2), 1], [np.zeros(2), 1], True),
    (torch.tensor([0.1, 0.9]), torch.tensor([0.1, 0.9]), True),
    (torch.tensor([0.1, 0.9]), torch.tensor([0.1, 0.8]), False),
    (torch.ones(2, dtype=torch.bfloat16), torch.ones(2, dtype=torch.bfloat16), True),
    (torch.ones(2, dtype=torch.float8_e4m3fn), torch.ones(2, dtype=torch.float8_e4m3fn), True),
    (torch.tensor([1 + 2j]).conj(), torch.tensor([1 - 2j]), True),
    ({"boxes": torch.ones(2, 4), "n": 2}, {"boxes": torch.ones(2, 4), "n": 2}, True),
    ({"boxes": torch.ones(2, 4), "n": 2}, {"boxes": torch.zeros(2, 4), "n": 2}, False),
])
def test_same_output_compares_arrays_value_for_value(a, b, same):
    assert same_output(a, b) is same


def test_show_output_counts_the_values_that_differ():
    a, b = np.zeros((4, 2)), np.zeros((4, 2))
    b[1, 0] = 1.0
    assert show_output(a, b) == "array (4, 2) float64, first values [0., 0., 0., 0., 0., 0.]; 1 of 8 values differ"
