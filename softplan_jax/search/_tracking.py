"""Tracking that does not give up (docs: Moving scenes, "Reaching a goal the field does not lead
to"). :func:`track_fallback` tracks a moving scene (:func:`~softplan_jax.track`) and, where the
tracker never reaches the goal, plans the scene at rest with :func:`~softplan_jax.plan_fallback`,
turns that plan's tip path into a moving goal (``waypoints`` points by arc length at
``waypoint_speed``, carried by the goal's curve where it rides one) and tracks again with it:
every step is still the tracker's, so the run stays collision-free by construction. The guided run
is judged against the true goal g(t) and kept where it reaches it (``planner``, ``reason``); a goal
with a path of its own is not guided."""

from __future__ import annotations

import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..base._status import Status, status_name
from ..planning._gains import default_gains
from ..planning._options import PlanOptions, make_track_options
from ..planning._records import hold_statistics
from ..planning._tracking import TrackResult, goal_trajectory, result_from_track, track, track_batch
from ..scenarios import stack_scenarios
from ..scenarios._motion import GoalPath, MovingScenario, stack_moving_scenarios
from ._fallback import plan_fallback
from ._reach import ReachOptions

__all__ = ["track_fallback", "waypoint_path"]

# The statuses of a tracked run that held on to the horizon (the engine's RUNNING at its end).
_HORIZON = (Status.REACHED, Status.HELD, Status.LOST, Status.MAX_STEPS)


def waypoint_path(tips, count: int, speed: float, attach, dtype) -> GoalPath:
    """A goal path along ``tips`` (K, 3): ``count`` points evenly spaced by arc length,
    at constant ``speed`` from t = 0 (at least 0.1 s in all), carried by curve ``attach``."""
    tips = np.asarray(tips, np.float64)
    seg = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    target = np.linspace(0.0, s[-1], count)
    points = np.stack([np.interp(target, s, tips[:, k]) for k in range(3)], axis=1)
    times = np.linspace(0.0, max(s[-1] / speed, 0.1), count)
    return GoalPath(jnp.asarray(times, dtype), jnp.asarray(points, dtype), jnp.asarray(attach, jnp.int32))


