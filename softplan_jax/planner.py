"""The potential-field planner of paper eq. (9), one jitted step, and rollouts.

One step::

    qdot = J_e^+ F_e(V_e) - sum_j J_sj^+ F_sj(V_sj)          (paper eq. 9)
    q   <- q + dt * qdot,  L_i clipped to [L_min_i, L_max_i]

with ``V_e = goal - tip`` and ``V_sj = (obstacle point) - (closest arm point)``
for obstacle j; ``J^+`` is the damped least-squares pseudo-inverse.

* ``method="curve"`` (the paper's proposed method): a curve obstacle's closest
  point comes from the exact solver of :mod:`softplan_jax.closest`.
* ``method="points"``: every curve is replaced by ``n_points`` points evenly
  spaced in u and handled by the N-point method (arm sampled at 10 points per
  segment, Jacobian at the arm sample nearest the obstacle).
Point-set obstacles always use the N-point method.

Step size. ``PlanOptions.step = "safe"`` (the default) is the clearance-bounded
step: the Euler step ``q -> q + dt qdot`` is scaled by ``alpha`` in [0, 1] so
that :func:`softplan_jax.kinematics.motion_bound` -- a sound bound on how far
ANY arm point can move during the whole step -- stays below
``safe_fraction * (clearance - floor)``, with the clearance of the planner's own
obstacle model (for the curve method the exact distance). Since no arm point
can move farther than the clearance, no step of the curve method can pass
through an obstacle (conservative advancement). ``step = "plain"`` is the
paper's step, unscaled (the paper tables use it).

Escapes (``PlanOptions.escapes``). A stall (no progress towards the goal for
``stall_window`` steps) is a local minimum of the potential field. While
escapes remain, the planner then takes ``escape_steps`` random-walk steps
(Barraquand & Latombe 1991): the attraction ``F_e`` is replaced by a tip
velocity of speed ``v_max`` in a random direction, the repulsion and the safe
step stay on; then the field takes over again. The PRNG key is in the scan's
carry, so a rollout stays one ``lax.scan`` and is reproducible from its key.

Rollouts (:func:`rollout`) run a fixed number of steps with ``lax.scan``; a
finished rollout is frozen. Each step records q, the tip and the TRUE clearance
to every obstacle (the real curve or point set, whatever model the planner
used), and checks the motion BETWEEN steps for a pass through an obstacle (see
:func:`softplan_jax.metrics.between_steps`). That search runs only for the
(step, obstacle) motions the motion bound does not prove clear
(:func:`softplan_jax.metrics.swept_clear`; ``PlanOptions.swept_proof``): with
the safe step, almost none for the curve method.
"""

from __future__ import annotations

import math
import time
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .batching import BATCH_AXIS, Progress, batch_mesh, gather, is_global, pad_batch, round_chunk, shard_batch
from .closest import DEFAULT_OPTIONS, ClosestPoint, SolverOptions
from .compilation_cache import load_or_export, rollout_compiler_options
from .kinematics import motion_bound, points_jacobian, tip_position
from .metrics import apply_collision_checks as apply_collision_checks  # moved to metrics; old import path
from .metrics import between_steps, contact_tolerance, swept_clear
from .numerics import damped_pinv, safe_norm, tie
from .obstacles import (
    model_closest,
    placeholder_closest,
    radius_and_mask,
    true_closest,
    warm_cells,
    warm_closest,
    warm_state,
)
from .scenarios import Scenario
from .status import STATUS_NAMES as STATUS_NAMES  # noqa: F401  (re-exported: the old import path)
from .status import Status, status_name

__all__ = [
    "Gains",
    "GainFunction",
    "default_gains",
    "attraction",
    "repulsion",
    "repulsion_scale",
    "PlanOptions",
    "PAPER_STEP",
    "planner_step",
    "Rollout",
    "rollout",
]


class Gains(NamedTuple):
    """Gains of the gain functions and of the integration (a pytree of arrays;
    every field is differentiable).

    Attributes:
      k_att: attraction gain [1/s]: F_e(V_e) = k_att V_e below saturation.
      v_max: saturation speed of the attraction [m/s].
      eta: repulsion gain.
      d0: influence distance of the repulsion [m] (clearance beyond it: no force).
      rep_max: smooth cap on the repulsion speed [m/s].
      damping: damping lambda of the pseudo-inverse J^T (J J^T + lambda^2 I)^-1.
      dt: integration step [s]: q <- q + dt * qdot.
    """

    k_att: jax.Array
    v_max: jax.Array
    eta: jax.Array
    d0: jax.Array
    rep_max: jax.Array
    damping: jax.Array
    dt: jax.Array


class GainFunction(NamedTuple):
    """Gains with the repulsion as a tunable FUNCTION of clearance and of the arm
    segment (a pytree of arrays; beyond the paper, tuned by :mod:`softplan_jax.smoothing`).

    The first seven fields are those of :class:`Gains`, with the same meaning.
    The repulsion of paper eq. (9) for an obstacle whose closest arm point lies
    on segment i at clearance d is :func:`repulsion`'s magnitude times::

        exp(profile(d / d0) + seg_weights[i])

    where ``profile`` interpolates ``rep_profile`` linearly between K knots evenly
    spaced in ``d / d0`` over [0, 1] (clipped outside). With all zeros it is the
    field of its :class:`Gains` exactly (:meth:`from_gains` builds that).

    Attributes:
      rep_profile: (K,) log-multipliers of the repulsion at the knots, K >= 2.
      seg_weights: (n,) log-multipliers of the repulsion per arm segment
        (n: the arm's segment count).
    """

    k_att: jax.Array
    v_max: jax.Array
    eta: jax.Array
    d0: jax.Array
    rep_max: jax.Array
    damping: jax.Array
    dt: jax.Array
    rep_profile: jax.Array
    seg_weights: jax.Array

    @classmethod
    def from_gains(cls, gains: Gains, knots: int, segments: int) -> GainFunction:
        """The gain function equal to ``gains`` (zero profile and weights)."""
        if int(knots) < 2 or int(segments) < 1:
            raise ValueError(f"a GainFunction needs knots >= 2 and segments >= 1, got {knots}, {segments}")
        dtype = jnp.result_type(gains.k_att)
        return cls(*gains[:7], jnp.zeros((int(knots),), dtype), jnp.zeros((int(segments),), dtype))

    def scalars(self) -> Gains:
        """The seven scalar gains (without the profile and weights)."""
        return Gains(*self[:7])


