"""Exact closest pairs only where they matter: the warm start of :mod:`._warm_start` for the
(segment, curve) pairs near enough to act on the step, a certified lower bound for the others.

Each pair carries, besides its u*, a lower bound ``D_lo`` on its distance: the exact distance where
it was last solved, less the distance its segment moved since (:func:`~._kinematics.motion_bound`
of each step; the distance to a set is 1-Lipschitz in the arm point, so for a static curve
``D(q_k) >= D(q_j) - sum of the bounds of steps j..k-1``; a moving curve's travel over those
steps is subtracted too). A pair whose bound is at or above the
``reach`` keeps it and skips its polish, certificate and full solve; every other pair is solved
as :func:`~._warm_start.warm_curves` solves it, and its bound becomes its new exact distance. A
curve whose nearest pair kept its bound reports that bound as its distance (a lower bound, never
above the exact distance). Under ``vmap`` the pairs to solve of the whole batch are folded into one
array and solved a chunk at a time (as the warm start's fallback), so a batch pays for the pairs
it needs, not for every pair of every scene. The reach the planner uses and what it changes:
docs, "How the planner works inside"."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..base._numerics import batch_folded, evaluate_where
from ._closest import SolverOptions, closest_from_pairs
from ._closest_newton import Segment
from ._kinematics import segment_frames
from ._warm_start import CurveData, Pairs, fallback, pair_picker, polish_and_certify

__all__ = ["near_curves"]

# The pairs to polish go through the polish loop in at most about NEAR_TRIPS chunks per step:
# chunk = the pairs (of the whole batch under vmap) / NEAR_TRIPS (docs: "How the planner works
# inside", "Exact solves only where they matter").
NEAR_TRIPS = 6


def near_curves(q, curves, data: CurveData, state, bound, fresh, active, reach, solver: SolverOptions,
                travel=None):
    """Closest pairs between the arm and a STACK of curves: exact where a pair's lower bound is
    below ``reach``, that bound elsewhere.

    Args:
      q: (n, 3) configuration (derivatives as in :func:`~._warm_start.warm_curves`).
      curves: a curve stack with leading axis m; data: their CurveData (m,).
      state: ``(u, D_lo)``, each (m, n): every pair's u* and the lower bound on its distance at
        the previous step (zeros before the first step).
      bound: (n,) how far each segment moved since the previous step (its motion bound).
      fresh: () bool, the first step: every active pair is solved in full.
      active: (m,) bool, False for padding slots (never solved).
      reach: () the distance (centre line to centre line) below which a pair is solved.
      solver: SolverOptions (static).
      travel: (m,) how far each curve can have moved since the previous step (None: static).

    Returns:
      ``(ClosestPoint with leading axis m, the next state (u, D_lo), fallbacks () int32: pairs
      that took the full solve)``. A curve whose nearest pair was not solved has as its distance
      that pair's bound, with a zero derivative; its points are placeholders (the arm's tip, the
      curve at the pair's last u*).
    """
    curves = curves.astype(q.dtype)
    segs = Segment.from_frame(q, *segment_frames(q))
    segs_ng, curves_ng, data = jax.tree_util.tree_map(jax.lax.stop_gradient, (segs, curves, data))
    u_prev, lower = jax.lax.stop_gradient(state)
    lower = lower - jax.lax.stop_gradient(bound)[None, :]
    if travel is not None:
        lower = lower - jax.lax.stop_gradient(travel)[:, None]
    # ~(lower >= reach): a NaN bound is solved (and gives NaN), never kept.
    need = active[:, None] & (fresh | ~(lower >= reach))
    pairs, certified = _polish_fn(solver)(segs_ng, curves_ng, data, u_prev, lower, need)
    fail = (fresh | ~certified) & need
    pairs = fallback(segs_ng, curves_ng, data, pairs, fail, solver)
    nearest = jnp.argmin(pairs.d2, axis=1)[:, None]
    kept = ~jnp.take_along_axis(need, nearest, axis=1)[:, 0]
    kept_bound = jnp.take_along_axis(lower, nearest, axis=1)[:, 0]
    cps = jax.vmap(lambda c, s, u, d2, conv: closest_from_pairs(segs, c, s, u, d2, conv))(
        curves, *_tip_where_kept(pairs, kept)
    )
    cps = cps._replace(distance=jnp.where(kept, jax.lax.stop_gradient(kept_bound), cps.distance))
    lower_next = jnp.where(need, jnp.sqrt(jnp.maximum(pairs.d2, 0.0)), lower)
    return cps, (pairs.u, lower_next), jnp.sum(fail).astype(jnp.int32)


def _tip_where_kept(pairs: Pairs, kept):
    """``(s, u, d2, converged)`` for :func:`~._closest.closest_from_pairs`, each (m, n): the
    pairs', except that a curve whose nearest pair kept its bound gets the arm's tip (the last
    segment, s = 1) as its placeholder point. The field's Jacobian of that point is the tip's,
    defined wherever the attraction's is: a segment's base (s = 0) of the first segment does not
    move with q, and with no damping the pseudo-inverse of its zero Jacobian is NaN (NaN * 0 =
    NaN, though the force there is 0)."""
    n = pairs.s.shape[1]
    last = (jnp.arange(n) == n - 1)[None, :]
    row = kept[:, None]
    s = jnp.where(row & last, 1.0, pairs.s).astype(pairs.s.dtype)
    d2 = jnp.where(row, jnp.where(last, 0.0, 1.0), pairs.d2).astype(pairs.d2.dtype)  # argmin: the tip
    return s, pairs.u, d2, pairs.converged | row


@functools.cache
def _polish_fn(solver: SolverOptions):
    """:func:`_polish_needed` for one SolverOptions, its batch axis folded into the pairs under
    vmap (:func:`~softplan_jax.base._numerics.batch_folded`, as the warm start's fallback;
    every input is stop_gradient-ed)."""
    return batch_folded(lambda segs, curves, data, u_prev, lower, need: _polish_needed(
        segs, curves, data, u_prev, lower, need, solver))


def _polish_needed(segs: Segment, curves, data: CurveData, u_prev, lower, need, solver: SolverOptions):
    """Polish and certify the pairs where ``need`` (lead + (m, n), any leading axes ``lead``), a
    chunk of the flattened pairs at a time (:func:`~softplan_jax.base._numerics.evaluate_where`).

    Returns ``(Pairs, certified)`` shaped like ``need``; a pair not needed keeps u_prev, s = 0,
    ``d2 = lower^2`` and counts as converged and certified."""
    total = need.size
    chunk = max(1, total // NEAR_TRIPS)
    pick = pair_picker(segs, curves, data, need.shape)
    u_f = u_prev.reshape(total)

    def one(idx):
        seg, curve, c = (jax.tree_util.tree_map(lambda x: x[None], part) for part in pick(idx))
        pair, cert = polish_and_certify(seg, curve, c, u_f[idx][None, None], solver)
        return Pairs(*(x[0, 0] for x in pair)), cert[0, 0]

    yes = jnp.ones(total, bool)
    fill = (Pairs(jnp.zeros(total, u_prev.dtype), u_f, (lower * lower).reshape(total), yes), yes)
    pairs, certified = evaluate_where(need.reshape(total), one, chunk, fill)
    return Pairs(*(x.reshape(need.shape) for x in pairs)), certified.reshape(need.shape)
