"""Reachability of the goal: can any collision-free configuration put the tip on the goal? Answered
for the goal alone (docs: Reaching every goal): proofs on the host (``beyond_reach``: farther than
``sum_i L_max_i`` from the base, as every point of a PCC arm lies within its backbone length;
``goal_in_obstacle``: closer than ``arm_radius + radius_j`` to obstacle j's centre line), then,
jitted and vmapped over the starts, tip IK (Levenberg-Marquardt on ``goal - tip(q)``, lengths in
``[L_min, L_max]``) and null-space steps ``dq = J_e^+ (goal - tip) + (I - J_e^+ J_e) sum_j w_j grad
c_j`` with ``w_j = max(0, 2 ik_clearance - c_j)`` and ``grad c_j = n_j^T J_sj`` (the envelope theorem
at the exact closest pair of paper §2.3). A start is a certified goal configuration when its exact
solves converged, its clearance is at least ``ik_clearance`` and ``|goal - tip| <= ik_tolerance``;
without one the reason is a proof or ``no_ik_solution`` (a multi-start decision, not a proof).
The fallback's IK takes an arm model (``arm``, :mod:`~softplan_jax.geometry._arm`): the tip, its
Jacobian, the points' Jacobians and the clearance are then the model's (a loaded arm's through
its equilibrium, its clearance widened by its pieces' gap); both proofs hold for it too."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._numerics import damped_pinv, safe_norm, solve_small
from ..geometry._arm import PCC
from ..geometry._closest import DEFAULT_OPTIONS, SolverOptions
from ..geometry._obstacles import clearance_of, placeholder_closest, radius_and_mask, true_closest
from ..planning._batching import lanes_map
from ..scenarios import Scenario
from ..scenarios._scenario import unreachable_reason

__all__ = ["ReachOptions", "Reachability", "REACH_REASONS", "reachability", "goal_configurations",
           "goal_configurations_batch", "scene_of"]


class ReachOptions(NamedTuple):
    """Settings of the reachability test and of the global fallback (static:
    changing one recompiles).

    Attributes:
      ik_starts: IK starts per goal (the start q0, the extra configuration if
        given, then random ones).
      ik_iterations: Levenberg-Marquardt iterations on the tip alone.
      ik_clear_iterations: null-space iterations that push the arm off the obstacles.
      ik_clearance: least exact clearance of a certified goal configuration
        (and the clearance the null-space push aims at twice of).
      ik_tolerance: largest tip error of a certified goal configuration.
      theta_max: random configurations (IK starts, RRT samples) bend each
        segment by theta in [0, theta_max].
      length_range: random lengths are drawn from ``[a L0_i, b L0_i]``
        (``(a, b) = length_range``, L0 the start's lengths), clipped to the limits.
      goal_roots: certified goal configurations that seed the goal tree of the
        global search.
      start_roots: configurations of the local planner's path (evenly spaced,
        its start and its end included) that seed the start tree.
      tree_size: nodes per tree of the global search (RRT-Connect).
      iterations: the most RRT-Connect iterations.
      extend_distance: an extension moves towards its sample by at most this
        motion bound (:func:`~softplan_jax.geometry._kinematics.motion_bound`).
      extend_substeps: conservative-advancement substeps of one extension.
      connect_substeps: substeps of one connection attempt.
      shortcut_attempts: random shortcuts tried on the found path.
      smooth_passes: passes of certified node relaxation after the shortcuts.
      step_motion: the most motion bound of one step of the returned path.
      path_steps: the most steps of the returned path (its array size).
      safe_fraction: every certified motion moves the arm by at most this
        fraction of ``(clearance - 2 contact)``, as the safe step does.
    """

    ik_starts: int = 16
    ik_iterations: int = 30
    ik_clear_iterations: int = 30
    ik_clearance: float = 0.02
    ik_tolerance: float = 1e-6
    theta_max: float = math.pi
    length_range: tuple = (0.5, 1.5)
    goal_roots: int = 8
    tree_size: int = 256
    iterations: int = 300
    extend_distance: float = 0.6
    extend_substeps: int = 8
    connect_substeps: int = 12
    start_roots: int = 8
    shortcut_attempts: int = 24
    smooth_passes: int = 1
    step_motion: float = 0.1
    path_steps: int = 1000
    safe_fraction: float = 0.8


def check_reach_options(options: ReachOptions) -> ReachOptions:
    """Validate ReachOptions (ValueError naming the field)."""
    if not isinstance(options, ReachOptions):
        raise ValueError(f"reach options must be a ReachOptions, got {type(options).__name__}")
    ints = ("ik_starts", "ik_iterations", "ik_clear_iterations", "goal_roots", "start_roots", "tree_size", "iterations",
            "extend_substeps", "connect_substeps", "shortcut_attempts", "smooth_passes", "path_steps")
    for name in ints:
        v = getattr(options, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"ReachOptions.{name} must be an int >= 0, got {v!r}")
    positive = ("ik_starts", "goal_roots", "start_roots", "tree_size", "extend_substeps", "connect_substeps",
                "path_steps")
    for name in positive:
        if getattr(options, name) < 1:
            raise ValueError(f"ReachOptions.{name} must be >= 1, got {getattr(options, name)}")
    if options.tree_size < 2:
        raise ValueError(f"ReachOptions.tree_size must be >= 2, got {options.tree_size}")
    floats = ("ik_clearance", "ik_tolerance", "theta_max", "extend_distance", "step_motion")
    for name in floats:
        v = getattr(options, name)
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise ValueError(f"ReachOptions.{name} must be a finite number > 0, got {v!r}")
    if not 0 < float(options.safe_fraction) <= 1:
        raise ValueError(f"ReachOptions.safe_fraction must be in (0, 1], got {options.safe_fraction!r}")
    lr = options.length_range
    if (not isinstance(lr, tuple) or len(lr) != 2 or not all(math.isfinite(float(x)) for x in lr)
            or not 0 < float(lr[0]) <= float(lr[1])):
        raise ValueError(f"ReachOptions.length_range must be a tuple (a, b) with 0 < a <= b, got {lr!r}")
    return options


# Why a result did not reach the goal (PlanResult.reason, the JSON's "reason"; "" when it did):
# proofs, the IK's verdict, the search's, and a global step whose certificate failed on
# recomputation (impossible by construction; the path is then discarded).
REACH_REASONS = ("", "beyond_reach", "goal_in_obstacle", "no_ik_solution", "search_exhausted", "uncertified_step")


class Reachability(NamedTuple):
    """What :func:`reachability` decides for one goal (batched: leading axis B).

    Attributes:
      reachable: () bool, a certified goal configuration was found.
      reason: str ("" when reachable; "beyond_reach", "goal_in_obstacle" (proven)
        or "no_ik_solution"); a tuple of str for a batch.
      best_error: () the smallest tip distance |goal - tip| of a configuration with
        exact clearance above the contact tolerance among the IK's starts and
        results (+inf if none, which a clear start pose rules out).
      q_goal: (ik_starts, n, 3) the IK results, certified ones first (by clearance).
      certified: (ik_starts,) bool, which rows of q_goal are certified.
      clearance: (ik_starts,) exact smallest clearance of each row.
      tip_error: (ik_starts,) |goal - tip| of each row.
    """

    reachable: np.ndarray
    reason: object
    best_error: np.ndarray
    q_goal: np.ndarray
    certified: np.ndarray
    clearance: np.ndarray
    tip_error: np.ndarray


# ----------------------------------------------------------------------------
# Traceable pieces (one scene; vmapped by the callers).


def clip_lengths(q, scenario: Scenario):
    """q with every L_i clipped to [L_min_i, L_max_i]."""
    return q.at[:, 0].set(jnp.clip(q[:, 0], scenario.L_min, scenario.L_max))


def sampling_box(scenario: Scenario, options: ReachOptions):
    """(lo, hi) of the random lengths: ``length_range`` times the start's lengths, within the limits."""
    L0 = scenario.q0[:, 0]
    a, b = (float(x) for x in options.length_range)
    lo = jnp.clip(a * L0, scenario.L_min, scenario.L_max)
    hi = jnp.clip(b * L0, scenario.L_min, scenario.L_max)
    return lo, hi


