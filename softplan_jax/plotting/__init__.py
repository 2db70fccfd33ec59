"""Figures and animations of plans and tracked runs (matplotlib, host side).

Imported on its own (``import softplan_jax.plotting``): the planner does not need matplotlib.

* :mod:`.snapshots` — the arm at a few iterations (the paper's Figs. 3-5), side by side, with a top view and
  the clearance per obstacle.
* :mod:`.tracking` — a tracking run among moving obstacles.
* :mod:`.animation` — animated GIFs of a plan and of a tracking run.
* :mod:`.clouds` — a point cloud with the curves fitted to it.
* :mod:`.benchmark` — collision rate against cost per step.
* :mod:`.actuators` — a timed trajectory's actuator lengths, speeds and accelerations against time, with
  their limits.
* :mod:`.scene` — what they share: the plan's data on the host, the view box, the scene and the arm.
"""

from .actuators import plot_actuators
from .animation import animate, animate_tracking
from .benchmark import plot_benchmark
from .clouds import plot_cloud_fit
from .snapshots import plot_clearance, plot_snapshot_panels, plot_snapshots, plot_snapshots_with_clearance
from .tracking import plot_tracking

__all__ = [
    "plot_snapshots",
    "plot_snapshot_panels",
    "plot_snapshots_with_clearance",
    "plot_clearance",
    "plot_tracking",
    "animate",
    "animate_tracking",
    "plot_cloud_fit",
    "plot_benchmark",
    "plot_actuators",
]
