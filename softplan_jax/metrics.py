"""True clearance and collisions.

The TRUE clearance to an obstacle is the distance from the arm backbone to the
real obstacle (the curve itself, or the point set), minus the arm radius,
minus the obstacle radius — whatever model the planner used. A collision is a
clearance <= 0 anywhere along the motion, including between two planner steps
(DESIGN.md).

Between two steps the configuration moves along the straight line from q_a to
q_b (the planner's Euler step). :func:`between_steps` estimates the minimum
distance during that motion from the exact closest pairs at both ends:

* a collision during the motion needs ``D_a + D_b <= delta + 2 R``, where
  ``delta`` bounds how far any arm point travels (the backbone's displacement,
  measured through the midpoint configuration) and R is the radius sum; if
  that fails the motion is certainly clear and the estimate is min(D_a, D_b);
* otherwise the closest-pair vector ``V = obstacle point - arm point`` is
  interpolated linearly, ``V(t) = V_a + t (V_b - V_a)``, and its minimum norm
  over t in [0, 1] is the estimate. A pass of the arm through a curve flips V,
  so the interpolated V passes near zero and the collision is reported even
  though both sampled configurations are clear.

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
    _point_set_closest,
)
from .kinematics import _backbone_points
from .numerics import safe_norm

__all__ = ["true_closest", "between_steps", "dense_trajectory_clearance"]


def true_closest(q, scenario, solver: SolverOptions) -> ClosestPoint:
    """Exact closest pairs to every obstacle slot of a scenario.

    Order: the polynomial curves (m_c), the point sets (m_p), the parametric
    curves. Returns a ClosestPoint whose fields have a leading axis m.
    Padding slots are solved too (their values are meaningless; mask them).
    """
    curves = jax.vmap(lambda c: _closest_point_curve(q, c, solver))(scenario.curves)
    points = jax.vmap(lambda p, m: _point_set_closest(q, p, m, solver))(scenario.points, scenario.point_mask)
    points = points._replace(segment=points.segment.astype(curves.segment.dtype))
    parts = [curves, points]
    for pc in scenario.parametric:
        cp = _closest_point_curve(q, pc, solver)
        parts.append(jax.tree_util.tree_map(lambda x: x[None], cp))
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)


def _displacement_bound(q_a, q_b, points_per_segment: int = 10):
    """Largest path length of an arm sample over the motion q_a -> q_b (two chords)."""
    q_m = 0.5 * (q_a + q_b)
    p_a = _backbone_points(q_a, points_per_segment)
    p_m = _backbone_points(q_m, points_per_segment)
    p_b = _backbone_points(q_b, points_per_segment)
    return jnp.max(safe_norm(p_m - p_a) + safe_norm(p_b - p_m))


def between_steps(q_a, q_b, truth_a: ClosestPoint, truth_b: ClosestPoint, radius_sum):
    """Estimated minimum clearance (m,) during the motion from q_a to q_b (see
    the module docstring). ``radius_sum`` (m,) = arm radius + obstacle radius."""
    # 10 % margin: the two-chord length slightly underestimates the path length.
    delta = 1.1 * _displacement_bound(q_a, q_b)
    V_a = truth_a.obstacle_point - truth_a.arm_point
    V_b = truth_b.obstacle_point - truth_b.arm_point
    D_a, D_b = truth_a.distance, truth_b.distance
    W = V_b - V_a
    t = jnp.clip(-jnp.sum(V_a * W, -1) / jnp.maximum(jnp.sum(W * W, -1), jnp.finfo(W.dtype).tiny), 0.0, 1.0)
    D_lin = safe_norm(V_a + t[:, None] * W)
    possible = D_a + D_b <= delta + 2.0 * radius_sum
    D_min = jnp.where(possible, jnp.minimum(D_lin, jnp.minimum(D_a, D_b)), jnp.minimum(D_a, D_b))
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
        arm = _backbone_points(q, arm_samples)
        arm = jnp.concatenate([jnp.zeros((1, 3), arm.dtype), arm])
        dc = jax.vmap(lambda p: min_dist(arm, p))(curve_pts) - radius_c
        dp = jax.vmap(lambda p, m: min_dist(arm, p, m))(scenario.points, scenario.point_mask) - scenario.point_radius
        dpar = [min_dist(arm, p) - pc.radius for p, pc in zip(par_pts, scenario.parametric)]
        out = jnp.concatenate([dc, dp, jnp.stack(dpar) if dpar else jnp.zeros((0,), dc.dtype)])
        return out - scenario.arm_radius

    def interval(q_a, q_b):
        return jnp.min(jax.vmap(lambda t: at(q_a + t * (q_b - q_a)))(taus), axis=0)

    res = jax.lax.map(lambda ab: interval(ab[0], ab[1]), (qs[:-1], qs[1:]))
    mask = jnp.concatenate(
        [scenario.curve_mask, jnp.any(scenario.point_mask, -1), jnp.ones((len(scenario.parametric),), bool)]
    )
    return jnp.where(mask[None, :], res, jnp.inf)
