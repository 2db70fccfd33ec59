"""Plan with the global fallback (docs: Reaching every goal). :func:`plan_fallback` runs the
potential-field planner of paper eq. (9) and, for every scene it leaves ``stalled`` or at
``max_steps``, decides reachability (:func:`~softplan_jax.search._reach.reachability`: status
``unreachable`` with its reason where no certified goal configuration is found) and otherwise
searches from configurations along the local path to the certified goal configurations
(:func:`~softplan_jax.search._tree.global_search`). The returned path is the local path up to the
configuration the search left from, then the search's, every step certified by the swept proof.
The IK, the search and the check of its path are one compiled program
(:func:`~softplan_jax.search._tree.reach_and_search_batch`), run on chunks of one shape: one scene
at a time by default, since a chunk runs its loops in lockstep until its slowest scene is done."""

from __future__ import annotations

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._status import Status, status_name
from ..geometry._arm import PCC
from ..geometry._clearance import contact_tolerance
from ..geometry._closest import DEFAULT_OPTIONS
from ..planning._batching import pad_batch
from ..planning._options import make_options
from ..planning._planner import PlanResult, arm_model, plan, plan_batch
from ..scenarios import Scenario, stack_scenarios
from ._reach import ReachOptions, check_reach_options, scene_of, unreachable_proof
from ._tree import reach_and_search_batch

__all__ = ["plan_fallback", "rescue", "rescue_batch"]

# The local planner's endings the global fallback rescues (the others stand: reached, collided, ...).
RESCUED = (Status.STALLED, Status.MAX_STEPS)


@functools.cache
def _fallback_jit(options: ReachOptions, solver, contact: float):
    """The fallback's one program: the IK, the search and its check (tree.reach_and_search_batch),
    the arm model an argument (the PCC arm has no leaves; a loaded arm's material is traced)."""
    def fallback(arm, scenarios, q_extra, ik_keys, proof, q_starts, n_starts, keys):
        return reach_and_search_batch(scenarios, q_extra, ik_keys, proof, q_starts, n_starts, keys, options, solver,
                                      contact, arm)

    return package_jit(fallback)


_tips_jit = package_jit(lambda arm, q: jax.vmap(arm.tip)(q), None)


def _start_roots(q_local: np.ndarray, count: int):
    """Indices of ``count`` configurations evenly spaced along the local path (start and end included)."""
    last = q_local.shape[0] - 1
    return np.unique(np.round(np.linspace(0.0, 1.0, count) * last).astype(int))


def _search_starts(q_local: np.ndarray, count: int):
    """The search's start roots after the local path: ``(q_starts (count, n, 3)`` padded with
    zeros, ``n_starts`` (int32), their indices in the path)."""
    idx = _start_roots(q_local, count)
    q_starts = np.zeros((count, *q_local.shape[1:]), q_local.dtype)
    q_starts[: len(idx)] = q_local[idx]
    return q_starts, np.int32(len(idx)), idx


def plan_fallback(scenarios: Scenario, method: str = "curve", n_points: int = 10, gains=None, max_steps: int = 600,
                  seed=0, *, reach: ReachOptions = ReachOptions(), chunk: int = 1, progress: bool = False,
                  model=None, **options):
    """Plan with the local planner, and where it stalls or runs out of steps decide
    reachability and search globally (module docstring).

    Args:
      scenarios: one Scenario or a batch (leading axis B).
      method, n_points, gains, max_steps, seed, **options: as :func:`~softplan_jax.plan`
        (the local planner's settings; ``options`` are :class:`~softplan_jax.PlanOptions` fields).
      reach: :class:`~softplan_jax.search._reach.ReachOptions` of the IK and of the search.
      chunk: scenes per compiled search call (vmapped; the last chunk is padded).
        Default 1: one scene at a time, the fastest on the CPU (docs: Reaching every goal).
      progress: one line per finished stage/chunk on stderr.
      model: None (the PCC arm) or a :class:`~softplan_jax.RodModel`: the loaded arm, for the
        local planner (as :func:`~softplan_jax.plan`) and the fallback alike (its IK, its
        certified motions and the check use the loaded tip, Jacobians, clearance and motion
        bound).

    Returns:
      A :class:`~softplan_jax.PlanResult` (one scene) or a list of them (a batch),
      with ``planner`` ("local": the local planner's path; "global": the local
      path up to where the search left it, then the search's path), ``reason``
      and ``best_error`` filled in (see :class:`~softplan_jax.PlanResult`).
    """
    if not isinstance(scenarios, Scenario):
        raise ValueError(f"scenarios must be a Scenario, got {type(scenarios).__name__}")
    check_reach_options(reach)
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk must be an int >= 1, got {chunk!r}")
    single = scenarios.q0.ndim == 2
    batch = stack_scenarios([scenarios]) if single else scenarios
    opts = make_options(method, n_points, **options)
    t0 = time.perf_counter()
    B = batch.q0.shape[0]
    if single:  # exactly plan's rollout (plan_batch's vmapped program rounds differently)
        results = [plan(scenarios, method, n_points, gains, max_steps, seed, model=model, **options)]
    else:
        r = jax.device_get(plan_batch(batch, method, n_points, gains, max_steps, seed, model=model, **options))
        results = [_local_result(r, b, batch) for b in range(B)]
    if progress:
        _say(f"plan_fallback: local planner on {B} scenes, {time.perf_counter() - t0:.1f} s")
    results = rescue(batch, results, opts, reach=reach, seed=seed, chunk=chunk, progress=progress, model=model)
    return results[0] if single else results


