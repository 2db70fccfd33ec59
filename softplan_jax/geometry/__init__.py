"""Geometry of the arm and the obstacles, no planning: PCC kinematics, Jacobians and the motion
bound (paper §2.1-2.2, :mod:`.kinematics`) and the arm model the engine sees (:mod:`.arm`);
curve-like obstacles (eq. 10, :mod:`.curves`); the exact closest point between an arm segment and
a curve (§2.3: the entry points and derivatives :mod:`.closest`, its Newton kernel and default
solver :mod:`.closest_newton`, the paper's grid-seeded solver :mod:`.closest_grid`, the certified
warm start along a path :mod:`.warm_start`, the engine's providers :mod:`.closest_pairs`); every
obstacle of a scene at once (:mod:`.obstacles`); point obstacles (the N-point method and exact
point-to-arm distances, :mod:`.point_sets`; point-to-curve distances on the host,
:mod:`.point_curve`); and the clearance during a motion with the collision checks of a trajectory
(:mod:`.clearance`)."""

from .clearance import dense_trajectory_clearance
from .closest import ClosestPoint, SolverOptions, closest_point
from .closest_grid import GridSolverOptions
from .curves import ParametricCurve, PolynomialCurve, curve_points, line_segment, stack_curves
from .kinematics import (
    backbone_points,
    motion_bound,
    point_jacobian,
    segment_frames,
    segment_point,
    segment_transform,
    tip_jacobian,
    tip_position,
)
from .obstacles import true_closest
from .point_sets import closest_point_to_points, point_distance

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