def random_configurations(key, scenario: Scenario, options: ReachOptions, count: int):
    """(count, n, 3) configurations: L uniform in :func:`sampling_box`, theta in
    [0, theta_max], phi in [-pi, pi]."""
    n, dtype = scenario.q0.shape[0], scenario.q0.dtype
    lo, hi = sampling_box(scenario, options)
    u = jax.random.uniform(key, (count, n, 3), dtype)
    L = lo + u[..., 0] * (hi - lo)
    theta = u[..., 1] * options.theta_max
    phi = (2.0 * u[..., 2] - 1.0) * math.pi
    return jnp.stack([L, theta, phi], axis=-1)


def clearances(q, scenario: Scenario, solver: SolverOptions = DEFAULT_OPTIONS, arm=PCC):
    """Exact clearance of every obstacle slot (+inf: padding), the closest pairs, and
    whether every real slot's solve converged (:func:`posed_clearances` without the posed arm)."""
    return posed_clearances(q, scenario, solver, arm)[:3]


def posed_clearances(q, scenario: Scenario, solver: SolverOptions, arm=PCC):
    """The exact clearances of the arm model ``arm`` at q (the planner's arm-model seam,
    :mod:`~softplan_jax.geometry._arm`): ``(c (m,), truth, ok, posed)``. ``posed = arm.at(q)``;
    ``truth`` the exact closest pairs of its shape (for a loaded arm: its pieces, rows of
    ``posed.shape(q)``); ``c`` their distance less the radii of the scene as the shape must see
    it (``posed.widened``: the pieces' proven gap added), so a lower bound of the model's
    clearance; ``ok`` every real slot's solve converged and no clearance is NaN (a loaded arm
    whose equilibrium did not converge gives NaN)."""
    posed = arm.at(q)
    sc = posed.widened(scenario)
    truth = true_closest(posed.shape(q), sc, solver)
    _, mask = radius_and_mask(scenario)
    c = clearance_of(truth, sc)
    ok = jnp.all(truth.converged | ~mask) & jnp.all(~jnp.isnan(c))
    return c, truth, ok, posed