def repulsion_scale(gains, clearance, segment):
    """The multiplier of the repulsion of a :class:`GainFunction` (1 for :class:`Gains`):
    ``exp(profile(clearance / d0) + seg_weights[segment])``; shapes broadcast."""
    if not isinstance(gains, GainFunction):
        return jnp.ones_like(clearance)
    K = gains.rep_profile.shape[-1]
    x = jnp.clip(clearance / gains.d0, 0.0, 1.0) * (K - 1)
    lo = jnp.clip(jnp.floor(x), 0, K - 2).astype(jnp.int32)
    t = x - lo.astype(x.dtype)
    log_scale = (1 - t) * gains.rep_profile[lo] + t * gains.rep_profile[lo + 1] + gains.seg_weights[segment]
    return jnp.exp(log_scale)


def default_gains(dtype=None) -> Gains:
    """The default gains (chosen by measurement on the paper's scenarios; see
    the README's "Gains" section).

    The tip moves at most ``v_max * dt = 0.05`` per step; the attraction is
    linear within ``v_max / k_att = 0.25`` of the goal. The influence distance
    ``d0 = 0.07`` is below the 0.080 between the tree goal and its nearest
    branch, so the goal lies outside every obstacle's field (d0 = 0.1 stalls
    the tree 0.03 short of its goal).
    """
    dtype = dtype or jnp.result_type(float)
    vals = dict(k_att=2.0, v_max=0.5, eta=1e-3, d0=0.07, rep_max=1.0, damping=0.05, dt=0.1)
    return Gains(**{k: jnp.asarray(v, dtype) for k, v in vals.items()})


def attraction(V_e, gains: Gains):
    """F_e(V_e): linear with gain k_att, saturated to speed v_max (paper eq. 9)."""
    speed = gains.k_att * safe_norm(V_e)
    return gains.k_att * V_e / jnp.maximum(1.0, speed / gains.v_max)


def repulsion(V_s, clearance, gains: Gains, kind: str = "khatib", scale=1.0):
    """F_s(V_s): repulsion speed along ``V_s`` (towards the obstacle; eq. 9
    subtracts it), as a function of the surface clearance.

    * ``"khatib"``: ``eta (1/d - 1/d0) / d^2`` for d < d0, 0 beyond (Khatib
      1986; Ataka et al. 2016), smoothly capped at ``rep_max`` (``inf``: no cap);
    * ``"exponential"``: ``rep_max * exp(-d / d0)`` — smooth everywhere, never
      exactly zero.
    ``d`` is floored at ``1e-3 d0`` (contact or penetration still repels).
    ``scale`` multiplies the uncapped magnitude (a :class:`GainFunction`'s
    :func:`repulsion_scale`).
    """
    d = jnp.maximum(clearance, 1e-3 * gains.d0)
    if kind == "khatib":
        raw = gains.eta * (1.0 / d - 1.0 / gains.d0) / (d * d)
        raw = scale * jnp.where(d < gains.d0, raw, 0.0)
        # rep_max = inf: no cap (Khatib's field as printed); double-where keeps inf out of both modes.
        uncapped = jnp.isinf(gains.rep_max)
        cap = jnp.where(uncapped, 1.0, gains.rep_max)
        mag = jnp.where(uncapped, raw, cap * jnp.tanh(raw / cap))
    elif kind == "exponential":
        mag = scale * gains.rep_max * jnp.exp(-d / gains.d0)
    else:
        raise ValueError(f"unknown repulsion {kind!r}; choose 'khatib' or 'exponential'")
    return mag * V_s / jnp.maximum(safe_norm(V_s), jnp.finfo(V_s.dtype).tiny)


class PlanOptions(NamedTuple):
    """Static planner settings (hashable: changing one recompiles).

    Attributes:
      method: "curve" (exact closest points) or "points" (N-point model).
      n_points: N of the N-point model of each curve (method "points").
      points_per_segment: arm samples per segment for the N-point method (paper: 10).
      repulsion: "khatib" or "exponential".
      goal_tolerance: reached when |V_e| < goal_tolerance.
      stall_window: stalled after this many steps without improving the best
        |V_e| by more than stall_tolerance (then an escape starts while any
        is left; else the rollout ends "stalled").
      stall_tolerance: see stall_window. The defaults (30 steps, 0.02) call
        creeping along an obstacle at under ~1e-3 per step a stall: it would
        not reach the goal within the step budget (benchmarks/safe_step.py).
      check_collisions: compute the true clearance and the between-step
        check inside the rollout (default). False gives a planning-only
        rollout (clearance records NaN, never "collided"), for timing the
        planner alone; :func:`apply_collision_checks` adds the checks after.
      contact_tolerance: a clearance at or below this counts as a collision
        (zero-radius curves that cross meet at a single point, which a
        solver reaches only to rounding). The rollout uses
        ``max(contact_tolerance, 10 sqrt(eps))``: 1e-6 in float64, 3.5e-3 in float32.
      solver: the exact closest-point solver: SolverOptions (default) or
        GridSolverOptions (the paper's 2-D solver).
      step: "safe" (default): the clearance-bounded step (see the module
        docstring); "plain": the paper's step ``q + dt qdot`` (paper eq. 9).
      safe_fraction: the safe step keeps the motion bound of every step below
        this fraction of ``(clearance - floor)``, in (0, 1]; floor is twice the
        contact tolerance, so the clearance never falls to the contact tolerance.
      escapes: random-walk escapes from stalls allowed per rollout (0: none;
        a stall then ends the rollout, as in the paper).
      escape_steps: steps of one random walk.
      warm_start: in a rollout, carry each (segment, curve) pair's closest
        point from step to step, polish it and certify it the global minimum
        (:mod:`softplan_jax.warm_start`); only pairs whose certificate fails
        take the full solve. Same closest points as the full solver, fewer
        solves. Applies to the default solver (SolverOptions) only; False:
        the full solve at every step. :func:`planner_step` and the post-hoc
        checks always use the full solve.
      swept_proof: run the between-step search only for the (step, obstacle)
        motions that the motion bound does not prove clear
        (:func:`softplan_jax.metrics.swept_clear`: the clearance at the start
        of the motion minus :func:`~softplan_jax.kinematics.motion_bound`
        stays above the contact tolerance); the statuses are the same, the
        search is skipped where it cannot find a collision (see
        ``Rollout.between``). False: search every motion (the earlier
        behaviour, for comparison).
    """

    method: str = "curve"
    n_points: int = 10
    points_per_segment: int = 10
    repulsion: str = "khatib"
    goal_tolerance: float = 1e-2
    stall_window: int = 30
    stall_tolerance: float = 0.02
    check_collisions: bool = True
    contact_tolerance: float = 1e-6
    solver: SolverOptions = DEFAULT_OPTIONS
    step: str = "safe"
    safe_fraction: float = 0.8
    escapes: int = 20
    escape_steps: int = 15
    warm_start: bool = True
    swept_proof: bool = True


