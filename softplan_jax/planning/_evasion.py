"""The evasive step: moving away from an obstacle that comes faster than the safe step allows
(``f (c_j - floor) < S_j dt``: no scale of the field's step is proven safe; docs: Moving scenes,
"The evasive step"). The velocity is the one closest to the field's (paper eq. 9) that meets the
control-barrier condition ``a_j . qdot >= S_j - gamma (c_j - c*_j)`` for every obstacle j
(``a_j = dc_j/dq = -J_j^T n_j`` by the envelope theorem, ``c*_j = floor + S_j dt / f``), a small
quadratic program solved by Hildreth's row-action method (:func:`barrier_velocity`), capped at
the actuators' speed. Its straight motion is proven clear by conservative advancement in time,
in pieces ``h = min_j f (c_j - floor) / (U / dt + S_j)`` (U the motion bound of the whole line;
:func:`certify_motion`); where the pieces do not cover the step the rollout ends ``too_fast`` at
q_k, the last configuration proven clear."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..geometry._clearance import contact_tolerance, safety_floor
from ..geometry._closest import ClosestPoint, curve_closest
from ..geometry._kinematics import motion_bound, points_jacobian
from ..geometry._obstacles import clearance_of, radius_and_mask, true_closest
from ..scenarios._motion import MovingScenario, moved_curves, scenario_at
from ._step import apply_step

__all__ = ["clearance_gradients", "barrier_velocity", "slot_clearance", "certify_motion", "evasive_target",
           "HILDRETH_SWEEPS"]

HILDRETH_SWEEPS = 8  # passes of the row-action method over the obstacles


def clearance_gradients(q, truth: ClosestPoint, mask):
    """``a_j = dc_j/dq`` (m, 3n) of the exact clearance to every obstacle slot at q:
    ``-J_j^T n_j`` with n_j the unit vector from the closest arm point to the
    closest obstacle point (the distance's gradient where the closest pair is
    unique, the envelope theorem). Padding slots (``mask`` False) and a zero
    distance give 0 (finite, no NaN)."""
    J = points_jacobian(q, truth.segment, truth.s)  # (m, 3, 3n)
    d = truth.obstacle_point - truth.arm_point
    norm = jnp.sqrt(jnp.sum(d * d, axis=-1, keepdims=True))
    ok = mask[:, None] & (norm > 0)
    n = jnp.where(ok, d / jnp.where(ok, norm, 1.0), 0.0)
    return -jnp.einsum("kij,ki->kj", J, n)


def barrier_velocity(v_field, a, b, sweeps: int = HILDRETH_SWEEPS):
    """The velocity closest to ``v_field`` (3n,) with ``a_j . v >= b_j`` for every row j
    of ``a`` (m, 3n): Hildreth's row-action method for ``min |v - v_field|^2`` under
    linear inequalities (``sweeps`` passes over the rows; exact for one row; a row
    with ``a_j = 0`` or ``b_j = -inf`` is inactive). Differentiable, fixed cost."""
    norms = jnp.sum(a * a, axis=-1)
    live = (norms > 0) & jnp.isfinite(b)
    inv = jnp.where(live, 1.0 / jnp.where(live, norms, 1.0), 0.0)
    b = jnp.where(live, b, 0.0)

    def row(state, j):
        v, lam = state
        new = jnp.maximum(0.0, lam[j] + (b[j] - a[j] @ v) * inv[j])
        return (v + (new - lam[j]) * a[j], lam.at[j].set(new)), None

    def sweep(state, _):
        return jax.lax.scan(row, state, jnp.arange(a.shape[0]))[0], None

    lam0 = jnp.zeros(a.shape[:1], v_field.dtype)
    return jax.lax.scan(sweep, (v_field, lam0), None, length=sweeps)[0][0]


def slot_clearance(moving: MovingScenario, q, t, j, solver):
    """The exact clearance of obstacle slot j to the arm at (q, t): for a scene of
    polynomial curves only, the one curve of slot j moved to t and solved alone;
    otherwise the whole scene at t (:func:`~softplan_jax.scenarios._motion.scenario_at`).
    One nested jit: the between-step search and the evasive step's proof trace it once."""
    return _slot_clearance(moving, q, t, jnp.asarray(j, jnp.int32), solver)


@functools.partial(jax.jit, static_argnums=4)
def _slot_clearance(moving: MovingScenario, q, t, j, solver):
    scene = moving.scene
    radius, mask = radius_and_mask(scene)
    if scene.points.shape[0] == 0 and not scene.parametric:
        one = jax.tree_util.tree_map(lambda x: x[j], (scene.curves, moving.motion))
        curve = moved_curves(jax.tree_util.tree_map(lambda x: x[None], one[0]),
                             jax.tree_util.tree_map(lambda x: x[None], one[1]), t)
        d = curve_closest(q, jax.tree_util.tree_map(lambda x: x[0], curve), solver).distance
        return d - scene.arm_radius - radius[j]
    return clearance_of(true_closest(q, scenario_at(moving, t), solver), scene)[j]


