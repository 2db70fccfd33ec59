"""Geometry of the arm and the obstacles: no planning here.

* :mod:`.kinematics` -- piecewise-constant-curvature forward kinematics
  (paper section 2.1), Jacobians by ``jax.jacfwd``, the motion bound;
* :mod:`.curves` -- curve-like obstacles F_o(u) (paper eq. 10);
* :mod:`.closest` -- the exact closest point between an arm segment and a
  curve (paper section 2.3): the entry points, the result type, the solver
  options and the derivatives with respect to q;
* :mod:`.closest_newton` -- its Newton kernel (the terms of eqs. 13-18, the
  trust region) and the default solver: the minimum over the arc in closed
  form, multi-start Newton in the curve parameter;
* :mod:`.closest_grid` -- the grid-seeded variant of that solver;
* :mod:`.warm_start` -- the certified warm start of the solver along a path;
* :mod:`.obstacles` -- every obstacle of a scene at once (curves, point sets,
  parametric curves);
* :mod:`.point_sets` -- closest points between the arm and point obstacles
  (the N-point method, exact point-to-arm distances);
* :mod:`.clearance` -- clearance during a motion (the swept proof and the
  between-step search) and the collision checks of a trajectory.
"""

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
