"""Closest points between the arm and point obstacles: the N-point method of paper §3
(:func:`closest_point_to_points`: the arm sampled at 10 points per segment, paper Table 1, against
the points, brute force like MATLAB's ``dsearchn``); the exact distance from points to the arm
backbone (:func:`point_distance`, :func:`point_set_closest`: the boundary problem of paper eqs.
(15)-(16) with a fixed obstacle point, in closed form per segment, differentiable in q like the
curve solver); and :class:`FixedPoint`, a point as a degenerate curve."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import safe_norm
from ..base._validation import check_configuration, check_points
from ._closest import ClosestPoint
from ._closest_newton import Segment, pair_terms, project_to_arc
from ._kinematics import backbone_points, segment_frames

__all__ = [
    "points_closest",
    "closest_point_to_points",
    "FixedPoint",
    "point_set_closest",
    "point_distance",
]


def points_closest(q, points, mask=None, points_per_segment: int = 10) -> ClosestPoint:
    """The N-point method (paper §3): the traceable core of
    :func:`closest_point_to_points`, without input validation.

    Args:
      q: (n, 3) configuration.
      points: (N, 3) obstacle points.
      mask: (N,) bool, False for padding points; None: all points.
      points_per_segment: arm samples per segment (static).

    Returns:
      ClosestPoint (``segment`` int32, ``u`` the point's index as q's dtype).
    """
    k = points_per_segment
    arm = backbone_points(q, k)  # (n k, 3)
    diff = arm[:, None, :] - points[None, :, :]
    d2 = jnp.sum(diff * diff, axis=-1)
    if mask is not None:
        d2 = jnp.where(mask[None, :], d2, jnp.inf)
    flat = jnp.argmin(d2)
    a, p = flat // points.shape[0], flat % points.shape[0]
    segment = a // k
    s = ((a % k) + 1).astype(q.dtype) / k
    return ClosestPoint(
        distance=safe_norm(arm[a] - points[p]),
        segment=segment.astype(jnp.int32),
        s=s,
        u=p.astype(q.dtype),
        arm_point=arm[a],
        obstacle_point=points[p],
        converged=jnp.asarray(True),
    )


_closest_point_to_points_jit = package_jit(points_closest, None, static_argnums=3)


def closest_point_to_points(q, points, points_per_segment: int = 10) -> ClosestPoint:
    """The N-point method: nearest pair between arm samples and obstacle points.

    The arm is sampled at ``points_per_segment`` points per segment, s = j/k,
    j = 1..k (paper Table 1: 10), and compared by brute force with every
    obstacle point (the analogue of MATLAB's ``dsearchn`` in paper §3).

    Args:
      q: (n, 3) configuration.
      points: (N, 3) obstacle points, N >= 1.

    Returns:
      :class:`ClosestPoint`; ``u`` is the index of the nearest obstacle point
      (as a float of q's dtype) and ``s`` the fraction of the nearest arm sample.
    """
    q = check_configuration(q)
    points = check_points(points).astype(q.dtype)
    if int(points_per_segment) < 1:
        raise ValueError(f"points_per_segment must be >= 1, got {points_per_segment}")
    return _closest_point_to_points_jit(q, points, None, int(points_per_segment))


class FixedPoint(NamedTuple):
    """A point ``p`` (3,) as a degenerate curve (u unused, derivatives zero):
    lets a curve routine handle the point-to-arm problem of a point set."""

    p: jax.Array

    @property
    def u_range(self):
        return jnp.array([0.0, 1.0], self.p.dtype)

    def point(self, u):
        return self.p

    def derivative(self, u):
        return jnp.zeros_like(self.p)

    second_derivative = derivative


def _point_closest(q, p) -> ClosestPoint:
    """Exact closest point of the arm backbone to one point p (3,): the
    boundary problem of paper eqs. (15)-(16) with a fixed obstacle point,
    solved per segment in closed form (:func:`project_to_arc`).
    Returns a ClosestPoint with u = 0."""
    segs = Segment.from_frame(q, *segment_frames(q))
    segs_ng = jax.tree_util.tree_map(jax.lax.stop_gradient, segs)
    p_ng = jax.lax.stop_gradient(p)
    dtype = q.dtype

    def per_segment(seg):
        return project_to_arc(seg, p_ng)

    s_all, d2_all = jax.vmap(per_segment)(segs_ng)
    i = jnp.argmin(d2_all)
    seg = jax.tree_util.tree_map(lambda x: x[i], segs)
    s = jax.lax.stop_gradient(s_all[i])
    # Implicit derivative of s* over a free s (as closest.py's curves), envelope theorem for the distance.
    t = pair_terms(seg, FixedPoint(p), s, jnp.zeros((), dtype))
    h = jnp.where(t.a > 0, t.a, jnp.abs(t.a) + jnp.finfo(dtype).eps)
    ds = jnp.where((s > 0) & (s < 1), t.gs / h, 0.0)
    s_diff = s - (ds - jax.lax.stop_gradient(ds))
    arm_point = seg.point(s_diff)
    distance = safe_norm(seg.point(s) - p)
    return ClosestPoint(distance, i.astype(jnp.int32), s_diff, jnp.zeros((), dtype), arm_point, p, jnp.asarray(True))


def point_set_closest(q, points, mask) -> ClosestPoint:
    """Exact closest pair between the arm backbone and a masked point set
    (the boundary problem of paper eqs. 15-16 with fixed obstacle points).

    Args:
      q: (n, 3) configuration.
      points: (N, 3).
      mask: (N,) bool, False for padding points.

    Returns:
      ClosestPoint (``u`` the nearest point's index as q's dtype).
    """
    cps = jax.vmap(lambda p: _point_closest(q, p))(points)
    k = jnp.argmin(jnp.where(mask, cps.distance, jnp.inf))
    cp = jax.tree_util.tree_map(lambda x: x[k], cps)
    return cp._replace(u=k.astype(q.dtype))


def point_distance(q, points):
    """Exact distance from each obstacle point to the arm backbone.

    Args:
      q: (n, 3) configuration.
      points: (N, 3).

    Returns:
      (N,) distances (the true clearance of a point obstacle before radii).
    """
    q = check_configuration(q)
    points = check_points(points).astype(q.dtype)
    return _point_distances(q, points)


def _point_distances_fn(q, points):
    return jax.vmap(lambda p: _point_closest(q, p).distance)(points)


_point_distances = package_jit(_point_distances_fn, None)
