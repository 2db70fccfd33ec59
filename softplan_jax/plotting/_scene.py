"""The scene of a figure, which every figure shares (NumPy and matplotlib on the host; matplotlib
imported inside the functions): the plan's data (:func:`trajectory_data`), the arm's smooth
backbone, one constant-curvature arc per segment (:func:`arm_backbones`, the paper's section 2),
the obstacles (:func:`scene_obstacles`), the view (:func:`view_box`, :func:`auto_view`,
:func:`setup_axes`) and the drawing (:func:`draw_scene`, :func:`draw_arm`, :func:`draw_shadow`,
:func:`draw_global_part`, :func:`readable_legend`)."""

from __future__ import annotations

import os
import sys

import numpy as np

__all__ = [
    "ARM_SAMPLES", "CURVE_SAMPLES", "OBSTACLE_COLOR", "POINTS_COLOR", "GOAL_COLOR", "PATH_COLOR", "BASE_COLOR",
    "pyplot", "trajectory_data", "arm_backbones", "joint_indices", "scene_obstacles", "view_box", "radius_linewidth",
    "auto_view", "setup_axes", "draw_global_part", "draw_scene", "readable_legend", "snapshot_colors", "draw_shadow",
    "draw_arm",
]

# Arm samples per segment for drawing the smooth backbone.
ARM_SAMPLES = 30
# Samples of an obstacle curve over its u_range.
CURVE_SAMPLES = 600

OBSTACLE_COLOR = "#8c5a2b"  # branch brown
POINTS_COLOR = "#6b4423"
GOAL_COLOR = "#f2b705"
PATH_COLOR = "#444444"
_GLOBAL_COLOR = "#1b9e77"  # the part of the path found by the global search (plan_fallback)
BASE_COLOR = "black"


# ----------------------------------------------------------------------------
# Host-side data.


def pyplot():
    """pyplot, with the Agg backend when there is no display and the user has
    not chosen a backend (scripts on servers, CI)."""
    if "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        headless = sys.platform.startswith("linux") and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        )
        if headless and not os.environ.get("MPLBACKEND"):
            matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def trajectory_data(scenario, result) -> dict:
    """Configurations, tips and outcome of ``result`` as NumPy, trimmed to the
    steps taken."""
    from ..planning import Rollout, result_from_rollout

    if scenario.q0.ndim != 2:
        raise ValueError("plot one scenario at a time (this Scenario is batched)")
    if isinstance(result, Rollout):
        if np.ndim(result.q) != 3:
            raise ValueError("plot one rollout at a time (this Rollout is batched; index it first)")
        result = result_from_rollout(result, scenario)
    for field in ("q", "tip", "iterations", "status"):
        if not hasattr(result, field):
            raise ValueError(
                f"result must be a PlanResult (from plan) or a Rollout; "
                f"{type(result).__name__} has no {field!r}"
            )
    q = np.asarray(result.q, dtype=float)
    n = int(np.shape(scenario.q0)[0])
    if q.ndim != 3 or q.shape[1:] != (n, 3) or q.shape[0] < 1:
        raise ValueError(f"result.q must have shape (steps + 1, {n}, 3) for this scenario; got {q.shape}")
    clearance = getattr(result, "clearance", None)
    return dict(
        q=q,
        tip=np.asarray(result.tip, dtype=float),
        iterations=int(result.iterations),
        status=str(result.status),
        min_clearance=float(getattr(result, "min_clearance", np.nan)),
        collided=bool(getattr(result, "collided", False)),
        clearance=None if clearance is None else np.asarray(clearance, dtype=float),
        planner=str(getattr(result, "planner", "local")),
        global_start=getattr(result, "global_start", None),
    )


def arm_backbones(qs) -> np.ndarray:
    """(T, n * ARM_SAMPLES + 1, 3) smooth backbones, the base (origin) first."""
    from ..geometry._kinematics import backbone_points

    out = []
    for q in qs:
        pts = np.asarray(backbone_points(q, ARM_SAMPLES), dtype=float)
        out.append(np.concatenate([np.zeros((1, 3)), pts]))
    return np.stack(out)


