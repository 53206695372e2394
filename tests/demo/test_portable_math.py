"""The demo scenes' portable arithmetic: correctly rounded, and the same scene bits whatever BLAS kernel runs."""

import math
import os
import platform
import subprocess
import sys
from fractions import Fraction

import mpmath
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from pytest_n2r.demo import portable_math as pm
from pytest_n2r.errors import InvalidArgument

ARGUMENTS = st.floats(-pm.MAX_ARGUMENT, pm.MAX_ARGUMENT, allow_nan=False)


def _exact(name: str, x: float) -> float:
    """``name``'s value at ``x`` to 400 bits, rounded to float64 (double rounding is out of reach at 400 bits)."""
    with mpmath.workprec(400):
        return float(getattr(mpmath, name)(mpmath.mpf(x)))


@given(ARGUMENTS)
@example(0.0).via("sign of zero")
@example(-0.0).via("sign of zero")
@example(5e-324).via("the smallest subnormal: the value is below every fixed point of the first round")
@example(math.pi).via("next to a zero of sin and of tan")
@example(math.pi / 2).via("next to a zero of cos, a pole of tan")
@example(355.0).via("355/113 is π to 7 digits")
@example(pm.MAX_ARGUMENT).via("the largest reduction")
def test_sin_cos_tan_are_correctly_rounded(x):
    for name in ("sin", "cos", "tan"):
        got, want = getattr(pm, name)(x), _exact(name, x)
        if x == 0 and name != "cos":
            want = x  # IEEE 754: sin(±0) = ±0, tan(±0) = ±0 (mpmath's zero has no sign)
        assert got == want and math.copysign(1, got) == math.copysign(1, want), (
            f"{name}({x!r}) = {got!r}, correctly rounded {want!r}")


@pytest.mark.parametrize("bad", [math.inf, math.nan, 1.5e6, "1.0"])
def test_an_argument_out_of_range_names_the_function_and_the_range(bad):
    with pytest.raises(InvalidArgument, match=r"sin\(x=.*expected a finite number of radians with \|x\| <= 1e\+06"):
        pm.sin(bad)


def test_fma_rounds_once():
    a, b = 1 + 2.0**-30, 1 - 2.0**-30  # a * b = 1 - 2**-60, which rounds to 1.0 as a product
    assert a * b - 1.0 == 0.0
    assert pm.fma(a, b, -1.0) == -(2.0**-60)
    with pytest.raises(InvalidArgument, match=r"fma\(a=inf, b=1.0, c=0.0\): expected finite numbers"):
        pm.fma(math.inf, 1.0, 0.0)


#: What the three roundings of the squares' sum may lose where it is subnormal (below 2**-1022 each rounding is
#: off by up to half the smallest subnormal, whatever the sum): absolute, not relative to the length.
SUBNORMAL_SUM_ERROR = 1.5 * 2.0**-1074  # three halves of the smallest subnormal (2**-1075 itself rounds to 0)


@given(st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
@example([1.0237536074107427e-156] * 3).via("squares subnormal: found by Hypothesis in the suite, 4 December")
def test_norm3_is_the_fma_chain_within_one_ulp_of_the_length(v):
    exact = math.sqrt(float(sum(Fraction(t) ** 2 for t in v)))
    got = pm.norm3(v)
    assert got == math.sqrt(pm.fma(v[2], v[2], pm.fma(v[1], v[1], v[0] * v[0])))
    # a sum off by δ gives a square root off by at most min(√δ, δ / length)
    underflow = min(math.sqrt(SUBNORMAL_SUM_ERROR), SUBNORMAL_SUM_ERROR / exact) if exact else 0.0
    assert abs(got - exact) <= math.ulp(exact) + underflow, f"norm3({v!r}) = {got!r}, length {exact!r}"


def test_norm3_names_a_wrong_vector():
    with pytest.raises(InvalidArgument, match=r"norm3\(v\): expected a 3-vector, got 2 components"):
        pm.norm3((1.0, 2.0))
    with pytest.raises(InvalidArgument, match=r"norm3\(v=\[1.0, nan, 0.0\]\): expected finite components"):
        pm.norm3((1.0, math.nan, 0.0))


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="OpenBLAS's x86 kernel names")
def test_the_demo_scenes_are_the_same_bits_whatever_blas_kernel_numpy_runs():
    """The content hashes key the shipped fitted twins: OpenBLAS's generic x86 kernel (``Prescott``: separate
    products) changed 12 of the 96 poses against the kernel it picks for this project's CPUs while the scenes used
    ``np.linalg.norm``. The CPU's own kernel is the one it picks (naming one, e.g. ``Haswell``, would need that
    CPU's instructions)."""
    code = ("import pytest_n2r.demo as d; print(*[d.ground_truth(n).content_hash for n in d.demo_scene_names()])")
    hashes = {}
    for kernel in ("Prescott", None):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel is not None:
            env["OPENBLAS_CORETYPE"] = kernel
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
        hashes[kernel or "the CPU's own"] = run.stdout.split()
    assert hashes["Prescott"] == hashes["the CPU's own"], (
        f"the demo scenes' content hashes follow the BLAS kernel: {hashes}")


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the claim is about glibc's libm")
@pytest.mark.parametrize("name", ["wall", "object"])
def test_glibc_gives_the_scenes_the_same_poses(name, monkeypatch):
    """portable_math's claim that glibc's sin, cos and tan are correctly rounded on every demo argument: the
    scenes built with them are the same bits (so the change to portable_math moved no pose on glibc)."""
    from pytest_n2r.demo import scenes

    portable = scenes.build_scene(name).content_hash
    for fn in ("sin", "cos", "tan"):
        monkeypatch.setattr(scenes, fn, getattr(math, fn))
    assert scenes.build_scene(name).content_hash == portable, f"{name}: glibc's trigonometry moved a pose"