# The paper's step (eq. 9, unscaled, no escapes) with the stall test of the earlier
# releases: ``make_options(method, N, **PAPER_STEP)`` plans exactly as before the safe
# step (bit for bit on the paper scenes); the paper tables and the NumPy baseline use it.
PAPER_STEP = {"step": "plain", "escapes": 0, "stall_window": 60, "stall_tolerance": 1e-4}




def check_options(options: PlanOptions) -> PlanOptions:
    if options.method not in ("curve", "points"):
        raise ValueError(f"unknown method {options.method!r}; choose 'curve' or 'points'")
    if options.repulsion not in ("khatib", "exponential"):
        raise ValueError(f"unknown repulsion {options.repulsion!r}; choose 'khatib' or 'exponential'")
    if int(options.n_points) < 1:
        raise ValueError(f"n_points must be >= 1, got {options.n_points}")
    if int(options.points_per_segment) < 1:
        raise ValueError(f"points_per_segment must be >= 1, got {options.points_per_segment}")
    if not options.goal_tolerance > 0:
        raise ValueError(f"goal_tolerance must be > 0, got {options.goal_tolerance}")
    if not options.contact_tolerance >= 0:
        raise ValueError(f"contact_tolerance must be >= 0, got {options.contact_tolerance}")
    if int(options.stall_window) < 1:
        raise ValueError(f"stall_window must be >= 1, got {options.stall_window}")
    if options.step not in ("safe", "plain"):
        raise ValueError(f"unknown step {options.step!r}; choose 'safe' (clearance-bounded) or 'plain' (the paper's)")
    if not 0 < float(options.safe_fraction) <= 1:
        raise ValueError(f"safe_fraction must be in (0, 1], got {options.safe_fraction}")
    if int(options.escapes) < 0:
        raise ValueError(f"escapes must be >= 0, got {options.escapes}")
    if int(options.escape_steps) < 1:
        raise ValueError(f"escape_steps must be >= 1, got {options.escape_steps}")
    return options


def field_velocity(q, scenario: Scenario, gains: Gains, truth: ClosestPoint, options: PlanOptions, walk=None):
    """Paper eq. (9): qdot = J_e^+ F_e(V_e) - sum_j J_sj^+ F_sj(V_sj).

    ``walk = (walking () bool, velocity (3,))``, if given: while walking, the
    velocity replaces F_e (an escape's random walk).
    Returns ``(qdot (n, 3), clearance (m,))``: the clearance of the planner's
    own obstacle model (exact for the curve method), +inf for padding slots.
    """
    n = q.shape[0]
    V_e = scenario.goal - tip_position(q)
    cps = model_closest(q, scenario, truth, options.method, options.n_points, options.points_per_segment)
    radius, mask = radius_and_mask(scenario)
    # J_e (the tip: s = 1 of the last segment) and every J_sj in one pass.
    segments = jnp.concatenate([jnp.array([n - 1], jnp.int32), cps.segment])
    s = jnp.concatenate([jnp.ones((1,), q.dtype), cps.s])
    J = points_jacobian(q, segments, s)
    # Padding slots get a full-rank stand-in Jacobian [I 0] (their force is zero): with
    # damping 0 (the plain pseudo-inverse) their placeholder point's Jacobian is singular
    # and would give NaN * 0 = NaN (double-where: finite values and gradients).
    active = jnp.concatenate([jnp.ones((1,), bool), mask])
    stand_in = jnp.eye(3, 3 * n, dtype=J.dtype)
    J = jnp.where(active[:, None, None], J, stand_in)
    pinvs = jax.vmap(lambda J_k: damped_pinv(J_k, gains.damping))(J)  # (1 + m, 3n, 3)
    V_s = cps.obstacle_point - cps.arm_point
    clearance = cps.distance - scenario.arm_radius - radius
    scale = repulsion_scale(gains, clearance, cps.segment)
    F_s = jax.vmap(lambda v, d, k: repulsion(v, d, gains, options.repulsion, k))(V_s, clearance, scale)
    F_s = jnp.where(mask[:, None], F_s, 0.0)
    F_e = attraction(V_e, gains)
    if walk is not None:
        F_e = jnp.where(walk[0], walk[1], F_e)
    # Paper eq. (9).
    qdot = pinvs[0] @ F_e - jnp.einsum("kij,kj->i", pinvs[1:], F_s)
    return qdot.reshape(n, 3), jnp.where(mask, clearance, jnp.inf)


def apply_step(q, qdot, scenario: Scenario, gains: Gains):
    q_next = q + gains.dt * qdot
    return q_next.at[:, 0].set(jnp.clip(q_next[:, 0], scenario.L_min, scenario.L_max))


def _step_scale(q, q_next, clearance, options: PlanOptions):
    """The safe step's scale alpha in [0, 1] for the motion q -> q_next.

    ``motion_bound(q, q + alpha (q_next - q)) <= alpha * motion_bound(q, q_next)``
    (the bound is linear in dq for a fixed length bound, and Lbar of the full
    step bounds every shorter one), so alpha = min(1, f (c - floor) / bound)
    keeps every arm point, at every instant of the step, closer to its start
    than ``f (c - floor)``: the clearance stays above ``floor`` (conservative
    advancement). ``c`` is the smallest clearance of the planner's model; no
    obstacle (c = inf) gives alpha = 1; NaN propagates (and ends the rollout).
    """
    floor = 2.0 * contact_tolerance(options, q.dtype)
    c = jnp.min(clearance, initial=jnp.inf)
    allowed = options.safe_fraction * jnp.maximum(c - floor, 0.0)
    bound = motion_bound(q, q_next)[-1]
    # Double-where: a zero bound (no motion) gives alpha = 1 and no 0/0 in either mode.
    moving = bound > 0
    bound_safe = jnp.where(moving, bound, 1.0)
    alpha = jnp.where(moving, jnp.minimum(1.0, allowed / bound_safe), 1.0)
    return jnp.where(jnp.isnan(c), jnp.nan, alpha)


