"""True clearance and collisions; post-hoc checks of a rollout (DESIGN.md: collision).

The TRUE clearance to an obstacle is the distance from the arm backbone to the
real obstacle (the curve itself, or the point set), minus the arm radius,
minus the obstacle radius — whatever model the planner used. A collision is a
clearance <= 0 anywhere along the motion, including between two planner steps
(DESIGN.md).

Between two steps the configuration moves along the straight line from q_a to
q_b (the planner's Euler step). :func:`between_steps` searches that motion for
the smallest distance: for every obstacle, Gauss-Newton over (tau, s, u) on
``|P_si(q_a + tau (q_b - q_a)) - F_o(u)|^2``, started from the exact closest
pairs at both ends. Every point it visits is a real configuration of the
motion, so what it reports is an actual distance reached during the motion:
a pass of the arm through a curve is reported even though both sampled
configurations are clear, and a collision is never invented. (It could in
principle miss a dip whose basin neither end's closest pair leads into.)

:func:`apply_collision_checks` adds the true-clearance and between-step
checks to a planning-only rollout after the fact (vectorised over time).
Every per-obstacle loop goes through :mod:`softplan_jax.obstacles`.

:func:`dense_trajectory_clearance` is the slow, brute-force check of a whole
trajectory (dense interpolation in q, dense sampling of arm and curve); the
tests use it as an independent reference.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .closest import ClosestPoint, FixedPoint
from .kinematics import backbone_points, segment_point
from .numerics import contact_floor, get_epsilon, safe_norm, solve_small
from .obstacles import map_obstacles, radius_and_mask, true_closest
from .status import Status

__all__ = [
    "true_closest",
    "between_steps",
    "contact_tolerance",
    "apply_collision_checks",
    "dense_trajectory_clearance",
]


def _motion_pair_distance(q_a, dq, i, x0, curve, iterations: int):
    """Smallest distance found between segment i and a curve over the motion
    q(tau) = q_a + tau dq, tau in [0, 1]: Gauss-Newton on
    r(tau, s, u) = P_si(q(tau)) - F_o(u) from x0 = (tau, s, u), box-clipped,
    never increasing |r| (best of the step lengths 1, 1/2, 1/4, 0).

    Every candidate is a real (configuration, arm point, obstacle point)
    triple, so the result is an upper bound on the true minimum over the
    motion: it can miss a dip, never invent one.
    """
    dtype = q_a.dtype
    lo = jnp.stack([jnp.zeros((), dtype), jnp.zeros((), dtype), curve.u_range[0]])
    hi = jnp.stack([jnp.ones((), dtype), jnp.ones((), dtype), curve.u_range[1]])
    ts = jnp.array([1.0, 0.5, 0.25, 0.0], dtype)

    def residual(x):
        return segment_point(q_a + x[0] * dq, i, x[1]) - curve.point(x[2])

    def body(_, x):
        r = residual(x)
        J = jax.jacfwd(residual)(x)  # (3, 3): d r / d(tau, s, u)
        H = J.T @ J
        # Levenberg-Marquardt damping relative to the dtype (1e-10 vanishes in float32, where a
        # rank-deficient H, e.g. a straight arm's base point, then solved to NaN).
        H = H + (get_epsilon(dtype) * jnp.trace(H) + jnp.finfo(dtype).tiny) * jnp.eye(3, dtype=dtype)
        step = -solve_small(H, J.T @ r)  # no LAPACK call: see solve_small (sharded batches)
        step = jnp.where(jnp.all(jnp.isfinite(step)), step, 0.0)  # never a NaN candidate
        cands = jnp.clip(x[None, :] + ts[:, None] * step[None, :], lo, hi)
        f = jax.vmap(lambda c: jnp.sum(residual(c) ** 2))(cands)
        f = jnp.where(jnp.isnan(f), jnp.inf, f)
        return cands[jnp.argmin(f)]

    x = jax.lax.fori_loop(0, iterations, body, jnp.clip(x0, lo, hi))
    return safe_norm(residual(x))


def between_steps(q_a, q_b, truth_a: ClosestPoint, truth_b: ClosestPoint, scenario, radius_sum,
                  iterations: int = 8):
    """Smallest clearance found (m,) during the motion from q_a to q_b.

    For every obstacle slot, Gauss-Newton over (tau, s, u) on the segment of
    the closest pair at either end, started from both ends' closest pairs
    (see :func:`_motion_pair_distance`); point sets use the closest point of
    each end. ``truth_a``/``truth_b``: :func:`~softplan_jax.obstacles.true_closest`
    at q_a and q_b. ``radius_sum`` (m,) = arm radius + obstacle radius.
    """
    q_a, q_b = jax.lax.stop_gradient(q_a), jax.lax.stop_gradient(q_b)
    truth_a, truth_b = jax.lax.stop_gradient(truth_a), jax.lax.stop_gradient(truth_b)
    dq = q_b - q_a
    dtype = q_a.dtype
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)

    ends = jnp.stack([zero, one])

    def from_both_ends(curve_a, curve_b, ta, tb):
        # Stacked starts (tau, s, u) at tau = 0 and tau = 1, each on its own segment.
        seg = jnp.stack([ta.segment, tb.segment])
        x0 = jnp.stack([ends, jnp.stack([ta.s, tb.s]), jnp.stack([ta.u, tb.u])], axis=-1)
        curves = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), curve_a, curve_b)
        d = jax.vmap(lambda i, x, c: _motion_pair_distance(q_a, dq, i, x, c, iterations))(seg, x0, curves)
        return jnp.min(d)

    def on_curve(c, a, b):
        return from_both_ends(c, c, a, b)

    def on_points(points, mask, a, b):
        # The closest point of each end, as a fixed point (u unused).
        return from_both_ends(
            FixedPoint(a.obstacle_point), FixedPoint(b.obstacle_point),
            a._replace(u=jnp.zeros_like(a.u)), b._replace(u=jnp.zeros_like(b.u)),
        )

    found = map_obstacles(scenario, on_curve, on_points, (truth_a, truth_b), empty=jnp.zeros((0,), dtype))
    D_min = jnp.minimum(found, jnp.minimum(truth_a.distance, truth_b.distance))
    return D_min - radius_sum


def contact_tolerance(options, dtype) -> float:
    """Clearance at or below which a rollout counts as collided: the planner options'
    ``contact_tolerance``, but never below ten times sqrt(eps) of ``dtype``."""
    return max(float(options.contact_tolerance), contact_floor(dtype))


def apply_collision_checks(r, scenario, options):
    """Add the true-clearance and between-step checks to a planning-only
    rollout (``check_collisions=False``), vectorised over time.

    The result equals what the checked rollout gives: the dynamics do not
    depend on the checks until the first collision, after which the checked
    rollout freezes, so the trajectory is cut and frozen at the first step
    whose clearance (at the step, or during the motion to it) is at or below
    the contact tolerance, or NaN (status non-finite: a NaN clearance never
    counts as clear). Pure; vmap it over a batch.

    Args:
      r: an unbatched :class:`~softplan_jax.planner.Rollout` (planning only).
      scenario: its Scenario.
      options: its PlanOptions (static: the solver, the contact tolerance).

    Returns:
      The Rollout with clearance, between-step clearance, status, iterations,
      converged and the derived fields as a checked rollout has them.
    """

    radius, mask = radius_and_mask(scenario)
    contact = contact_tolerance(options, scenario.q0.dtype)
    truths = jax.vmap(lambda q: true_closest(q, scenario, options.solver))(r.q)
    c = jnp.where(mask, truths.distance - scenario.arm_radius - radius, jnp.inf)
    prev = jax.tree_util.tree_map(lambda x: x[:-1], truths)
    nxt = jax.tree_util.tree_map(lambda x: x[1:], truths)
    cb = jax.vmap(lambda qa, qb, ta, tb: between_steps(qa, qb, ta, tb, scenario, scenario.arm_radius + radius))(
        r.q[:-1], r.q[1:], prev, nxt
    )
    cb = jnp.concatenate([c[:1], jnp.where(mask, cb, jnp.inf)])
    steps = jnp.arange(r.q.shape[0], dtype=r.iterations.dtype)
    nan = jnp.any(jnp.isnan(c), axis=1) | jnp.any(jnp.isnan(cb), axis=1)
    hit = (jnp.any(c <= contact, axis=1) | jnp.any(cb <= contact, axis=1) | nan) & (steps <= r.iterations)
    first = jnp.argmax(hit).astype(r.iterations.dtype)
    collided = jnp.any(hit)
    end = jnp.where(collided, first, r.iterations)
    keep = steps <= end
    q = jnp.where(keep[:, None, None], r.q, r.q[end])
    tip = jnp.where(keep[:, None], r.tip, r.tip[end])
    c = jnp.where(keep[:, None], c, c[end])
    cb = jnp.where(keep[:, None], cb, c[end])
    status = jnp.where(collided, jnp.where(nan[first], Status.NONFINITE, Status.COLLIDED), r.status)
    status = status.astype(r.status.dtype)
    step_scale = jnp.where(steps < end, r.step_scale, 0.0)
    converged = r.converged & jnp.all(jnp.where(mask, truths.converged, True), axis=1)
    converged = jnp.where(keep, converged, converged[end])
    return r._replace(
        converged=converged,
        q=q, tip=tip, clearance=c, between=cb, status=status, iterations=end.astype(r.iterations.dtype),
        step_scale=step_scale,
        reached=status == Status.REACHED, collided=status == Status.COLLIDED,
        min_clearance=jnp.minimum(jnp.min(c, initial=jnp.inf), jnp.min(cb, initial=jnp.inf)),
        final_error=safe_norm(scenario.goal - tip[-1]),
    )


def dense_trajectory_clearance(qs, scenario, substeps: int = 20, arm_samples: int = 200, curve_samples: int = 2000):
    """Brute-force minimum clearance of a trajectory, for checking.

    Interpolates each step linearly in q with ``substeps`` sub-steps, samples
    the arm at ``arm_samples`` points per segment and each curve at
    ``curve_samples`` points, and returns (T, m) minimum clearance per step
    interval and obstacle slot (padding slots: +inf). Slow: for tests and audits.
    """
    from .curves import curve_points

    radius, mask = radius_and_mask(scenario)
    taus = jnp.linspace(0.0, 1.0, substeps + 1)

    def min_dist(arm, pts, mask=None):
        d = jnp.sqrt(jnp.sum((arm[:, None, :] - pts[None, :, :]) ** 2, -1))
        if mask is not None:
            d = jnp.where(mask[None, :], d, jnp.inf)
        return jnp.min(d)

    def at(q):
        arm = backbone_points(q, arm_samples)
        arm = jnp.concatenate([jnp.zeros((1, 3), arm.dtype), arm])
        d = map_obstacles(
            scenario,
            lambda c: min_dist(arm, curve_points(c, curve_samples)),
            lambda p, m: min_dist(arm, p, m),
            empty=jnp.zeros((0,), q.dtype),
        )
        return d - radius - scenario.arm_radius

    def interval(q_a, q_b):
        return jnp.min(jax.vmap(lambda t: at(q_a + t * (q_b - q_a)))(taus), axis=0)

    res = jax.lax.map(lambda ab: interval(ab[0], ab[1]), (qs[:-1], qs[1:]))
    return jnp.where(mask[None, :], res, jnp.inf)
