"""Obstacle curves (paper eq. 10) against NumPy and closed forms."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose, closest_per_obstacle, unpack_stacked

import softplan_jax as sp

P = np.polynomial.polynomial


# curve methods as jitted functions of (curve, u): the curve is a pytree, so
# one compilation per coefficient shape serves every curve of that shape
_point = jax.jit(lambda c, u: c.point(u))
_d1 = jax.jit(lambda c, u: c.derivative(u))
_d2 = jax.jit(lambda c, u: c.second_derivative(u))
_d1_autodiff = jax.jit(lambda c, us: jax.vmap(jax.jacfwd(c.point))(us))
_d1_vmap = jax.jit(lambda c, us: jax.vmap(c.derivative)(us))


def _u_values(rng, u_range, k=7):
    a, b = u_range
    return np.concatenate([[a, b, 0.5 * (a + b)], rng.uniform(a, b, k)])


@pytest.mark.parametrize("degree", [0, 1, 2, 3, 5])
def test_polynomial_curve_matches_polyval(degree):
    rng = np.random.default_rng(degree)
    for _ in range(5):
        coeffs = rng.normal(size=(3, degree + 1)) * rng.choice([0.1, 1.0, 5.0])
        u_range = tuple(np.sort(rng.uniform(-3, 3, 2)))
        c = sp.PolynomialCurve(jnp.asarray(coeffs), u_range)
        d1 = P.polyder(coeffs, axis=1) if degree >= 1 else np.zeros((3, 1))
        d2 = P.polyder(coeffs, 2, axis=1) if degree >= 2 else np.zeros((3, 1))
        for k_u, u in enumerate(_u_values(rng, u_range)):
            want = np.array([P.polyval(u, coeffs[k]) for k in range(3)])
            want1 = np.array([P.polyval(u, d1[k]) for k in range(3)])
            want2 = np.array([P.polyval(u, d2[k]) for k in range(3)])
            scale = max(1.0, np.abs(coeffs).sum() * max(1, abs(u)) ** degree)
            if k_u == 0:  # the eager methods once
                got = c.point(jnp.float64(u))
                assert got.shape == (3,)
                assert_allclose(got, want, atol=1e-14 * scale, err_msg=f"point u={u}")
                assert_allclose(c.derivative(jnp.float64(u)), want1, atol=1e-13 * scale)
                assert_allclose(c.second_derivative(jnp.float64(u)), want2, atol=1e-13 * scale)
            uj = jnp.float64(u)
            assert_allclose(_point(c, uj), want, atol=1e-14 * scale, err_msg=f"point u={u}")
            assert_allclose(_d1(c, uj), want1, atol=1e-13 * scale, err_msg=f"d1 u={u}")
            assert_allclose(_d2(c, uj), want2, atol=1e-13 * scale, err_msg=f"d2 u={u}")
        # vmap over u, and the derivatives agree with autodiff of point
        us = jnp.asarray(_u_values(rng, u_range))
        assert_allclose(_d1_vmap(c, us), _d1_autodiff(c, us), atol=1e-12 * scale)


def test_polynomial_curve_attributes_and_pytree():
    coeffs = np.array([[1.0, 2.0, 3.0], [0.0, 1.0, 0.0], [4.0, 0.0, -1.0]])
    c = sp.PolynomialCurve(jnp.asarray(coeffs), (-1.0, 2.0), radius=0.05)
    assert_allclose(c.coeffs, coeffs, atol=0)
    assert np.asarray(c.u_range).shape == (2,)
    assert_allclose(c.u_range, [-1.0, 2.0], atol=0)
    assert float(c.radius) == 0.05
    assert float(sp.PolynomialCurve(jnp.asarray(coeffs), (-1.0, 2.0)).radius) == 0.0
    leaves = jax.tree_util.tree_leaves(c)
    assert any(np.array_equal(np.asarray(x), coeffs) for x in leaves)
    # a pytree through jit: the traced curve evaluates the same
    f = jax.jit(lambda cc, u: cc.point(u))
    assert_allclose(f(c, jnp.float64(0.7)), [P.polyval(0.7, coeffs[k]) for k in range(3)], atol=1e-14)


def test_paper_obstacles_as_written():
    # Sim2: X = 0.5, Y = u, Z = 5u^2
    c = sp.PolynomialCurve(jnp.asarray([[0.5, 0, 0], [0, 1.0, 0], [0, 0, 5.0]]), (-2.0, 2.0))
    assert_allclose(c.point(jnp.float64(1.5)), [0.5, 1.5, 11.25], atol=1e-14)
    assert_allclose(c.derivative(jnp.float64(1.5)), [0, 1, 15], atol=1e-14)
    assert_allclose(c.second_derivative(jnp.float64(-0.3)), [0, 0, 10], atol=1e-14)


def _helix(u):
    return jnp.stack([jnp.cos(u), jnp.sin(u), 0.2 * u])


def test_parametric_curve_helix():
    c = sp.ParametricCurve(_helix, (0.0, 6.0))
    assert_allclose(c.u_range, [0.0, 6.0], atol=0)
    assert float(c.radius) == 0.0
    for u in [0.0, 0.3, 1.0, np.pi, 5.9, 6.0]:
        uj = jnp.float64(u)
        assert_allclose(c.point(uj), [np.cos(u), np.sin(u), 0.2 * u], atol=1e-15)
        assert_allclose(c.derivative(uj), [-np.sin(u), np.cos(u), 0.2], atol=1e-15)
        assert_allclose(c.second_derivative(uj), [-np.cos(u), -np.sin(u), 0.0], atol=1e-15)
    us = jnp.linspace(0.0, 6.0, 9)
    assert_allclose(
        jax.jit(jax.vmap(c.derivative))(us), np.stack([-np.sin(us), np.cos(us), 0.2 + 0 * us], 1), atol=1e-15
    )
    # the curve is a pytree usable inside jit
    g = jax.jit(lambda cc, u: cc.second_derivative(u))
    assert_allclose(g(c, jnp.float64(1.0)), [-np.cos(1.0), -np.sin(1.0), 0.0], atol=1e-15)


def test_line_segment():
    a = np.array([0.3, -1.0, 2.0])
    b = np.array([1.0, 0.5, -0.5])
    c = sp.line_segment(jnp.asarray(a), jnp.asarray(b), radius=0.1)
    assert isinstance(c, sp.PolynomialCurve)
    assert_allclose(c.u_range, [0.0, 1.0], atol=0)
    assert float(c.radius) == pytest.approx(0.1)
    assert_allclose(c.point(jnp.float64(0.0)), a, atol=0)
    assert_allclose(c.point(jnp.float64(1.0)), b, atol=1e-15)
    assert_allclose(c.point(jnp.float64(0.25)), a + 0.25 * (b - a), atol=1e-15)
    assert_allclose(c.derivative(jnp.float64(0.7)), b - a, atol=1e-15)
    assert_allclose(c.second_derivative(jnp.float64(0.7)), np.zeros(3), atol=0)


def test_stack_curves_padding_and_mask():
    rng = np.random.default_rng(3)
    curves_np = [
        (rng.normal(size=(3, 2)), (-1.0, 1.0), 0.0),
        (rng.normal(size=(3, 3)), (0.0, 1.5), 0.2),
        (rng.normal(size=(3, 4)), (-2.0, 2.0), 0.05),
    ]
    curves = [sp.PolynomialCurve(jnp.asarray(cf), ur, radius=r) for cf, ur, r in curves_np]

    stacked, mask = unpack_stacked(sp.geometry.stack_curves(curves))
    assert stacked.coeffs.shape == (3, 3, 4)
    assert mask.dtype == np.bool_ and mask.tolist() == [True, True, True]

    stacked, mask = unpack_stacked(sp.geometry.stack_curves(curves, size=5, degree=5))
    assert stacked.coeffs.shape == (5, 3, 6)
    assert np.asarray(stacked.u_range).shape == (5, 2)
    assert np.asarray(stacked.radius).shape == (5,)
    assert mask.tolist() == [True, True, True, False, False]
    for k, (cf, ur, r) in enumerate(curves_np):
        K = cf.shape[1]
        assert_allclose(stacked.coeffs[k, :, :K], cf, atol=0)
        assert_allclose(stacked.coeffs[k, :, K:], 0.0, atol=0)
        assert_allclose(stacked.u_range[k], ur, atol=0)
        assert float(stacked.radius[k]) == pytest.approx(r)
    # padding slots: a valid (finite, non-empty) range so they never produce NaN
    pad_ranges = np.asarray(stacked.u_range[3:])
    assert np.all(np.isfinite(pad_ranges)) and np.all(pad_ranges[:, 0] < pad_ranges[:, 1])
    # evaluating the stacked batch with vmap reproduces each curve
    for u in (-0.5, 0.0, 0.9):
        pts = jax.vmap(lambda cc, u=u: cc.point(jnp.float64(u)))(stacked)
        for k, (cf, _, _) in enumerate(curves_np):
            assert_allclose(pts[k], [P.polyval(u, cf[j]) for j in range(3)], atol=1e-13)
        d2 = jax.vmap(lambda cc, u=u: cc.second_derivative(jnp.float64(u)))(stacked)
        for k, (cf, _, _) in enumerate(curves_np):
            want = [P.polyval(u, P.polyder(cf[j], 2)) if cf.shape[1] > 2 else 0.0 for j in range(3)]
            assert_allclose(d2[k], want, atol=1e-13)
    # closest points over a padded batch stay finite in the padding slots
    # (shapes shared with test_closest's per-obstacle test: one compilation)
    stacked, mask = unpack_stacked(sp.geometry.stack_curves(curves, size=9, degree=3))
    q = jnp.asarray([[1.0, 0.4, 0.2], [1.0, 0.0, 1.0], [0.5, 0.0, 0.0]])
    res = closest_per_obstacle(q, stacked)
    for f in ("distance", "s", "u", "arm_point", "obstacle_point"):
        assert np.all(np.isfinite(np.asarray(getattr(res, f)))), f


def test_stack_curves_rejects_too_small_size_or_degree():
    curves = [sp.PolynomialCurve(jnp.ones((3, 3)), (0.0, 1.0)) for _ in range(3)]
    with pytest.raises(ValueError):
        sp.geometry.stack_curves(curves, size=2)
    with pytest.raises(ValueError):
        sp.geometry.stack_curves(curves, degree=1)


@pytest.mark.parametrize("n_points", [1, 2, 5, 33])
def test_curve_points(n_points):
    coeffs = np.array([[1.0, 0.5, -0.2], [0.0, 1.0, 0.0], [2.0, 0.0, 0.3]])
    u_range = (-1.5, 2.5)
    c = sp.PolynomialCurve(jnp.asarray(coeffs), u_range)
    pts = np.asarray(sp.geometry.curve_points(c, n_points))
    assert pts.shape == (n_points, 3)
    us = np.array([0.5]) if n_points == 1 else np.linspace(-1.5, 2.5, n_points)
    want = np.stack([P.polyval(us, coeffs[k]) for k in range(3)], 1)
    assert_allclose(pts, want, atol=1e-14)
    h = sp.ParametricCurve(_helix, (0.0, 6.0))
    hp = np.asarray(sp.geometry.curve_points(h, n_points))
    us = np.array([3.0]) if n_points == 1 else np.linspace(0, 6, n_points)
    assert_allclose(hp, np.stack([np.cos(us), np.sin(us), 0.2 * us], 1), atol=1e-14)


# --------------------------------------------------------------------------
# fitting
# --------------------------------------------------------------------------


def _chord_parameter(points):
    d = np.linalg.norm(np.diff(points, axis=0), axis=1)
    u = np.concatenate([[0.0], np.cumsum(d)])
    return u / u[-1]


def test_fit_recovers_a_line_with_uneven_samples():
    # along a straight line the normalised chord length IS the line's
    # parameter, so a cubic fit must return exactly a + (b - a) u
    rng = np.random.default_rng(8)
    a, b = np.array([0.2, -1.0, 0.5]), np.array([1.5, 0.3, 2.0])
    t = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 30)]))
    pts = a + t[:, None] * (b - a)
    c = sp.clouds.fit_polynomial_curve(jnp.asarray(pts), 3)
    assert c.coeffs.shape == (3, 4)
    assert_allclose(c.u_range, [0.0, 1.0], atol=0)
    assert_allclose(c.coeffs, np.stack([a, b - a, 0 * a, 0 * a], 1), atol=1e-12)


def test_fit_recovers_a_cubic_given_in_chord_parameter():
    # The fit parameterises by normalised chord length, and a non-straight
    # polynomial curve is never a polynomial in its own chord length when
    # densely sampled, so exact recovery is only well posed for degree + 1
    # samples: take 4 noiseless samples of a cubic, compute their chord
    # parameters u_k independently, and the known cubic G through (u_k, p_k)
    # (NumPy interpolation) is what the fit must return, exactly.
    rng = np.random.default_rng(9)
    for _ in range(5):
        coeffs = rng.normal(size=(3, 4))
        t = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0.1, 0.9, 2)]))
        pts = np.stack([P.polyval(t, coeffs[k]) for k in range(3)], 1)
        u = _chord_parameter(pts)
        G = np.stack([P.polyfit(u, pts[:, k], 3) for k in range(3)])
        assert np.abs(np.stack([P.polyval(u, G[k]) for k in range(3)], 1) - pts).max() < 1e-10
        c = sp.clouds.fit_polynomial_curve(jnp.asarray(pts), 3)
        assert c.coeffs.shape == (3, 4)
        assert_allclose(c.coeffs, G, atol=1e-8 * max(1.0, np.abs(G).max()))
        assert_allclose(c.point(jnp.float64(0.0)), pts[0], atol=1e-9)
        assert_allclose(c.point(jnp.float64(1.0)), pts[-1], atol=1e-9)


def test_fit_matches_least_squares_on_chord_parameter():
    # dense noiseless samples of a cubic (not a polynomial in chord length):
    # the fit must be the least-squares polynomial in the normalised chord
    # parameter, and it must follow the cubic closely
    coeffs = np.array([[0.0, 1.0, 0.3, -0.2], [1.0, 0.2, -0.5, 0.1], [0.5, 0.4, 0.1, 0.3]])
    t = np.linspace(0, 1, 200)
    pts = np.stack([P.polyval(t, coeffs[k]) for k in range(3)], 1)
    for degree in (2, 3, 4):
        c = sp.clouds.fit_polynomial_curve(jnp.asarray(pts), degree)
        u = _chord_parameter(pts)
        V = np.vander(u, degree + 1, increasing=True)
        want = np.linalg.lstsq(V, pts, rcond=None)[0].T
        assert_allclose(c.coeffs, want, atol=1e-9, err_msg=f"degree {degree}")
        if degree >= 3:
            fitted = np.stack([P.polyval(u, np.asarray(c.coeffs)[k]) for k in range(3)], 1)
            assert np.abs(fitted - pts).max() < 5e-3


def test_point_curve_lower_bound_never_exceeds_the_distance():
    """point_curve_lower_bound (the cheap skip of the goal-in-obstacle check) stays at or below
    the exact point-curve distance and a dense sampling of the curve, for degrees 1 to 9, ranges
    inside and beyond [-1, 1] and points on, near and far from the curve; far away it is within
    its slack of the distance (it does skip)."""
    from softplan_jax.geometry._point_curve import point_curve_distance, point_curve_lower_bound

    rng = np.random.default_rng(7)
    for trial in range(60):
        degree = 1 + trial % 9
        coeffs = rng.normal(size=(3, degree + 1)) / np.arange(1, degree + 2) ** 1.5
        lo = rng.uniform(-2.0, 0.5)
        hi = lo + rng.uniform(0.01, 2.0)
        u = np.linspace(lo, hi, 200_001)
        curve = np.stack([P.polyval(u, coeffs[k]) for k in range(3)], 1)
        on = curve[rng.integers(u.size)]
        for p in (on, on + rng.normal(scale=1e-3, size=3), on + rng.normal(scale=0.3, size=3),
                  on + rng.normal(scale=30.0, size=3)):
            bound = point_curve_lower_bound(coeffs, (lo, hi), p)
            exact = point_curve_distance(coeffs, (lo, hi), p)
            dense = np.linalg.norm(curve - p, axis=1).min()
            assert bound <= exact + 1e-12 and bound <= dense, (trial, bound, exact, dense)
    far = np.array([5.0, 5.0, 5.0])
    coeffs = np.array([[0.0, 1.0, 0.3], [0.0, 0.2, -0.5], [0.0, 0.4, 0.1]])
    exact = point_curve_distance(coeffs, (0.0, 1.0), far)
    assert exact - 0.01 < point_curve_lower_bound(coeffs, (0.0, 1.0), far) <= exact


def test_point_curve_lower_bounds_of_many_curves_equal_each_curves_own():
    """point_curve_lower_bounds of m curves of mixed degrees, padded to one width, gives each
    curve's bound from its unpadded coefficients bit for bit (padding columns change nothing),
    and an empty array for no curves."""
    from softplan_jax.geometry._point_curve import point_curve_lower_bound, point_curve_lower_bounds

    rng = np.random.default_rng(3)
    degrees = (0, 1, 2, 4, 8)
    coeffs = np.zeros((len(degrees), 3, 9))
    u_range = np.zeros((len(degrees), 2))
    for i, d in enumerate(degrees):
        coeffs[i, :, : d + 1] = rng.normal(size=(3, d + 1))
        u_range[i] = np.sort(rng.uniform(-1.5, 1.5, 2))
    p = rng.normal(size=3)
    each = [point_curve_lower_bound(coeffs[i, :, : d + 1], u_range[i], p) for i, d in enumerate(degrees)]
    np.testing.assert_array_equal(point_curve_lower_bounds(coeffs, u_range, p), each)
    assert point_curve_lower_bounds(np.zeros((0, 3, 4)), np.zeros((0, 2)), p).shape == (0,)


def test_goal_obstacle_hits_skip_only_far_curves():
    """goal_obstacle_hits asks point_obstacle_distances for exact distances only where the bound
    does not clear the radius plus the arm's: the same hits, clearances and exactness as the
    exact distance of every curve, for goals inside, on, just outside and far from the tree's
    obstacles."""
    from softplan_jax.geometry._obstacles import point_obstacle_distances
    from softplan_jax.scenarios._scenario import goal_obstacle_hits

    tree = sp.paper_scenario("tree")
    arm_r = float(tree.arm_radius)
    coeffs, u_range = np.asarray(tree.curves.coeffs), np.asarray(tree.curves.u_range)
    radius = np.asarray(tree.curves.radius)
    rng = np.random.default_rng(3)
    goals, skipped = [], 0
    for k in np.nonzero(np.asarray(tree.curve_mask))[0]:
        u = rng.uniform(*u_range[k], 4)
        on = np.stack([P.polyval(u, coeffs[k][a]) for a in range(3)], 1)
        for c in on:
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            for offset in (0.0, radius[k] + arm_r - 1e-9, radius[k] + arm_r + 1e-9, 0.05, 1.0):
                goals.append(c + offset * direction)
    for g in goals:
        scene = tree._replace(goal=jnp.asarray(g))
        every = point_obstacle_distances(scene, g)
        want = [(o["slot"], o["distance"] - o["radius"] - arm_r, o["exact"]) for o in every
                if o["distance"] - o["radius"] - arm_r <= 0]
        assert goal_obstacle_hits(scene) == want
        skipped += sum(not o["exact"] for o in point_obstacle_distances(scene, g, beyond=arm_r))
    assert skipped > len(goals)  # most curves are skipped for most goals