def _next_q(q, scenario: Scenario, gains: Gains, truth: ClosestPoint, options: PlanOptions, walk=None):
    """One planner step from q: ``(q_next, alpha)`` (alpha = 1 for the plain step)."""
    qdot, clearance = field_velocity(q, scenario, gains, truth, options, walk)
    q_next = apply_step(q, qdot, scenario, gains)
    if options.step == "plain":
        return q_next, jnp.ones((), q.dtype)
    alpha = _step_scale(q, q_next, clearance, options)
    # q and q_next lie in the length box, so every point of the segment between them does too.
    return q + alpha * (q_next - q), alpha


@partial(jax.jit, static_argnames=("options",))
def planner_step(q, scenario: Scenario, gains: Gains, options: PlanOptions = PlanOptions()):
    """One planner step (paper eq. 9) as a single jitted function.

    Args:
      q: (n, 3) configuration.
      scenario: Scenario (one, not batched; vmap for batches).
      gains: Gains.
      options: PlanOptions (static).

    Returns:
      (n, 3) next configuration: ``q + dt qdot`` with lengths clipped to their
      limits (``options.step = "plain"``), scaled down by the clearance-bounded
      step where it could reach an obstacle (``"safe"``, the default).
    """
    truth = true_closest(q, scenario, options.solver) if options.method == "curve" else None
    if truth is None:
        # The points method never uses the exact solver: a placeholder of the right shape.
        truth = placeholder_closest(q, scenario)
    return _next_q(q, scenario, gains, truth, options)[0]


