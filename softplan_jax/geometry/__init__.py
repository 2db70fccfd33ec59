"""Geometry of the arm and the obstacles, no planning: PCC kinematics, Jacobians and the motion
bound (paper §2.1-2.2, :mod:`._kinematics`) and the arm model the engine sees (:mod:`._arm`);
curve-like obstacles (eq. 10, :mod:`._curves`); the exact closest point between an arm segment and
a curve (§2.3: the entry points and derivatives :mod:`._closest`, its Newton kernel and default
solver :mod:`._closest_newton`, the paper's grid-seeded solver :mod:`._closest_grid`, the certified
warm start along a path :mod:`._warm_start`, the engine's providers :mod:`._closest_pairs`); every
obstacle of a scene at once (:mod:`._obstacles`); point obstacles (the N-point method and exact
point-to-arm distances, :mod:`._point_sets`; point-to-curve distances on the host,
:mod:`._point_curve`); and the clearance during a motion with the collision checks of a trajectory
(:mod:`._clearance`)."""

from ._clearance import dense_trajectory_clearance
from ._closest import ClosestPoint, SolverOptions, closest_point
from ._closest_grid import GridSolverOptions
from ._curves import ParametricCurve, PolynomialCurve, curve_points, line_segment, stack_curves
from ._kinematics import (
    backbone_points,
    motion_bound,
    point_jacobian,
    segment_frames,
    segment_point,
    segment_transform,
    tip_jacobian,
    tip_position,
)
from ._obstacles import true_closest
from ._point_sets import closest_point_to_points, point_distance

__all__ = [
    "segment_transform",
    "segment_frames",
    "segment_point",
    "tip_position",
    "point_jacobian",
    "tip_jacobian",
    "backbone_points",
    "motion_bound",
    "PolynomialCurve",
    "ParametricCurve",
    "line_segment",
    "stack_curves",
    "curve_points",
    "ClosestPoint",
    "SolverOptions",
    "GridSolverOptions",
    "closest_point",
    "closest_point_to_points",
    "point_distance",
    "true_closest",
    "dense_trajectory_clearance",
]
