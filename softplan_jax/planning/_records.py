"""What a rollout returns: the :class:`Rollout` type, the per-step records, and the
summary of a finished rollout (its status, its clearance, and for tracking the
statistics of holding the goal).

Records after the step where a rollout ended hold its last state (q, tip,
clearances, goal, error: frozen; in a static scene the between-step clearance of
the non-motions after the end is the clearance) and no events (step scale 0, no
solver fallbacks, no between-step search). The mode of a rollout, plan or track,
is its options' (:func:`setup`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._memory import check_memory
from ..base._numerics import safe_norm
from ..base._status import Status
from ..geometry._obstacles import obstacle_count, radius_and_mask
from ..scenarios._motion import MovingScenario
from ._options import tracks

__all__ = ["Rollout", "Record", "Setup", "setup", "record_zeros", "check_rollout_memory", "freeze", "finish",
           "hold_statistics"]


class Rollout(NamedTuple):
    """A rollout, planned or tracked (arrays padded to max_steps + 1 along time).

    Attributes:
      q: (T+1, n, 3) configurations; frozen after the rollout finished.
      tip: (T+1, 3).
      clearance: (T+1, m) true clearance (surface to surface) to every obstacle
        slot (padding slots: +inf); for a moving scene, to the obstacles at
        the step's time. With ``far_margin`` set (PlanOptions), a clearance above
        ``d0 + far_margin`` may be a certified lower bound instead.
      between: (T+1, m) smallest clearance found during the motion from the
        previous step (entry 0: the start's clearance); an ACHIEVED clearance,
        so an upper bound on the true minimum over the motion. Where the
        between-step search ran (``between_searched``) it is the search's
        result (at most the clearance at both ends); where the motion bound
        proved the motion clear (``PlanOptions.swept_proof``) it is the smaller
        of the two ends' clearances, and the true minimum lies between
        ``clearance[k-1] - motion_bound(q[k-1], q[k])[-1]`` (less the
        obstacle's travel, for a moving scene; above the contact tolerance: no
        collision) and this value (above ``d0 + far_margin`` the ends' clearances may be
        lower bounds, see ``clearance``).
      status: () int, a :class:`~softplan_jax.base._status.Status` code.
      iterations: () int, planner steps taken.
      reached, collided: () bool (tracking: reached = within the goal
        tolerance at some step).
      min_clearance: () minimum over time, obstacles and between-step motion.
      final_error: () |goal - tip| at the end.
      step_scale: (T+1,) the safe step's alpha for the step from q_k (1 for the
        plain step; 0 where no step was taken).
      escapes: () int, random-walk escapes started.
      converged: (T+1,) bool, every exact closest-point solve of a real
        obstacle slot at q_k met its Newton tolerance.
      fallbacks: (T+1,) int32, (segment, curve) pairs of real curve slots
        that took the full closest-point solve at q_k: with the warm start
        (``PlanOptions.warm_start``) the pairs whose certificate failed (all
        at k = 0); without it every pair, or 0 where no exact solve ran.
      between_searched: (T+1, m) bool, the between-step search ran for the
        motion to q_k and obstacle slot j.
      goal, time, error, reached_step, held_steps, held_to_end: tracking only
        (None for a planned rollout): g(t_k) (T+1, 3), t_k = k dt (T+1,),
        |g(t_k) - tip_k| (T+1,), the first step within the goal tolerance
        (-1: never), the steps it was held from then (error <= hold
        tolerance) and whether it was held to the end.
      evasive: tracking only, (T+1,) bool: the step from q_k was the evasive step
        (:mod:`softplan_jax.planning._evasion`; ``TrackOptions.evasion``).
    """

    q: jax.Array
    tip: jax.Array
    clearance: jax.Array
    between: jax.Array
    status: jax.Array
    iterations: jax.Array
    reached: jax.Array
    collided: jax.Array
    min_clearance: jax.Array
    final_error: jax.Array
    step_scale: jax.Array
    escapes: jax.Array
    converged: jax.Array
    fallbacks: jax.Array
    between_searched: jax.Array
    goal: jax.Array | None = None
    time: jax.Array | None = None
    error: jax.Array | None = None
    reached_step: jax.Array | None = None
    held_steps: jax.Array | None = None
    held_to_end: jax.Array | None = None
    evasive: jax.Array | None = None


class Record(NamedTuple):
    """What one step records (the per-step arrays of a Rollout)."""

    q: jax.Array
    tip: jax.Array
    clearance: jax.Array
    between: jax.Array
    step_scale: jax.Array
    converged: jax.Array
    fallbacks: jax.Array
    between_searched: jax.Array
    goal: jax.Array | None = None
    time: jax.Array | None = None
    error: jax.Array | None = None
    evasive: jax.Array | None = None


# After the end, the state records stay at their last value and the event records are empty.
EVENTS = ("step_scale", "fallbacks", "between_searched", "evasive")


class Setup(NamedTuple):
    """Trace-time facts of one rollout: what moves and what ends it."""

    moving: bool  # the scene moves (a MovingScenario)
    scene: object  # the Scenario (at rest)
    plan: object  # PlanOptions of the step
    track: object  # TrackOptions (hold the goal to the horizon) or None (stop at the goal)
    stop_at_goal: bool


def setup(world, options) -> Setup:
    """The mode is the options' (:func:`tracks`), for a static scene as for a moving one."""
    moving = isinstance(world, MovingScenario)
    track = options if tracks(options) else None
    if moving and track is None:
        raise ValueError("a moving scene is tracked: pass TrackOptions (see make_track_options)")
    return Setup(moving, world.scene if moving else world, track.plan if track else options, track, track is None)