def joint_indices(n_segments: int) -> np.ndarray:
    """Backbone indices of the base and every segment end (the last is the tip)."""
    return np.arange(n_segments + 1) * ARM_SAMPLES


def scene_obstacles(scenario) -> list[dict]:
    """Every real obstacle as a dict(kind "curve" | "points", pts (N, 3), radius)."""
    from ..geometry._obstacles import obstacle_samples

    return obstacle_samples(scenario, CURVE_SAMPLES)


# ----------------------------------------------------------------------------
# The view box and the drawing.


def view_box(core: np.ndarray, obstacles: list[dict]):
    """Axis limits (3, 2) and the obstacles clipped to them.

    The view is the box around the arm, tip path and goal (``core``), grown by
    a margin; obstacle parts outside it are not drawn (a long curve such as
    sim2's Z = 5 u^2 would otherwise shrink the arm to a few pixels), and the
    final limits are the union of the core and the visible obstacle parts.
    """
    lo, hi = core.min(axis=0), core.max(axis=0)
    span = float(np.max(hi - lo))
    margin = max(0.5 * span, 0.3)
    box_lo, box_hi = lo - margin, hi + margin
    clipped = []
    all_lo, all_hi = lo.copy(), hi.copy()
    for ob in obstacles:
        pts = ob["pts"]
        inside = np.all((pts >= box_lo) & (pts <= box_hi), axis=1)
        if ob["kind"] == "curve":
            shown = np.where(inside[:, None], pts, np.nan)  # NaN breaks the line
        else:
            shown = pts[inside]
        if inside.any():
            all_lo = np.minimum(all_lo, pts[inside].min(axis=0))
            all_hi = np.maximum(all_hi, pts[inside].max(axis=0))
        clipped.append(dict(ob, pts=shown, hidden=int((~inside).sum())))
    ranges = all_hi - all_lo
    min_range = 0.35 * float(np.max(ranges)) if np.max(ranges) > 0 else 1.0
    centre = 0.5 * (all_lo + all_hi)
    half = 0.5 * np.maximum(ranges, min_range) * 1.05
    limits = np.stack([centre - half, centre + half], axis=1)
    return limits, clipped


def radius_linewidth(ax, limits, radius: float, floor: float) -> float:
    """Line width in points that shows a tube of ``radius`` (data units), at
    least ``floor``: approximate, the 3D projection has no exact scale."""
    if radius <= 0:
        return floor
    fig = ax.figure
    width_pts = fig.get_figwidth() * 72.0 * ax.get_position().width
    span = float(np.max(limits[:, 1] - limits[:, 0]))
    # An axis of the box spans roughly 70 % of the axes width at the default view.
    return max(floor, 2.0 * radius / span * 0.7 * width_pts)


def auto_view(scenario, view):
    """(elevation, azimuth): given, or looking across the goal's direction
    from the base so that the arm's sideways motion lies in the picture plane."""
    if view is not None:
        if len(view) != 2:
            raise ValueError(f"view must be (elevation, azimuth) in degrees, got {view!r}")
        return float(view[0]), float(view[1])
    g = np.asarray(scenario.goal, dtype=float)
    if np.hypot(g[0], g[1]) < 1e-9:
        return 22.0, -60.0
    return 22.0, float(np.degrees(np.arctan2(g[1], g[0]))) - 90.0


def setup_axes(ax, limits, view):
    """Limits (3, 2), equal scale on the three axes, labels, camera ``view`` (elevation, azimuth) and light panes."""
    from matplotlib.ticker import MaxNLocator

    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_zlim(*limits[2])
    ax.set_box_aspect(tuple(limits[:, 1] - limits[:, 0]))
    ax.set_xlabel("X")
    ax.set_ylabel("Y")
    ax.set_zlabel("Z")
    ax.view_init(elev=view[0], azim=view[1])
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.pane.set_alpha(0.25)
    ax.tick_params(labelsize=8, pad=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))


