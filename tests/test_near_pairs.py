"""Exact closest pairs only within reach (softplan_jax.geometry._near_pairs).

References: the full solver for every solved pair, the carried bound (the last exact distance
less the motion bounds) for every kept pair, and one member at a time for the batch's folded
polish. The rollout checks (records exact within reach, lower bounds beyond) are in
tests/test_warm_start.py, on the compilation of test_plan_batch_matches_single, and
tests/test_moving.py; the tree planned with every pair solved (``--exact-clearances``) in
tests/test_cli.py.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.geometry import _near_pairs as near
from softplan_jax.geometry import _warm_start as ws
from softplan_jax.geometry._closest import DEFAULT_OPTIONS
from softplan_jax.geometry._closest_newton import Segment, solve_pair_reduced
from softplan_jax.geometry._closest_pairs import NearPairs, WarmPairs
from softplan_jax.geometry._kinematics import segment_frames
from softplan_jax.planning._engine import closest_pairs

REACH = 1.5  # distance below which a pair is solved, in the cases below


def _cases():
    """4 members (2 curves, 3 segments): the first fresh, then carried bounds on both sides of
    REACH, with a padding slot in member 2."""
    rng = np.random.default_rng(21)
    qs = np.stack([np.full((4, 3), 1.0), rng.uniform(-1.5, 1.5, (4, 3)), rng.uniform(-np.pi, np.pi, (4, 3))], -1)
    coeffs = rng.normal(0.0, 1.0, (4, 2, 3, 3))
    coeffs[:, :, 2, 0] += 1.5
    curves = sp.PolynomialCurve(jnp.asarray(coeffs), jnp.tile(jnp.array([-1.0, 1.0]), (4, 2, 1)))
    data = jax.vmap(jax.vmap(lambda c: ws.curve_data(c, DEFAULT_OPTIONS)))(curves)
    u_prev = jnp.asarray(rng.uniform(-1.0, 1.0, (4, 2, 3)))
    lower = jnp.asarray(rng.uniform(0.5, 2.5, (4, 2, 3)))
    bound = jnp.asarray(rng.uniform(0.0, 0.2, (4, 3)))
    fresh = jnp.array([True, False, False, False])
    active = jnp.array([[True, True], [True, True], [True, False], [True, True]])
    return jnp.asarray(qs), curves, data, (u_prev, lower), bound, fresh, active


def _member(q, c, d, state, bound, f, a):
    cps, (u, lower), fb = near.near_curves(q, c, d, state, bound, f, a, REACH, DEFAULT_OPTIONS)
    return cps.distance, u, lower, fb


@jax.jit
def _full(q, c, d):
    """Every (curve, segment) pair of one member by the full solver: d2 (m, n)."""
    segs = Segment.from_frame(q, *segment_frames(q))
    solve = jax.vmap(lambda c, d: jax.vmap(lambda seg: solve_pair_reduced(seg, c, d.u_grid, d.C_grid,
                                                                          DEFAULT_OPTIONS))(segs))
    return solve(c, d)[2]


def test_solved_pairs_exact_kept_pairs_carry_their_bound():
    """A pair whose carried bound (lower - bound) is below the reach, and every pair of the
    fresh member, gets the full solver's distance; the others keep the bound. A curve reports
    the smaller of its solved distances and kept bounds."""
    args = _cases()
    q, curves, data, (_, lower), bound, fresh, active = args
    run = jax.jit(_member)
    kept_seen = solved_seen = 0
    for b in range(4):
        member = jax.tree_util.tree_map(lambda x, b=b: x[b], args)
        dist, _, lower_next, fb = (np.asarray(x) for x in run(*member))
        exact = np.sqrt(np.asarray(_full(q[b], *jax.tree_util.tree_map(lambda x, b=b: x[b], (curves, data)))))
        carried = np.asarray(lower[b] - bound[b][None, :])
        act = np.asarray(active[b])[:, None]
        solve = act & (bool(fresh[b]) | (carried < REACH))
        np.testing.assert_allclose(lower_next[solve], exact[solve], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(lower_next[~solve], carried[~solve])
        rows = np.asarray(active[b])
        np.testing.assert_allclose(dist[rows], np.min(np.where(solve, exact, carried), axis=1)[rows], atol=1e-9)
        assert int(fb) <= int(solve.sum())
        kept_seen += int((~solve & act).sum())
        solved_seen += int(solve.sum())
    assert kept_seen > 0 and solved_seen > 0, (kept_seen, solved_seen)


def test_batched_polish_equals_one_member_at_a_time():
    """Under vmap the pairs to solve of the whole batch are polished together (the batching
    rule of _near_pairs._polish_fn): each member's answers as alone."""
    args = _cases()
    batched = jax.jit(jax.vmap(_member))(*args)
    single = jax.jit(_member)
    for b in range(4):
        ref = single(*jax.tree_util.tree_map(lambda x, b=b: x[b], args))
        for x, y in zip(batched, ref, strict=True):
            x, y = np.asarray(x[b]), np.asarray(y)
            if b == 2 and x.ndim:  # the padding slot's values are meaningless (but finite)
                x, y = x[:1], y[:1]
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-13)


def test_provider_by_options():
    """NearPairs for the default options; the certified warm start of every pair with
    far_margin None or the exponential repulsion (it acts at any distance)."""
    assert closest_pairs(sp.PlanOptions()) == NearPairs(DEFAULT_OPTIONS, sp.PlanOptions().far_margin)
    assert isinstance(closest_pairs(sp.PlanOptions(far_margin=None)), WarmPairs)
    assert isinstance(closest_pairs(sp.PlanOptions(repulsion="exponential")), WarmPairs)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "0.2", True])
def test_far_margin_must_be_a_finite_non_negative_number(bad):
    with pytest.raises(ValueError, match="far_margin"):
        sp.make_options(far_margin=bad)
