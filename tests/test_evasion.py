"""The evasive step's parts (issue 38), against independent references: SciPy's SLSQP for the
barrier filter's quadratic program, central finite differences for the clearance gradients, and
the brute force of the oracle (its own kinematics, the curve moved by SciPy's expm, sampled in
space and time) for the proof in time. The rollouts that use them are in test_moving.py."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize

import softplan_jax as sp
from softplan_jax.geometry._obstacles import radius_and_mask
from softplan_jax.planning._evasion import barrier_velocity, certify_motion, clearance_gradients
from softplan_jax.testing import oracle

PAD = dict(curve_slots=5, degree=2)
SOLVER = sp.geometry.SolverOptions()


def _qp_reference(v0, a, b):
    """min |v - v0|^2 s.t. a v >= b, by SciPy's SLSQP (tight tolerances)."""
    res = minimize(lambda v: np.sum((v - v0) ** 2), v0, jac=lambda v: 2 * (v - v0), method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda v: a @ v - b, "jac": lambda v: a}],
                   options={"ftol": 1e-14, "maxiter": 500})
    assert res.success, res.message
    return res.x


@pytest.mark.parametrize("rows", [1, 3])
def test_barrier_velocity_is_the_projection(rows):
    rng = np.random.default_rng(rows)
    v0 = rng.normal(size=9)
    a = rng.normal(size=(rows, 9))
    b = a @ v0 + rng.uniform(0.2, 1.0, rows)  # every row violated at v0
    b[-1] -= 3.0 if rows > 1 else 0.0  # ... but the last of several: inactive
    sweeps = 8 if rows == 1 else 200  # one row: exact in one pass; several: the row-action method converges
    v = np.asarray(barrier_velocity(jnp.asarray(v0), jnp.asarray(a), jnp.asarray(b), sweeps))
    np.testing.assert_allclose(v, _qp_reference(v0, a, b), atol=1e-7)
    assert np.all(a @ v >= b - 1e-9)
    # Inactive rows (a = 0, b = -inf) change nothing; theta-free degenerate input stays finite.
    a0 = np.vstack([a, np.zeros((1, 9))])
    b0 = np.append(b, -np.inf)
    v_pad = np.asarray(barrier_velocity(jnp.asarray(v0), jnp.asarray(a0), jnp.asarray(b0), sweeps))
    np.testing.assert_allclose(v_pad, v, atol=1e-12)


def test_barrier_velocity_has_finite_gradients():
    v0, a, b = jnp.ones(6), jnp.zeros((2, 6)), jnp.array([1.0, -jnp.inf])
    g = jax.grad(lambda v0: jnp.sum(barrier_velocity(v0, a, b)))(v0)
    assert np.all(np.isfinite(np.asarray(g)))


def _scene():
    """Two wires near a bent arm, padded to the tree's shape."""
    wires = [sp.line_segment([0.9, -0.4, 0.9], [0.9, 1.6, 1.0]), sp.line_segment([-0.2, 0.5, 0.3], [0.6, 0.5, 1.6])]
    return sp.make_scenario(jnp.asarray([1.2, 0.9, 1.4]), wires, **PAD)


@jax.jit  # one program for the gradients and every finite-difference evaluation of both cases
def _gradients_and_distances(q, scene):
    _, mask = radius_and_mask(scene)
    truth = sp.geometry.true_closest(q, scene, SOLVER)
    return clearance_gradients(q, truth, mask), jnp.where(mask, truth.distance, 0.0)


@pytest.mark.parametrize("straight", [False, True])
def test_clearance_gradients_match_finite_differences(straight):
    scene = _scene()
    rng = np.random.default_rng(3)
    q = np.column_stack([np.full(3, 0.45), rng.uniform(0.2, 0.8, 3), rng.uniform(-1.0, 1.0, 3)])
    if straight:
        q[:, 1] = 0.0  # theta = 0: an ordinary input
    _, mask = radius_and_mask(scene)
    both = functools.partial(_gradients_and_distances, scene=scene)
    a = np.asarray(both(jnp.asarray(q))[0])
    assert np.all(np.isfinite(a)) and np.all(a[~np.asarray(mask)] == 0)
    h = 1e-6
    fd = np.zeros_like(a)
    for i in range(q.size):
        e = np.zeros(q.size)
        e[i] = h
        e = e.reshape(q.shape)
        fd[:, i] = (np.asarray(both(jnp.asarray(q + e))[1]) - np.asarray(both(jnp.asarray(q - e))[1])) / (2 * h)
    np.testing.assert_allclose(a[np.asarray(mask)], fd[np.asarray(mask)], atol=1e-6)


def test_certified_motion_is_clear_by_brute_force():
    """Random straight motions near a moving wire: every motion proven clear is clear at dense
    samples in space and time (the oracle); a start at the floor and want=False prove nothing."""
    wire = sp.line_segment([0.9, 0.4, 1.2], [0.9, 2.0, 1.2])
    scene = sp.make_scenario(jnp.asarray([1.2, 0.9, 1.4]), [wire], **PAD)
    m = sp.make_moving_scenario(scene, [sp.moving.curve_motion(shift=(0.0, 0.0, 0.8), omega=1.0)])
    speed = sp.moving.speed_bounds(m)
    radius, mask = radius_and_mask(scene)
    dt, floor, f = 0.1, 2e-6, 0.8

    @jax.jit
    def prove(q_a, q_b, t_a, want):
        d = sp.geometry.true_closest(q_a, sp.moving.scenario_at(m, t_a), SOLVER).distance
        c = jnp.where(mask, d - radius, jnp.inf)
        return certify_motion(m, q_a, q_b, t_a, c, speed, dt, floor, f, SOLVER, 16, want), c

    rng = np.random.default_rng(0)
    motion = {k: np.asarray(v[0]) for k, v in m.motion._asdict().items()}
    args = (np.asarray(scene.curves.coeffs[:1]), np.asarray(scene.curves.u_range[:1]),
            np.asarray(scene.curves.radius[:1]), [motion])
    proven_count = 0
    for _ in range(12):
        q_a = np.column_stack([rng.uniform(0.35, 0.55, 3), rng.uniform(0.1, 1.0, 3), rng.uniform(-1.5, 1.5, 3)])
        q_b = q_a + rng.normal(scale=0.08, size=(3, 3))
        t_a = float(rng.uniform(0.0, 6.0))
        (proven, pieces), _ = prove(jnp.asarray(q_a), jnp.asarray(q_b), t_a, True)
        if bool(proven):
            proven_count += 1
            brute = oracle.moving_min_clearance(np.stack([q_a, q_b]), np.array([t_a, t_a + dt]), *args, substeps=40)
            assert brute > floor, (brute, int(pieces))
    assert proven_count >= 3  # the check above ran
    (proven, pieces), _ = prove(jnp.asarray(q_a), jnp.asarray(q_b), t_a, False)
    assert not bool(proven) and int(pieces) == 0