def record_zeros(world, options, T: int) -> Record:
    """Zero records of T steps (what :func:`~softplan_jax.planning._engine.make_step` records,
    stacked), without tracing a step."""
    su = setup(world, options)
    q0 = su.scene.q0
    n, dtype = q0.shape[0], q0.dtype
    m = radius_and_mask(su.scene)[1].shape[0]

    def z(shape, dt=dtype):
        return jnp.zeros((T, *shape), dt)

    rec = Record(z((n, 3)), z((3,)), z((m,)), z((m,)), z(()), z((), bool), z((), jnp.int32), z((m,), bool))
    if su.track:
        rec = rec._replace(goal=z((3,)), time=z(()), error=z(()), evasive=z((), bool))
    return rec


# Copies of a rollout's records alive at once: the loop's buffer, the records cut to length,
# the frozen records of the result, and the result brought to the host.
RECORD_COPIES = 4


def check_rollout_memory(world, options, max_steps: int, scenes: int = 1, side_by_side: int = 1) -> None:
    """A ValueError naming the field before anything is allocated, when the arrays of
    ``scenes`` rollouts of ``max_steps`` steps (:func:`record_zeros` per scene, about
    ``RECORD_COPIES`` copies) and the N-point model's per-step arrays (``side_by_side``
    scenes stepped at once) would not fit in the memory available
    (:func:`~softplan_jax.base._memory.check_memory`). Shapes only: works on tracers."""
    su = setup(world, options)
    q0 = su.scene.q0
    n, item = q0.shape[-2], jnp.dtype(q0.dtype).itemsize
    m = obstacle_count(su.scene)
    # One step's record (record_zeros): q, tip, clearance, between, step_scale [, goal, time, error] in the
    # dtype, converged (bool), fallbacks (int32), between_searched (m bools) [, evasive (bool)].
    row = item * (3 * n + 3 + 2 * m + 1 + (5 if su.track else 0)) + 1 + 4 + m + (1 if su.track else 0)
    records = RECORD_COPIES * row * (int(max_steps) + 1) * int(scenes)
    points = 0
    if su.plan.method == "points":  # every curve as N points, against n * points_per_segment arm samples
        m_c = su.scene.curves.coeffs.shape[-3]
        per = m_c * int(su.plan.n_points) * (3 + n * int(su.plan.points_per_segment))
        points = 4 * item * per * int(side_by_side)
    if points > records:
        check_memory(records + points, "n_points", f"the N-point model with N = {su.plan.n_points}",
                     "use a smaller N (the paper uses N <= 100) or the curve method")
    else:
        field = "max_steps" if scenes == 1 else "max_steps x the number of scenes"
        what = f"the records of {int(scenes)} rollout(s) of max_steps + 1 = {int(max_steps) + 1} steps " \
               f"({row} bytes per step)"
        check_memory(records + points, field, what,
                     "lower max_steps (a rollout stops at its goal: the default 600 plans the paper's scenes)"
                     + ("" if scenes == 1 else ", or plan the scenes in smaller batches"))


