"""True clearance and collisions.

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

:func:`dense_trajectory_clearance` is the slow, brute-force check of a whole
trajectory (dense interpolation in q, dense sampling of arm and curve); the
tests use it as an independent reference.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .closest import (
    ClosestPoint,
    SolverOptions,
    _closest_point_curve,
    _FixedPoint,
    _point_set_closest,
)
from .kinematics import backbone_points, segment_point
from .numerics import get_epsilon, safe_norm

__all__ = ["true_closest", "between_steps", "dense_trajectory_clearance"]


def true_closest(q, scenario, solver: SolverOptions) -> ClosestPoint:
    """Exact closest pairs to every obstacle slot of a scenario.

    Order: the polynomial curves (m_c), the point sets (m_p), the parametric
    curves. Returns a ClosestPoint whose fields have a leading axis m.
    Padding slots are solved too (their values are meaningless; mask them).
    """
    parts = []
    if scenario.curves.coeffs.shape[0]:
        parts.append(jax.vmap(lambda c: _closest_point_curve(q, c, solver))(scenario.curves))
    if scenario.points.shape[0]:
        parts.append(
            jax.vmap(lambda p, m: _point_set_closest(q, p, m, solver))(scenario.points, scenario.point_mask)
        )
    for pc in scenario.parametric:
        cp = _closest_point_curve(q, pc, solver)
        parts.append(jax.tree_util.tree_map(lambda x: x[None], cp))
    if not parts:
        return empty_closest(q.dtype)
    parts = [p._replace(segment=p.segment.astype(jnp.int32), u=p.u.astype(q.dtype)) for p in parts]
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)


def empty_closest(dtype) -> ClosestPoint:
    """A ClosestPoint with zero obstacles (a scene without obstacles)."""
    z = jnp.zeros((0,), dtype)
    return ClosestPoint(z, jnp.zeros((0,), jnp.int32), z, z, jnp.zeros((0, 3), dtype), jnp.zeros((0, 3), dtype),
                        jnp.zeros((0,), bool))


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
        step = -jnp.linalg.solve(H, J.T @ r)
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
    each end. ``radius_sum`` (m,) = arm radius + obstacle radius.
    """
    q_a, q_b = jax.lax.stop_gradient(q_a), jax.lax.stop_gradient(q_b)
    truth_a, truth_b = jax.lax.stop_gradient(truth_a), jax.lax.stop_gradient(truth_b)
    dq = q_b - q_a
    dtype = q_a.dtype
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)
    m_c = scenario.curves.coeffs.shape[0]
    m_p = scenario.points.shape[0]

    ends = jnp.stack([zero, one])

    def from_both_ends(curve_a, curve_b, ta, tb):
        # Stacked starts (tau, s, u) at tau = 0 and tau = 1, each on its own segment.
        seg = jnp.stack([ta.segment, tb.segment])
        x0 = jnp.stack([ends, jnp.stack([ta.s, tb.s]), jnp.stack([ta.u, tb.u])], axis=-1)
        curves = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), curve_a, curve_b)
        d = jax.vmap(lambda i, x, c: _motion_pair_distance(q_a, dq, i, x, c, iterations))(seg, x0, curves)
        return jnp.min(d)

    def pick(truth, a, b):
        return jax.tree_util.tree_map(lambda x: x[a:b], truth)

    parts = [jnp.zeros((0,), dtype)]
    if m_c:
        ta, tb = pick(truth_a, 0, m_c), pick(truth_b, 0, m_c)
        parts.append(jax.vmap(lambda c, a, b: from_both_ends(c, c, a, b))(scenario.curves, ta, tb))
    if m_p:
        ta, tb = pick(truth_a, m_c, m_c + m_p), pick(truth_b, m_c, m_c + m_p)
        parts.append(
            jax.vmap(
                lambda a, b: from_both_ends(
                    _FixedPoint(a.obstacle_point), _FixedPoint(b.obstacle_point),
                    a._replace(u=jnp.zeros_like(a.u)), b._replace(u=jnp.zeros_like(b.u))
                )
            )(ta, tb)
        )
    for k, pc in enumerate(scenario.parametric):
        j = m_c + m_p + k
        at_j = lambda t, j=j: jax.tree_util.tree_map(lambda x: x[j], t)  # noqa: E731
        parts.append(from_both_ends(pc, pc, at_j(truth_a), at_j(truth_b))[None])
    found = jnp.concatenate(parts)
    D_min = jnp.minimum(found, jnp.minimum(truth_a.distance, truth_b.distance))
    return D_min - radius_sum


def dense_trajectory_clearance(qs, scenario, substeps: int = 20, arm_samples: int = 200, curve_samples: int = 2000):
    """Brute-force minimum clearance of a trajectory, for checking.

    Interpolates each step linearly in q with ``substeps`` sub-steps, samples
    the arm at ``arm_samples`` points per segment and each curve at
    ``curve_samples`` points, and returns (T, m) minimum clearance per step
    interval and obstacle slot (padding slots: +inf). Slow: for tests and audits.
    """
    from .curves import curve_points

    radius_c = scenario.curves.radius
    taus = jnp.linspace(0.0, 1.0, substeps + 1)
    curve_pts = jax.vmap(lambda c: curve_points(c, curve_samples))(scenario.curves)  # (m_c, S, 3)
    par_pts = [curve_points(pc, curve_samples) for pc in scenario.parametric]

    def min_dist(arm, pts, mask=None):
        d = jnp.sqrt(jnp.sum((arm[:, None, :] - pts[None, :, :]) ** 2, -1))
        if mask is not None:
            d = jnp.where(mask[None, :], d, jnp.inf)
        return jnp.min(d)

    def at(q):
        arm = backbone_points(q, arm_samples)
        arm = jnp.concatenate([jnp.zeros((1, 3), arm.dtype), arm])
        dc = jax.vmap(lambda p: min_dist(arm, p))(curve_pts) - radius_c
        dp = jax.vmap(lambda p, m: min_dist(arm, p, m))(scenario.points, scenario.point_mask) - scenario.point_radius
        dpar = [min_dist(arm, p) - pc.radius for p, pc in zip(par_pts, scenario.parametric, strict=True)]
        out = jnp.concatenate([dc, dp, jnp.stack(dpar) if dpar else jnp.zeros((0,), dc.dtype)])
        return out - scenario.arm_radius

    def interval(q_a, q_b):
        return jnp.min(jax.vmap(lambda t: at(q_a + t * (q_b - q_a)))(taus), axis=0)

    res = jax.lax.map(lambda ab: interval(ab[0], ab[1]), (qs[:-1], qs[1:]))
    mask = jnp.concatenate(
        [scenario.curve_mask, jnp.any(scenario.point_mask, -1), jnp.ones((len(scenario.parametric),), bool)]
    )
    return jnp.where(mask[None, :], res, jnp.inf)