def _tip_lm(q, scenario: Scenario, iterations, arm=PCC):
    """Levenberg-Marquardt on goal - tip(q), lengths in the box; a step that does not
    lower the error is refused (and the damping raised), so the error never grows.
    ``iterations``: an int, or a traced int (the IK's rounds choose it). ``arm``: the arm
    model whose tip and tip Jacobian these are. Each trip of the loop poses the arm once
    (one equilibrium solve for a loaded arm): at the start, then at each step's candidate,
    whose tip error and Jacobian are kept where it is accepted."""
    n = q.shape[0]
    dtype = q.dtype
    eye = jnp.eye(3, dtype=dtype)

    def body(k, carry):
        q, e, J, lam, q_c = carry
        posed = arm.at(q_c)
        e_c, J_c = scenario.goal - posed.tip(q_c), posed.tip_jacobian(q_c)
        better = (jnp.sum(e_c**2) < jnp.sum(e**2)) & jnp.all(jnp.isfinite(q_c))
        lam = jnp.where(k == 0, lam, jnp.clip(jnp.where(better, lam * 0.3, lam * 10.0), 1e-9, 1e6))
        better = better | (k == 0)  # trip 0 poses the start itself
        q, e, J = jnp.where(better, q_c, q), jnp.where(better, e_c, e), jnp.where(better, J_c, J)
        dq = J.T @ solve_small(J @ J.T + lam * eye, e)
        return q, e, J, lam, clip_lengths(q + dq.reshape(n, 3), scenario)

    start = (q, jnp.zeros(3, dtype), jnp.zeros((3, 3 * n), dtype), jnp.asarray(1e-2, dtype), q)
    return jax.lax.fori_loop(0, iterations + 1, body, start)[0]


