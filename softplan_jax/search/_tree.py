"""The global fallback's search: RRT-Connect (Kuffner & LaValle 2000) in configuration space with
certified edges, from where the potential-field planner (paper eq. 9) stopped to the certified goal
configurations of :mod:`softplan_jax.search._reach`. Every motion is a straight line in q walked by
conservative advancement (the exact clearance of paper §2.3 against the sound motion bound: the
local planner's safe step, :func:`~softplan_jax.planning._step.safe_scale`), so what it reaches is
collision-free all the way; random shortcuts and smoothing follow, the final polyline is walked
again in steps of at most ``step_motion`` of motion bound, and the check solves every step anew
and requires the swept proof of every motion between steps. The whole search runs as one loop with
one exact solve per iteration (:mod:`._machine`). Docs: Reaching every goal."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..geometry._arm import PCC
from ..geometry._closest import SolverOptions
from ..geometry._kinematics import tip_position
from ..planning._batching import lanes_map
from ..scenarios import Scenario
from ._machine import run_search
from ._motions import advance, substep, wrap_delta
from ._reach import ReachOptions, ik_result

__all__ = ["wrap_delta", "substep", "advance", "global_search", "global_search_batch", "reach_and_search_batch",
           "SearchResult"]


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
      clearance: (path_steps + 1, m) the exact clearance of every obstacle slot at every
        step of the path, solved anew after the walk (+inf: padding slots; the last step's
        repeated after the end; 0 where no path was found).
      proven: () bool, every motion between steps of the path passes the swept proof of
        :func:`~softplan_jax.geometry._clearance.swept_clear` at that recomputation (False
        where no path was found).
    """

    found: jax.Array
    start: jax.Array
    q: jax.Array
    steps: jax.Array
    iterations: jax.Array
    nodes: jax.Array
    path_nodes: jax.Array
    clearance: jax.Array
    proven: jax.Array


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
      options: :class:`~softplan_jax.search._reach.ReachOptions` (static).
      solver: the exact solver's options (static); contact: the contact tolerance.
    """
    batch = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], (scenario, q_starts, n_starts, q_goals, n_goals,
                                                                     key))
    return jax.tree_util.tree_map(lambda x: x[0], global_search_batch(*batch, options, solver, contact))


def global_search_batch(scenarios: Scenario, q_starts, n_starts, q_goals, n_goals, keys, options: ReachOptions,
                        solver: SolverOptions, contact: float) -> SearchResult:
    """:func:`global_search` of B scenes (every argument with a leading axis B), the
    scenes' searches in one loop (:func:`~softplan_jax.search._machine.run_search`); the
    same results as ``jax.vmap(global_search)``, without evaluating every phase of the
    search on every iteration."""
    return _result(*run_search(scenarios, q_starts, n_starts, q_goals, n_goals, keys, options, solver, contact))


def reach_and_search_batch(scenarios: Scenario, q_extra, ik_keys, proof, q_starts, n_starts, keys,
                           options: ReachOptions, solver: SolverOptions, contact: float, arm=PCC):
    """The global fallback's program for B scenes (every argument with a leading axis B): the IK
    of :func:`~softplan_jax.search._reach.goal_configurations` (``ik_keys``, extra starts
    ``q_extra``), then :func:`global_search_batch` from its first ``goal_roots`` results where
    the first is certified and ``proof`` (the goal proven unreachable) is False, in one loop
    with one exact solve site (:func:`~softplan_jax.search._machine.run_search`). ``arm``: the arm
    model (:mod:`~softplan_jax.geometry._arm`) the IK and the search certify.

    Returns ``(ik, search)``: ``ik`` as :func:`~softplan_jax.search._reach.goal_configurations`
    returns it (batched), ``search`` a :class:`SearchResult` (not found where the IK certified
    nothing or a proof holds)."""
    *found, ik = run_search(scenarios, q_starts, n_starts, None, None, keys, options, solver, contact,
                            ik=(ik_keys, q_extra, proof), arm=arm)
    return lanes_map(ik_result, ik), _result(*found)


def _result(trees, length, start, steps_q, steps, complete, clear, proven) -> SearchResult:
    found = trees.done & complete
    return SearchResult(found, start, steps_q, jnp.where(found, steps, 0), trees.it, trees.count,
                        jnp.where(found, length, 0), clear, proven & found)


def tip_error(scenario: Scenario, q):
    """|goal - tip(q)|."""
    return jnp.linalg.norm(scenario.goal - tip_position(q))