def certify_motion(moving: MovingScenario, q_a, q_b, t_a, c_a, speed, dt, floor, fraction, solver, max_pieces: int,
                   want=True):
    """Prove the straight motion q_a -> q_b over ``[t_a, t_a + dt]`` clear of the moving
    obstacles by conservative advancement in time (module docstring).

    Each slot keeps a lower bound ``low_j`` on its clearance at the current time
    tau (at first the exact ``c_a``). A piece of length
    ``h = min_j f (low_j - floor) / r_j`` (``r_j = U/dt + S_j``, the pair's closing
    speed bound) keeps every clearance above ``floor``; after it every bound
    drops by ``r_j h`` and the slot that set h is solved exactly at the new time
    (:func:`slot_clearance`), so one curve is solved per piece.

    Args:
      moving: the moving scene; q_a, q_b: (n, 3) the motion's ends.
      t_a: the motion's start time; c_a: (m,) exact clearances at (q_a, t_a) (+inf: padding).
      speed: (m,) the obstacles' speed bounds S_j; dt: the motion's duration.
      floor, fraction: as :func:`~softplan_jax.planning._step.safe_scale`.
      solver: the exact solver's options; max_pieces: the most pieces (static).
      want: False: nothing to prove (no piece runs; a batch's loop runs for the
        scenes that want it).

    Returns:
      ``(proven, pieces)``: whether the pieces cover the interval, and how many
      were used. Not differentiated (a ``while_loop``; its inputs are held).
    """
    q_a, q_b, t_a, c_a = jax.lax.stop_gradient((q_a, q_b, t_a, c_a))
    _, mask = radius_and_mask(moving.scene)
    U = motion_bound(q_a, q_b)[-1]  # every arm point moves at most U over the whole line
    rate = U / dt + speed  # (m,) closing speed bound of each pair
    moves = mask & (rate > 0)

    def cond(state):
        tau, low, pieces, done = state
        return ~done & (pieces < max_pieces)

    def body(state):
        tau, low, pieces, _ = state
        h_j = jnp.where(moves, fraction * jnp.maximum(low - floor, 0.0) / jnp.where(moves, rate, 1.0), jnp.inf)
        j = jnp.argmin(h_j)
        h = jnp.minimum(h_j[j], dt - tau)
        done = h_j[j] >= dt - tau  # this piece reaches the end of the interval
        stuck = ~(h > 0) | jnp.any(mask & (low <= floor))
        tau = tau + h
        low = low - rate * h

        def solve(tau):  # the binding slot exactly, at the next piece's start (none after the last)
            q_t = q_a + (tau / dt) * (q_b - q_a)
            return low.at[j].set(slot_clearance(moving, q_t, t_a + tau, j, solver))

        low = jax.lax.cond(done | stuck, lambda tau: low, solve, tau)
        # A stuck piece ends the loop unproven.
        return tau, low, jnp.where(stuck, max_pieces, pieces + 1), done & ~stuck

    zero = jnp.zeros((), c_a.dtype)
    state0 = (zero, c_a, jnp.zeros((), jnp.int32), ~jnp.asarray(want, bool))
    _, _, pieces, done = jax.lax.while_loop(cond, body, state0)
    return done & jnp.asarray(want, bool), pieces


def evasive_target(moving: MovingScenario, q, q_full, truth: ClosestPoint, c, t, speed, gains, track, want=True):
    """The end of the evasive step from q at time t, and whether its motion is proven clear.

    Args:
      moving: the moving scene; q: (n, 3) q_k; q_full: the field's full step (paper
        eq. 9, lengths clipped; its straight line is the nominal motion).
      truth: the exact closest pairs at (q, t); c: (m,) their clearances (+inf: padding).
      speed: (m,) the obstacles' speed bounds; gains: the planner's gains (dt).
      track: TrackOptions (evasion_speed, barrier_gain, evasion_pieces, plan.safe_fraction).
      want: whether this scene needs the step (see :func:`certify_motion`).

    Returns:
      ``(q_target, proven, pieces)``: the evasive configuration at t + dt, whether
      :func:`certify_motion` proved the line clear, and its pieces.
    """
    plan = track.plan
    dt = gains.dt
    _, mask = radius_and_mask(moving.scene)
    floor = safety_floor(contact_tolerance(plan, q.dtype))
    f = plan.safe_fraction
    a = clearance_gradients(q, truth, mask)  # (m, 3n)
    level = floor + speed * dt / f  # c*_j: where the ordinary safe step is proven again
    b = jnp.where(mask, speed - track.barrier_gain * (c - level), -jnp.inf)
    v = barrier_velocity(((q_full - q) / dt).reshape(-1), a, b).reshape(q.shape)
    # The actuators' limit: the arm's motion bound over the step at most evasion_speed * dt.
    U = motion_bound(q, q + dt * v)[-1]
    cap = track.evasion_speed * dt
    v = v * jnp.where(U > cap, cap / jnp.where(U > cap, U, 1.0), 1.0)
    q_target = apply_step(q, v, moving.scene, gains)
    proven, pieces = certify_motion(moving, q, q_target, t, c, speed, dt, floor, f, plan.solver,
                                    track.evasion_pieces, want)
    return q_target, proven, pieces