def _push_step(q, c, truth, scenario: Scenario, options: ReachOptions, arm=PCC):
    """One null-space step: the tip kept on the goal, the arm moved up the exact
    clearance gradient of every obstacle within 2 ik_clearance (see the module docstring).
    ``c, truth``: :func:`clearances` at q (of the arm model ``arm``)."""
    n = q.shape[0]
    dtype = q.dtype
    posed = arm.at(q)
    away = truth.arm_point - truth.obstacle_point
    normal = away / jnp.maximum(safe_norm(away), jnp.finfo(dtype).tiny)[:, None]
    J_s, J = posed.jacobians_with_tip(q, truth.segment, truth.s)  # (m, 3, 3n), (3, 3n)
    grad_c = jnp.einsum("ka,kaj->kj", normal, J_s)  # (m, 3n): d c_j / d q (envelope theorem)
    w = jnp.where(jnp.isfinite(c), jnp.maximum(2.0 * options.ik_clearance - c, 0.0), 0.0)
    push = w @ grad_c
    e = scenario.goal - posed.tip(q)
    Jp = damped_pinv(J, jnp.asarray(1e-3, dtype))
    dq = Jp @ e + (jnp.eye(3 * n, dtype=dtype) - Jp @ J) @ push
    dq = jnp.clip(dq, -0.2, 0.2)  # at most 0.2 per coordinate: the push is a local linearisation
    q_new = clip_lengths(q + dq.reshape(n, 3), scenario)
    return jnp.where(jnp.all(jnp.isfinite(q_new)), q_new, q)


class IKState(NamedTuple):
    """The state of the IK's loop for one scene (S starts; the search's loop carries it too).

    Attributes:
      r: () int32, rounds done.
      q: (S, n, 3) the round's configurations.
      solved: ``(c_all (S, m), truth)``: the exact clearances and closest pairs at q.
      c: (S,) smallest clearance; err: (S,) |goal - tip|.
      certified, free: (S,) bool (see :func:`ik_assess`).
      best: () the smallest tip distance of a collision-free configuration so far.
    """

    r: jax.Array
    q: jax.Array
    solved: tuple
    c: jax.Array
    err: jax.Array
    certified: jax.Array
    free: jax.Array
    best: jax.Array


def ik_start(scenario: Scenario, key, q_extra, options: ReachOptions):
    """The IK's starts (S, n, 3) (q0, the extra configuration if given, random ones) and the
    loop's first :class:`IKState`."""
    S = int(options.ik_starts)
    q0 = scenario.q0
    fixed = [q0] if q_extra is None else [q0, q_extra.astype(q0.dtype)]
    fixed = jnp.stack(fixed)[:S]
    starts = jnp.concatenate([fixed, random_configurations(key, scenario, options, S - fixed.shape[0])])
    starts = jax.vmap(lambda q: clip_lengths(q, scenario))(starts)
    # Rounds 0 and 1 compute a push from these placeholders and the starts' clearances; it is not taken.
    dtype = q0.dtype
    truth = jax.vmap(lambda q: placeholder_closest(q, scenario))(starts)
    solved = (jnp.zeros(truth.distance.shape, dtype), truth)
    none = jnp.zeros((S,), bool)
    state = IKState(jnp.zeros((), jnp.int32), starts, solved, jnp.zeros((S,), dtype), jnp.zeros((S,), dtype), none,
                    none, jnp.asarray(jnp.inf, dtype))
    return starts, state


def ik_more(state: IKState, options: ReachOptions):
    """Whether the IK's loop runs another round: rounds 0 and 1, then while no start is certified
    (at most ik_clear_iterations times)."""
    return (state.r < 2) | ((state.r - 2 < options.ik_clear_iterations) & ~jnp.any(state.certified))


def ik_round_configurations(state: IKState, scenario: Scenario, starts, options: ReachOptions, arm=PCC):
    """The configurations (S, n, 3) that the IK's round ``state.r`` assesses (no exact solve):
    round 0 the starts; round 1 ik_iterations tip steps from them; later rounds a null-space push
    from the last round's clearances and 3 tip steps (one copy of the tip IK in the program, its
    number of steps chosen by the round)."""
    r = state.r
    pushed = jax.vmap(lambda q, s: _push_step(q, *s, scenario, options, arm))(state.q, state.solved)
    steps = jnp.where(r == 0, 0, jnp.where(r == 1, options.ik_iterations, 3))
    return jax.vmap(lambda q: _tip_lm(q, scenario, steps, arm))(jnp.where(r <= 1, starts, pushed))


