"""Figures and animations of plans and tracked runs (matplotlib, host side; imported on its own,
``import softplan_jax.plotting``, since the planner does not need matplotlib): :mod:`.snapshots`
(the arm at a few iterations, the paper's Figs. 3-5, with a top view and the clearance),
:mod:`.tracking` (a run among moving obstacles), :mod:`.animation` (GIFs of both),
:mod:`.clouds` (a point cloud with its fitted curves), :mod:`.benchmark` (collision rate against
cost per step), :mod:`.actuators` (a timed trajectory's actuator lengths, speeds and
accelerations against time, with their limits) and :mod:`.scene` (what they share)."""

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
