"""The NumPy/SciPy peer (benchmarks/_numpy_baseline.py) against the JAX planner,
against dense brute force and against the closest-point oracle.

Tolerances:

* Trajectories, 1e-8 over 10 steps. Both sides run in float64 and implement
  the same formulas; the Jacobians are analytic in the peer and ``jacfwd`` in
  the library, both exact to rounding, and both closest-point solvers
  converge to rounding, so each step differs by rounding only (measured:
  ~1e-14 over 10 steps). 1e-8 is 6 orders of magnitude below one step's
  motion (~1e-2), so a wrong gain, sign, clip, closest point or Jacobian
  column on either side fails.
* Jacobians: against the complex-step oracle (exact to rounding) to 1e-12,
  and against central finite differences (error ~1e-10) to 2e-9, under both
  rotation conventions.
* Closest points, against a dense grid of D(s, u) per segment: the solver
  must be no worse than the grid (up to rounding, 1e-12), and not better than
  the grid's rigorous Lipschitz bound ``L_i ds/2 + max|F_o'| du/2`` allows;
  and against the oracle's answers on the paper-obstacle corpus
  (``closest_cases``, ``TOL`` = 1e-9).
"""

from __future__ import annotations

import _numpy_baseline as nb  # benchmarks/ is on sys.path (conftest); importing it changes no jax setting
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.testing import closest_cases, oracle

TRAJ_TOL = 1e-8
STEPS = 10


def _dense_curve_distance(q, coeffs, u_range, n_s=501, n_u=2001):
    """Brute-force min distance arm <-> curve on a dense (s, u) grid, and the
    grid's Lipschitz error bound. Arm points from softplan_jax/testing/oracle.py (independent)."""
    u = np.linspace(u_range[0], u_range[1], n_u)
    C = np.stack([np.polynomial.polynomial.polyval(u, coeffs[k]) for k in range(3)], axis=-1)
    dC = np.stack([np.polynomial.polynomial.polyval(u, np.polynomial.polynomial.polyder(coeffs[k]))
                   for k in range(3)], axis=-1)
    speed_u = np.max(np.linalg.norm(dC, axis=-1)) * 1.01 + 1e-12
    s = np.linspace(0.0, 1.0, n_s)
    best, bound = np.inf, 0.0
    for i in range(q.shape[0]):
        A = oracle.segment_points(q, i, s)
        d2 = np.sum(A * A, 1)[:, None] + np.sum(C * C, 1)[None, :] - 2.0 * A @ C.T
        # The minimising pair's distance recomputed directly (the expansion loses digits).
        a, c = np.unravel_index(int(np.argmin(d2)), d2.shape)
        best = min(best, float(np.linalg.norm(A[a] - C[c])))
        # max over segments of the bound (the minimum may be on any segment)
        bound = max(bound, 0.5 * q[i, 0] / (n_s - 1) + 0.5 * speed_u * (u_range[1] - u_range[0]) / (n_u - 1))
    return best, bound


def _configurations():
    """The straight default start (parallel to the tree's trunk: a continuum of
    minima) and seeded random bent arms, each with one straight segment."""
    rng = np.random.default_rng(1234)
    qs = [np.asarray(sp.scenarios.default_start(dtype=jnp.float64))]
    for k in range(3):
        q = np.stack([rng.uniform(0.7, 1.3, 3), rng.uniform(-2.0, 2.0, 3), rng.uniform(-np.pi, np.pi, 3)], 1)
        q[(k + 1) % 3, 1] = 0.0
        qs.append(q)
    return qs


@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_closest_point_matches_dense_grid(name):
    scn = nb.to_numpy_scenario(name)
    for q in _configurations():
        for coeffs, u_range, _ in scn.curves:
            cp = nb.closest_point_curve(q, coeffs, u_range)
            grid, bound = _dense_curve_distance(q, coeffs, u_range)
            assert cp.distance <= grid + 1e-12, (name, q.tolist(), cp, grid)
            assert cp.distance >= grid - bound, (name, q.tolist(), cp, grid, bound)
            # The reported pair is consistent: the arm point is P_si, the obstacle point F_o(u).
            np.testing.assert_allclose(cp.arm_point, oracle.segment_point(q, cp.segment, cp.s), atol=1e-13)
            F = np.array([np.polynomial.polynomial.polyval(cp.u, coeffs[k]) for k in range(3)])
            np.testing.assert_allclose(cp.obstacle_point, F, atol=1e-12)
            assert abs(np.linalg.norm(cp.arm_point - cp.obstacle_point) - cp.distance) < 1e-14
            assert 0.0 <= cp.s <= 1.0 and u_range[0] <= cp.u <= u_range[1]


