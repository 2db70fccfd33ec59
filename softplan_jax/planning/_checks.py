"""The collision checks of a planning-only rollout (``check_collisions=False``) after the fact:
the true clearance at every step and during every motion between two steps, the rollout cut
and frozen at its first contact as the checked rollout would be."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._numerics import safe_norm
from ..base._status import Status
from ..geometry._clearance import (
    POST_HOC_CHUNK,
    SEARCH_ITERATIONS,
    between_steps,
    contact_tolerance,
    searched_motions,
    swept_clear,
)
from ..geometry._obstacles import clearance_of, radius_and_mask, true_closest
from ._records import Record, freeze

__all__ = ["apply_collision_checks"]


def _between(r, truths, c, scenario, options, contact):
    """``(cb (T, m), search (T, m))``: the clearance during each motion of the rollout and
    where it was searched (only where the swept proof fails, with ``options.swept_proof``)."""
    radius, mask = radius_and_mask(scenario)
    radius_sum = scenario.arm_radius + radius
    prev = jax.tree_util.tree_map(lambda x: x[:-1], truths)
    nxt = jax.tree_util.tree_map(lambda x: x[1:], truths)
    steps = jnp.arange(r.q.shape[0], dtype=r.iterations.dtype)
    moved = (steps[1:] <= r.iterations)[:, None] & mask  # (T, m): the motions the rollout made
    if not options.swept_proof:
        cb = jax.vmap(lambda qa, qb, ta, tb: between_steps(qa, qb, ta, tb, scenario, radius_sum))(
            r.q[:-1], r.q[1:], prev, nxt)
        return cb, moved
    q_ng, prev_ng, nxt_ng = jax.lax.stop_gradient((r.q, prev, nxt))
    proven = jax.vmap(lambda qa, qb, ta, ca: swept_clear(qa, qb, ta, ca, contact))(q_ng[:-1], q_ng[1:], prev_ng,
                                                                                   c[:-1])
    search = moved & ~proven
    found = searched_motions(q_ng[:-1], q_ng[1:], prev_ng, nxt_ng, scenario, search, SEARCH_ITERATIONS,
                             chunk=POST_HOC_CHUNK)
    return jnp.minimum(found, jnp.minimum(prev_ng.distance, nxt_ng.distance)) - radius_sum, search


def apply_collision_checks(r, scenario, options):
    """Add the true-clearance and between-step checks to a planning-only rollout, vectorised
    over time; the result equals the checked rollout's (the dynamics do not depend on the
    checks until the first contact, where the checked rollout stops).

    Args:
      r: an unbatched :class:`~softplan_jax.planning._records.Rollout` of a static scene with
        ``check_collisions=False`` (vmap this function over a batch).
      scenario: its Scenario.
      options: its PlanOptions (static: the solver, the contact tolerance, ``swept_proof``).

    Returns:
      The Rollout with the clearances, status, iterations, converged flags and between-step
      searches of a checked rollout, frozen after the first step whose clearance (at the step,
      or during the motion to it) is at or below the contact tolerance or NaN.
    """
    _, mask = radius_and_mask(scenario)
    contact = contact_tolerance(options, scenario.q0.dtype)
    truths = jax.vmap(lambda q: true_closest(q, scenario, options.solver))(r.q)
    c = jax.vmap(lambda t: clearance_of(t, scenario))(truths)
    cb, search = _between(r, truths, c, scenario, options, contact)
    cb = jnp.concatenate([c[:1], jnp.where(mask, cb, jnp.inf)])
    steps = jnp.arange(r.q.shape[0], dtype=r.iterations.dtype)
    nan = jnp.any(jnp.isnan(c), axis=1) | jnp.any(jnp.isnan(cb), axis=1)
    hit = (jnp.any(c <= contact, axis=1) | jnp.any(cb <= contact, axis=1) | nan) & (steps <= r.iterations)
    first = jnp.argmax(hit).astype(r.iterations.dtype)
    collided = jnp.any(hit)
    end = jnp.where(collided, first, r.iterations)
    # The checked rollout's status rule: a NaN clearance, then a contact.
    status = jnp.where(collided, jnp.where(nan[first], Status.NONFINITE, Status.COLLIDED), r.status)
    status = status.astype(r.status.dtype)
    converged = r.converged & jnp.all(jnp.where(mask, truths.converged, True), axis=1)
    searched = jnp.concatenate([jnp.zeros_like(search[:1]), search])
    # No step is taken from the step where the checked rollout stops.
    step_scale = jnp.where(steps < end, r.step_scale, 0.0)
    records = Record(r.q, r.tip, c, cb, step_scale, converged, r.fallbacks, searched)
    f = freeze(records, end, still=True)
    return r._replace(
        q=f.q, tip=f.tip, clearance=f.clearance, between=f.between, status=status,
        iterations=end.astype(r.iterations.dtype), step_scale=f.step_scale, converged=f.converged,
        fallbacks=f.fallbacks, between_searched=f.between_searched,
        reached=status == Status.REACHED, collided=status == Status.COLLIDED,
        min_clearance=jnp.minimum(jnp.min(f.clearance, initial=jnp.inf), jnp.min(f.between, initial=jnp.inf)),
        final_error=safe_norm(scenario.goal - f.tip[-1]),
    )