class Rollout(NamedTuple):
    """A planned rollout (arrays padded to max_steps + 1 along time).

    Attributes:
      q: (T+1, n, 3) configurations; frozen after the rollout finished.
      tip: (T+1, 3).
      clearance: (T+1, m) true clearance (surface to surface) to every obstacle
        slot (padding slots: +inf).
      between: (T+1, m) smallest clearance found during the motion from the
        previous step (entry 0: the start's clearance); an ACHIEVED clearance,
        so an upper bound on the true minimum over the motion. Where the
        between-step search ran (``between_searched``) it is the search's
        result (at most the clearance at both ends); where the motion bound
        proved the motion clear (``PlanOptions.swept_proof``) it is the smaller
        of the two ends' clearances, and the true minimum lies between
        ``clearance[k-1] - motion_bound(q[k-1], q[k])[-1]`` (above the contact
        tolerance: no collision) and this value.
      status: () int, a :class:`Status` code.
      iterations: () int, planner steps taken.
      reached, collided: () bool.
      min_clearance: () minimum over time, obstacles and between-step motion.
      final_error: () |goal - tip| at the end.
      step_scale: (T+1,) the safe step's alpha for the step from q_k (1 for the
        plain step; 0 where no step was taken).
      escapes: () int, random-walk escapes started.
      converged: (T+1,) bool, every exact closest-point solve of a real
        obstacle slot at q_k met its Newton tolerance (always True where no
        exact solve ran: the points method without collision checks).
      fallbacks: (T+1,) int32, (segment, curve) pairs of real curve slots
        that took the full closest-point solve at q_k: with the warm start
        (``PlanOptions.warm_start``) the pairs whose certificate failed (all
        at k = 0); without it every pair, or 0 where no exact solve ran.
      between_searched: (T+1, m) bool, the between-step search ran for the
        motion to q_k and obstacle slot j. False where the motion bound proved
        that motion clear of the obstacle (``PlanOptions.swept_proof``), at
        k = 0, for padding slots, after the rollout finished, and without
        collision checks.
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


class _Carry(NamedTuple):
    q: jax.Array  # q_k
    q_prev: jax.Array  # q_{k-1} (q_0 at k = 0)
    truth_prev: ClosestPoint  # exact closest pairs at q_{k-1}
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


def rollout(scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, key=None) -> Rollout:
    """Roll the planner out for ``max_steps`` steps with ``lax.scan`` (pure;
    wrap in jit/vmap/grad as needed; :func:`softplan_jax.plan` is the jitted
    entry point).

    Scan iteration k (k = 0..max_steps) looks at q_k: exact closest pairs to
    every obstacle (shared by the clearance record and, for the curve method,
    by the planner), the true clearance at q_k and during the motion from
    q_{k-1}; then the status; then, while running, the step to q_{k+1}
    (clearance-bounded for ``options.step = "safe"``).

    Status: non-finite (a clearance or a step is NaN/inf: the last finite
    configuration is kept; a NaN clearance never counts as clear), collided
    (true clearance <= the contact tolerance at a step or during the motion
    between two steps; this wins over reached), reached (|V_e| <
    goal_tolerance), stalled (the best |V_e| did not improve by
    stall_tolerance over stall_window steps, and no escape is left; while one
    is, a random walk of ``escape_steps`` steps starts instead), else
    max_steps. Once finished, the state is frozen.

    Args:
      scenario, gains, options, max_steps: as :func:`softplan_jax.plan`.
      key: PRNG key of the escapes' random walks (default ``PRNGKey(0)``).
    """
    radius, mask = radius_and_mask(scenario)
    q0 = scenario.q0
    dtype = q0.dtype
    contact = contact_tolerance(options, dtype)
    key = jax.random.PRNGKey(0) if key is None else key

    def clearance_of(truth):
        return jnp.where(mask, truth.distance - scenario.arm_radius - radius, jnp.inf)

    check = options.check_collisions
    walks = options.escapes > 0
    exact = check or options.method == "curve"
    warm = exact and options.warm_start and isinstance(options.solver, SolverOptions)
    cells = warm_cells(scenario, options.solver) if warm else ()
    n_pairs = q0.shape[0] * (jnp.sum(scenario.curve_mask) + len(scenario.parametric)).astype(jnp.int32)

    def body(carry: _Carry, k):
        q = carry.q
        warm_next = carry.warm
        if warm:
            truth, warm_next, fallbacks = warm_closest(q, scenario, options.solver, cells, carry.warm, carry.first)
        elif exact:
            truth = true_closest(q, scenario, options.solver)
            fallbacks = n_pairs
        else:
            truth = placeholder_closest(q, scenario)
            fallbacks = jnp.zeros((), jnp.int32)
        running = carry.status == Status.RUNNING
        if check:
            c = clearance_of(truth)
            radius_sum = scenario.arm_radius + radius
            if options.swept_proof:
                # The search runs only where the motion bound cannot prove the motion clear
                # (metrics.swept_clear), in a while loop over those slots.
                c_prev = clearance_of(carry.truth_prev)
                proven = swept_clear(carry.q_prev, q, carry.truth_prev, c_prev, contact)
                searched = mask & ~carry.first & running & ~proven
                cb = between_steps(carry.q_prev, q, carry.truth_prev, truth, scenario, radius_sum, search=searched)
            else:
                searched = mask & ~carry.first
                cb = between_steps(carry.q_prev, q, carry.truth_prev, truth, scenario, radius_sum)
            cb = jnp.where(carry.first | ~mask, c, cb)
            nan_clearance = jnp.any(jnp.isnan(c)) | jnp.any(jnp.isnan(cb))
            hit = jnp.any(c <= contact) | jnp.any(cb <= contact)
        else:
            c = cb = jnp.full(mask.shape, jnp.nan, dtype)
            searched = jnp.zeros(mask.shape, bool)
            nan_clearance = hit = jnp.zeros((), bool)
        err = safe_norm(scenario.goal - tip_position(q))
        improved = err < carry.best_error - options.stall_tolerance
        walking = carry.walk_left > 0
        since = jnp.where(improved | carry.first | walking, 0, carry.since_best + 1)
        stalled = since >= options.stall_window
        # A stall with an escape left starts a random walk instead of ending the rollout.
        escape = stalled & (carry.escapes < options.escapes)
        judged = jnp.where(
            nan_clearance,
            Status.NONFINITE,
            jnp.where(
                hit,
                Status.COLLIDED,
                jnp.where(
                    err < options.goal_tolerance,
                    Status.REACHED,
                    jnp.where(stalled & ~escape, Status.STALLED, Status.RUNNING),
                ),
            ),
        )
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
            walk_left = jnp.where(start, options.escape_steps, walk_left)
            escapes = escapes + start.astype(jnp.int32)
            since = jnp.where(start, 0, since)
            q_next, alpha = _next_q(q, scenario, gains, truth, options, (walk_left > 0, walk_velocity))
        else:
            q_next, alpha = _next_q(q, scenario, gains, truth, options)
        finite = jnp.all(jnp.isfinite(q_next))
        status = jnp.where(stepping & ~finite, Status.NONFINITE, status).astype(jnp.int32)
        moved = stepping & finite
        new = _Carry(
            q=jnp.where(moved, q_next, q),
            q_prev=q,
            truth_prev=truth,
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
        return new, (q, tip_position(q), c, cb, alpha, converged, fallbacks, searched)

    truth_dummy = placeholder_closest(q0, scenario)
    carry0 = _Carry(
        q=q0,
        q_prev=q0,
        truth_prev=truth_dummy,
        first=jnp.ones((), bool),
        status=jnp.asarray(Status.RUNNING, jnp.int32),
        iterations=jnp.zeros((), jnp.int32),
        best_error=jnp.asarray(jnp.inf, dtype),
        since_best=jnp.zeros((), jnp.int32),
        key=key,
        escapes=jnp.zeros((), jnp.int32),
        walk_left=jnp.zeros((), jnp.int32),
        walk_velocity=jnp.zeros((3,), dtype),
        warm=warm_state(scenario) if warm else (),
    )
    carry0 = tie(carry0, q0)  # under vmap (a batch), the carry is batched from the start (see tie)
    final, (qs, tips, cs, cbs, alphas, converged, fallbacks, searched) = jax.lax.scan(
        body, carry0, jnp.arange(max_steps + 1)
    )
    status = jnp.where(final.status == Status.RUNNING, Status.MAX_STEPS, final.status)
    return Rollout(
        q=qs,
        tip=tips,
        clearance=cs,
        between=cbs,
        status=status,
        iterations=final.iterations,
        reached=status == Status.REACHED,
        collided=status == Status.COLLIDED,
        min_clearance=jnp.minimum(jnp.min(cs, initial=jnp.inf), jnp.min(cbs, initial=jnp.inf)),
        final_error=safe_norm(scenario.goal - tips[-1]),
        step_scale=alphas,
        escapes=final.escapes,
        converged=converged,
        fallbacks=fallbacks,
        between_searched=searched,
    )


# ----------------------------------------------------------------------------
# Entry points.


def strong_gains(gains: Gains, dtype) -> Gains:
    """Gains as arrays of the scenario's dtype, never weakly typed: a gain given as
    a Python float or ``jnp.asarray(0.1)`` (weak) would otherwise compile anew."""
    return type(gains)(*(jnp.asarray(v, dtype) for v in gains))


def prng_key(seed):
    """A PRNG key from an int seed (or a key, returned as it is)."""
    if seed is None:
        seed = 0
    if isinstance(seed, (int, np.integer)):
        return jax.random.PRNGKey(int(seed))
    return seed


def _rollout_jit(scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, key) -> Rollout:
    return rollout(scenario, gains, options, max_steps, key)


def _rollout_batch(scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, keys,
                   mesh=None) -> Rollout:
    def vmapped(scenarios, gains, keys):
        return jax.vmap(lambda sc, k: rollout(sc, gains, options, max_steps, k))(scenarios, keys)

    if mesh is None:
        return vmapped(scenarios, gains, keys)
    # Every device runs the vmapped rollout on its own shard of the batch: the scenarios are
    # independent, so there is no cross-device communication. check_vma=False: the scan's
    # carries start from constants (unvarying over the mesh), its outputs vary.
    batch, shared = jax.sharding.PartitionSpec(BATCH_AXIS), jax.sharding.PartitionSpec()
    return jax.shard_map(vmapped, mesh=mesh, in_specs=(batch, shared, batch), out_specs=batch,
                         check_vma=False)(scenarios, gains, keys)


def batch_keys(seed, batch: int):
    """One key per scenario: ``jax.random.split(key(seed), batch)``, or ``seed`` itself when it
    already holds one key per scenario (shape (batch, 2) raw keys, or (batch,) typed keys)."""
    key = prng_key(seed)
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    if key.ndim == (1 if typed else 2):
        if key.shape[0] != batch:
            raise ValueError(f"seed holds {key.shape[0]} keys for a batch of {batch} scenarios")
        return key
    return jax.random.split(key, batch)


class CompiledRollout:
    """A jitted rollout entry point: normalises its arguments (gains as strong
    arrays of the scenario's dtype, an int seed as a PRNG key) before the jit
    boundary, so that equal shapes always hit one compilation.

    Call it as ``f(scenario, gains, options, max_steps, seed=0)``; ``f.lower``
    takes the same arguments and lowers ahead of time (``.compile()`` then
    compiles without running); ``f.cache_size()`` counts the compilations.
    """

    def __init__(self, fn, static_argnames, batched: bool, doc: str):
        self._fn = fn
        self._static_argnames = static_argnames
        self._jits = {}
        self._nested = None
        self._batched = batched
        self.__doc__ = doc

    def _jitted(self, options: PlanOptions):
        """``jax.jit`` of the rollout with this package's XLA options for the options'
        method (:func:`~softplan_jax.compilation_cache.rollout_compiler_options`), built
        on first use: the options depend on the backend, which importing must not start."""
        method = options.method
        if method not in self._jits:
            self._jits[method] = jax.jit(self._fn, static_argnames=self._static_argnames,
                                         compiler_options=rollout_compiler_options(method))
        return self._jits[method]

    def _call(self, *args):
        """The jitted rollout; inside the user's own jit (jax allows compiler options on
        top-level jits only) a plain jit of it, compiled with the enclosing program's options."""
        try:
            return self._jitted(args[2])(*args)
        except ValueError as e:
            if "top-level" not in str(e):
                raise
            if self._nested is None:
                self._nested = jax.jit(self._fn, static_argnames=self._static_argnames)
            return self._nested(*args)

    def _args(self, scenario, gains, options, max_steps, seed):
        dtype = scenario.q0.dtype
        key = batch_keys(seed, scenario.q0.shape[0]) if self._batched else prng_key(seed)
        return scenario, strong_gains(gains, dtype), options, max_steps, key

    def __call__(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0) -> Rollout:
        return self._call(*self._args(scenario, gains, options, max_steps, seed))

    def lower(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0):
        """``jax.jit(...).lower`` of the rollout for these arguments."""
        return self._jitted(options).lower(*self._args(scenario, gains, options, max_steps, seed))

    def cache_size(self) -> int:
        """Number of compilations so far (one per padded shape, dtype, options, max_steps)."""
        return sum(j._cache_size() for j in self._jits.values())

    def cached(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int):
        """Compile ahead of time, keeping the TRACED program on disk for the next process
        (:func:`softplan_jax.compilation_cache.load_or_export`; ``softplan run`` uses it).

        Returns:
          ``(run, loaded)``: ``run(scenario, gains, seed=0) -> Rollout`` for arguments
          of these shapes (options and max_steps fixed), and whether the traced
          program came from disk. Without an artifact (cache off, a ParametricCurve
          in the scenario, jax.export unavailable) ``run`` is :meth:`lower`'s
          compiled program and ``loaded`` False; the results are the same.
        """
        args = self._args(scenario, gains, options, max_steps, 0)
        dynamic = (args[0], args[1], args[4])  # scenario, gains, key: options and max_steps are static
        leaves, treedef = jax.tree_util.tree_flatten(dynamic)
        out_def = jax.tree_util.tree_structure(Rollout(*([0] * len(Rollout._fields))))

        def flat(*xs):  # arrays in, arrays out: the artifact needs no pytree registrations
            s, g, k = jax.tree_util.tree_unflatten(treedef, xs)
            return tuple(jax.tree_util.tree_leaves(self._fn(s, g, options, max_steps, k)))

        compiled, loaded = (None, False)
        if not scenario.parametric and not self._batched:
            compiled, loaded = load_or_export(flat, leaves, (repr(options), str(int(max_steps)), str(treedef)),
                                              rollout_compiler_options(options.method))
        if compiled is None:
            plain = self._jitted(options).lower(*self._args(scenario, gains, options, max_steps, 0)).compile()

            def run(scenario, gains, seed=0):
                s, g, _, _, k = self._args(scenario, gains, options, max_steps, seed)
                return plain(s, g, k)

            return run, False

        def run(scenario, gains, seed=0):
            s, g, _, _, k = self._args(scenario, gains, options, max_steps, seed)
            return jax.tree_util.tree_unflatten(out_def, compiled(*jax.tree_util.tree_leaves((s, g, k))))

        return run, loaded


