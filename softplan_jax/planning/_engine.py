"""The rollout engine: one step loop for planning a path and for tracking a moving goal.

Step k looks at q_k: the exact closest pairs to every obstacle (a closest-point provider,
:mod:`softplan_jax.geometry._closest_pairs`), the true clearance at q_k and during the motion
from q_{k-1} (the world's check, :mod:`softplan_jax.planning._world`), the status; then, while
running, the step to q_{k+1} (paper eq. 9 scaled by the safe step, the world's step). A stall
starts a random walk of the tip (an escape; Barraquand & Latombe 1991) while escapes are left.
:func:`run` rolls one scene out (a ``lax.scan``, or chunks of scans that stop after the end);
:func:`run_lanes` steps a batch's scenes side by side and refills a finished scene's lane, so a
batch costs about the sum of its scenes' steps. After its end a rollout's records are frozen
(:func:`~softplan_jax.planning._records.freeze`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._numerics import safe_norm, tie
from ..base._status import Status
from ..base._validation import check_int
from ..geometry._arm import PCC
from ..geometry._closest import ClosestPoint, SolverOptions
from ..geometry._closest_pairs import ExactPairs, NearPairs, NoPairs, WarmPairs
from ..geometry._obstacles import clearance_of, placeholder_closest, radius_and_mask
from ._records import Record, Rollout, finish, record_zeros, setup
from ._world import make_world, world_data

__all__ = ["Carry", "DEFAULT_STEP_CHUNK", "DEFAULT_LANES", "TRACK_LANES", "DEFAULT_QUANTUM", "ACCELERATOR_LANES",
           "default_lanes", "closest_pairs", "run", "run_lanes", "check_engine_sizes"]

DEFAULT_STEP_CHUNK = 8  # steps between two checks of "done": at most 7 steps computed past the end
DEFAULT_LANES = 128  # the most scenes planned side by side in a batch on a CPU (docs: Performance)
LANE_STEPS = 75  # a CPU batch's lanes: ceil(scenes * LANE_STEPS / max_steps), at most DEFAULT_LANES
MIN_LANES = 8  # ... and at least this many (default_lanes)
TRACK_LANES = 1024  # ... tracked on a CPU: a tracked scene holds its lane to the horizon
ACCELERATOR_LANES = 16384  # ... on a GPU or TPU: every scene of a device's share, up to this many
DEFAULT_QUANTUM = 64  # steps a lane holds a scene while others wait (run_lanes)


def default_lanes(platform: str | None = None, tracking: bool = False, scenes: int | None = None,
                  max_steps: int | None = None) -> int:
    """The lanes of a batch when none are given (at most the batch): on a CPU
    :data:`DEFAULT_LANES` when planning, :data:`TRACK_LANES` when tracking;
    :data:`ACCELERATOR_LANES` on a GPU or TPU, where a wide vmapped step is nearly
    as fast as a narrow one. ``platform``: a jax platform name ("cpu", "gpu", "cuda",
    "rocm", "tpu"); None: ``jax.default_backend()``.

    Given the batch's ``scenes`` and ``max_steps``, a CPU plans on
    ``ceil(scenes * LANE_STEPS / max_steps)`` lanes, between :data:`MIN_LANES` and
    :data:`DEFAULT_LANES`: while a scene runs to ``max_steps``, each other lane plans
    about ``max_steps / LANE_STEPS`` scenes, so few lanes idle at the batch's end
    (docs: Performance, "Lanes")."""
    platform = jax.default_backend() if platform is None else platform
    if platform != "cpu":
        return ACCELERATOR_LANES
    if tracking:
        return TRACK_LANES
    if scenes is None or max_steps is None:
        return DEFAULT_LANES
    return min(DEFAULT_LANES, max(MIN_LANES, -(-int(scenes) * LANE_STEPS // max(int(max_steps), 1))))


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
    warm: tuple  # the closest-point provider's state
    certified: jax.Array  # the motion from q_{k-1} to q_k was proven clear by the evasive step


def check_engine_sizes(max_steps, step_chunk=DEFAULT_STEP_CHUNK, lanes=None) -> tuple:
    """Validate the engine's sizes on the host, before anything compiles: ``(max_steps, step_chunk,
    lanes)`` as ints (``lanes`` may be None). ValueError for anything but an int >= 1 (a bool, 2.5, "8")."""
    sizes = check_int(max_steps, "max_steps", 1), check_int(step_chunk, "step_chunk", 1)
    return (*sizes, None if lanes is None else check_int(lanes, "lanes", 1))


def closest_pairs(plan):
    """The closest-point provider of a rollout's PlanOptions: the certified warm start
    (``warm_start``, the default solver), solving only the pairs within reach of the Khatib
    repulsion (``far_margin`` not None); else the full solve where exact pairs are needed (the
    curve method, or the collision checks), else none (the N-point model alone)."""
    exact = plan.check_collisions or plan.method == "curve"
    if exact and plan.warm_start and isinstance(plan.solver, SolverOptions):
        if plan.far_margin is not None and plan.repulsion == "khatib":
            return NearPairs(plan.solver, plan.far_margin)
        return WarmPairs(plan.solver)
    return ExactPairs(plan.solver) if exact else NoPairs()


def init_carry(world, options, key, arm=PCC) -> Carry:
    """The carry at step 0 (q_0 = the scene's start); ``arm``: the arm model, whose shape's
    rows the closest-point provider's state follows."""
    su = setup(world, options)
    scene = su.scene
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
        warm=closest_pairs(su.plan).init(scene, arm.rows(q0.shape[0])),
        certified=jnp.zeros((), bool),
    )
    return tie(carry0, q0)  # under vmap (a batch), the carry is batched from the start (see tie)


