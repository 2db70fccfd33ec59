"""Certified straight motions in configuration space, and the trees and polylines
made of them (the pieces of :func:`~softplan_jax.search._tree.global_search`).

A motion is a straight line in q (phi moves the short way round:
:func:`wrap_delta`) walked by conservative advancement: at q the exact clearance
c of every obstacle and the sound motion bound B of the rest of the line give
the fraction ``alpha = min(1, f (c - 2 contact) / B)`` of it that no arm point
can cross an obstacle on (:func:`~softplan_jax.planning._step.safe_scale`, the
local planner's safe step): :func:`substep`, :func:`advance`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..geometry._arm import PCC
from ..geometry._clearance import safety_floor
from ..geometry._closest import SolverOptions
from ..geometry._kinematics import motion_bound
from ..planning._step import safe_scale
from ..scenarios import Scenario
from ._reach import ReachOptions, clearances

__all__ = ["wrap_delta", "line_bound", "substep", "advance_fraction", "advance", "Trees", "nearest", "chain", "tree_path",
           "unwrap"]


def wrap_delta(q_a, q_b):
    """``q_b - q_a`` with each phi difference wrapped to [-pi, pi): the straight
    line from q_a along it turns every bending plane the short way round."""
    d = q_b - q_a
    dphi = jnp.mod(d[..., 2] + math.pi, 2.0 * math.pi) - math.pi
    return d.at[..., 2].set(dphi)


def line_bound(q_a, dq):
    """Motion bound of the whole PCC arm for the line q_a -> q_a + dq (the search's measure of
    how far apart two configurations are, whatever the arm model: the nearest node, the length
    of an extension; the certified motions use the model's own bound)."""
    return motion_bound(q_a, q_a + dq)[-1]


def substep(q_a, dq, q_e, t, scenario: Scenario, options: ReachOptions, solver: SolverOptions, contact: float,
            cap=None, arm=PCC):
    """One conservative-advancement substep of the motion q_a -> q_e (= q_a + dq) from its
    fraction t: the exact clearances at ``q = q_a + t dq``, the safe step
    ``alpha = safe_scale(q, q_e, c, 2 contact, f[, cap])`` and
    ``t_new = 1 if alpha >= 1 else t + alpha (1 - t)``. Returns ``(t_new, good)``; not
    good (a solve did not converge, or alpha is not > 0): t_new = t, the motion stops.
    ``arm``: the arm model whose clearances and motion bound these are."""
    q = q_a + t * dq
    c, _, ok = clearances(q, scenario, solver, arm)
    return advance_fraction(q, q_e, t, c, ok, options, contact, cap, arm)


def advance_fraction(q, q_e, t, c, ok, options: ReachOptions, contact: float, cap=None, arm=PCC):
    """The rest of :func:`substep` once the exact clearances ``c`` at ``q`` (``ok``: every
    solve converged) are known: ``(t_new, good)`` (for a caller that solves at q itself)."""
    alpha = safe_scale(q, q_e, c, safety_floor(contact), options.safe_fraction, cap=cap, arm=arm)[0]
    good = ok & jnp.isfinite(alpha) & (alpha > 0)
    alpha = jnp.where(good, alpha, 0.0)
    return jnp.where(alpha >= 1.0, 1.0, t + alpha * (1.0 - t)).astype(q.dtype), good


def advance(q_a, q_b, scenario: Scenario, substeps: int, options: ReachOptions, solver: SolverOptions,
            contact: float, arm=PCC):
    """Walk the straight line q_a -> q_a + wrap_delta(q_a, q_b) by conservative advancement.

    Returns ``(q, t, reached)``: the configuration reached, its fraction t of
    the line, and ``t == 1``. Every configuration on the line up to t is
    collision-free (module docstring). It stops early after ``substeps``
    substeps (near an obstacle the substeps shrink with the clearance), or
    where a solve does not converge (t = 0 when that is at q_a). ``arm``: the arm model.
    """
    dq = wrap_delta(q_a, q_b)
    q_e = q_a + dq
    dtype = q_a.dtype

    def cond(state):
        k, t, stop = state
        return (k < substeps) & (t < 1.0) & ~stop

    def body(state):
        k, t, _ = state
        t_new, good = substep(q_a, dq, q_e, t, scenario, options, solver, contact, arm=arm)
        return k + 1, t_new, ~good

    _, t, _ = jax.lax.while_loop(cond, body, (jnp.zeros((), jnp.int32), jnp.zeros((), dtype), jnp.zeros((), bool)))
    return q_a + t * dq, t, t >= 1.0


class Trees(NamedTuple):
    """RRT-Connect's two fixed-size trees (T nodes each) and the search's progress."""

    nodes: jax.Array  # (2, T, n, 3): tree 0 grows from the start, tree 1 from the goal roots
    parent: jax.Array  # (2, T) int32, -1 for a root
    count: jax.Array  # (2,) int32 nodes in use
    done: jax.Array  # () bool: connected
    link: jax.Array  # (2,) int32: the connection joins node link[0] of tree 0 to node link[1] of tree 1
    it: jax.Array  # () int32 iterations run
    key: jax.Array  # the samples' key


def nearest(nodes, count, q):
    """Index of the node (of the first ``count``) whose motion to q has the smallest bound."""
    d = jax.vmap(lambda p: line_bound(p, wrap_delta(p, q)))(nodes)
    d = jnp.where(jnp.arange(nodes.shape[0], dtype=count.dtype) < count, d, jnp.inf)
    return jnp.argmin(d)


def chain(parent, start, T: int):
    """(T,) node indices from ``start`` up to its root, then -1s."""

    def step(k, _):
        return jnp.where(k >= 0, parent[jnp.maximum(k, 0)], -1), k

    _, idx = jax.lax.scan(step, start, None, length=T)
    return idx


def tree_path(trees: Trees, T: int):
    """The connected path (2T, n, 3) from a start root to a goal root, its node count,
    and the index of its start root."""
    ca = chain(trees.parent[0], trees.link[0], T)
    cb = chain(trees.parent[1], trees.link[1], T)
    la = jnp.sum(ca >= 0, dtype=jnp.int32)
    lb = jnp.sum(cb >= 0, dtype=jnp.int32)
    p = jnp.arange(2 * T, dtype=jnp.int32)
    from_a = p < la
    ia = ca[jnp.clip(la - 1 - p, 0, T - 1)]
    ib = cb[jnp.clip(p - la, 0, T - 1)]
    length = la + lb
    last = cb[jnp.clip(lb - 1, 0, T - 1)]
    ib = jnp.where(p < length, ib, last)
    path = jnp.where(from_a[:, None, None], trees.nodes[0, jnp.maximum(ia, 0)], trees.nodes[1, jnp.maximum(ib, 0)])
    return path, length, jnp.maximum(ca[jnp.clip(la - 1, 0, T - 1)], 0)


def unwrap(path):
    """The polyline with each node moved by whole turns of phi so that consecutive nodes
    differ by wrap_delta: the straight lines between the stored nodes are the certified motions."""

    def step(prev, q):
        q_u = prev + wrap_delta(prev, q)
        return q_u, q_u

    _, rest = jax.lax.scan(step, path[0], path[1:])
    return jnp.concatenate([path[:1], rest])
