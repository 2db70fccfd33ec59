"""One planner step: the potential field of paper eq. (9),
``qdot = J_e^+ F_e(V_e) - sum_j J_sj^+ F_sj(V_sj)`` with ``V_e = goal - tip``, ``V_sj`` from the
closest arm point to obstacle j's closest point (exact for ``method="curve"``, the N-point model
of paper §3 for ``"points"`` and for point sets) and ``J^+`` the damped least-squares
pseudo-inverse, then ``q <- q + dt qdot`` with the lengths clipped to ``[L_min_i, L_max_i]``. The
safe step (the default) scales it by :func:`safe_scale`'s
``alpha = min(1, (f (c - floor) - travel) / B)``, B the
:func:`~softplan_jax.geometry._kinematics.motion_bound` (conservative advancement), the rule that
also certifies every motion of the global search; ``step = "plain"`` is the paper's step,
unscaled. The gains are in :mod:`._gains` (re-exported here)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import damped_pinv, safe_norm
from ..geometry._arm import PCC
from ..geometry._clearance import contact_tolerance, safety_floor
from ..geometry._closest import ClosestPoint
from ..geometry._obstacles import model_closest, placeholder_closest, radius_and_mask, true_closest
from ..scenarios import Scenario
from ._gains import GOAL_GAINS, GainFunction, Gains, default_gains, goal_scaled, repulsion_scale
from ._options import PROGRAM_KIND, PlanOptions

__all__ = [
    "Gains",
    "GainFunction",
    "default_gains",
    "attraction",
    "tracking_attraction",
    "repulsion",
    "repulsion_scale",
    "GOAL_GAINS",
    "goal_scaled",
    "field_velocity",
    "apply_step",
    "safe_scale",
    "step_target",
    "scaled_step",
    "next_q",
    "planner_step",
]


def attraction(V_e, gains: Gains):
    """F_e(V_e): linear with gain k_att, saturated to speed v_max (paper eq. 9)."""
    speed = gains.k_att * safe_norm(V_e)
    return gains.k_att * V_e / jnp.maximum(1.0, speed / gains.v_max)


def tracking_attraction(V_e, goal_rate, gains: Gains, feedforward: bool = True):
    """The attraction's tip velocity for a moving goal: ``k_att V_e + dg/dt``
    saturated at ``v_max`` (paper eq. 9's F_e with a feed-forward term; without
    it a proportional law lags a goal moving at speed w by ``w / k_att``)."""
    v = gains.k_att * V_e + (goal_rate if feedforward else 0.0)
    return v / jnp.maximum(1.0, safe_norm(v) / gains.v_max)


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


def field_velocity(q, scenario: Scenario, gains: Gains, truth: ClosestPoint, options: PlanOptions, F_e=None,
                   arm=PCC):
    """Paper eq. (9): qdot = J_e^+ F_e(V_e) - sum_j J_sj^+ F_sj(V_sj).

    ``F_e`` (3,), if given, replaces the attraction :func:`attraction` (a moving goal's
    :func:`tracking_attraction`, an escape's random walk). ``arm``: the arm model
    (:mod:`softplan_jax.geometry._arm`; default the PCC arm).
    Returns ``(qdot (n, 3), clearance (m,))``: the clearance of the planner's
    own obstacle model (exact for the curve method), +inf for padding slots.
    """
    n = q.shape[0]
    arm = arm.at(q)
    V_e = scenario.goal - arm.tip(q)
    gains = goal_scaled(gains, V_e)  # a GainFunction's dependence on the goal distance (else as given)
    shape = arm.shape(q)
    cps = model_closest(shape, scenario, truth, options.method, options.n_points, options.points_per_segment)
    radius, mask = radius_and_mask(scenario)
    # J_e (the tip: s = 1 of the shape's last segment) and every J_sj in one pass.
    segments = jnp.concatenate([jnp.array([shape.shape[0] - 1], jnp.int32), cps.segment])
    s = jnp.concatenate([jnp.ones((1,), q.dtype), cps.s])
    J = arm.jacobians(q, segments, s)
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
    if F_e is None:
        F_e = attraction(V_e, gains)
    # Paper eq. (9).
    qdot = pinvs[0] @ F_e - jnp.einsum("kij,kj->i", pinvs[1:], F_s)
    return qdot.reshape(n, 3), jnp.where(mask, clearance, jnp.inf)


def apply_step(q, qdot, scenario: Scenario, gains: Gains):
    q_next = q + gains.dt * qdot
    return q_next.at[:, 0].set(jnp.clip(q_next[:, 0], scenario.L_min, scenario.L_max))


def safe_scale(q, q_target, clearance, floor, fraction, travel=None, cap=None, arm=PCC):
    """The safe step's scale alpha in [0, 1] for the straight motion q -> q_target,
    and whether even standing still is unsafe.

    ``motion_bound(q, q + alpha (q_target - q)) <= alpha * motion_bound(q, q_target)``
    (the bound is linear in dq for a fixed length bound, and Lbar of the full
    motion bounds every shorter one), so::

        alpha = min(1, min_j (f (c_j - floor) - travel_j) / B)

    keeps every arm point, at every instant of the motion, closer to its start
    than ``f (c_j - floor) - travel_j``: the clearance to obstacle j stays above
    ``floor`` even when the obstacle comes ``travel_j`` closer meanwhile
    (conservative advancement with both bodies moving). This one rule scales
    the planner's step (static and moving scenes) and every certified motion
    of the global search.

    Args:
      q, q_target: (n, 3) the motion's ends.
      clearance: (m,) clearance of each obstacle at q (+inf: padding slots).
      floor: the clearance never to reach (twice the contact tolerance).
      fraction: ``f`` in (0, 1], the share of the clearance the motion may use.
      travel: (m,) how far each obstacle can move during the motion (None: static).
      cap: an upper bound on the allowed motion (None: none).
      arm: the arm model whose motion bound B is (default the PCC arm).

    Returns:
      ``(alpha, too_fast)``: too_fast is True where some ``f (c_j - floor) <
      travel_j`` (no motion, not even standing still, is proven safe; always
      False without travel). No obstacle (c = inf) gives alpha = 1; a NaN
      clearance gives alpha = NaN (which ends a rollout as non-finite).
    """
    budget = fraction * jnp.maximum(clearance - floor, 0.0)
    if travel is not None:
        budget = budget - travel
        too_fast = jnp.any(budget < 0)
    else:
        too_fast = jnp.zeros((), bool)
    # min_j f max(c_j - floor, 0) equals f max(min_j c_j - floor, 0) exactly (monotone rounding).
    allowed = jnp.maximum(jnp.min(budget, initial=jnp.inf), 0.0)
    if cap is not None:
        allowed = jnp.minimum(allowed, cap)
    bound = arm.motion_bound(q, q_target)
    # Double-where: a zero bound (no motion) gives alpha = 1 and no 0/0 in either mode.
    moving = bound > 0
    alpha = jnp.where(moving, jnp.minimum(1.0, allowed / jnp.where(moving, bound, 1.0)), 1.0)
    return jnp.where(jnp.isnan(jnp.min(clearance, initial=jnp.inf)), jnp.nan, alpha), too_fast


def step_target(q, scenario: Scenario, gains: Gains, truth: ClosestPoint, options: PlanOptions, F_e=None,
                lead=None, arm=PCC):
    """The field's full step from q and the clearance the safe step scales it by:
    ``(q_full, clearance)``. Paper eq. (9) (:func:`field_velocity`, ``F_e`` and ``arm``
    as there), then the Euler step with the length limits (:func:`apply_step`).
    ``lead`` (m,), if given: ``scenario``'s obstacles are inflated by it for the
    field (a look-ahead), and it is added back to the field's clearance."""
    qdot, clearance = field_velocity(q, scenario, gains, truth, options, F_e, arm)
    if lead is not None:
        clearance = clearance + lead
    return apply_step(q, qdot, scenario, gains), clearance


def scaled_step(q, q_full, clearance, options: PlanOptions, travel=None, arm=PCC):
    """``(q_next, alpha, too_fast)`` of the step q -> q_full: for ``options.step = "safe"``
    scaled by :func:`safe_scale` (``travel``: the obstacles' travel over the step, None
    for a static scene); ``"plain"`` is the paper's step (alpha = 1)."""
    if options.step == "plain":
        return q_full, jnp.ones((), q.dtype), jnp.zeros((), bool)
    floor = safety_floor(contact_tolerance(options, q.dtype))
    alpha, too_fast = safe_scale(q, q_full, clearance, floor, options.safe_fraction, travel, arm=arm)
    # q and q_full lie in the length box, so every point of the segment between them does too.
    return q + alpha * (q_full - q), alpha, too_fast


def next_q(q, scenario: Scenario, gains: Gains, truth: ClosestPoint, options: PlanOptions, F_e=None, travel=None,
           lead=None):
    """One planner step from q: ``(q_next, alpha, too_fast)``: :func:`step_target`
    (paper eq. 9; ``F_e`` and ``lead`` as there), then :func:`scaled_step`
    (``travel`` as there)."""
    q_full, clearance = step_target(q, scenario, gains, truth, options, F_e, lead)
    return scaled_step(q, q_full, clearance, options, travel)


def _planner_step(q, scenario: Scenario, gains: Gains, options: PlanOptions):
    truth = true_closest(q, scenario, options.solver) if options.method == "curve" else None
    if truth is None:
        # The points method never uses the exact solver: a placeholder of the right shape.
        truth = placeholder_closest(q, scenario)
    return next_q(q, scenario, gains, truth, options)[0]


_PLANNER_STEP = {}  # method -> package_jit of _planner_step (the rollouts' XLA options for the method)


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

    Compiled once per shape and options with the rollouts' XLA options for
    ``options.method``
    (:class:`~softplan_jax.base._compilation_cache.package_jit`).
    """
    if not isinstance(options, PlanOptions):
        raise ValueError(f"options must be a PlanOptions (see make_options), got {type(options).__name__}")
    if options.method not in _PLANNER_STEP:
        kind = PROGRAM_KIND[options.method]
        _PLANNER_STEP[options.method] = package_jit(_planner_step, kind, static_argnames=("options",))
    return _PLANNER_STEP[options.method](q, scenario, gains, options)