def prepare(world, options) -> tuple:
    """What a rollout computes once per scene, before its first step
    (:func:`~softplan_jax.planning._world.world_data`)."""
    su = setup(world, options)
    return world_data(world, su, closest_pairs(su.plan))


def _clearances(w, carry, q, truth, running, t, sc):
    """``(c, cb, searched, nan, hit)`` at step k: the true clearance at q_k, during the motion
    from q_{k-1}, where the between-step search ran, and whether either is NaN or in contact.
    Without the checks (``check_collisions=False``): NaN clearances, never a contact."""
    mask = w.mask
    if not w.plan.check_collisions:
        nan = jnp.full(mask.shape, jnp.nan, q.dtype)
        return nan, nan, jnp.zeros(mask.shape, bool), jnp.zeros((), bool), jnp.zeros((), bool)
    c = clearance_of(truth, sc)
    cb, searched = w.between(carry, q, truth, c, running, t, sc)
    cb = jnp.where(carry.first | ~mask, c, cb)
    nan = jnp.any(jnp.isnan(c)) | jnp.any(jnp.isnan(cb))
    hit = jnp.any(c <= w.contact) | jnp.any(cb <= w.contact)
    return c, cb, searched, nan, hit


def _stall(carry, err, su):
    """``(since, stalled, escape)``: steps since the best goal error last improved by
    ``stall_tolerance``, whether that reached ``stall_window``, and whether an escape is left."""
    plan = su.plan
    improved = err < carry.best_error - plan.stall_tolerance
    settled = improved | carry.first | (carry.walk_left > 0)
    if not su.stop_at_goal:
        settled = settled | (err <= su.track.hold_tolerance)  # holding the goal is no stall
    since = jnp.where(settled, 0, carry.since_best + 1)
    stalled = since >= plan.stall_window
    return since, stalled, stalled & (carry.escapes < plan.escapes)


def _judge(su, carry, err, stalled, escape, nan, hit):
    """The status rule: a non-finite clearance, then a contact; planning also ends at the goal
    and at a stall with no escape left, tracking holds on to the horizon."""
    judged = Status.RUNNING
    if su.stop_at_goal:
        judged = jnp.where(err < su.plan.goal_tolerance, Status.REACHED,
                           jnp.where(stalled & ~escape, Status.STALLED, Status.RUNNING))
    judged = jnp.where(nan, Status.NONFINITE, jnp.where(hit, Status.COLLIDED, judged))
    return jnp.where(carry.status == Status.RUNNING, judged, carry.status)


def _walk(carry, start, since, gains, plan, dtype):
    """An escape: where ``start``, a random walk of the tip at speed ``v_max`` in a random
    direction for ``escape_steps`` steps. ``(key, walk_velocity, walk_left, escapes, since)``."""
    key, walk_velocity, walk_left, escapes = carry.key, carry.walk_velocity, carry.walk_left, carry.escapes
    if plan.escapes > 0:
        key, sub = jax.random.split(key)
        direction = jax.random.normal(sub, (3,), dtype)
        direction = direction / jnp.maximum(safe_norm(direction), jnp.finfo(dtype).tiny)
        walk_velocity = jnp.where(start, gains.v_max * direction, walk_velocity)
        walk_left = jnp.where(start, plan.escape_steps, walk_left)
        escapes = escapes + start.astype(jnp.int32)
        since = jnp.where(start, 0, since)
    return key, walk_velocity, walk_left, escapes, since