def rescue(scenarios: Scenario, results: list, options, *, reach: ReachOptions = ReachOptions(), seed=0,
           chunk: int = 1, progress: bool = False, model=None) -> list:
    """The fallback after the local planner: for the results (PlanResult, one per scene of
    the batch ``scenarios``) that ended "stalled" or "max_steps", reachability and the
    global search; the others are returned unchanged. ``options``: the local planner's
    PlanOptions (its contact tolerance, solver and goal tolerance are the search's).
    ``model``: None (the PCC arm) or the :class:`~softplan_jax.RodModel` the local planner
    used (ValueError for anything else)."""
    reach = check_reach_options(reach)
    seed = _int_seed(seed)
    batch = stack_scenarios([scenarios]) if scenarios.q0.ndim == 2 else scenarios
    arm = arm_model(model, batch.q0.shape[-2])
    arm = PCC if arm is None else arm
    results = list(results)
    dtype = batch.q0.dtype
    contact = contact_tolerance(options, dtype)
    solver = options.solver if options.method == "curve" else DEFAULT_OPTIONS
    todo = [b for b in range(len(results)) if Status.from_label(results[b].status) in RESCUED]
    if not todo:
        return results
    _reach_and_search(batch, results, todo, reach, solver, contact, options.goal_tolerance, seed, chunk, progress,
                      arm)
    return results


def rescue_batch(scenarios: Scenario, rollout, options, *, reach: ReachOptions = ReachOptions(), seed=0,
                 chunk: int = 1, progress: bool = False, model=None):
    """:func:`rescue` after :func:`~softplan_jax.plan_batch`: the scenes of the batch
    ``scenarios`` whose batched ``rollout`` ended stalled or at max_steps, as one sub-batch
    (``model``: as :func:`rescue`).

    Returns:
      ``(idx, results)``: those scenes' indices in the batch (int array) and their
      PlanResults after reachability and the search (``planner``, ``reason`` filled in).
    """
    status = np.asarray(rollout.status)
    idx = np.nonzero(np.isin(status, (int(Status.STALLED), int(Status.MAX_STEPS))))[0]
    if idx.size == 0:
        return idx, []
    r = jax.tree_util.tree_map(lambda x: np.asarray(x)[idx], rollout)
    sub = jax.tree_util.tree_map(lambda x: x[idx], scenarios)
    local = [_local_result(r, k, sub) for k in range(idx.size)]
    return idx, rescue(sub, local, options, reach=reach, seed=seed, chunk=chunk, progress=progress, model=model)


