"""Tracking a moving goal among moving curves (issue 23), collision-free by construction.

The planner is the same step as :mod:`softplan_jax.planner` (paper eq. 9) on the
scene at the step's time: at step k (time ``t_k = k dt``, dt the gains'
integration step) the curves are where :func:`~softplan_jax.motion.scenario_at`
puts them and the goal is ``g(t_k)``. Beyond the static planner:

* **Feed-forward** (``TrackOptions.feedforward``, default on): the tip velocity
  of eq. (9)'s attraction is ``k_att V_e + dg/dt``, saturated at ``v_max``
  (:func:`tracking_attraction`); without it a proportional law lags a goal
  moving at speed w by ``w / k_att``.
* **The clearance-bounded step with moving obstacles.** Obstacle j moves at
  most ``S_j dt`` during a step (:func:`~softplan_jax.motion.speed_bounds`, a
  proof). The step's scale alpha keeps

      alpha * motion_bound(q_k, q_k + dt qdot) + S_j dt <= f (c_j - floor)   for every j,

  so by the triangle inequality the arm-to-obstacle distance stays above
  ``floor`` at every instant of the step (conservative advancement with both
  bodies moving). When ``f (c_j - floor) < S_j dt`` even standing still is not
  provably safe: the rollout ends with status ``too_fast`` at the last
  configuration proven clear, never with a collision reported as success.
* **Between-step check.** The motion from (q_{k-1}, t_{k-1}) to (q_k, t_k) is
  proven clear where ``c_{k-1} - B - S_j dt`` exceeds the contact tolerance
  (:func:`~softplan_jax.metrics.swept_clear` with the clearance reduced by the
  obstacle's travel); elsewhere (the N-point models) the exact clearance is
  evaluated at ``search_substeps`` instants in between, arm and curves
  interpolated together (a search, as the static between-step check: an
  achieved clearance).
* **Tracking, not stopping.** The rollout runs to ``max_steps`` (a horizon of
  ``max_steps dt`` seconds); it stops early only on a collision, a non-finite
  number or ``too_fast``. Then: ``reached`` (|g(t) - tip| < goal_tolerance at
  some step), ``held_steps`` (steps from the first reach until the error first
  exceeds ``hold_tolerance``), and the status ``reached`` (held to the end),
  ``lost`` (reached, not held) or ``max_steps`` (never reached).

Stalls start the random-walk escapes of the static planner (not while the tip
holds the goal); a stall with no escape left does not end the rollout, since
the scene keeps changing. Static scenes stay with :func:`~softplan_jax.plan`:
nothing here changes it.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .batching import Progress, pad_batch
from .closest import ClosestPoint, SolverOptions, curve_closest
from .compilation_cache import rollout_compiler_options
from .kinematics import motion_bound, tip_position
from .metrics import contact_tolerance, swept_clear
from .motion import MovingScenario, goal_at, goal_velocity, moved_cells, moved_curves, scenario_at, speed_bounds
from .numerics import evaluate_where, safe_norm, tie
from .obstacles import radius_and_mask, true_closest, warm_cells, warm_closest, warm_state
from .planner import (
    Gains,
    PlanOptions,
    apply_step,
    batch_keys,
    check_gains,
    field_velocity,
    make_options,
    prng_key,
    strong_gains,
)
from .status import Status, status_name

__all__ = ["TrackOptions", "Track", "TrackResult", "tracking_attraction", "track_rollout", "track", "track_batch"]


class TrackOptions(NamedTuple):
    """Static settings of a tracking rollout (hashable: changing one recompiles).

    Attributes:
      plan: the PlanOptions of the step (method, N, safe step, escapes, goal
        tolerance, solver, warm start, ...). ``check_collisions`` must be on.
      hold_tolerance: the goal counts as held while |g(t) - tip| <= this, > 0.
      feedforward: add dg/dt to the attraction (module docstring).
      search_substeps: instants of the between-step search, >= 1.
      anticipation: seconds of look-ahead of the repulsion, >= 0: eq. (9)'s
        field sees obstacle j inflated by ``S_j * anticipation`` (S_j its
        speed bound), so the arm gives way to a fast obstacle before the safe
        step has to stop it. 0: the static field. The safe step always uses
        the true clearance.
    """

    plan: PlanOptions = PlanOptions()
    hold_tolerance: float = 0.02
    feedforward: bool = True
    search_substeps: int = 8
    anticipation: float = 0.0


def check_track_options(options: TrackOptions) -> TrackOptions:
    if not options.plan.check_collisions:
        raise ValueError("tracking needs check_collisions=True (the status depends on the clearance)")
    if not (math.isfinite(float(options.hold_tolerance)) and float(options.hold_tolerance) > 0):
        raise ValueError(f"hold_tolerance must be a finite number > 0, got {options.hold_tolerance}")
    if int(options.search_substeps) < 1:
        raise ValueError(f"search_substeps must be >= 1, got {options.search_substeps}")
    if not (math.isfinite(float(options.anticipation)) and float(options.anticipation) >= 0):
        raise ValueError(f"anticipation must be a finite number >= 0, got {options.anticipation}")
    return options


class Track(NamedTuple):
    """A tracking rollout (arrays padded to max_steps + 1 along time).

    Attributes:
      q, tip, clearance, between, step_scale, converged, fallbacks,
        between_searched, escapes, iterations, collided, min_clearance: as
        :class:`~softplan_jax.planner.Rollout` (clearances against the curves
        at the step's time).
      time: (T+1,) t_k = k dt [s].
      goal: (T+1, 3) g(t_k).
      error: (T+1,) |g(t_k) - tip_k| (frozen after the rollout ended).
      status: () int: REACHED (reached and held to the end), LOST, MAX_STEPS
        (never reached), COLLIDED, NONFINITE or TOO_FAST.
      reached: () bool, the error fell below the goal tolerance at some step.
      reached_step: () int, the first such step (-1: never).
      held_steps: () int, steps from reached_step on with error <= hold_tolerance
        before it first exceeds it (0: never reached).
      held_to_end: () bool, held from reached_step to the last step.
      final_error: () the error at the last step.
    """

    q: jax.Array
    tip: jax.Array
    goal: jax.Array
    time: jax.Array
    error: jax.Array
    clearance: jax.Array
    between: jax.Array
    step_scale: jax.Array
    converged: jax.Array
    fallbacks: jax.Array
    between_searched: jax.Array
    status: jax.Array
    iterations: jax.Array
    escapes: jax.Array
    reached: jax.Array
    reached_step: jax.Array
    held_steps: jax.Array
    held_to_end: jax.Array
    collided: jax.Array
    min_clearance: jax.Array
    final_error: jax.Array


class _Carry(NamedTuple):
    q: jax.Array
    q_prev: jax.Array
    truth_prev: ClosestPoint
    c_prev: jax.Array
    first: jax.Array
    status: jax.Array
    iterations: jax.Array
    best_error: jax.Array
    since_best: jax.Array
    key: jax.Array
    escapes: jax.Array
    walk_left: jax.Array
    walk_velocity: jax.Array
    warm: tuple


def tracking_attraction(V_e, goal_rate, gains: Gains, feedforward: bool = True):
    """The attraction's tip velocity: ``k_att V_e + dg/dt`` saturated at ``v_max``
    (paper eq. 9's F_e with a feed-forward term; without it, or for dg/dt = 0,
    exactly :func:`~softplan_jax.planner.attraction`)."""
    v = gains.k_att * V_e + (goal_rate if feedforward else 0.0)
    return v / jnp.maximum(1.0, safe_norm(v) / gains.v_max)


def _moving_cells(cells, moving: MovingScenario, t):
    if not cells or not moving.scene.curves.coeffs.shape[0]:
        return cells
    return (moved_cells(cells[0], moving.motion, t), *cells[1:])


def track_rollout(moving: MovingScenario, gains: Gains, options: TrackOptions, max_steps: int, key=None) -> Track:
    """Roll the tracking planner out for ``max_steps`` steps with ``lax.scan``
    (pure; :func:`track` is the jitted entry point). See the module docstring."""
    plan = options.plan
    scene = moving.scene
    radius, mask = radius_and_mask(scene)
    q0 = scene.q0
    dtype = q0.dtype
    contact = contact_tolerance(plan, dtype)
    floor = 2.0 * contact
    key = jax.random.PRNGKey(0) if key is None else key
    dt = gains.dt
    speed = speed_bounds(moving)
    travel = speed * dt  # (m,) how far each obstacle can move in one step
    lead = speed * options.anticipation  # (m,) the field's inflation (TrackOptions.anticipation)
    m_c = scene.curves.coeffs.shape[0]
    warm = plan.warm_start and isinstance(plan.solver, SolverOptions)
    cells0 = warm_cells(scene, plan.solver) if warm else ()
    walks = plan.escapes > 0
    substeps = jnp.arange(1, options.search_substeps + 1, dtype=dtype) / (options.search_substeps + 1)

    def clearance_of(truth):
        return jnp.where(mask, truth.distance - scene.arm_radius - radius, jnp.inf)

    only_polynomials = scene.points.shape[0] == 0 and not scene.parametric

    def searched_clearance(q_a, q_b, t_a, moving, j):
        """Slot j's smallest exact clearance at the search instants, arm and curves moving together."""

        def at(tau):
            q_tau = q_a + tau * (q_b - q_a)
            if only_polynomials:  # the one curve of slot j, moved to the instant
                one = jax.tree_util.tree_map(lambda x: x[j], (moving.scene.curves, moving.motion))
                curve = moved_curves(jax.tree_util.tree_map(lambda x: x[None], one[0]),
                                     jax.tree_util.tree_map(lambda x: x[None], one[1]), t_a + tau * dt)
                d = curve_closest(q_tau, jax.tree_util.tree_map(lambda x: x[0], curve), plan.solver).distance
                return d - scene.arm_radius - radius[j]
            sc = scenario_at(moving, t_a + tau * dt)
            return clearance_of(true_closest(q_tau, sc, plan.solver))[j]

        return jnp.min(jax.vmap(at)(substeps))

    def body(carry: _Carry, k):
        q = carry.q
        t = k.astype(dtype) * dt
        sc = scenario_at(moving, t)
        if warm:
            cells = _moving_cells(cells0, moving, t)
            truth, warm_next, fallbacks = warm_closest(q, sc, plan.solver, cells, carry.warm, carry.first)
        else:
            truth, warm_next = true_closest(q, sc, plan.solver), carry.warm
            fallbacks = q.shape[0] * (jnp.sum(scene.curve_mask) + len(scene.parametric)).astype(jnp.int32)
        running = carry.status == Status.RUNNING
        c = clearance_of(truth)
        # The motion from (q_{k-1}, t_{k-1}): proven clear where the clearance at its start, less the
        # arm's motion bound and the obstacle's travel, stays above the contact tolerance.
        proven = swept_clear(carry.q_prev, q, carry.truth_prev, carry.c_prev - travel, contact)
        searched = mask & ~carry.first & running & ~proven

        def search(j):
            # Slot j's clearance at the search instants. The barrier ties the search to the slot index
            # (a loop variable of evaluate_where): without it XLA hoists the loop-invariant solves out
            # of the while loop and runs them at every step.
            q_a, q_b, t_a, ms, j = jax.lax.optimization_barrier((carry.q_prev, q, t - dt, moving, j))
            return searched_clearance(*jax.lax.stop_gradient((q_a, q_b, t_a, ms)), j)

        found = evaluate_where(searched, search, 1, jnp.full(mask.shape, jnp.inf, dtype))
        cb = jnp.minimum(jnp.minimum(carry.c_prev, c), jnp.where(searched, found, jnp.inf))
        cb = jnp.where(carry.first | ~mask, c, cb)
        nan_clearance = jnp.any(jnp.isnan(c)) | jnp.any(jnp.isnan(cb))
        hit = jnp.any(c <= contact) | jnp.any(cb <= contact)
        err = safe_norm(sc.goal - tip_position(q))
        holding = err <= options.hold_tolerance
        improved = err < carry.best_error - plan.stall_tolerance
        walking = carry.walk_left > 0
        since = jnp.where(improved | carry.first | walking | holding, 0, carry.since_best + 1)
        escape = (since >= plan.stall_window) & (carry.escapes < plan.escapes)
        judged = jnp.where(nan_clearance, Status.NONFINITE, jnp.where(hit, Status.COLLIDED, Status.RUNNING))
        status = jnp.where(running, judged, carry.status)
        stepping = (status == Status.RUNNING) & (k < max_steps)
        key, walk_velocity, walk_left, escapes = carry.key, carry.walk_velocity, carry.walk_left, carry.escapes
        if walks:
            start = stepping & escape
            key, sub = jax.random.split(key)
            direction = jax.random.normal(sub, (3,), dtype)
            direction = direction / jnp.maximum(safe_norm(direction), jnp.finfo(dtype).tiny)
            walk_velocity = jnp.where(start, gains.v_max * direction, walk_velocity)
            walk_left = jnp.where(start, plan.escape_steps, walk_left)
            escapes = escapes + start.astype(jnp.int32)
            since = jnp.where(start, 0, since)
        F_e = tracking_attraction(sc.goal - tip_position(q), goal_velocity(moving, t), gains, options.feedforward)
        F_e = jnp.where(walk_left > 0, walk_velocity, F_e)
        # The field sees each curve inflated by its look-ahead; the safe step below gets the true clearance.
        field = sc._replace(curves=sc.curves.__class__.tree_unflatten(
            None, [sc.curves.coeffs, sc.curves.u_range, sc.curves.radius + lead[:m_c]]))
        qdot, model_clearance = field_velocity(q, field, gains, truth, plan, (jnp.ones((), bool), F_e))
        model_clearance = model_clearance + lead
        q_full = apply_step(q, qdot, sc, gains)
        if plan.step == "plain":
            alpha = jnp.ones((), dtype)
            too_fast = jnp.zeros((), bool)
        else:
            # Paper eq. (9)'s step, scaled so that arm motion + obstacle travel <= f (c - floor).
            budget = plan.safe_fraction * jnp.maximum(model_clearance - floor, 0.0) - travel
            too_fast = jnp.any(budget < 0)
            allowed = jnp.maximum(jnp.min(budget, initial=jnp.inf), 0.0)
            bound = motion_bound(q, q_full)[-1]
            moving_arm = bound > 0
            alpha = jnp.where(moving_arm, jnp.minimum(1.0, allowed / jnp.where(moving_arm, bound, 1.0)), 1.0)
            alpha = jnp.where(jnp.isnan(jnp.min(model_clearance, initial=jnp.inf)), jnp.nan, alpha)
        q_next = q + alpha * (q_full - q)
        finite = jnp.all(jnp.isfinite(q_next))
        status = jnp.where(stepping & too_fast, Status.TOO_FAST, status)
        status = jnp.where(stepping & ~too_fast & ~finite, Status.NONFINITE, status).astype(jnp.int32)
        moved = stepping & ~too_fast & finite
        new = _Carry(
            q=jnp.where(moved, q_next, q),
            q_prev=q,
            truth_prev=truth,
            c_prev=c,
            first=jnp.zeros((), bool),
            status=status,
            iterations=carry.iterations + moved.astype(jnp.int32),
            best_error=jnp.minimum(err, carry.best_error),
            since_best=since,
            key=key,
            escapes=escapes,
            walk_left=jnp.where(moved, jnp.maximum(walk_left - 1, 0), walk_left).astype(jnp.int32),
            walk_velocity=walk_velocity,
            warm=warm_next,
        )
        converged = jnp.all(jnp.where(mask, truth.converged, True))
        alpha = jnp.where(moved, alpha, 0.0).astype(dtype)
        return new, (q, tip_position(q), sc.goal, t, err, c, cb, alpha, converged, fallbacks, searched)

    from .obstacles import placeholder_closest

    carry0 = _Carry(
        q=q0,
        q_prev=q0,
        truth_prev=placeholder_closest(q0, scene),
        c_prev=jnp.full(mask.shape, jnp.inf, dtype),
        first=jnp.ones((), bool),
        status=jnp.asarray(Status.RUNNING, jnp.int32),
        iterations=jnp.zeros((), jnp.int32),
        best_error=jnp.asarray(jnp.inf, dtype),
        since_best=jnp.zeros((), jnp.int32),
        key=key,
        escapes=jnp.zeros((), jnp.int32),
        walk_left=jnp.zeros((), jnp.int32),
        walk_velocity=jnp.zeros((3,), dtype),
        warm=warm_state(scene) if warm else (),
    )
    carry0 = tie(carry0, q0)
    final, (qs, tips, goals, times, errs, cs, cbs, alphas, converged, fallbacks, searched) = jax.lax.scan(
        body, carry0, jnp.arange(max_steps + 1)
    )
    # After the rollout ended the arm stands still but the scene moves on: the records stop at the
    # last step taken (as the static planner's frozen records do).
    steps = jnp.arange(max_steps + 1, dtype=jnp.int32)
    alive = steps <= final.iterations
    end = final.iterations

    def freeze(x):
        return jnp.where(alive.reshape((-1,) + (1,) * (x.ndim - 1)), x, x[end])

    goals, times, errs, cs, cbs = (freeze(x) for x in (goals, times, errs, cs, cbs))
    converged, fallbacks = freeze(converged), jnp.where(alive, fallbacks, 0)
    searched = searched & alive[:, None]
    # Tracking statistics over the steps taken (0..iterations).
    within = (errs < plan.goal_tolerance) & alive
    reached = jnp.any(within)
    reached_step = jnp.where(reached, jnp.argmax(within), -1).astype(jnp.int32)
    after = alive & (steps >= reached_step) & reached
    lost_at = jnp.where(after & (errs > options.hold_tolerance), steps, max_steps + 1)
    first_loss = jnp.min(lost_at)
    held_to_end = reached & (first_loss > final.iterations)
    held_steps = jnp.where(reached, jnp.minimum(first_loss, final.iterations + 1) - reached_step, 0).astype(jnp.int32)
    status = jnp.where(
        final.status == Status.RUNNING,
        jnp.where(held_to_end, Status.REACHED, jnp.where(reached, Status.LOST, Status.MAX_STEPS)),
        final.status,
    ).astype(jnp.int32)
    return Track(
        q=qs, tip=tips, goal=goals, time=times, error=errs, clearance=cs, between=cbs, step_scale=alphas,
        converged=converged, fallbacks=fallbacks, between_searched=searched, status=status,
        iterations=final.iterations, escapes=final.escapes, reached=reached, reached_step=reached_step,
        held_steps=held_steps, held_to_end=held_to_end, collided=status == Status.COLLIDED,
        min_clearance=jnp.minimum(jnp.min(cs, initial=jnp.inf), jnp.min(cbs, initial=jnp.inf)),
        final_error=errs[final.iterations],
    )


# ----------------------------------------------------------------------------
# Entry points.


@functools.cache
def track_program(options: TrackOptions, max_steps: int, batched: bool):
    """The jitted tracking rollout ``(moving, gains, key) -> Track`` for these static settings
    (vmapped over moving scenarios and keys when ``batched``), built once per setting."""
    def single(moving, gains, key):
        return track_rollout(moving, gains, options, max_steps, key)

    fn = jax.vmap(single, in_axes=(0, None, 0)) if batched else single
    return jax.jit(fn, compiler_options=rollout_compiler_options())


class TrackResult(NamedTuple):
    """What :func:`track` returns (host side, trimmed to the steps taken).

    Attributes:
      status: "reached" (reached and held to the end), "lost" (reached, then
        left the hold tolerance), "max_steps" (never reached), "collided",
        "too_fast" (an obstacle could reach the arm within one step whatever
        it did: the rollout stopped at the last configuration proven clear)
        or "non_finite".
      reached, collided, held_to_end: bool.
      reached_step: first step within the goal tolerance (None: never).
      held_steps: steps the goal was held from reached_step; held_time: in seconds.
      iterations: planner steps taken.
      min_clearance: float, over steps and between steps.
      final_error: float, |g(t) - tip| at the last step.
      time, goal, error: (iterations + 1,) / (iterations + 1, 3) / (iterations + 1,).
      q, tip, clearance: as :class:`~softplan_jax.planner.PlanResult`.
      moving: the MovingScenario (for plots and checks).
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
    time: np.ndarray
    goal: np.ndarray
    error: np.ndarray
    q: np.ndarray
    tip: np.ndarray
    clearance: np.ndarray
    moving: MovingScenario


def _check_moving(moving, batched: bool):
    if not isinstance(moving, MovingScenario):
        raise ValueError(f"expected a MovingScenario (see make_moving_scenario), got {type(moving).__name__}")
    ndim = moving.scene.q0.ndim
    if batched and ndim != 3:
        raise ValueError("track_batch takes a stacked MovingScenario (see stack_moving_scenarios)")
    if not batched and ndim != 2:
        raise ValueError("track takes one MovingScenario; use track_batch for a stack")


def make_track_options(method="curve", n_points=10, *, hold_tolerance=0.02, feedforward=True, search_substeps=8,
                       anticipation=0.0, **plan_options) -> TrackOptions:
    """TrackOptions from keyword arguments (PlanOptions fields go to ``plan``), validated."""
    return check_track_options(TrackOptions(make_options(method, n_points, **plan_options), float(hold_tolerance),
                                            bool(feedforward), int(search_substeps), float(anticipation)))


def track(moving: MovingScenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
          max_steps: int = 600, seed=0, **options) -> TrackResult:
    """Track the goal of one MovingScenario for ``max_steps`` steps (``max_steps dt``
    seconds; jitted, compiles once per shape and option set).

    Args:
      moving: a :class:`~softplan_jax.motion.MovingScenario`.
      method, n_points, gains, seed, **options: as :func:`~softplan_jax.plan`.
      max_steps: steps of the horizon (the rollout does not stop at the goal).
      **options: :class:`TrackOptions` fields (hold_tolerance, feedforward,
        search_substeps, anticipation) and :class:`~softplan_jax.PlanOptions`
        fields (step, safe_fraction, escapes, goal_tolerance, ...).

    Returns:
      :class:`TrackResult`.
    """
    _check_moving(moving, batched=False)
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    opts = make_track_options(method, n_points, **options)
    dtype = moving.scene.q0.dtype
    g = strong_gains(check_gains(gains, dtype, moving.n_segments), dtype)
    r = track_program(opts, int(max_steps), False)(moving, g, prng_key(seed))
    return result_from_track(r, moving, float(g.dt))


def result_from_track(r: Track, moving: MovingScenario, dt: float) -> TrackResult:
    """Trim one (unbatched) Track to the steps taken, on the host."""
    it = int(r.iterations)
    _, mask = radius_and_mask(moving.scene)
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
        time=np.asarray(r.time[: it + 1]),
        goal=np.asarray(r.goal[: it + 1]),
        error=np.asarray(r.error[: it + 1]),
        q=np.asarray(r.q[: it + 1]),
        tip=np.asarray(r.tip[: it + 1]),
        clearance=np.asarray(r.clearance[: it + 1])[:, np.asarray(mask)],
        moving=moving,
    )


def track_batch(movings: MovingScenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
                max_steps: int = 600, seed=0, *, chunk: int | None = None, progress: bool = False,
                **options) -> Track:
    """Track a stack of moving scenarios (vmapped, jitted once, in chunks of one shape).

    Arguments as :func:`track` and :func:`~softplan_jax.plan_batch` (``chunk``:
    scenarios per call, the last padded; ``progress``: a line per chunk on
    stderr). Returns a batched :class:`Track` of NumPy arrays.
    """
    _check_moving(movings, batched=True)
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1):
        raise ValueError(f"chunk must be None or an int >= 1, got {chunk!r}")
    opts = make_track_options(method, n_points, **options)
    dtype = movings.scene.q0.dtype
    g = strong_gains(check_gains(gains, dtype, movings.n_segments), dtype)
    batch = movings.scene.q0.shape[0]
    size = batch if chunk is None else min(int(chunk), batch)
    n_chunks = math.ceil(batch / size)
    keys = batch_keys(seed, batch)
    fn = track_program(opts, int(max_steps), True)
    host = jax.tree_util.tree_map(np.asarray, (movings, keys))
    bar = Progress(n_chunks, batch, 1, label="track_batch") if progress else None
    out = None
    for i, a in enumerate(range(0, batch, size)):
        m, k = pad_batch(jax.tree_util.tree_map(lambda x, a=a: x[a : a + size], host), size)
        r = jax.device_get(fn(m, g, k))
        n = min(size, batch - a)
        if out is None:
            out = jax.tree_util.tree_map(lambda x: np.empty((batch, *x.shape[1:]), x.dtype), r)
        for o, x in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(r), strict=True):
            o[a : a + n] = x[:n]
        if bar is not None:
            bar.update(i + 1, a + n)
    return out


def goal_trajectory(moving: MovingScenario, times):
    """g(t) at each of ``times`` (T,) -> (T, 3) (for plots)."""
    return jax.vmap(lambda t: goal_at(moving, t))(jnp.asarray(times, moving.scene.q0.dtype))