def freeze(records: Record, end, still: bool):
    """Records after step ``end``: the state records hold their value at ``end``, the events are
    empty. ``still`` (a static scene): after the end nothing moves, so the clearance during the
    "motion" to each later step is the clearance itself; in a moving scene the records stop at the
    last step taken, the between-step clearance at its last motion's."""
    T1 = records.q.shape[0]
    alive = jnp.arange(T1, dtype=jnp.int32) <= end

    def fix(name, x):
        if x is None:
            return None
        a = alive.reshape((-1,) + (1,) * (x.ndim - 1))
        if name in EVENTS:
            return jnp.where(a, x, jnp.zeros((), x.dtype))
        last = records.clearance[end] if (still and name == "between") else x[end]
        return jnp.where(a, x, last)

    return Record(*(fix(f, getattr(records, f)) for f in Record._fields))


def finish(world, options, records: Record, final) -> Rollout:
    """The Rollout from a rollout's records (frozen after its end) and its last carry."""
    su = setup(world, options)
    plan = su.plan
    end = final.iterations
    r = freeze(records, end, still=not su.moving)
    min_clearance = jnp.minimum(jnp.min(r.clearance, initial=jnp.inf), jnp.min(r.between, initial=jnp.inf))
    out = dict(q=r.q, tip=r.tip, clearance=r.clearance, between=r.between, iterations=final.iterations,
               min_clearance=min_clearance, step_scale=r.step_scale, escapes=final.escapes, converged=r.converged,
               fallbacks=r.fallbacks, between_searched=r.between_searched)
    # A collision at step 0 is the start pose's own: nothing was planned.
    start_hit = (final.status == Status.COLLIDED) & (end == 0)
    collided = final.status == Status.COLLIDED
    if su.stop_at_goal:
        status = jnp.where(final.status == Status.RUNNING, Status.MAX_STEPS, final.status)
        status = jnp.where(start_hit, Status.START_COLLIDED, status).astype(jnp.int32)
        return Rollout(**out, status=status, reached=status == Status.REACHED, collided=collided,
                       final_error=safe_norm(su.scene.goal - r.tip[-1]))
    # Tracking statistics over the steps taken (0..end).
    status, reached, reached_step, held_steps, held_to_end = hold_statistics(
        r.error, end, final.status, plan.goal_tolerance, su.track.hold_tolerance)
    status = jnp.where(start_hit, Status.START_COLLIDED, status).astype(jnp.int32)
    return Rollout(**out, status=status, reached=reached, collided=collided,
                   final_error=r.error[end], goal=r.goal, time=r.time, error=r.error, reached_step=reached_step,
                   held_steps=held_steps, held_to_end=held_to_end, evasive=r.evasive)


def hold_statistics(error, end, status, goal_tolerance, hold_tolerance):
    """A tracking run's outcome from its goal errors (T+1,) over the steps taken (0..end)
    and its engine status: ``(status, reached, reached_step, held_steps, held_to_end)``.

    Reached: within ``goal_tolerance`` at some step (reached_step: the first; -1:
    never); held: from then while within ``hold_tolerance``. A run still running at
    the horizon (status RUNNING) is "reached" when held to the end, "held" when it
    left the hold tolerance and is within it at the last step, "lost" when not,
    "max_steps" when never reached; any other status stands.
    """
    T1 = error.shape[0]
    steps = jnp.arange(T1, dtype=jnp.int32)
    alive = steps <= end
    within = (error < goal_tolerance) & alive
    reached = jnp.any(within)
    reached_step = jnp.where(reached, jnp.argmax(within), -1).astype(jnp.int32)
    after = alive & (steps >= reached_step) & reached
    lost_at = jnp.where(after & (error > hold_tolerance), steps, T1)
    first_loss = jnp.min(lost_at)
    held_to_end = reached & (first_loss > end)
    held_steps = jnp.where(reached, jnp.minimum(first_loss, end + 1) - reached_step, 0).astype(jnp.int32)
    # Left the hold tolerance after the first reach: "held" when back within it at the last step, else "lost".
    regained = error[end] <= hold_tolerance
    status = jnp.where(
        status == Status.RUNNING,
        jnp.where(held_to_end, Status.REACHED,
                  jnp.where(reached, jnp.where(regained, Status.HELD, Status.LOST), Status.MAX_STEPS)),
        status,
    )
    return status, reached, reached_step, held_steps, held_to_end