def ik_assess(q, c_all, truth, ok, posed, scenario: Scenario, options: ReachOptions, contact):
    """The IK's verdict on q from the exact solve at q (:func:`posed_clearances`: ``c_all, truth,
    ok, posed``): ``(solved, c, err, certified, free)`` (kept: the next push starts from ``solved``)."""
    err = safe_norm(scenario.goal - posed.tip(q))
    c = jnp.min(c_all, initial=jnp.inf)
    finite = jnp.all(jnp.isfinite(q)) & jnp.isfinite(err)
    certified = finite & ok & (c >= options.ik_clearance) & (err <= options.ik_tolerance)
    free = finite & ok & (c > contact)
    return (c_all, truth), c, err, certified, free


def ik_round_end(state: IKState) -> IKState:
    """After the round's assessments: one round more, and the best collision-free tip distance."""
    return state._replace(r=state.r + 1,
                          best=jnp.minimum(state.best, jnp.min(jnp.where(state.free, state.err, jnp.inf))))


def _ik_round(state: IKState, scenario: Scenario, starts, options: ReachOptions, solver, contact, arm=PCC):
    """One round of the IK's loop, its one exact solve site (see goal_configurations)."""
    q = ik_round_configurations(state, scenario, starts, options, arm)
    solved, c, err, certified, free = jax.vmap(
        lambda q: ik_assess(q, *posed_clearances(q, scenario, solver, arm), scenario, options, contact))(q)
    return ik_round_end(IKState(state.r, q, solved, c, err, certified, free, state.best))


def ik_result(state: IKState):
    """``(q, certified, clearance, tip_error, best_error)`` of the IK, sorted: certified first,
    widest clearance first."""
    order = jnp.argsort(jnp.where(state.certified, -state.c, jnp.inf))
    return state.q[order], state.certified[order], state.c[order], state.err[order], state.best


def goal_configurations(scenario: Scenario, key, q_extra, options: ReachOptions,
                        solver: SolverOptions = DEFAULT_OPTIONS, contact=1e-6):
    """Multi-start IK for one scene (traceable; a batch: :func:`goal_configurations_batch`).

    Tip IK from every start, then the exact clearances; while no start is
    certified (and at most ``ik_clear_iterations`` times), one null-space
    clearance step and a tip polish for every start, and the clearances anew
    (a ``while_loop``: a goal certified at once pays two exact solves per start,
    one at the start itself and one after the IK).

    Returns ``(q (S, n, 3), certified (S,), clearance (S,), tip_error (S,),
    best_error ())``, sorted: certified first, then by clearance (largest first).
    ``contact``: a configuration counts as collision-free for ``best_error``
    when its clearance exceeds this.
    """
    # One exact solve site and one tip IK, the loop's body (one copy of each in the compiled
    # program). Round 0 assesses the starts themselves: they count for the best
    # collision-free tip distance (the start pose is clear in a valid scene: a goal inside
    # an obstacle still gets a finite distance). Round 1: the tip IK from the starts
    # (ik_iterations Levenberg-Marquardt steps). Rounds 2, 3, ...: while no start is
    # certified (at most ik_clear_iterations times), one null-space push from the
    # clearances the last round found and a 3-step tip polish.
    starts, state = ik_start(scenario, key, q_extra, options)
    state = jax.lax.while_loop(lambda st: ik_more(st, options),
                               lambda st: _ik_round(st, scenario, starts, options, solver, contact), state)
    return ik_result(state)


def goal_configurations_batch(scenarios: Scenario, keys, q_extra, options: ReachOptions,
                              solver: SolverOptions = DEFAULT_OPTIONS, contact=1e-6):
    """:func:`goal_configurations` of a stacked batch of scenes (leading axis B; ``keys`` (B,),
    ``q_extra`` (B, n, 3) or None), as ``jax.vmap`` of it computes them, with one loop for the
    batch: each round runs every scene's round (vmapped) and keeps it where that scene's loop
    goes on, until none does. (Under vmap, jax turns the per-scene loop into this same loop,
    but traces and batches its body more than once; docs: "How the planner works inside".) A batch of one
    scene is traced without vmap (:func:`~softplan_jax.planning._batching.lanes_map`), as the
    global fallback's program traces its IK: the two give the same arrays bit for bit where a
    start is certified at once (rounds 0 and 1), and to rounding over the null-space rounds
    (XLA fuses the push step differently in the two programs)."""
    if q_extra is None:
        starts, state = lanes_map(lambda s, k: ik_start(s, k, None, options), scenarios, keys)
    else:
        starts, state = lanes_map(lambda s, k, e: ik_start(s, k, e, options), scenarios, keys, q_extra)

    def more(state):
        return lanes_map(lambda st: ik_more(st, options), state)

    def body(state):
        going = more(state)
        new = lanes_map(lambda st, s, a: _ik_round(st, s, a, options, solver, contact), state, scenarios, starts)
        return jax.tree_util.tree_map(
            lambda x, y: jnp.where(going.reshape((-1,) + (1,) * (x.ndim - 1)), x, y), new, state)

    state = jax.lax.while_loop(lambda st: jnp.any(more(st)), body, state)
    return lanes_map(ik_result, state)


