"""The timed trajectory: :class:`Trajectory`, what a controller needs (time, the
actuators' lengths and speeds, q and the tip), with the plan's status, the
actuator layout and limits, and the check of every sample against them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..actuators._layout import ActuatorLayout
from ..actuators._limits import ActuatorLimits, LimitReport

__all__ = ["Trajectory", "PATH_KINDS"]

# How the trajectory was made: the spline through the waypoints (proven clear), the plan's straight
# motions with a stop at every waypoint, a mix of both, or a tracked run's own time stamps.
PATH_KINDS = ("smooth", "linear", "mixed", "tracked")


class Trajectory(NamedTuple):
    """A timed trajectory of the arm's actuators (host-side NumPy).

    Attributes:
      t: (T,) time [s], from 0, increasing.
      q: (T, n, 3) configuration at each sample.
      lengths: (T, n, k) actuator lengths [m] (``softplan_jax.actuators.actuator_lengths``).
      speeds: (T, n, k) their rates [m/s] (planned: exact, ``dl/ds * ds/dt``; tracked: central
        differences of the samples).
      tip: (T, 3) tip position.
      layout: the ActuatorLayout.
      limits: the ActuatorLimits.
      status: the plan's (or tracked run's) status, e.g. "reached".
      path: one of ``PATH_KINDS``.
      duration: ``t[-1]`` [s].
      stops: (S,) times where the arm comes to rest between the start and the end.
      waypoints: (K+1, n, 3) the plan's configurations the path runs through.
      waypoint_times: (K+1,) when the trajectory passes each waypoint.
      linear_spans: (J,) indices k of the spans ``waypoints[k] -> waypoints[k+1]`` timed along the
        plan's straight motion (all of them for "linear"; none for "smooth").
      report: the LimitReport of the samples (speeds and accelerations by divided differences).
      max_tip_speed: the tip speed limit [m/s] (None: none).
    """

    t: np.ndarray
    q: np.ndarray
    lengths: np.ndarray
    speeds: np.ndarray
    tip: np.ndarray
    layout: ActuatorLayout
    limits: ActuatorLimits
    status: str
    path: str
    duration: float
    stops: np.ndarray
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    linear_spans: np.ndarray
    report: LimitReport
    max_tip_speed: float | None = None