def draw_global_part(ax, traj):
    """Over the tip path: its part planned by the global search (plan_fallback), in its own colour."""
    if traj["planner"] != "global" or traj["global_start"] is None:
        return
    tip = traj["tip"][int(traj["global_start"]):]
    ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], lw=1.6, color=_GLOBAL_COLOR, label="tip path (global search)")


def draw_scene(ax, scenario, limits, obstacles, tip_path=None):
    """Obstacles, goal and the base; returns the artists of the tip path."""
    curve_labelled = points_labelled = False
    for ob in obstacles:
        pts = ob["pts"]
        if ob["kind"] == "curve":
            lw = radius_linewidth(ax, limits, ob["radius"], floor=2.5)
            label = None if curve_labelled else "obstacle curve"
            ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=OBSTACLE_COLOR, lw=lw, alpha=0.9,
                    solid_capstyle="round", label=label)
            draw_shadow(ax, pts, limits, lw=1.5)
            curve_labelled = True
        elif len(pts):
            size = radius_linewidth(ax, limits, ob["radius"], floor=4.0) ** 2
            label = None if points_labelled else "obstacle points"
            ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=size, color=POINTS_COLOR, alpha=0.8,
                       depthshade=False, label=label)
            points_labelled = True
    goal = np.asarray(scenario.goal, dtype=float)
    # A drop line from the floor to the goal locates it in depth.
    ax.plot([goal[0]] * 2, [goal[1]] * 2, [limits[2, 0], goal[2]], ls=":", lw=1.0, color=PATH_COLOR,
            alpha=0.7)
    ax.scatter(goal[0], goal[1], limits[2, 0], marker="*", s=60, color="0.55", alpha=0.5, depthshade=False)
    ax.scatter(*goal, marker="*", s=320, color=GOAL_COLOR, edgecolors="black", linewidths=0.8,
               depthshade=False, label="goal", zorder=10)
    ax.scatter(0, 0, 0, marker="s", s=40, color=BASE_COLOR, depthshade=False, label="base")
    if tip_path is not None:
        (line,) = ax.plot(tip_path[:, 0], tip_path[:, 1], tip_path[:, 2], ls="--", lw=1.0,
                          color=PATH_COLOR, label="tip path")
        return line
    return None


def readable_legend(target, **kw):
    """A legend whose handles keep a readable size (tube-width lines and
    radius-sized markers are shrunk in the legend only)."""
    from matplotlib.collections import PathCollection
    from matplotlib.lines import Line2D

    leg = target.legend(**kw)
    for h in getattr(leg, "legend_handles", getattr(leg, "legendHandles", [])):
        if isinstance(h, Line2D):
            h.set_linewidth(min(h.get_linewidth(), 4.0))
        elif isinstance(h, PathCollection):
            h.set_sizes(np.minimum(h.get_sizes(), 200.0))
    return leg


def snapshot_colors(k: int):
    """Light (early) to dark (late) blues."""
    from matplotlib import colormaps

    cmap = colormaps["Blues"]
    if k == 1:
        return [cmap(0.95)]
    return [cmap(v) for v in np.linspace(0.4, 0.95, k)]


def draw_shadow(ax, pts, limits, **kw):
    """Faint projection of a polyline onto the floor of the box (a depth cue)."""
    z = np.full(len(pts), limits[2, 0])
    ax.plot(pts[:, 0], pts[:, 1], z, color="0.55", alpha=0.35, zorder=1, **kw)


def draw_arm(ax, backbone, n_segments, color, lw, label):
    """The arm's backbone (n * ARM_SAMPLES + 1, 3) as a line of width ``lw``, with a marker at the base and at
    every segment end."""
    joints = backbone[joint_indices(n_segments)]
    ax.plot(backbone[:, 0], backbone[:, 1], backbone[:, 2], color=color, lw=lw, label=label,
            solid_capstyle="round", zorder=5)
    ax.plot(joints[:, 0], joints[:, 1], joints[:, 2], ls="none", marker="o", ms=5, color=color,
            markeredgecolor="white", markeredgewidth=0.8, zorder=6)
