"""The SH colour of the renderer: the 3DGS basis (orthonormal on the sphere) and its evaluation."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.splats.sh import rgb_to_sh, view_colours

from ..render.splat_reference import sh_basis


def test_the_basis_is_orthonormal_on_the_sphere():
    """∫ Y_i Y_j dΩ = δ_ij for the 16 functions of degree ≤ 3 (Gauss–Legendre in cos θ, uniform in φ: exact for
    polynomials of this degree), so the constants are the real SH normalizations."""
    x, w = np.polynomial.legendre.leggauss(12)
    phi = np.arange(24) * 2 * np.pi / 24
    ct, ph = np.meshgrid(x, phi, indexing="ij")
    st = np.sqrt(1 - ct ** 2)
    d = np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1).reshape(-1, 3)
    weights = (w[:, None] * np.full_like(ph, 2 * np.pi / 24)).ravel()
    Y = sh_basis(d, 3)
    gram = (Y * weights[:, None]).T @ Y
    np.testing.assert_allclose(gram, np.eye(16), atol=1e-12, err_msg="the SH basis is not orthonormal")


def test_the_compiled_colour_is_the_basis_times_the_coefficients_plus_a_half():
    rng = np.random.default_rng(4)
    for degree in range(4):
        sh = rng.normal(size=(50, (degree + 1) ** 2, 3))
        d = rng.normal(size=(50, 3))
        unit = d / np.linalg.norm(d, axis=1, keepdims=True)
        expected = np.maximum(np.einsum("nk,nkc->nc", sh_basis(unit, degree), sh) + 0.5, 0.0)
        np.testing.assert_allclose(view_colours(sh, d), expected, atol=1e-12,
                                   err_msg=f"SH colours of degree {degree} differ from the basis")


@settings(max_examples=50, deadline=None)
@given(rgb=st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
       direction=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(lambda d: max(map(abs, d)) > 1e-3))
def test_a_colour_stored_as_its_dc_coefficient_is_seen_as_that_colour(rgb, direction):
    """``rgb_to_sh`` is the inverse of the renderer's colour at degree 0 (the demo's splats store their colours so)."""
    sh = rgb_to_sh(np.array(rgb))[None, None, :]
    seen = view_colours(sh, np.array([direction]))[0]
    np.testing.assert_allclose(seen, rgb, rtol=0, atol=1e-12,
                               err_msg=f"colour {rgb} stored by rgb_to_sh is seen as {seen.tolist()}")
