"""Batches: the LAPACK-free small solve, plan_batch in chunks with progress,
and plan_batch sharded over 2 host devices.

* :func:`softplan_jax.numerics.solve_small` (the planner's and the swept
  check's 3x3 solves): backward stable against NumPy's LAPACK solve over
  condition numbers up to 1e12, pivots, differentiable; no LAPACK custom call
  left in a lowered rollout or collision check. (jaxlib's batched LAPACK
  kernels split a large batch over XLA's intra-op thread pool and wait for it:
  a batch sharded over as many CPU devices as the pool has threads deadlocked.)
* ``plan_batch(chunk=...)``: the same statuses, iterations and trajectories (to
  rounding: a vmapped program's rounding depends on its batch size) as one
  call; equal chunk shapes compile once; ``progress=True`` writes to stderr.
* 2 host devices (``XLA_FLAGS=--xla_force_host_platform_device_count=2``, in a
  subprocess: the device count is fixed when jax starts): the sharded
  plan_batch, collision checks included, finishes and gives the statuses and
  iterations of the 1-device run, trajectories to rounding (see
  :func:`test_two_host_devices_match_one`).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.metrics import apply_collision_checks
from softplan_jax.numerics import solve_small
from softplan_jax.planner import make_options, rollout_batch, rollout_jit

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAD = dict(curve_slots=5, degree=2)


# ----------------------------------------------------------------------------
# solve_small


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_solve_small_backward_stable(n):
    rng = np.random.default_rng(n)
    for cond in (1.0, 1e4, 1e8, 1e12):
        U, _ = np.linalg.qr(rng.normal(size=(200, n, n)))
        V, _ = np.linalg.qr(rng.normal(size=(200, n, n)))
        A = (U * np.logspace(0, -np.log10(cond), n)[None, None, :]) @ V.transpose(0, 2, 1)
        B = rng.normal(size=(200, n, 4))
        X = np.asarray(jax.vmap(solve_small)(jnp.asarray(A), jnp.asarray(B)))
        # Backward error |A X - B| / (|A| |X|) at rounding level, whatever the conditioning.
        res = np.linalg.norm(A @ X - B, axis=(1, 2)) / (np.linalg.norm(A, axis=(1, 2)) * np.linalg.norm(X, axis=(1, 2)))
        assert res.max() < 1e-15, (cond, res.max())
        # Forward error within conditioning of LAPACK's answer.
        Xr = np.linalg.solve(A, B)
        rel = np.linalg.norm(X - Xr, axis=(1, 2)) / np.linalg.norm(Xr, axis=(1, 2))
        assert rel.max() < 100 * cond * np.finfo(np.float64).eps, (cond, rel.max())
        # A vector right-hand side.
        x = np.asarray(solve_small(jnp.asarray(A[0]), jnp.asarray(B[0, :, 0])))
        assert np.linalg.norm(A[0] @ x - B[0, :, 0]) < 1e-15 * np.linalg.norm(A[0]) * np.linalg.norm(x)


def test_solve_small_pivots_and_singular():
    # A zero leading entry needs a row exchange.
    P = jnp.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(np.asarray(solve_small(P, jnp.array([1.0, 2.0, 3.0]))), [3.0, 1.0, 2.0])
    # Exactly singular: not finite (as LAPACK's solve), never a silent wrong number.
    assert not np.all(np.isfinite(np.asarray(solve_small(jnp.zeros((3, 3)), jnp.ones(3)))))
    with pytest.raises(ValueError, match="solve_small"):
        solve_small(jnp.zeros((3, 2)), jnp.ones(3))
    # Larger systems fall back to jnp.linalg.solve.
    A = jnp.eye(6) * 2.0
    np.testing.assert_allclose(np.asarray(solve_small(A, jnp.ones(6))), 0.5)


def test_solve_small_gradient_matches_linalg_solve():
    rng = np.random.default_rng(7)
    A = jnp.asarray(rng.normal(size=(3, 3))) + 3.0 * jnp.eye(3)
    B = jnp.asarray(rng.normal(size=(3, 5)))

    def loss(solve):
        return lambda A, B: jnp.sum(jnp.sin(solve(A, B)))

    for argnum in (0, 1):
        g = jax.grad(loss(solve_small), argnum)(A, B)
        ref = jax.grad(loss(jnp.linalg.solve), argnum)(A, B)
        np.testing.assert_allclose(np.asarray(g), np.asarray(ref), rtol=1e-12, atol=1e-14)


def test_no_lapack_call_in_rollouts_and_checks():
    """The deadlock's cause, checked at the source: no LAPACK custom call (jaxlib's
    ``lapack_*_ffi``, whose batched kernels wait on XLA's intra-op pool) in the
    lowered checked rollout (both methods), the batched rollout, or the post-hoc checks."""
    sc = sp.paper_scenario("tree", **PAD)
    gains = sp.default_gains()
    texts = []
    for method in ("curve", "points"):
        texts.append(rollout_jit.lower(sc, gains, make_options(method), 20).as_text())
    batch = sp.stack_scenarios([sc, sc])
    texts.append(rollout_batch.lower(batch, gains, make_options("curve"), 20).as_text())
    r = jax.eval_shape(lambda s: sp.rollout(s, gains, make_options("curve", check_collisions=False), 20), sc)
    r = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), r)
    texts.append(jax.jit(lambda r, s: apply_collision_checks(r, s, make_options("curve"))).lower(r, sc).as_text())
    for text in texts:
        assert "lapack" not in text.lower()
    # The test can fail: jnp.linalg.solve lowers to a LAPACK call on CPU.
    A = jnp.eye(3)[None].repeat(4, 0)
    assert "lapack" in jax.jit(jax.vmap(jnp.linalg.solve)).lower(A, A).as_text().lower()