def make_step(world, gains, options, max_steps: int, prepared=None, arm=PCC):
    """The engine's step ``(carry, k) -> (carry, record)`` for this scene (static or
    moving), gains and options (PlanOptions: plan; TrackOptions: track);
    ``prepared``: :func:`prepare` of the scene (None: computed here); ``arm``: the arm
    model (:mod:`softplan_jax.geometry._arm`)."""
    su = setup(world, options)
    plan, dtype = su.plan, su.scene.q0.dtype
    pairs = closest_pairs(plan)
    w = make_world(world, su, gains, world_data(world, su, pairs) if prepared is None else prepared, arm)
    d0, travel = w.reach()  # for a provider that solves only the pairs within reach (the others ignore them)

    def step(carry: Carry, k):
        q = carry.q
        t = k.astype(dtype) * gains.dt if su.track else None
        posed = arm.at(q)  # the arm model at q (one equilibrium solve for a loaded arm)
        sc, cells = w.at(t)
        sc = posed.widened(sc)
        truth, warm_next, fallbacks = pairs.query(posed.shape(q), sc, cells, carry.warm, carry.first, d0, travel)
        running = carry.status == Status.RUNNING
        c, cb, searched, nan, hit = _clearances(w, carry, q, truth, running, t, sc)
        V_e = sc.goal - posed.tip(q)
        err = safe_norm(V_e)
        since, stalled, escape = _stall(carry, err, su)
        status = _judge(su, carry, err, stalled, escape, nan, hit)
        # The step to q_{k+1}, taken only while running (and not past max_steps).
        stepping = (status == Status.RUNNING) & (k < max_steps)
        key, walk_velocity, walk_left, escapes, since = _walk(carry, stepping & escape, since, gains, plan, dtype)
        # An escape's random walk replaces the attraction (paper eq. 9's F_e).
        F_e = jnp.where(walk_left > 0, walk_velocity, w.attraction(V_e, t))
        q_next, alpha, too_fast, evasive = w.step(q, sc, truth, c, t, F_e, stepping, posed)
        finite = jnp.all(jnp.isfinite(q_next))
        status = jnp.where(stepping & too_fast, Status.TOO_FAST, status)
        status = jnp.where(stepping & ~too_fast & ~finite, Status.NONFINITE, status).astype(jnp.int32)
        moved = stepping & ~too_fast & finite
        new = Carry(
            q=jnp.where(moved, q_next, q), q_prev=q, truth_prev=truth, c_prev=c, first=jnp.zeros((), bool),
            status=status, iterations=carry.iterations + moved.astype(jnp.int32),
            best_error=jnp.minimum(err, carry.best_error), since_best=since, key=key, escapes=escapes,
            walk_left=jnp.where(moved, jnp.maximum(walk_left - 1, 0), walk_left).astype(jnp.int32),
            walk_velocity=walk_velocity, warm=warm_next, certified=evasive & moved)
        converged = jnp.all(jnp.where(w.mask, truth.converged, True))
        alpha = jnp.where(moved, alpha, 0.0).astype(dtype)
        record = Record(q, posed.tip(q), c, cb, alpha, converged, fallbacks, searched)
        if su.track:
            record = record._replace(goal=sc.goal, time=t, error=err, evasive=evasive & moved)
        return new, record

    return step


def run(world, gains, options, max_steps: int, key, *, driver: str = "chunks",
        step_chunk: int = DEFAULT_STEP_CHUNK, arm=PCC) -> Rollout:
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
    step = make_step(world, gains, options, max_steps, arm=arm)
    carry0 = init_carry(world, options, key, arm)
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
              step_chunk: int = DEFAULT_STEP_CHUNK, quantum: int | None = None, arm=PCC) -> Rollout:
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
    B = jax.tree_util.tree_leaves(worlds)[0].shape[0]
    lanes = default_lanes(tracking=not planning, scenes=B, max_steps=max_steps) if lanes is None else lanes
    quantum = check_int((DEFAULT_QUANTUM if planning else max_steps + 1) if quantum is None else quantum, "quantum", 1)
    L = min(lanes, B)
    prepared = jax.vmap(lambda w: prepare(w, options))(worlds)  # once per scene

    def take(b, kept, k_kept):
        """Scene b's world, prepared data, carry and step kept (b: (L,) indices)."""
        w, p, carry = jax.tree_util.tree_map(lambda x: x[b], (worlds, prepared, kept))
        return (w, p, carry), k_kept[b]

    def step_one(world, prep, carry, k):
        return make_step(world, gains, options, max_steps, prep, arm)(carry, k)

    # kept: each scene's carry: its first until it starts, its last once suspended (until it resumes)
    # or finished; k_kept: the step it resumes at (0: not started).
    kept0 = jax.vmap(lambda w, key: init_carry(w, options, key, arm))(worlds, keys)
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
