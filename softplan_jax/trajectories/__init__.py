"""Timed trajectories of the actuators (a layer above planning).

* :mod:`._timing` -- :func:`time_parametrize`: a plan timed along its certified path as
  fast as the actuator limits allow (TOPP-RA), or a tracked run's motion checked
  against them;
* :mod:`._trajectory` -- :class:`Trajectory`, what a controller needs;
* :mod:`._files` -- its CSV and JSON files;
* :mod:`._arm_limits` -- the segment length limits a scene gets from its actuators, and
  how far a plan stretched the arm;
* :mod:`._paths`, :mod:`._certify`, :mod:`._topp` -- the path through the plan's waypoints,
  the proof that its spline is clear, and TOPP-RA on one piece of it.
"""

from ._arm_limits import constrain_scenario, extension
from ._files import TIMED_FORMAT, load_trajectory, save_trajectory
from ._timing import time_parametrize
from ._trajectory import Trajectory

__all__ = ["Trajectory", "time_parametrize", "save_trajectory", "load_trajectory", "TIMED_FORMAT",
           "constrain_scenario", "extension"]
