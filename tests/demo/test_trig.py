"""The renderer's inlined sine and cosine against NumPy's, and compiled blend masks against their numpy form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from pytest_n2r.demo.mask_kernel import compile_mask
from pytest_n2r.demo.scenes import _growth_mask, _road_mask
from pytest_n2r.demo.trig import sincos
from pytest_n2r.errors import InvalidArgument


@njit(cache=True)
def _sincos_array(x):
    s, c = np.empty_like(x), np.empty_like(x)
    for i in range(x.size):
        s[i], c[i] = sincos(x[i])
    return s, c


@pytest.mark.parametrize("limit", [1.0, 30.0, 500.0])
def test_sincos_is_within_two_ulp_of_numpy(limit):
    x = np.random.default_rng(0).uniform(-limit, limit, 200_000)
    x[:4] = [0.0, math.pi / 4, -math.pi / 2, limit]
    s, c = _sincos_array(x)
    for name, got, want in (("sin", s, np.sin(x)), ("cos", c, np.cos(x))):
        err = np.abs(got - want)
        # near a zero of the function (x a float64 next to a multiple of π/2) the reduction's rounding leaves an
        # absolute error far below any use, though many ulp of the tiny result
        ulp = err / np.maximum(np.spacing(np.abs(want)), 1e-22)
        assert ulp.max() <= 2, f"{name} off by {ulp.max():.1f} ulp at x={x[ulp.argmax()]!r} (|x| <= {limit})"
        assert err.max() <= 1.2e-16, f"{name} off by {err.max():.2g} (|x| <= {limit})"


def test_sincos_rounded_to_float32_is_within_one_float32_ulp_of_numpy():
    """The relief's waves take float32 phases and use float32 sines, as :meth:`ReliefWall.height_and_gradient`."""
    x = np.random.default_rng(1).uniform(-80, 80, 200_000).astype(np.float32)
    s, c = _sincos_array(x.astype(np.float64))
    for name, got, want in (("sin", s.astype(np.float32), np.sin(x)), ("cos", c.astype(np.float32), np.cos(x))):
        ulp = np.abs(got.astype(np.float64) - want) / np.spacing(np.abs(want))
        assert ulp.max() <= 1, f"float32 {name} off by {ulp.max():.0f} float32 ulp at x={x[ulp.argmax()]!r}"


@pytest.mark.parametrize("mask", [_growth_mask, _road_mask])
def test_a_compiled_mask_agrees_with_its_numpy_form(mask):
    rng = np.random.default_rng(2)
    a, b = rng.uniform(-25, 25, 5000), rng.uniform(-25, 25, 5000)
    out = np.full(5000, np.nan)
    compile_mask(mask)(a, b, out, 4000)
    np.testing.assert_allclose(out[:4000], mask(a[:4000], b[:4000]), rtol=0, atol=1e-14,
                               err_msg=f"{mask.__name__}: compiled and numpy masks differ")
    assert np.isnan(out[4000:]).all(), "the compiled mask wrote past count"


def _math_mask(a, b):
    return 0.5 + 0.5 * math.sin(a) * math.cos(b)


def test_a_mask_written_with_math_compiles_too():
    a, b = np.linspace(-9, 9, 101), np.linspace(3, -7, 101)
    out = np.empty(101)
    compile_mask(_math_mask)(a, b, out, 101)
    np.testing.assert_allclose(out, [_math_mask(x, y) for x, y in zip(a, b)], rtol=0, atol=1e-15)


def test_a_mask_that_is_not_a_function_is_named():
    with pytest.raises(InvalidArgument, match="Blend mask 'maximum' is a ufunc; expected a plain Python function"):
        compile_mask(np.maximum)