rollout_jit = CompiledRollout(_rollout_jit, ("options", "max_steps"), batched=False, doc="""\
:func:`rollout` under ``jit`` (options and
max_steps static): ``rollout_jit(scenario, gains, options, max_steps, seed=0)``. One compilation per
padded scenario shape, dtype, options and max_steps; new goals, obstacles, gain values or seeds reuse
it. ``seed``: an int or a PRNG key for the escapes. ``rollout_jit.lower(...)`` lowers ahead of time;
``rollout_jit.cache_size()`` counts compilations (see :class:`CompiledRollout`).""")

class BatchedRollout(CompiledRollout):
    """The batched, jitted rollout, sharded over devices (see :data:`rollout_batch`).

    Call it as ``f(scenarios, gains, options, max_steps, seed=0, devices=None)``;
    ``f.lower`` takes the same arguments; ``f.cache_size()`` counts the
    compilations (one per batch shape, dtype, options, max_steps and device set).
    """

    def _sharded_args(self, scenarios, gains, options, max_steps, seed, devices):
        s, g, o, T, keys = self._args(scenarios, gains, options, max_steps, seed)
        mesh = batch_mesh(devices)
        if mesh is None:
            return (s, g, o, T, keys, None), 0
        batch = s.q0.shape[0]
        size = round_chunk(None, batch, mesh.size)
        (s, keys), g = shard_batch(mesh, pad_batch((s, keys), size), g)
        return (s, g, o, T, keys, mesh), size - batch

    def __call__(self, scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0,
                 devices=None) -> Rollout:
        args, pad = self._sharded_args(scenarios, gains, options, max_steps, seed, devices)
        r = self._call(*args)
        if pad:
            batch = scenarios.q0.shape[0]
            r = jax.tree_util.tree_map(lambda x: x[:batch], r)
        return r

    def lower(self, scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0,
              devices=None):
        """``jax.jit(...).lower`` of the batched rollout for these arguments (the batch
        padded to a multiple of the device count)."""
        return self._jitted(options).lower(*self._sharded_args(scenarios, gains, options, max_steps, seed, devices)[0])