def _int_seed(seed) -> int:
    """An int seed for the fallback's keys from plan's seed (an int, or a PRNG key: its last word)."""
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return int(seed)
    key = seed
    if jnp.issubdtype(jnp.asarray(key).dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    words = np.asarray(key)
    if words.dtype.kind not in "ui" or words.size == 0:
        raise ValueError(f"seed must be an int or a JAX PRNG key, got {seed!r}")
    return int(words.ravel()[-1])


def _say(msg: str):
    import sys

    print(msg, file=sys.stderr, flush=True)


def _local_result(r, b: int, batch: Scenario) -> PlanResult:
    from ..planning._planner import result_from_rollout

    one = jax.tree_util.tree_map(lambda x: x[b], r)
    return result_from_rollout(one, scene_of(batch, b))


def _reach_and_search(batch, results, todo, reach: ReachOptions, solver, contact, tolerance, seed, chunk, progress,
                      arm=PCC):
    """Reachability and the global search of the scenes ``todo`` (their results replaced in
    place), in chunks of ``chunk`` scenes padded to one shape: one program whatever the number
    of scenes. The IK of a chunk's scene k has the key ``split(PRNGKey(seed), chunk)[k]`` and
    the extra start where the local planner stopped (as :func:`~softplan_jax.search._reach.reachability`
    of the chunk); the search of scene b the key ``split(PRNGKey(seed + 1), B)[b]``. ``arm``: the
    arm model."""
    host = jax.device_get(batch)
    fn = _fallback_jit(reach, solver, float(contact))
    R = int(reach.start_roots)
    size = min(int(chunk), len(todo))
    ik_keys = np.asarray(jax.random.split(jax.random.PRNGKey(seed), size))
    keys = np.asarray(jax.random.split(jax.random.PRNGKey(seed + 1), len(results)))
    t0, unreachable = time.perf_counter(), 0
    for a in range(0, len(todo), size):
        part = todo[a : a + size]
        sub = jax.tree_util.tree_map(lambda x, part=part: np.asarray(x)[part], host)
        proofs = [unreachable_proof(scene_of(sub, k)) for k in range(len(part))]  # exact, host side
        q_starts, n_starts, roots = zip(*(_search_starts(results[b].q, R) for b in part), strict=True)
        q_starts, n_starts = np.stack(q_starts).astype(host.q0.dtype), np.array(n_starts, np.int32)
        q_end = np.stack([results[b].q[-1] for b in part])
        args = (sub, q_end, np.array([bool(p) for p in proofs]), q_starts, n_starts, keys[part])
        sub, q_end, proof, q_starts, n_starts, part_keys = pad_batch(args, size)
        ik, out = jax.device_get(fn(arm, sub, q_end, ik_keys, proof, q_starts, n_starts, part_keys))
        _, certified, _, _, best = ik  # goal_configurations: (q, certified, clearance, tip_error, best_error)
        for k, b in enumerate(part):
            results[b] = results[b]._replace(best_error=float(best[k]))
            if proofs[k] or not certified[k, 0]:  # reachability's verdict
                unreachable += 1
                results[b] = results[b]._replace(status=status_name(Status.UNREACHABLE),
                                                 reason=proofs[k] or "no_ik_solution")
            elif not out.found[k]:
                results[b] = results[b]._replace(reason="search_exhausted")
            else:
                k_root = int(roots[k][int(out.start[k])])
                steps = int(out.steps[k])
                q = np.concatenate([results[b].q[: k_root + 1], out.q[k][1 : steps + 1]])
                check = out.clearance[k][: steps + 1], bool(out.proven[k])
                results[b] = _with_path(results[b], q, k_root, scene_of(host, b), check, tolerance, out.q.shape[1],
                                        arm)
        if progress:
            _say(f"plan_fallback: reachability and global search {min(a + size, len(todo))}/{len(todo)} scenes, "
                 f"{unreachable} unreachable, {time.perf_counter() - t0:.1f} s")


def _with_path(local: PlanResult, q: np.ndarray, k_root: int, scenario: Scenario, check, tolerance,
               size: int, arm=PCC) -> PlanResult:
    """The result for the path q (the local path to step k_root, then the search's).
    ``check``: the search's check of its part ``q[k_root:]`` (SearchResult.clearance at
    its steps, SearchResult.proven); ``arm``: the arm model (its tips)."""
    from ..geometry._obstacles import radius_and_mask

    c, proven = check
    part = q[k_root:]
    _, mask = radius_and_mask(scenario)
    mask = np.asarray(mask)
    # The local part was checked by the rollout itself; every motion of the search's part must be proven.
    if not proven:
        return local._replace(reason="uncertified_step")  # cannot happen by construction; never reported as reached
    # The search's part padded with its last configuration to one shape (one program for every length).
    padded = np.concatenate([part, np.repeat(part[-1:], size - part.shape[0], axis=0)])
    tips = np.concatenate([local.tip[:k_root], np.asarray(_tips_jit(arm, jnp.asarray(padded)))[: part.shape[0]]])
    err = float(np.linalg.norm(np.asarray(scenario.goal) - tips[-1]))
    clearance = np.concatenate([local.clearance[:k_root], c[:, mask]])
    clear = float(np.min(c[:, mask])) if mask.any() else float("inf")
    if k_root > 0:
        # The local rollout's minimum also covers its between-step checks up to k_root (and beyond: conservative).
        clear = min(clear, float(np.min(local.clearance[: k_root + 1])) if mask.any() else clear)
    reached = err < tolerance
    return local._replace(
        reached=reached,
        iterations=q.shape[0] - 1,
        q=q,
        tip=tips,
        status=status_name(Status.REACHED if reached else Status.from_label(local.status)),
        clearance=clearance,
        final_error=err,
        min_clearance=clear,
        planner="global",
        reason="" if reached else "search_exhausted",
        global_start=k_root,
    )

