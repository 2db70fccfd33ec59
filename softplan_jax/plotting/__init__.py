"""Figures and animations of plans and tracked runs (matplotlib, host side).

Imported on its own (``import softplan_jax.plotting``): the planner does not need matplotlib.
"""

from .figures import (
    animate,
    animate_tracking,
    plot_benchmark,
    plot_clearance,
    plot_cloud_fit,
    plot_snapshot_panels,
    plot_snapshots,
    plot_snapshots_with_clearance,
    plot_tracking,
)

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
]