rollout_batch = BatchedRollout(_rollout_batch, ("options", "max_steps", "mesh"), batched=True, doc="""\
:func:`rollout` vmapped over a batch of
scenarios of one padded shape (every leaf of ``scenarios`` has a leading batch axis; gains shared),
jitted: ``rollout_batch(scenarios, gains, options, max_steps, seed=0, devices=None)``. Scenario b's
escapes use ``jax.random.split(key(seed), B)[b]`` (or ``seed[b]`` when ``seed`` holds B keys).

With more than one local device the batch is sharded over all of them (``devices``: None = every
local device, an int k = the first k, 1 = no sharding, a sequence of jax devices, or ``"global"``:
every process's devices under ``jax.distributed``, the result then a global array; see
:func:`plan_batch`, which gathers it on every process): padded to a
multiple of the device count with copies of its last scenario (dropped from the result), each
device runs the vmapped rollout on its shard (``jax.shard_map``, no cross-device communication).
The result agrees with the unsharded call to rounding, not bit for bit (XLA optimises a
partitioned program differently); a rollout that amplifies rounding (a near-tie of the stall or
contact test) can end differently. ``.lower`` and ``.cache_size()`` as :class:`CompiledRollout`.""")


class PlanResult(NamedTuple):
    """What :func:`plan` returns (host-side, trimmed to the steps taken).

    Attributes:
      reached: bool, the tip reached the goal without collision.
      iterations: int, planner steps taken (paper: "iterations to reach goal").
      collided: bool, the true clearance fell to <= 0 at a step or between steps.
      min_clearance: float, minimum true clearance over the motion.
      q: (iterations + 1, n, 3) configurations, start first.
      tip: (iterations + 1, 3) tip positions.
      status: "reached", "collided", "stalled", "max_steps", "non_finite" or
        (with the fallback) "unreachable".
      clearance: (iterations + 1, m) true clearance per step and real obstacle.
      final_error: float, |goal - tip| at the end.
      planner: "local" (the path is the potential-field planner's) or "global"
        (:func:`~softplan_jax.plan_fallback`: the local path up to step
        ``global_start``, then the global search's certified path).
      reason: why the goal was not reached, from the fallback: "beyond_reach",
        "goal_in_obstacle" (proofs), "no_ik_solution" (status "unreachable"), or
        "search_exhausted" (reachable, but the search found no path); else "".
      best_error: the smallest tip distance of a collision-free configuration
        found by the reachability IK (None where it did not run).
      global_start: the step where the global search's path leaves the local
        path (None for a local path).
    """

    reached: bool
    iterations: int
    collided: bool
    min_clearance: float
    q: np.ndarray
    tip: np.ndarray
    status: str
    clearance: np.ndarray
    final_error: float
    planner: str = "local"
    reason: str = ""
    best_error: float | None = None
    global_start: int | None = None


def make_options(method="curve", n_points=10, **kwargs) -> PlanOptions:
    """PlanOptions from keyword arguments, validated."""
    unknown = set(kwargs) - set(PlanOptions._fields)
    if unknown:
        raise ValueError(f"unknown planner option(s) {sorted(unknown)}; known: {list(PlanOptions._fields)}")
    return check_options(PlanOptions(method=method, n_points=int(n_points), **kwargs))


def check_gains(gains: Gains | GainFunction | None, dtype, n_segments: int | None = None):
    """Validate gains on the host: a :class:`Gains` or :class:`GainFunction` of finite
    positive scalars (``damping`` may be 0, ``rep_max`` inf) and, for a GainFunction,
    finite ``rep_profile`` (K >= 2) and ``seg_weights`` (``n_segments``, when given);
    returned as arrays of ``dtype``. None gives :func:`default_gains`."""
    if gains is None:
        return default_gains(dtype)
    if not isinstance(gains, (Gains, GainFunction)):
        raise ValueError(f"gains must be a Gains or a GainFunction, got {type(gains).__name__}")
    vals = {k: np.asarray(v) for k, v in gains._asdict().items()}
    for k in Gains._fields:
        v = vals[k]
        if v.shape != () or not np.isfinite(v) or v <= 0:
            if not ((k == "damping" and v.shape == () and v == 0) or (k == "rep_max" and v.shape == () and v == np.inf)):
                raise ValueError(f"gain {k} must be a finite positive scalar, got {v!r}")
    if isinstance(gains, GainFunction):
        p, w = vals["rep_profile"], vals["seg_weights"]
        if p.ndim != 1 or p.shape[0] < 2 or not np.all(np.isfinite(p)):
            raise ValueError(f"rep_profile must be a finite (K,) array with K >= 2, got shape {p.shape}")
        if w.ndim != 1 or w.shape[0] < 1 or not np.all(np.isfinite(w)):
            raise ValueError(f"seg_weights must be a finite (n,) array, got shape {w.shape}")
        if n_segments is not None and w.shape[0] != int(n_segments):
            raise ValueError(f"seg_weights has {w.shape[0]} entries for an arm of {n_segments} segments")
    return type(gains)(**{k: jnp.asarray(v, dtype) for k, v in vals.items()})


