"""Tracking a moving goal among moving curves, collision-free by construction (docs: Moving scenes).
The planner is the step and the loop of static planning (paper eq. 9;
:mod:`softplan_jax.planning._engine`) on the scene at the step's time ``t_k = k dt``, with the goal's
velocity fed forward to the attraction, the safe step keeping
``alpha motion_bound + S_j dt <= f (c_j - floor)`` for every obstacle j (``S_j`` its proven speed
bound), the evasive step where even standing still is not proven safe
(:mod:`softplan_jax.planning._evasion`), and the between-step check with the obstacles' travel. The
rollout runs to its horizon (``max_steps dt`` seconds), stopping early only on a collision, a
non-finite number or ``too_fast``, and reports whether the goal was reached and held."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._status import status_name
from ..geometry._obstacles import radius_and_mask
from ..scenarios._motion import MovingScenario, goal_at
from ._options import make_track_options
from ._planner import arm_model, check_gains, start_arm
from ._programs import rollout_batch, rollout_jit, strong_gains
from ._records import Rollout
from ._step import Gains

__all__ = ["Track", "TrackResult", "track", "track_batch", "result_from_track", "goal_trajectory"]


# One result type: a tracking rollout is an engine Rollout with its tracking fields
# (goal, time, error, reached_step, held_steps, held_to_end) filled in.
Track = Rollout


class TrackResult(NamedTuple):
    """What :func:`track` returns (host side, trimmed to the steps taken).

    Attributes:
      status: "reached" (reached and held to the end), "held" (reached, left
        the hold tolerance, and within it again at the last step), "lost"
        (reached, left, and not within it at the last step), "max_steps"
        (never reached), "collided", "start_in_collision" (the start pose),
        "too_fast" (an obstacle could reach the arm within one step whatever
        it did: the rollout stopped at the last configuration proven clear)
        or "non_finite".
      reached, collided, held_to_end: bool.
      reached_step: first step within the goal tolerance (None: never).
      held_steps: steps the goal was held from reached_step; held_time: in seconds.
      iterations: planner steps taken.
      min_clearance: float, over steps and between steps.
      final_error: float, |g(t) - tip| at the last step.
      evasive_steps: steps taken by the evasive step (``TrackOptions.evasion``),
        where the field's step was not proven safe.
      time, goal, error: (iterations + 1,) / (iterations + 1, 3) / (iterations + 1,).
      q, tip, clearance: as :class:`~softplan_jax.planning._planner.PlanResult`.
      evasive: (iterations + 1,) bool, the step from q_k was evasive.
      moving: the MovingScenario (for plots and checks).
      planner: how the result got there: "local" (the tracker alone) or
        "search" (guided by the global search's path,
        :func:`~softplan_jax.search._tracking.track_fallback`).
      reason: why a fallback did not help (None: none tried, or it did).
    """

    status: str
    reached: bool
    collided: bool
    held_to_end: bool
    reached_step: int | None
    held_steps: int
    held_time: float
    iterations: int
    min_clearance: float
    final_error: float
    evasive_steps: int
    time: np.ndarray
    goal: np.ndarray
    error: np.ndarray
    q: np.ndarray
    tip: np.ndarray
    clearance: np.ndarray
    evasive: np.ndarray
    moving: MovingScenario
    planner: str = "local"
    reason: str | None = None


def _check_moving(moving, batched: bool):
    if not isinstance(moving, MovingScenario):
        raise ValueError(f"expected a MovingScenario (see make_moving_scenario), got {type(moving).__name__}")
    ndim = moving.scene.q0.ndim
    if batched and ndim != 3:
        raise ValueError("track_batch takes a stacked MovingScenario (see stack_moving_scenarios)")
    if not batched and ndim != 2:
        raise ValueError("track takes one MovingScenario; use track_batch for a stack")


def track(moving: MovingScenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
          max_steps: int = 600, seed=0, *, model=None, **options) -> TrackResult:
    """Track the goal of one MovingScenario for ``max_steps`` steps (``max_steps dt``
    seconds; jitted, compiles once per shape and option set).

    Args:
      moving: a :class:`~softplan_jax.scenarios._motion.MovingScenario`.
      method, n_points, gains, seed, **options: as :func:`~softplan_jax.plan`.
      max_steps: steps of the horizon (the rollout does not stop at the goal).
      model: None (the PCC arm) or a :class:`~softplan_jax.rod.RodModel`: the loaded arm
        tracks, its clearance and motion bounds proving every step as for :func:`~softplan_jax.plan`
        (it takes no evasive step: where no step is proven safe, the rollout ends "too_fast").
      **options: :class:`TrackOptions` fields (hold_tolerance, feedforward,
        search_substeps, anticipation, evasion, evasion_speed, barrier_gain,
        evasion_pieces) and :class:`~softplan_jax.PlanOptions`
        fields (step, safe_fraction, escapes, goal_tolerance, ...).

    Returns:
      :class:`TrackResult`.

    Raises:
      ValueError: bad input; a ``model`` that cannot carry its load at the start pose.
    """
    _check_moving(moving, batched=False)
    opts = make_track_options(method, n_points, **options)
    dtype = moving.scene.q0.dtype
    g = strong_gains(check_gains(gains, dtype, moving.n_segments), dtype)
    arm = start_arm(model, moving.scene.q0)
    r = rollout_jit(moving, g, opts, max_steps, seed, arm=arm)
    return result_from_track(r, moving, float(g.dt))


def result_from_track(r: Track, moving: MovingScenario, dt: float) -> TrackResult:
    """Trim one (unbatched) Track to the steps taken, on the host."""
    r = jax.device_get(r)  # NumPy slices below: no slice program compiled per step count
    it = int(r.iterations)
    _, mask = radius_and_mask(moving.scene, np)
    rs = int(r.reached_step)
    return TrackResult(
        status=status_name(r.status),
        reached=bool(r.reached),
        collided=bool(r.collided),
        held_to_end=bool(r.held_to_end),
        reached_step=None if rs < 0 else rs,
        held_steps=int(r.held_steps),
        held_time=int(r.held_steps) * dt,
        iterations=it,
        min_clearance=float(r.min_clearance),
        final_error=float(r.final_error),
        evasive_steps=int(np.sum(r.evasive)),
        time=r.time[: it + 1],
        goal=r.goal[: it + 1],
        error=r.error[: it + 1],
        q=r.q[: it + 1],
        tip=r.tip[: it + 1],
        clearance=r.clearance[: it + 1][:, np.asarray(mask)],
        evasive=r.evasive[: it + 1],
        moving=moving,
    )


def track_batch(movings: MovingScenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
                max_steps: int = 600, seed=0, *, chunk: int | None = None, progress: bool = False,
                lanes: int | None = None, model=None, **options) -> Track:
    """Track a stack of moving scenarios (vmapped, jitted once, in chunks of one shape).

    Arguments as :func:`track` and :func:`~softplan_jax.plan_batch` (``chunk``:
    scenarios per call, the last padded; ``progress``: a line per chunk on
    stderr; ``lanes``: scenes stepped side by side, see
    :func:`~softplan_jax.planning._engine.run_lanes`; None: the whole batch up to
    :data:`~softplan_jax.planning._engine.TRACK_LANES` (1,024) on a CPU, as every tracked scene
    holds its lane to the horizon; ``model``: as :func:`track`, one for every scene). Returns a
    batched :class:`Track` (an engine Rollout with the tracking fields) of NumPy arrays.
    """
    _check_moving(movings, batched=True)
    opts = make_track_options(method, n_points, **options)
    dtype = movings.scene.q0.dtype
    g = strong_gains(check_gains(gains, dtype, movings.n_segments), dtype)
    arm = arm_model(model, movings.n_segments)
    r = rollout_batch.in_chunks(movings, g, opts, max_steps, seed, chunk=chunk, progress=progress, lanes=lanes,
                                devices=1, label="track_batch", arm=arm)
    return jax.device_get(r)


def goal_trajectory(moving: MovingScenario, times):
    """g(t) at each of ``times`` (T,) -> (T, 3) (for plots)."""
    return jax.vmap(lambda t: goal_at(moving, t))(jnp.asarray(times, moving.scene.q0.dtype))