@functools.cache
def _goal_configurations_jit(options: ReachOptions, solver, contact: float, extra: bool):
    def goal_configs(scenarios, keys, q_extra):
        return goal_configurations_batch(scenarios, keys, q_extra if extra else None, options, solver, contact)

    return package_jit(goal_configs)


# ----------------------------------------------------------------------------
# Host side: proofs and the public entry point.


def unreachable_proof(scenario: Scenario) -> str:
    """"beyond_reach", "goal_in_obstacle" or "" for one (unbatched) scene (exact, host side;
    :func:`~softplan_jax.scenarios._scenario.unreachable_reason`)."""
    return unreachable_reason(scenario)


def scene_of(scenarios: Scenario, b: int) -> Scenario:
    """Scene b of a stacked batch of scenes (every leaf indexed on its leading axis)."""
    return jax.tree_util.tree_map(lambda x: x[b], scenarios)


def reachability(scenario: Scenario, q_extra=None, *, seed=0, options: ReachOptions = ReachOptions(),
                 solver: SolverOptions = DEFAULT_OPTIONS, contact_tolerance: float = 1e-6) -> Reachability:
    """Decide whether a collision-free configuration puts the tip on the goal.

    Args:
      scenario: one Scenario, or a batch (leading axis B; one compiled program).
      q_extra: an extra IK start (n, 3) (batch: (B, n, 3)), e.g. where the
        local planner stopped; None: none.
      seed: int seed of the random IK starts (scene b of a batch uses
        ``split(PRNGKey(seed), B)[b]``).
      options: :class:`ReachOptions`.
      solver: the exact closest-point solver's options.
      contact_tolerance: clearance at or below which a configuration collides.

    Returns:
      :class:`Reachability` (NumPy arrays; batched for a batch).
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    options = check_reach_options(options)
    batched = scenario.q0.ndim == 3
    scenes = scenario if batched else jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], scenario)
    B, n = scenes.q0.shape[0], scenes.q0.shape[-2]
    if q_extra is not None:
        q_extra = jnp.asarray(q_extra, scenes.q0.dtype)
        want = (B, n, 3) if batched else (n, 3)
        if q_extra.shape != want:
            raise ValueError(f"q_extra must have shape {want}, got {q_extra.shape}")
        if not bool(jnp.all(jnp.isfinite(q_extra))):
            raise ValueError("q_extra must be finite")
        q_extra = q_extra if batched else q_extra[None]
    keys = jax.random.split(jax.random.PRNGKey(int(seed)), B)
    fn = _goal_configurations_jit(options, solver, float(contact_tolerance), q_extra is not None)
    extra = q_extra if q_extra is not None else jnp.zeros((B, n, 3), scenes.q0.dtype)
    q, cert, c, err, best = jax.device_get(fn(scenes, keys, extra))
    host = jax.device_get(scenes)
    proofs = [unreachable_proof(scene_of(host, b)) for b in range(B)]
    reachable = np.array([bool(cert[b, 0]) and not proofs[b] for b in range(B)])
    reasons = tuple("" if reachable[b] else (proofs[b] or "no_ik_solution") for b in range(B))
    out = Reachability(reachable, reasons, best, q, cert, c, err)
    if batched:
        return out
    return Reachability(bool(reachable[0]), reasons[0], float(best[0]), q[0], cert[0], c[0], err[0])