def test_closest_point_matches_oracle_corpus():
    """The oracle's answers for the paper's obstacles (closest_cases "paper": 20 arms each)."""
    cases = closest_cases.cases("paper")
    want = closest_cases.oracle_distances("paper")
    got = np.array([nb.closest_point_curve(c.q, c.coeffs, c.u_range).distance for c in cases])
    assert np.all(np.abs(got - want) <= closest_cases.TOL), np.max(np.abs(got - want))


@pytest.mark.parametrize("theta", [0.0, 1e-9, 1e-4, 0.3, -2.5])
def test_analytic_jacobians_match_complex_step_and_fd(theta):
    q = np.array([[1.0, theta, 0.4], [0.8, -0.7, 2.1], [1.2, theta, -1.0]])
    for i, s in [(0, 0.0), (0, 0.6), (1, 0.37), (1, 1.0), (2, 0.2), (2, 1.0)]:
        np.testing.assert_allclose(nb.point_jacobian(q, i, s), oracle.point_jacobian(q, i, s), rtol=0, atol=1e-12)
    np.testing.assert_allclose(nb.tip_jacobian(q), oracle.tip_jacobian(q), rtol=0, atol=1e-12)
    # The oracle knows only the paper's R_i: finite differences for both conventions.
    for convention in ("paper", "webster_jones"):
        with nb.rotation_convention(convention):
            np.testing.assert_allclose(nb.tip_jacobian(q), nb.fd_jacobian(nb.tip_position, q), rtol=0, atol=2e-9)
            for i, s in [(0, 0.6), (1, 0.37), (2, 0.2)]:
                fd = nb.fd_jacobian(lambda Q, i=i, s=s: nb.segment_point(Q, i, s), q)
                np.testing.assert_allclose(nb.point_jacobian(q, i, s), fd, rtol=0, atol=2e-9)
            # Several points in one call, as the planner step asks for them.
            Js = nb.point_jacobians(q, [2, 0], [1.0, 0.6])
            np.testing.assert_allclose(Js[0], nb.tip_jacobian(q), rtol=0, atol=1e-15)
            np.testing.assert_allclose(Js[1], nb.point_jacobian(q, 0, 0.6), rtol=0, atol=1e-15)


def _max_diff(a, b):
    T = min(len(a), len(b))
    assert T == STEPS + 1, (len(a), len(b))
    return float(np.max(np.abs(a[:T] - b[:T])))


@pytest.fixture(scope="module")
def sim1_near_obstacle():
    """sim1 restarted a few steps before the arm first enters the repulsion's
    range, with the baseline's stress gains (d0 = 0.25: with the default gains
    the repulsion acts on a single step of sim1), so that the repulsion and the
    closest point matter on most of the 10 steps. The step is found on the JAX
    curve trajectory with a dense brute-force clearance."""
    scenario = sp.paper_scenario("sim1")
    g = nb.stress_gains()
    coeffs, u_range, _ = nb.to_numpy_scenario(scenario).curves[0]
    qj = nb.jax_trajectory(scenario, "curve", 10, 120, gains=g)
    inside = [_dense_curve_distance(q, coeffs, u_range, n_s=201, n_u=2001)[0] < g["d0"] - 1e-3 for q in qj]
    if not any(inside):
        pytest.fail("the sim1 curve trajectory never enters the repulsion's range: pick another start")
    k = inside.index(True)
    return scenario._replace(q0=jnp.asarray(qj[max(k - 3, 0)]))


@pytest.mark.parametrize("method", ["curve", "points"])
def test_trajectory_agrees_with_jax_from_start(method):
    scenario = sp.paper_scenario("sim1")
    q_np = nb.numpy_plan(scenario, method, 10, STEPS).q
    q_jax = nb.jax_trajectory(scenario, method, 10, STEPS)
    assert _max_diff(q_np, q_jax) < TRAJ_TOL


@pytest.mark.parametrize("method", ["curve", "points"])
def test_trajectory_agrees_with_jax_near_obstacle(method, sim1_near_obstacle):
    g = nb.stress_gains()
    r = nb.numpy_plan(sim1_near_obstacle, method, 10, STEPS, gains=g)
    assert np.sum(r.active > 0) >= 3, "the repulsion hardly acted: the test would not test it"
    q_jax = nb.jax_trajectory(sim1_near_obstacle, method, 10, STEPS, gains=g)
    assert _max_diff(r.q, q_jax) < TRAJ_TOL


def test_svd_pinv_option_runs():
    r = nb.numpy_plan("sim1", "points", 10, 3, pinv="svd")
    assert r.q.shape == (4, 3, 3) and np.all(np.isfinite(r.q))
    with pytest.raises(ValueError, match="pinv"):
        nb.numpy_plan("sim1", "points", 10, 1, pinv="nope")
