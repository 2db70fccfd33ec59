"""The loaded arm: each segment a Kirchhoff rod under its weight and a tip load (gravity along
-z), beside the PCC kinematics in the geometry layer; its shape handed to the closest-point
kernel as short constant-curvature pieces with a proven gap, and a bound on how far it moves
along a straight motion in q.

* :mod:`._model` -- :class:`RodModel`, the material and the loads;
* :mod:`._equilibrium` -- the static equilibrium (shooting, implicit derivatives), the backbone;
* :mod:`._pieces` -- the shape as constant-curvature pieces for the closest-point kernel, the gap;
* :mod:`._motion` -- how far the loaded arm moves along a straight motion in q;
* :mod:`._arm` -- :class:`LoadedArm`, the loaded arm as the planner's arm model;
* :mod:`._lie` -- the SO(3) and SE(3) exponentials of the integrator.
"""

from ._arm import DEFAULT_PIECES, LoadedArm
from ._equilibrium import (
    LoadedShape,
    intrinsic_curvature,
    loaded_backbone,
    loaded_points,
    loaded_points_jacobian,
    solve_equilibrium,
)
from ._model import RodModel
from ._motion import load_number, loaded_motion_bound
from ._pieces import loaded_pieces, piece_location, pieces_from_shape

__all__ = [
    "RodModel",
    "LoadedArm",
    "DEFAULT_PIECES",
    "LoadedShape",
    "solve_equilibrium",
    "loaded_backbone",
    "loaded_points",
    "loaded_points_jacobian",
    "intrinsic_curvature",
    "loaded_pieces",
    "pieces_from_shape",
    "piece_location",
    "loaded_motion_bound",
    "load_number",
]
