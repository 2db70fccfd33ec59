"""The global fallback: RRT-Connect in configuration space with certified edges.

When the potential-field planner (paper eq. 9) stalls or runs out of steps,
:func:`global_search` looks for a path from where it stopped to one of the
certified goal configurations of :mod:`softplan_jax.search.reach`:

* **Certified motions.** Every motion is a straight line in q (phi moves the
  short way round: :func:`wrap_delta`), walked by conservative advancement:
  at q, the exact clearance c of every obstacle (paper §2.3, the closest-point
  solver whose convergence is certified) and the sound motion bound B of the
  rest of the line (:func:`~softplan_jax.geometry.kinematics.motion_bound`) give the
  fraction ``alpha = min(1, f (c - 2 contact) / B)`` of it that no arm point
  can cross an obstacle on: the local planner's safe step,
  :func:`~softplan_jax.planning.step.safe_scale`. A motion advances until it reaches its end, a solve does not
  converge, or its substeps run out (near an obstacle the substeps shrink
  geometrically); what it reaches is proven collision-free, all the way.
* **RRT-Connect** (Kuffner & LaValle 2000) with a tree at the start and a tree
  whose roots are up to ``goal_roots`` certified goal configurations; trees
  alternate; an extension moves towards a random configuration by at most
  ``extend_distance`` of motion bound; the other tree then tries to connect
  to the new node in one straight certified motion. Nearest neighbours by the
  motion bound itself (a bound on how far the arm moves). Fixed-size trees, a
  ``while_loop`` over iterations: a batch of scenes runs vmapped in one
  compiled program (the loop runs until every scene is connected or the
  iterations are spent).
* **Shortcuts and smoothing.** Random shortcuts (a straight certified motion
  between two path nodes replaces the nodes between them), then passes that
  move each inner node halfway towards the midpoint of its neighbours when both
  new motions are certified.
* **The returned path** walks the final polyline again by conservative
  advancement, with steps of at most ``step_motion`` of motion bound: every
  step of it satisfies the swept proof of :func:`softplan_jax.geometry.clearance.swept_clear`
  (the exact clearance at its start exceeds its motion bound plus the contact
  tolerance), so the path is collision-free by construction, and the tests
  check it against the brute-force :func:`~softplan_jax.geometry.clearance.dense_trajectory_clearance`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..geometry.closest import SolverOptions
from ..geometry.kinematics import motion_bound, tip_position
from ..planning.step import safe_scale
from ..scenarios import Scenario
from .reach import ReachOptions, clearances, random_configurations

__all__ = ["wrap_delta", "advance", "global_search", "SearchResult"]


def wrap_delta(q_a, q_b):
    """``q_b - q_a`` with each phi difference wrapped to [-pi, pi): the straight
    line from q_a along it turns every bending plane the short way round."""
    d = q_b - q_a
    dphi = jnp.mod(d[..., 2] + math.pi, 2.0 * math.pi) - math.pi
    return d.at[..., 2].set(dphi)


def _bound(q_a, dq):
    """Motion bound of the whole arm for the line q_a -> q_a + dq."""
    return motion_bound(q_a, q_a + dq)[-1]


def advance(q_a, q_b, scenario: Scenario, substeps: int, options: ReachOptions, solver: SolverOptions,
            contact: float):
    """Walk the straight line q_a -> q_a + wrap_delta(q_a, q_b) by conservative advancement.

    Returns ``(q, t, reached)``: the configuration reached, its fraction t of
    the line, and ``t == 1``. Every configuration on the line up to t is
    collision-free (module docstring). It stops early after ``substeps``
    substeps (near an obstacle the substeps shrink with the clearance), or
    where a solve does not converge (t = 0 when that is at q_a).
    """
    dq = wrap_delta(q_a, q_b)
    q_e = q_a + dq
    floor = 2.0 * contact
    dtype = q_a.dtype

    def cond(state):
        k, t, stop = state
        return (k < substeps) & (t < 1.0) & ~stop

    def body(state):
        k, t, _ = state
        q = q_a + t * dq
        c, _, ok = clearances(q, scenario, solver)
        alpha = safe_scale(q, q_e, c, floor, options.safe_fraction)[0]
        good = ok & jnp.isfinite(alpha) & (alpha > 0)
        alpha = jnp.where(good, alpha, 0.0)
        t_new = jnp.where(alpha >= 1.0, 1.0, t + alpha * (1.0 - t))
        return k + 1, t_new.astype(dtype), ~good

    _, t, _ = jax.lax.while_loop(cond, body, (jnp.zeros((), jnp.int32), jnp.zeros((), dtype), jnp.zeros((), bool)))
    return q_a + t * dq, t, t >= 1.0


class _Trees(NamedTuple):
    nodes: jax.Array  # (2, T, n, 3): tree 0 grows from the start, tree 1 from the goal roots
    parent: jax.Array  # (2, T) int32, -1 for a root
    count: jax.Array  # (2,) int32 nodes in use
    done: jax.Array  # () bool: connected
    link: jax.Array  # (2,) int32: the connection joins node link[0] of tree 0 to node link[1] of tree 1
    it: jax.Array  # () int32 iterations run
    key: jax.Array


def _nearest(nodes, count, q):
    """Index of the node (of the first ``count``) whose motion to q has the smallest bound."""
    d = jax.vmap(lambda p: _bound(p, wrap_delta(p, q)))(nodes)
    d = jnp.where(jnp.arange(nodes.shape[0], dtype=count.dtype) < count, d, jnp.inf)
    return jnp.argmin(d)


def _connect_trees(scenario: Scenario, q_starts, n_starts, q_goals, n_goals, key, options: ReachOptions, solver,
                   contact):
    """RRT-Connect: grow both trees until they connect or the iterations run out.
    Tree 0's roots are the first n_starts rows of q_starts, tree 1's the first n_goals of q_goals."""
    T = int(options.tree_size)
    n = q_starts.shape[1]
    dtype = q_starts.dtype
    nodes = jnp.zeros((2, T, n, 3), dtype)
    nodes = nodes.at[0, : q_starts.shape[0]].set(q_starts[:T]).at[1, : q_goals.shape[0]].set(q_goals[:T])
    parent = jnp.full((2, T), -1, jnp.int32)
    count = jnp.stack([jnp.minimum(n_starts, T), jnp.minimum(n_goals, T)]).astype(jnp.int32)
    trees = _Trees(nodes, parent, count, jnp.zeros((), bool), jnp.zeros((2,), jnp.int32), jnp.zeros((), jnp.int32), key)

    def add(trees, tree, q, par, allowed):
        idx = jnp.minimum(trees.count[tree], T - 1)
        ok = allowed & (trees.count[tree] < T)
        nodes = trees.nodes.at[tree, idx].set(jnp.where(ok, q, trees.nodes[tree, idx]))
        parent = trees.parent.at[tree, idx].set(jnp.where(ok, par, trees.parent[tree, idx]))
        count = trees.count.at[tree].add(ok.astype(jnp.int32))
        return trees._replace(nodes=nodes, parent=parent, count=count), idx, ok

    def cond(trees):
        return ~trees.done & (trees.it < options.iterations) & (trees.count[0] > 0) & (trees.count[1] > 0)

    def body(trees):
        a = trees.it % 2
        b = 1 - a
        key, k_rand = jax.random.split(trees.key)
        q_rand = random_configurations(k_rand, scenario, options, 1)[0]
        # Extend tree a towards the sample by at most extend_distance of motion bound.
        near = _nearest(trees.nodes[a], trees.count[a], q_rand).astype(jnp.int32)
        q_near = trees.nodes[a, near]
        dq = wrap_delta(q_near, q_rand)
        B = _bound(q_near, dq)
        target = q_near + jnp.minimum(1.0, options.extend_distance / jnp.maximum(B, 1e-30)) * dq
        q_new, t, _ = advance(q_near, target, scenario, options.extend_substeps, options, solver, contact)
        moved = t > 0.05
        trees, new_idx, added = add(trees, a, q_new, near, moved)
        # Connect tree b to the new node in one straight certified motion.
        near_b = _nearest(trees.nodes[b], trees.count[b], q_new).astype(jnp.int32)
        q_c, t_c, reached = advance(trees.nodes[b, near_b], q_new, scenario, options.connect_substeps,
                                    options, solver, contact)
        joined = added & reached
        trees, _, _ = add(trees, b, q_c, near_b, added & ~reached & (t_c > 0.05))
        link = jnp.where(a == 0, jnp.stack([new_idx, near_b]), jnp.stack([near_b, new_idx])).astype(jnp.int32)
        return trees._replace(done=joined, link=jnp.where(joined, link, trees.link), it=trees.it + 1, key=key)

    return jax.lax.while_loop(cond, body, trees)


def _chain(parent, start, T: int):
    """(T,) node indices from ``start`` up to its root, then -1s."""

    def step(k, _):
        return jnp.where(k >= 0, parent[jnp.maximum(k, 0)], -1), k

    _, idx = jax.lax.scan(step, start, None, length=T)
    return idx


def _tree_path(trees: _Trees, T: int):
    """The connected path (2T, n, 3) from a start root to a goal root, its node count,
    and the index of its start root."""
    ca = _chain(trees.parent[0], trees.link[0], T)
    cb = _chain(trees.parent[1], trees.link[1], T)
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


def _shortcut(path, length, key, scenario, options: ReachOptions, solver, contact):
    """Random shortcuts: a certified straight motion from node i to node j >= i + 2
    replaces the nodes between them."""
    P = path.shape[0]

    def attempt(_, state):
        path, length, key = state
        key, ki, kj = jax.random.split(key, 3)
        i = jax.random.randint(ki, (), 0, jnp.maximum(length - 2, 1), dtype=jnp.int32)
        j = jax.random.randint(kj, (), i + 2, jnp.maximum(length, i + 3), dtype=jnp.int32)
        possible = j <= length - 1
        _, _, reached = advance(path[i], path[jnp.minimum(j, P - 1)], scenario, options.connect_substeps,
                                options, solver, contact)
        cut = possible & reached
        removed = jnp.where(cut, j - i - 1, 0)
        p = jnp.arange(P, dtype=jnp.int32)
        src = jnp.where(p <= i, p, jnp.minimum(p + removed, P - 1))
        return path[src], length - removed, key

    if options.shortcut_attempts == 0:
        return path, length
    path, length, _ = jax.lax.fori_loop(0, options.shortcut_attempts, attempt, (path, length, key))
    return path, length


def _smooth(path, length, scenario, options: ReachOptions, solver, contact):
    """Passes over the inner nodes: node k moves halfway towards the midpoint of its
    neighbours when both new motions are certified (else it stays)."""

    def node(k, path):
        p_k = path[k]
        a = p_k + wrap_delta(p_k, path[k - 1])
        b = p_k + wrap_delta(p_k, path[k + 1])
        cand = p_k + 0.5 * (0.5 * (a + b) - p_k)
        _, _, r1 = advance(path[k - 1], cand, scenario, options.extend_substeps, options, solver, contact)
        _, _, r2 = advance(cand, path[k + 1], scenario, options.extend_substeps, options, solver, contact)
        return path.at[k].set(jnp.where(r1 & r2, cand, p_k))

    def one_pass(_, path):
        def cond(state):
            return state[0] < length - 1

        def body(state):
            k, path = state
            return k + 1, node(k, path)

        return jax.lax.while_loop(cond, body, (jnp.ones((), jnp.int32), path))[1]

    return jax.lax.fori_loop(0, options.smooth_passes, one_pass, path)


def _unwrap(path):
    """The polyline with each node moved by whole turns of phi so that consecutive nodes
    differ by wrap_delta: the straight lines between the stored nodes are the certified motions."""

    def step(prev, q):
        q_u = prev + wrap_delta(prev, q)
        return q_u, q_u

    _, rest = jax.lax.scan(step, path[0], path[1:])
    return jnp.concatenate([path[:1], rest])


def _densify(path, length, scenario, options: ReachOptions, solver, contact):
    """Walk the polyline by conservative advancement in steps of at most step_motion:
    ``(steps (S + 1, n, 3), count, complete)``; steps[0] is the first node."""
    S = int(options.path_steps)
    floor = 2.0 * contact
    path = _unwrap(path)
    dtype = path.dtype
    out = jnp.broadcast_to(path[0], (S + 1, *path.shape[1:]))

    def cond(state):
        k, e, _, _, stuck = state
        return (e < length - 1) & (k < S) & ~stuck

    def body(state):
        k, e, t, out, _ = state
        q_a, q_e = path[e], path[e + 1]
        q = q_a + t * (q_e - q_a)
        c, _, ok = clearances(q, scenario, solver)
        alpha = safe_scale(q, q_e, c, floor, options.safe_fraction, cap=options.step_motion)[0]
        good = ok & jnp.isfinite(alpha) & (alpha > 0)
        alpha = jnp.where(good, alpha, 0.0)
        t_new = jnp.where(alpha >= 1.0, 1.0, t + alpha * (1.0 - t)).astype(dtype)
        end = t_new >= 1.0
        q_next = jnp.where(end, q_e, q_a + t_new * (q_e - q_a))
        out = out.at[k + 1].set(jnp.where(good, q_next, out[k + 1]))
        return (k + good.astype(jnp.int32), e + end.astype(jnp.int32), jnp.where(end, 0.0, t_new).astype(dtype),
                out, ~good)

    state = (jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), jnp.zeros((), dtype), out, jnp.zeros((), bool))
    k, e, _, out, _ = jax.lax.while_loop(cond, body, state)
    out = jnp.where((jnp.arange(S + 1, dtype=jnp.int32) <= k)[:, None, None], out, out[k])  # pad with the last step
    return out, k, e >= length - 1


class SearchResult(NamedTuple):
    """What :func:`global_search` returns for one scene (batched: leading axis B).

    Attributes:
      found: () bool, the trees connected and the returned path reaches its goal root.
      start: () int, the start root the path leaves from (a row of q_starts).
      q: (path_steps + 1, n, 3) the path, padded with its last configuration.
      steps: () int, steps of the path (q[: steps + 1] is it).
      iterations: () int, RRT-Connect iterations run.
      nodes: (2,) int, nodes of the start and goal trees.
      path_nodes: () int, nodes of the polyline after shortcuts.
    """

    found: jax.Array
    start: jax.Array
    q: jax.Array
    steps: jax.Array
    iterations: jax.Array
    nodes: jax.Array
    path_nodes: jax.Array


def global_search(scenario: Scenario, q_starts, n_starts, q_goals, n_goals, key, options: ReachOptions,
                  solver: SolverOptions, contact: float) -> SearchResult:
    """RRT-Connect from the first ``n_starts`` rows of q_starts to the first ``n_goals``
    rows of q_goals (certified goal configurations), shortcuts, smoothing and the
    certified path (traceable; vmap over scenes).

    Args:
      scenario: one Scenario.
      q_starts: (R, n, 3) collision-free start roots (configurations the local
        planner passed through); n_starts: () int, how many are real.
      q_goals: (G, n, 3) goal roots; n_goals: () int, how many are real (0: no search).
      key: PRNG key of the samples and shortcuts.
      options: :class:`~softplan_jax.search.reach.ReachOptions` (static).
      solver: the exact solver's options (static); contact: the contact tolerance.
    """
    T = int(options.tree_size)
    k_tree, k_cut = jax.random.split(key)
    trees = _connect_trees(scenario, q_starts, n_starts, q_goals, n_goals, k_tree, options, solver, contact)
    path, length, start = _tree_path(trees, T)
    path, length = _shortcut(path, length, k_cut, scenario, options, solver, contact)
    if options.smooth_passes:
        path = _smooth(path, length, scenario, options, solver, contact)
    steps_q, steps, complete = _densify(path, length, scenario, options, solver, contact)
    found = trees.done & complete
    return SearchResult(found, start, steps_q, jnp.where(found, steps, 0), trees.it, trees.count,
                        jnp.where(found, length, 0))


def tip_error(scenario: Scenario, q):
    """|goal - tip(q)|."""
    return jnp.linalg.norm(scenario.goal - tip_position(q))
