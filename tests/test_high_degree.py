"""Polynomial curves of high degree: exact values, exact closest points, and a traced
program that does not grow with the degree (a degree-12 curve once compiled for
minutes: the warm start's curvature bound differentiated the curve once per degree).
"""

from __future__ import annotations

import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose

import softplan_jax as sp
from softplan_jax.geometry._curves import HORNER_MAX_DEGREE, taylor_coefficients
from softplan_jax.planning._programs import rollout
from softplan_jax.testing import oracle

P = np.polynomial.polynomial


def _count_eqns(jaxpr) -> int:
    """Equations of a jaxpr, those of its sub-jaxprs (loops, conds, custom rules) included."""
    n = 0
    for eqn in jaxpr.eqns:
        n += 1
        for v in eqn.params.values():
            for sub in v if isinstance(v, (list, tuple)) else (v,):
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    n += _count_eqns(sub.jaxpr)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    n += _count_eqns(sub)
    return n


def _curve(degree: int, seed: int = 0, scale: float = 0.3):
    rng = np.random.default_rng(seed)
    c = np.zeros((3, degree + 1))
    c[:, 0] = [0.6, 0.0, 0.9]
    c[1, 1] = 1.0
    c[:, 2:] = rng.normal(size=(3, degree - 1)) * scale / np.arange(2, degree + 1) ** 2
    return c


@pytest.mark.parametrize("degree", [HORNER_MAX_DEGREE + 1, 12, 30])
def test_values_and_derivatives_match_polyval(degree):
    rng = np.random.default_rng(degree)
    coeffs = rng.normal(size=(3, degree + 1))
    c = sp.PolynomialCurve(jnp.asarray(coeffs), (-1.2, 1.1))
    for u in (-1.2, -0.7, 0.0, 0.4, 1.1):
        uj = jnp.float64(u)
        scale = np.abs(coeffs).sum() * max(1.0, abs(u)) ** degree * degree**2
        want = [np.array([P.polyval(u, P.polyder(coeffs[a], m)) for a in range(3)]) for m in range(3)]
        got = [c.point(uj), c.derivative(uj), c.second_derivative(uj)]
        for m in range(3):
            assert_allclose(got[m], want[m], atol=1e-14 * scale, err_msg=f"derivative {m} at u={u}")
        # autodiff of point agrees with the explicit derivatives (the power basis's own rule)
        assert_allclose(jax.jacfwd(c.point)(uj), got[1], atol=1e-13 * scale)
        assert_allclose(jax.jacfwd(jax.jacfwd(c.point))(uj), got[2], atol=1e-13 * scale)


@pytest.mark.parametrize("degree", [2, 5, 13])
def test_taylor_shift_and_curvature_bound(degree):
    coeffs = np.random.default_rng(degree).normal(size=(3, degree + 1))
    shifted = np.asarray(taylor_coefficients(jnp.asarray(coeffs), 0.7))
    for t in (-0.5, 0.0, 0.3):
        assert_allclose(P.polyval(t, shifted.T), P.polyval(t + 0.7, coeffs.T), atol=1e-12 * np.abs(coeffs).sum())
    c = sp.PolynomialCurve(coeffs, (-1.0, 1.0))
    bound = float(c.second_derivative_bound(jnp.float64(-0.4), jnp.float64(0.9)))
    u = np.linspace(-0.4, 0.9, 2001)
    d2 = np.linalg.norm(np.stack([P.polyval(u, P.polyder(coeffs[a], 2)) for a in range(3)]), axis=0)
    assert bound >= d2.max() * (1 - 1e-12)


def test_traced_program_does_not_grow_with_the_degree():
    """Curve evaluation, the warm start's curvature bound and the whole rollout: as many
    jaxpr equations for degree 12 as for degree 30."""
    def sizes(degree):
        curve = sp.PolynomialCurve(_curve(degree), (-1.0, 1.0))
        u = jnp.float64(0.3)
        point = _count_eqns(jax.make_jaxpr(lambda c, u: (c.point(u), c.derivative(u), c.second_derivative(u)))(
            curve, u).jaxpr)
        bound = _count_eqns(jax.make_jaxpr(lambda c: c.second_derivative_bound(jnp.float64(-1.0), jnp.float64(1.0)))(
            curve).jaxpr)
        sc = sp.make_scenario(jnp.array([0.3, 0.5, 1.2]), [curve])
        opts = sp.make_options()
        g = sp.default_gains(jnp.float64)
        whole = _count_eqns(jax.make_jaxpr(lambda s, g, k: rollout(s, g, opts, 20, k, driver="chunks"))(
            sc, g, jax.random.PRNGKey(0)).jaxpr)
        return point, bound, whole

    assert sizes(12) == sizes(30)


@pytest.mark.parametrize("degree", [12, 20])
def test_closest_point_matches_oracle(degree):
    """The exact closest point on high-degree curves: |distance - oracle| <= 1e-9."""
    rng = np.random.default_rng(100 + degree)
    coeffs = _curve(degree, seed=degree, scale=2.0)
    curve = sp.PolynomialCurve(coeffs, (-1.0, 1.0))
    ocurve = oracle.OPoly(coeffs, -1.0, 1.0)
    solve = jax.jit(sp.closest_point)
    for _ in range(3):
        q = np.stack([rng.uniform(0.6, 1.2, 3), rng.uniform(-1.5, 1.5, 3), rng.uniform(-np.pi, np.pi, 3)], axis=1)
        got = float(solve(jnp.asarray(q), curve).distance)
        want = oracle.closest_distance(q, ocurve)
        assert abs(got - want) <= 1e-9, (got, want)
