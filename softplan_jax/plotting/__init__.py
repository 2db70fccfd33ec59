"""Figures and animations of plans and tracked runs (matplotlib, host side; imported on its own,
``import softplan_jax.plotting``, since the planner does not need matplotlib): :mod:`._snapshots`
(the arm at a few iterations, the paper's Figs. 3-5, with a top view and the clearance),
:mod:`._tracking` (a run among moving obstacles), :mod:`._animation` (GIFs of both),
:mod:`._clouds` (a point cloud with its fitted curves), :mod:`._benchmark` (collision rate against
cost per step), :mod:`._actuators` (a timed trajectory's actuator lengths, speeds and
accelerations against time, with their limits) and :mod:`._scene` (what they share)."""

from ._actuators import plot_actuators
from ._animation import animate, animate_tracking
from ._benchmark import plot_benchmark
from ._clouds import plot_cloud_fit
from ._snapshots import plot_clearance, plot_snapshot_panels, plot_snapshots, plot_snapshots_with_clearance
from ._tracking import plot_tracking

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
