"""The rollout engine: one step loop for planning a path and for tracking a moving goal.

A rollout steps from q at time t with the planner of paper eq. (9) and the safe
step (:mod:`softplan_jax.planning.step`), until it is done. A static scene
(:class:`~softplan_jax.scenarios.Scenario`) and a moving one
(:class:`~softplan_jax.scenarios.motion.MovingScenario`) run the same step, carry, escape
rule, status rule and result type; what differs is read off the scene at trace
time:

* the scene at step k: a static scene is itself; a moving one is
  :func:`~softplan_jax.scenarios.motion.scenario_at` at ``t_k = k dt``, its obstacles
  travel at most ``S_j dt`` during a step (:func:`~softplan_jax.scenarios.motion.speed_bounds`),
  which the safe step and the between-step proof subtract;
* the attraction: paper eq. (9)'s F_e, with the goal's velocity fed forward
  for a moving goal (:func:`~softplan_jax.planning.step.tracking_attraction`);
* where even standing still is not proven safe among moving obstacles (the rollout used
  to end ``too_fast``): the evasive step of :mod:`~softplan_jax.planning.evasion`
  (``TrackOptions.evasion``), run only for the scenes that need it;
* when to stop, set by the options: with PlanOptions (planning) a rollout
  ends at the goal or at a stall with no escape left; with TrackOptions
  (tracking, a static scene or a moving one) it holds the goal to the horizon
  and ends early only on a collision, a non-finite number or ``too_fast``,
  recording the goal, the time and the error at every step.

Step k looks at q_k: exact closest pairs to every obstacle (warm-started,
:mod:`softplan_jax.geometry.warm_start`), the true clearance at q_k and during the
motion from q_{k-1} (a search only where :func:`~softplan_jax.geometry.clearance.swept_clear`
does not prove the motion clear), the status, then while running the step to
q_{k+1}. Escapes: a stall (no progress by ``stall_tolerance`` over
``stall_window`` steps) starts a random walk of ``escape_steps`` steps (the
attraction replaced by a tip velocity of speed ``v_max`` in a random direction;
Barraquand & Latombe 1991); the PRNG key is in the carry.

Paid by the step. :func:`run` has three drivers of the same step:

* ``"scan"``: one ``lax.scan`` of max_steps + 1 steps (reverse-mode differentiable;
  what the gradient tuner differentiates);
* ``"chunks"``: ``lax.scan`` over ``step_chunk`` steps inside a ``while_loop`` that
  stops after the chunk in which the rollout finished;
* ``"lanes"`` (a batch, :func:`run_lanes`): ``lanes`` scenes step side by side
  (vmapped); when one finishes, its lane takes the next scene of the batch at the next
  step, and a scene that has held its lane for ``quantum`` steps while others wait goes
  back to the queue (round robin), so a batch costs about the sum of its scenes' steps,
  not batch size x the slowest scene, nor a tail of long scenes in idle lanes.

Every driver returns the same arrays, padded to max_steps + 1 along time:
after the step where a rollout ended, the records hold its last state
(q, tip, clearances, goal, error: frozen; in a static scene the between-step
clearance of the non-motions after the end is the clearance) and no events
(step scale 0, no solver fallbacks, no between-step search).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base.numerics import evaluate_where, safe_norm, tie, when_any
from ..base.status import Status
from ..geometry.clearance import between_steps, contact_tolerance, swept_clear
from ..geometry.closest import ClosestPoint, SolverOptions
from ..geometry.kinematics import tip_position
from ..geometry.obstacles import placeholder_closest, radius_and_mask, true_closest, warm_cells, warm_closest, warm_state
from ..scenarios.motion import MovingScenario, goal_velocity, moved_cells, scenario_at, speed_bounds
from .evasion import evasive_target, slot_clearance
from .records import Record, Rollout, finish, record_zeros, setup
from .step import attraction, goal_scaled, scaled_step, step_target, tracking_attraction

__all__ = ["Carry", "DEFAULT_STEP_CHUNK", "DEFAULT_LANES", "TRACK_LANES", "DEFAULT_QUANTUM", "ACCELERATOR_LANES",
           "default_lanes", "run", "run_lanes", "check_engine_sizes"]

DEFAULT_STEP_CHUNK = 8  # steps between two checks of "done": at most 7 steps computed past the end
DEFAULT_LANES = 64  # scenes planned side by side in a batch on a CPU (benchmarks/engine.py)
# ... tracked on a CPU: a tracked scene holds its lane to the horizon, so refills buy nothing and a
# wider step costs less per scene (1,024 moving scenes: 17.6 / 19.2 / 21.0 s with 1,024 / 256 / 64).
TRACK_LANES = 1024
# ... and on an accelerator: every scene of a device's share at once, up to this many (one H200,
# float64: 1,024 lanes 8x faster than 64; 16,384 lanes 3.7e6 scene-steps/s; benchmarks/gpu.py).
ACCELERATOR_LANES = 16384
DEFAULT_QUANTUM = 64  # steps a lane holds a scene while others wait (run_lanes); faster than 32 or 128 here


def default_lanes(platform: str | None = None, tracking: bool = False) -> int:
    """The lanes of a batch when none are given (at most the batch): on a CPU
    :data:`DEFAULT_LANES` (64) when planning, :data:`TRACK_LANES` (1,024) when tracking;
    :data:`ACCELERATOR_LANES` (16,384) on a GPU or TPU, where a wide vmapped step is nearly
    as fast as a narrow one. ``platform``: a jax platform name ("cpu", "gpu", "cuda",
    "rocm", "tpu"); None: ``jax.default_backend()``."""
    platform = jax.default_backend() if platform is None else platform
    return ACCELERATOR_LANES if platform != "cpu" else TRACK_LANES if tracking else DEFAULT_LANES


class Carry(NamedTuple):
    """The state a rollout carries from step to step."""

    q: jax.Array  # q_k
    q_prev: jax.Array  # q_{k-1} (q_0 at k = 0)
    truth_prev: ClosestPoint  # exact closest pairs at q_{k-1}
    c_prev: jax.Array  # (m,) true clearance at q_{k-1}
    first: jax.Array
    status: jax.Array
    iterations: jax.Array
    best_error: jax.Array
    since_best: jax.Array
    key: jax.Array  # PRNG key of the escapes
    escapes: jax.Array  # escapes started so far
    walk_left: jax.Array  # steps left in the current random walk (0: following the field)
    walk_velocity: jax.Array  # (3,) tip velocity of the current walk
    warm: tuple  # the warm start's state (obstacles.warm_state), () without it
    certified: jax.Array  # the motion from q_{k-1} to q_k was proven clear by the evasive step


def _whole(name, v) -> int:  # v as an int; ValueError for anything but an int >= 1
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 1:
        raise ValueError(f"{name} must be an int >= 1, got {v!r}")
    return int(v)


def check_engine_sizes(max_steps, step_chunk=DEFAULT_STEP_CHUNK, lanes=None) -> tuple:
    """Validate the engine's sizes on the host, before anything compiles: ``(max_steps, step_chunk,
    lanes)`` as ints (``lanes`` may be None). ValueError for anything but an int >= 1 (a bool, 2.5, "8")."""
    sizes = _whole("max_steps", max_steps), _whole("step_chunk", step_chunk)
    return (*sizes, None if lanes is None else _whole("lanes", lanes))


def _moving_cells(cells, moving: MovingScenario, t):
    if not cells or not moving.scene.curves.coeffs.shape[0]:
        return cells
    return (moved_cells(cells[0], moving.motion, t), *cells[1:])


def init_carry(world, options, key) -> Carry:
    """The carry at step 0 (q_0 = the scene's start)."""
    su = setup(world, options)
    scene, plan = su.scene, su.plan
    _, mask = radius_and_mask(scene)
    q0 = scene.q0
    dtype = q0.dtype
    carry0 = Carry(
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
        warm=warm_state(scene) if _warm(plan) else (),
        certified=jnp.zeros((), bool),
    )
    return tie(carry0, q0)  # under vmap (a batch), the carry is batched from the start (see tie)


def _warm(plan) -> bool:
    exact = plan.check_collisions or plan.method == "curve"
    return exact and plan.warm_start and isinstance(plan.solver, SolverOptions)


def prepare(world, options) -> tuple:
    """What a rollout computes once per scene, before its first step: the warm start's
    per-curve data (:func:`~softplan_jax.geometry.obstacles.warm_cells`) and, for a moving scene,
    its obstacles' speed bounds (:func:`~softplan_jax.scenarios.motion.speed_bounds`)."""
    su = setup(world, options)
    cells = warm_cells(su.scene, su.plan.solver) if _warm(su.plan) else ()
    return cells, (speed_bounds(world) if su.moving else ())


def make_step(world, gains, options, max_steps: int, prepared=None):
    """The engine's step ``(carry, k) -> (carry, record)`` for this scene (static or
    moving), gains and options (PlanOptions: plan; TrackOptions: track);
    ``prepared``: :func:`prepare` of the scene (None: computed here)."""
    su = setup(world, options)
    scene, plan, track = su.scene, su.plan, su.track
    radius, mask = radius_and_mask(scene)
    q0 = scene.q0
    dtype = q0.dtype
    contact = contact_tolerance(plan, dtype)
    check = plan.check_collisions
    walks = plan.escapes > 0
    exact = check or plan.method == "curve"
    warm = _warm(plan)
    cells0, speed = prepare(world, options) if prepared is None else prepared
    n_pairs = q0.shape[0] * (jnp.sum(scene.curve_mask) + len(scene.parametric)).astype(jnp.int32)
    radius_sum = scene.arm_radius + radius
    if su.moving:
        dt = gains.dt
        travel = speed * dt  # (m,) how far each obstacle can move in one step
        lead = speed * track.anticipation  # (m,) the field's inflation (TrackOptions.anticipation)
        m_c = scene.curves.coeffs.shape[0]
        substeps = jnp.arange(1, track.search_substeps + 1, dtype=dtype) / (track.search_substeps + 1)
    # The evasive step (TrackOptions.evasion) needs the true clearance (check_collisions) and the safe step.
    evades = su.moving and track.evasion and check and plan.step == "safe"

    def clearance_of(truth):
        return jnp.where(mask, truth.distance - scene.arm_radius - radius, jnp.inf)

    def moving_search(q_a, q_b, t_a, w, j):
        """Slot j's smallest exact clearance at the search instants, arm and curves moving together."""

        def at(tau):
            return slot_clearance(w, q_a + tau * (q_b - q_a), t_a + tau * dt, j, plan.solver)

        return jnp.min(jax.vmap(at)(substeps))

    def between(carry, q, truth, c, running, t, sc):
        """(cb, searched): the clearance during the motion from q_{k-1} to q_k (module docstring)."""
        if su.moving:
            # Proven clear where the clearance at its start, less the arm's motion bound and the
            # obstacle's travel, stays above the contact tolerance.
            proven = swept_clear(carry.q_prev, q, carry.truth_prev, carry.c_prev - travel, contact)
            proven = proven | carry.certified  # an evasive step's motion: proven in time (planning.evasion)
            searched = mask & ~carry.first & running & ~proven

            def search(j):
                # The barrier ties the search to the slot index (a loop variable of evaluate_where):
                # without it XLA hoists the loop-invariant solves out of the while loop.
                q_a, q_b, t_a, w, j = jax.lax.optimization_barrier((carry.q_prev, q, t - dt, world, j))
                return moving_search(*jax.lax.stop_gradient((q_a, q_b, t_a, w)), j)

            found = evaluate_where(searched, search, 1, jnp.full(mask.shape, jnp.inf, dtype))
            cb = jnp.minimum(jnp.minimum(carry.c_prev, c), jnp.where(searched, found, jnp.inf))
        elif plan.swept_proof:
            # The search runs only where the motion bound cannot prove the motion clear.
            proven = swept_clear(carry.q_prev, q, carry.truth_prev, carry.c_prev, contact)
            searched = mask & ~carry.first & running & ~proven
            cb = between_steps(carry.q_prev, q, carry.truth_prev, truth, sc, radius_sum, search=searched)
        else:
            searched = mask & ~carry.first & running
            cb = between_steps(carry.q_prev, q, carry.truth_prev, truth, sc, radius_sum)
        return cb, searched

    def step(carry: Carry, k):
        q = carry.q
        t = k.astype(dtype) * gains.dt if track else None
        if su.moving:
            sc = scenario_at(world, t)
            cells = _moving_cells(cells0, world, t)
        else:
            sc, cells = scene, cells0
        warm_next = carry.warm
        if warm:
            truth, warm_next, fallbacks = warm_closest(q, sc, plan.solver, cells, carry.warm, carry.first)
        elif exact:
            truth = true_closest(q, sc, plan.solver)
            fallbacks = n_pairs
        else:
            truth = placeholder_closest(q, sc)
            fallbacks = jnp.zeros((), jnp.int32)
        running = carry.status == Status.RUNNING
        if check:
            c = clearance_of(truth)
            cb, searched = between(carry, q, truth, c, running, t, sc)
            cb = jnp.where(carry.first | ~mask, c, cb)
            nan_clearance = jnp.any(jnp.isnan(c)) | jnp.any(jnp.isnan(cb))
            hit = jnp.any(c <= contact) | jnp.any(cb <= contact)
        else:
            c = cb = jnp.full(mask.shape, jnp.nan, dtype)
            searched = jnp.zeros(mask.shape, bool)
            nan_clearance = hit = jnp.zeros((), bool)
        V_e = sc.goal - tip_position(q)
        err = safe_norm(V_e)
        improved = err < carry.best_error - plan.stall_tolerance
        walking = carry.walk_left > 0
        settled = improved | carry.first | walking
        if not su.stop_at_goal:
            settled = settled | (err <= track.hold_tolerance)  # holding the goal is no stall
        since = jnp.where(settled, 0, carry.since_best + 1)
        stalled = since >= plan.stall_window
        # A stall with an escape left starts a random walk instead of ending the rollout.
        escape = stalled & (carry.escapes < plan.escapes)
        # The status rule: a non-finite clearance, then a contact; planning also ends at the goal
        # and at a stall with no escape left, tracking holds on to the horizon.
        judged = Status.RUNNING
        if su.stop_at_goal:
            judged = jnp.where(err < plan.goal_tolerance, Status.REACHED,
                               jnp.where(stalled & ~escape, Status.STALLED, Status.RUNNING))
        judged = jnp.where(nan_clearance, Status.NONFINITE, jnp.where(hit, Status.COLLIDED, judged))
        status = jnp.where(running, judged, carry.status)
        # The step to q_{k+1}, taken only while running (and not past max_steps).
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
        if su.moving:
            F_e = tracking_attraction(V_e, goal_velocity(world, t), goal_scaled(gains, V_e), track.feedforward)
            # The field sees each curve inflated by its look-ahead; the safe step gets the true clearance.
            field = sc._replace(curves=sc.curves.__class__.tree_unflatten(
                None, [sc.curves.coeffs, sc.curves.u_range, sc.curves.radius + lead[:m_c]]))
            extra = dict(travel=travel, lead=lead)
        else:
            F_e, field, extra = attraction(V_e, goal_scaled(gains, V_e)), sc, {}
        # An escape's random walk replaces the attraction (paper eq. 9's F_e).
        F_e = jnp.where(walk_left > 0, walk_velocity, F_e)
        q_full, field_c = step_target(q, field, gains, truth, plan, (jnp.ones((), bool), F_e), extra.get("lead"))
        q_next, alpha, too_fast = scaled_step(q, q_full, field_c, plan, extra.get("travel"))
        evasive = jnp.zeros((), bool)
        if evades:
            # Where no scale of the field's step is proven safe: the evasive step (planning.evasion),
            # computed only for the scenes that need it (under vmap too: base.numerics.when_any).
            want = stepping & too_fast

            def evade(args):  # every array an operand: under vmap each may be batched
                w, q_a, q_b, tr, c_a, t_a, s, g, go = args
                q_ev, proven, _ = evasive_target(w, q_a, q_b, tr, c_a, t_a, s, g, track, go)
                return q_ev, proven

            # Held (stop_gradient): a rollout stays differentiable, the evasive step itself is not.
            args = jax.lax.stop_gradient((world, q, q_full, truth, c, t, speed, gains, want))
            q_ev, proven = when_any(want, evade, lambda args: (args[1], jnp.zeros((), bool)), args, chunk="auto")
            evasive = want & proven
            q_next = jnp.where(evasive, q_ev, q_next)
            alpha = jnp.where(evasive, 1.0, alpha)
            too_fast = too_fast & ~evasive
        finite = jnp.all(jnp.isfinite(q_next))
        status = jnp.where(stepping & too_fast, Status.TOO_FAST, status)
        status = jnp.where(stepping & ~too_fast & ~finite, Status.NONFINITE, status).astype(jnp.int32)
        moved = stepping & ~too_fast & finite
        evaded = evasive & moved  # the step just taken was the evasive one
        new = Carry(
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
            certified=evaded,
        )
        converged = jnp.all(jnp.where(mask, truth.converged, True))
        alpha = jnp.where(moved, alpha, 0.0).astype(dtype)
        record = Record(q, tip_position(q), c, cb, alpha, converged, fallbacks, searched)
        if track:
            record = record._replace(goal=sc.goal, time=t, error=err, evasive=evaded)
        return new, record

    return step


def run(world, gains, options, max_steps: int, key, *, driver: str = "chunks",
        step_chunk: int = DEFAULT_STEP_CHUNK) -> Rollout:
    """One rollout of ``world`` (a Scenario or a MovingScenario; pure, traceable).

    Args:
      world: the scene, static or moving.
      gains: Gains or GainFunction.
      options: PlanOptions (plan: stop at the goal) or TrackOptions (track: hold the goal to
        the horizon; a moving scene needs them), static.
      max_steps: the most planner steps (static).
      key: PRNG key of the escapes.
      driver: "chunks" (stops after the chunk of ``step_chunk`` steps in which
        the rollout finished) or "scan" (all max_steps + 1 steps; reverse-mode
        differentiable). Both give the same arrays.
    """
    step = make_step(world, gains, options, max_steps)
    carry0 = init_carry(world, options, key)
    T1 = max_steps + 1
    if driver == "scan":
        final, records = jax.lax.scan(step, carry0, jnp.arange(T1))
    elif driver == "chunks":
        C = min(int(step_chunk), T1)
        n_chunks = math.ceil(T1 / C)
        buf = tie(record_zeros(world, options, n_chunks * C), carry0.q)

        def cond(state):
            i, carry, _ = state
            return (i < n_chunks) & (carry.status == Status.RUNNING)

        def body(state):
            i, carry, buf = state
            carry, part = jax.lax.scan(step, carry, i * C + jnp.arange(C))
            buf = jax.tree_util.tree_map(lambda b, p: jax.lax.dynamic_update_slice_in_dim(b, p, i * C, 0), buf, part)
            return i + 1, carry, buf

        i0 = jnp.zeros((), jnp.arange(0).dtype)  # the scan driver's step index dtype
        _, final, buf = jax.lax.while_loop(cond, body, (i0, carry0, buf))
        records = jax.tree_util.tree_map(lambda b: b[:T1], buf)
    else:
        raise ValueError(f"unknown driver {driver!r}; choose 'chunks' or 'scan' (a batch: run_lanes)")
    return finish(world, options, records, final)


def run_lanes(worlds, gains, options, max_steps: int, keys, *, lanes: int | None = None,
              step_chunk: int = DEFAULT_STEP_CHUNK, quantum: int | None = None) -> Rollout:
    """A batch of rollouts (``worlds``: a stacked Scenario or MovingScenario, leading
    axis B; ``keys`` (B,) keys), ``lanes`` at a time (None: :func:`default_lanes`),
    refilled as they finish.

    Each lane steps one scene (:func:`run`'s rollout, its own carry, key and step count;
    vmapped: equal to one-at-a-time rollouts to rounding). A lane whose scene finished (or
    reached max_steps) takes the next scene of the queue: the scenes not yet started, in
    batch order, then the suspended ones. A lane that has held its scene ``quantum`` steps
    while others wait suspends it (carry and step kept) and takes the next (round robin),
    so that the scenes started last do not run alone in otherwise idle lanes; the results
    do not depend on the quantum. None: :data:`DEFAULT_QUANTUM` when planning, none when
    tracking (every scene holds to the horizon: nothing to balance). The loop stops after
    the ``step_chunk`` steps in which the last scene finished.

    Returns a batched :class:`Rollout` (leading axis B).
    """
    max_steps, step_chunk, lanes = check_engine_sizes(max_steps, step_chunk, lanes)
    one = jax.tree_util.tree_map(lambda x: x[0], worlds)
    planning = setup(one, options).stop_at_goal
    lanes = default_lanes(tracking=not planning) if lanes is None else lanes
    quantum = _whole("quantum", (DEFAULT_QUANTUM if planning else max_steps + 1) if quantum is None else quantum)
    B = jax.tree_util.tree_leaves(worlds)[0].shape[0]
    L = min(lanes, B)
    prepared = jax.vmap(lambda w: prepare(w, options))(worlds)  # once per scene

    def take(b, kept, k_kept):
        """Scene b's world, prepared data, carry and step kept (b: (L,) indices)."""
        w, p, carry = jax.tree_util.tree_map(lambda x: x[b], (worlds, prepared, kept))
        return (w, p, carry), k_kept[b]

    def step_one(world, prep, carry, k):
        return make_step(world, gains, options, max_steps, prep)(carry, k)

    # kept: each scene's carry: its first until it starts, its last once suspended (until it resumes)
    # or finished; k_kept: the step it resumes at (0: not started).
    kept0 = jax.vmap(lambda w, key: init_carry(w, options, key))(worlds, keys)
    k_kept0 = jnp.zeros((B,), jnp.int32)
    idx0 = jnp.arange(L, dtype=jnp.int32)
    lane0, k0 = take(idx0, kept0, k_kept0)
    out = jax.tree_util.tree_map(lambda x: jnp.zeros((B, *x.shape), x.dtype), record_zeros(one, options, max_steps + 1))
    # The queue, a ring of B scene indices read at head and written at tail: first the scenes
    # L, ..., B - 1 (not started), then each suspended scene in the order of its suspension.
    queue0 = jnp.arange(L, L + B, dtype=jnp.int32) % B
    ring0 = (queue0, jnp.zeros((), jnp.int32), jnp.asarray(B - L, jnp.int32))  # queue, head, tail
    state0 = (out, kept0, k_kept0, idx0, k0, jnp.zeros((L,), jnp.int32), lane0, ring0)

    def lane_step(state, _):
        out, kept, k_kept, idx, k, held, (w, p, carry), ring = state
        active = idx < B
        carry, rec = jax.vmap(step_one)(w, p, carry, k)
        row = jnp.where(active, idx, B)  # B: out of range, dropped
        out = jax.tree_util.tree_map(lambda o, r: o.at[row, k].set(r, mode="drop"), out, rec)
        done = active & ((carry.status != Status.RUNNING) | (k >= max_steps))
        # Suspend (in lane order) as many scenes at the end of their quantum as wait in the
        # queue beyond those the finished lanes take: none gets its own scene back.
        queue, head, tail = ring
        spare = tail - head - jnp.sum(done, dtype=jnp.int32)
        due = active & ~done & (held + 1 >= quantum)
        suspend = due & (jnp.cumsum(due.astype(jnp.int32)) <= spare)
        vacated = done | suspend

        def refill(state):
            kept, k_kept, idx, (queue, head, tail), lane = state
            kept = jax.tree_util.tree_map(lambda f, c: f.at[jnp.where(vacated, idx, B)].set(c, mode="drop"), kept,
                                          lane[2])
            parked = jnp.where(suspend, idx, B)
            k_kept = k_kept.at[parked].set(k + 1, mode="drop")
            queue = queue.at[jnp.where(suspend, (tail + jnp.cumsum(suspend.astype(jnp.int32)) - 1) % B, B)].set(
                idx, mode="drop")
            tail = tail + jnp.sum(suspend, dtype=jnp.int32)
            # The vacated lanes take the queue's next scenes, in lane order (none left: index B, idle).
            rank = jnp.cumsum(vacated.astype(jnp.int32)) - 1
            gets = vacated & (rank < tail - head)
            idx = jnp.where(vacated, jnp.where(gets, queue[(head + rank) % B], B), idx)
            head = head + jnp.sum(gets, dtype=jnp.int32)
            fresh, k_fresh = take(jnp.minimum(idx, B - 1), kept, k_kept)
            lane = jax.tree_util.tree_map(
                lambda a, b: jnp.where(vacated.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), fresh, lane)
            return kept, k_kept, idx, (queue, head, tail), lane, k_fresh

        kept, k_kept, idx, ring, lane, k_fresh = jax.lax.cond(
            jnp.any(vacated), refill, lambda state: (*state, k), (kept, k_kept, idx, ring, (w, p, carry)))
        k = jnp.where(vacated, k_fresh, k + 1)
        held = jnp.where(vacated, 0, held + 1)
        return (out, kept, k_kept, idx, k, held, lane, ring), None

    def cond(state):
        return jnp.any(state[3] < B)

    def body(state):
        return jax.lax.scan(lane_step, state, None, length=step_chunk)[0]

    out, kept, *_ = jax.lax.while_loop(cond, body, state0)
    return jax.vmap(lambda w, rec, fin: finish(w, options, rec, fin))(worlds, out, kept)