def track_fallback(moving: MovingScenario, method: str = "curve", n_points: int = 10, gains=None,
                   max_steps: int = 600, seed=0, *, reach: ReachOptions = ReachOptions(), waypoints: int = 32,
                   waypoint_speed: float | None = None, retries: int = 1, progress: bool = False, model=None,
                   **options):
    """Track the goal of a moving scene, and where the tracker never reaches it, track again
    guided by the global search's path at rest (module docstring).

    Args:
      moving: one MovingScenario or a stack (:func:`~softplan_jax.moving.stack_moving_scenarios`;
        tracked by :func:`~softplan_jax.track_batch`, the searches one scene at a time).
      method, n_points, gains, max_steps, seed, **options: as :func:`~softplan_jax.track`.
      reach: the search's :class:`~softplan_jax.search._reach.ReachOptions`.
      waypoints: points of the guiding goal path, >= 2 (one compiled shape).
      waypoint_speed: its speed [m/s], > 0 (None: half the gains' ``v_max``).
      retries: guided runs that do not reach the goal run again, up to this many times,
        each with other seeds of the escapes' random walks, >= 0.
      progress: a line per stage on stderr.
      model: None (the PCC arm) or a :class:`~softplan_jax.RodModel`: the loaded arm, for the
        tracker (as :func:`~softplan_jax.track`) and the search at rest
        (:func:`~softplan_jax.plan_fallback`) alike.

    Returns:
      A :class:`~softplan_jax.planning._tracking.TrackResult` (one scene) or a list of
      them (a stack), with ``planner`` and ``reason``.
    """
    if not isinstance(moving, MovingScenario):
        raise ValueError(f"expected a MovingScenario (see make_moving_scenario), got {type(moving).__name__}")
    if isinstance(waypoints, bool) or not isinstance(waypoints, (int, np.integer)) or waypoints < 2:
        raise ValueError(f"waypoints must be an int >= 2, got {waypoints!r}")
    if waypoint_speed is not None and not (isinstance(waypoint_speed, (int, float, np.integer, np.floating))
                                           and math.isfinite(waypoint_speed) and waypoint_speed > 0):
        raise ValueError(f"waypoint_speed must be a finite number > 0, got {waypoint_speed!r}")
    if isinstance(retries, bool) or not isinstance(retries, (int, np.integer)) or retries < 0:
        raise ValueError(f"retries must be an int >= 0, got {retries!r}")
    opts = make_track_options(method, n_points, **options)
    single = moving.scene.q0.ndim == 2
    dtype = moving.scene.q0.dtype
    given = gains if gains is not None else default_gains(dtype)
    v_max, dt = float(given.v_max), float(given.dt)
    speed = 0.5 * v_max if waypoint_speed is None else float(waypoint_speed)
    kw = dict(method=method, n_points=n_points, gains=gains, max_steps=max_steps, seed=seed, model=model, **options)
    scenes = [moving] if single else [jax.tree_util.tree_map(lambda x, b=b: x[b], moving)
                                      for b in range(moving.scene.q0.shape[0])]
    results = [track(moving, **kw)] if single else _results(track_batch(moving, **kw), scenes, dt)
    todo = [b for b, r in enumerate(results) if Status.from_label(r.status) == Status.MAX_STEPS]
    if moving.goal_path.times.shape[-1] != 1:  # a goal with a path of its own: not guided
        return _out([r._replace(reason="moving_goal_path") if b in todo else r for b, r in enumerate(results)],
                    single)
    if not todo:
        return _out(results, single)
    t0 = time.perf_counter()
    rest = stack_scenarios([scenes[b].scene._replace(goal=scenes[b].goal_path.points[0]) for b in todo])
    plan_options = {k: v for k, v in options.items() if k in PlanOptions._fields}
    planned = plan_fallback(rest, method, n_points, gains, max_steps, seed, reach=reach, model=model, **plan_options)
    if progress:
        _say(f"track_fallback: {len(todo)} never reached; at rest {sum(p.status == 'reached' for p in planned)} "
             f"planned, {time.perf_counter() - t0:.1f} s")
    guide = []
    for b, p in zip(todo, planned, strict=True):
        if p.status != "reached":
            results[b] = results[b]._replace(reason=f"at rest: {p.reason or p.status}")
        else:
            path = waypoint_path(p.tip, int(waypoints), speed, scenes[b].goal_path.attach, dtype)
            guide.append((b, scenes[b]._replace(goal_path=path)))
    if not guide:
        return _out(results, single)
    # The guided runs; those that do not reach the goal run again with other escape seeds (``retries``).
    guided_scenes = [b for b, _ in guide]
    for attempt in range(int(retries) + 1):
        run_kw = dict(kw, seed=_attempt_seed(seed, attempt))
        if single:
            guided = [track(guide[0][1], **run_kw)]
        else:
            stack = stack_moving_scenarios([m for _, m in guide])
            guided = _results(track_batch(stack, **run_kw), [m for _, m in guide], dt)
        for (b, _), g in zip(guide, guided, strict=True):
            results[b] = _judge(results[b], g, scenes[b], opts, dt)
        guide = [(b, m) for b, m in guide if results[b].planner != "search"]
        if not guide:
            break
    if progress:
        _say(f"track_fallback: {sum(results[b].planner == 'search' for b in guided_scenes)} of {len(guided_scenes)} "
             f"guided scenes reached the goal, {time.perf_counter() - t0:.1f} s")
    return _out(results, single)


def _attempt_seed(seed, attempt: int):
    """The escapes' seed of a guided run's attempt: the run's own first, then others."""
    if attempt == 0:
        return seed
    base = int(seed) if isinstance(seed, (int, np.integer)) else 0
    return base + 7919 * attempt


def _out(results, single):
    return results[0] if single else results


def _results(batched, scenes, dt: float) -> list:
    """TrackResults, one per scene, from a batched Track (``dt``: the gains' step)."""
    return [result_from_track(jax.tree_util.tree_map(lambda x, b=b: x[b], batched), m, dt)
            for b, m in enumerate(scenes)]


def _judge(first: TrackResult, guided: TrackResult, moving: MovingScenario, opts, dt: float) -> TrackResult:
    """The guided run judged against the TRUE goal g(t): kept where it reaches it."""
    goal = np.asarray(goal_trajectory(moving, guided.time))
    error = np.linalg.norm(goal - guided.tip, axis=1)
    engine = Status.from_label(guided.status)
    engine = int(Status.RUNNING if engine in _HORIZON else engine)
    status, reached, reached_step, held_steps, held_to_end = (np.asarray(x) for x in hold_statistics(
        jnp.asarray(error), guided.iterations, engine, opts.plan.goal_tolerance, opts.hold_tolerance))
    if not bool(reached):
        return first._replace(reason="the guided run did not reach the goal")
    return guided._replace(status=status_name(int(status)), reached=True, held_to_end=bool(held_to_end),
                           reached_step=int(reached_step), held_steps=int(held_steps),
                           held_time=int(held_steps) * dt, final_error=float(error[-1]), goal=goal, error=error,
                           moving=moving, planner="search")


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)