def plan(scenario: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
         max_steps: int = 600, seed=0, **options) -> PlanResult:
    """Plan a path for one scenario (jitted rollout; compiles once per padded
    scenario shape, method and option set).

    Args:
      scenario: a :class:`~softplan_jax.scenarios.Scenario` (make_scenario,
        paper_scenario or load_scenario).
      method: "curve" (the paper's exact closest points) or "points" (each curve
        modelled by ``n_points`` points).
      n_points: N of the N-point model (method "points").
      gains: :class:`Gains` or :class:`GainFunction` (e.g. from
        :func:`~softplan_jax.gains_file.load_gains`); default :func:`default_gains`.
      max_steps: the most planner steps.
      seed: int seed (or PRNG key) of the escapes' random walks.
      **options: further :class:`PlanOptions` fields (step, safe_fraction,
        escapes, goal_tolerance, repulsion, stall_window, solver, ...).

    Returns:
      :class:`PlanResult`.
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario (see make_scenario), got {type(scenario).__name__}")
    if scenario.q0.ndim != 2:
        raise ValueError("plan takes one scenario; use plan_batch for a batch")
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    opts = make_options(method, n_points, **options)
    g = check_gains(gains, scenario.q0.dtype, scenario.q0.shape[0])
    r = rollout_jit(scenario, g, opts, int(max_steps), seed)
    return result_from_rollout(r, scenario)


def result_from_rollout(r: Rollout, scenario: Scenario) -> PlanResult:
    """Trim a single (unbatched) Rollout to the steps taken, on the host."""
    it = int(r.iterations)
    _, mask = radius_and_mask(scenario)
    mask = np.asarray(mask)
    return PlanResult(
        reached=bool(r.reached),
        iterations=it,
        collided=bool(r.collided),
        min_clearance=float(r.min_clearance),
        q=np.asarray(r.q[: it + 1]),
        tip=np.asarray(r.tip[: it + 1]),
        status=status_name(r.status),
        clearance=np.asarray(r.clearance[: it + 1])[:, mask],
        final_error=float(r.final_error),
    )


def plan_batch(scenarios: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
               max_steps: int = 600, seed=0, *, chunk: int | None = None, devices=None, progress: bool = False,
               **options) -> Rollout:
    """Plan a batch of scenarios: vmapped and jitted, sharded over the local
    devices, in chunks of one shape.

    Args:
      scenarios: a batched Scenario (:func:`stack_scenarios`, or
        :func:`softplan_jax.scenarios.random_scenarios`).
      seed: int seed or PRNG key; scenario b's escapes use
        ``jax.random.split(key(seed), B)[b]`` whatever the chunk. Or one key per
        scenario (B raw keys (B, 2), or B typed keys): then scenario b uses
        ``seed[b]`` (a share of a larger suite keeps the suite's keys, see the
        README's "Many scenarios, several devices").
      chunk: scenarios per call (None: the whole batch in one call). Rounded up
        to a multiple of the device count; the last chunk is padded with copies
        of the last scenario, so every call has the same shape and compiles
        once.
      devices: None (every local device), an int k (the first k local devices;
        1: no sharding), a sequence of local jax devices, or ``"global"``: every
        device of every process under ``jax.distributed`` (call it with the
        same arguments on every process; each process computes its devices'
        shards and every process gets the whole result as NumPy arrays). With
        more than one device, every chunk is split over them (see
        :data:`rollout_batch`).
      progress: write one line per finished chunk to stderr (chunks done,
        scenarios, elapsed time, estimated time left, compile time).
      Other arguments as :func:`plan`.

    Returns:
      A batched :class:`Rollout` (leading axis: scenario; time padded to
      max_steps + 1). In one call its arrays are jax arrays; in several chunks
      (or with ``devices="global"`` on several processes) they are NumPy arrays
      assembled on the host, so the devices hold about
      two chunks at a time. Size: about ``(max_steps + 1) * (8 * (13 + 2 m) + 5)``
      bytes per scenario in float64 (m obstacle slots): 142 kB for 600 steps and
      8 slots, 1.4 GB for 10^4 such scenarios.

    Rounding: a vmapped program's rounding depends on its batch shape and on
    the device count, so results agree with another chunk size or device count
    to rounding (not bit for bit); a rollout that amplifies rounding (a
    near-tie of the stall test or of the contact test) can end differently.
    """
    if not isinstance(scenarios, Scenario) or scenarios.q0.ndim != 3:
        raise ValueError("plan_batch takes a batched Scenario (see stack_scenarios)")
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if chunk is not None and (isinstance(chunk, (bool, np.bool_)) or not isinstance(chunk, (int, np.integer))
                              or chunk < 1):
        raise ValueError(f"chunk must be None or an int >= 1, got {chunk!r}")
    if not isinstance(progress, (bool, np.bool_)):
        raise ValueError(f"progress must be True or False, got {progress!r}")
    opts = make_options(method, n_points, **options)
    dtype = scenarios.q0.dtype
    g = strong_gains(check_gains(gains, dtype, scenarios.q0.shape[-2]), dtype)
    T = int(max_steps)
    mesh = batch_mesh(devices)
    n_dev = 1 if mesh is None else mesh.size
    batch = scenarios.q0.shape[0]
    size = round_chunk(chunk, batch, n_dev)
    n_chunks = math.ceil(batch / size)
    bar = Progress(n_chunks, batch, n_dev) if progress else None
    spread = is_global(mesh)  # several processes: results are gathered on every host
    if n_chunks == 1 and bar is None and not spread:
        return rollout_batch(scenarios, g, opts, T, seed, devices=devices)

    keys = batch_keys(seed, batch)
    host = jax.tree_util.tree_map(np.asarray, scenarios)
    out, done = None, 0

    def call(a):
        part = pad_batch(jax.tree_util.tree_map(lambda x: x[a : a + size], (host, keys)), size)
        if mesh is None:
            (s, k), g_dev = jax.device_put(part), g  # jax arrays, as rollout_batch's: one jit signature
        else:
            (s, k), g_dev = shard_batch(mesh, part, g)
        return rollout_batch._call(s, g_dev, opts, T, k, mesh)

    def collect(a, r):
        nonlocal out, done
        n = min(size, batch - a)
        if n_chunks == 1 and not spread:
            out = jax.tree_util.tree_map(lambda x: x[:n], r) if n < size else r
        else:
            r = gather(r)
            if out is None:
                out = jax.tree_util.tree_map(lambda x: np.empty((batch, *x.shape[1:]), x.dtype), r)
            for o, x in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(r), strict=True):
                o[a : a + n] = x[:n]
        done += 1
        if bar is not None:
            jax.block_until_ready(out)
            bar.update(done, a + n)

    # Dispatch chunk i + 1 before fetching chunk i: the devices stay busy while the host copies.
    pending = None
    for i, a in enumerate(range(0, batch, size)):
        t0 = time.perf_counter()
        r = call(a)
        if i == 0 and bar is not None:
            bar.compiled(time.perf_counter() - t0)
        if pending is not None:
            collect(*pending)
        pending = (a, r)
    collect(*pending)
    return out
