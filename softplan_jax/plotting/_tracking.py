"""A tracking run among moving obstacles in one figure (matplotlib, host side):
:func:`plot_tracking` draws a :class:`~softplan_jax.planning.TrackResult` (the arm with the
obstacles where they were at a few times, the goal's path and the tip path, beside the distance
to the goal and the smallest clearance over time); :func:`tracking_data` and
:func:`obstacles_at` read the run for it and for the animation."""

from __future__ import annotations

import numpy as np

from ._scene import (
    BASE_COLOR,
    GOAL_COLOR,
    OBSTACLE_COLOR,
    PATH_COLOR,
    POINTS_COLOR,
    arm_backbones,
    auto_view,
    draw_arm,
    pyplot,
    radius_linewidth,
    readable_legend,
    scene_obstacles,
    setup_axes,
    snapshot_colors,
    view_box,
)

__all__ = ["plot_tracking", "tracking_data", "obstacles_at"]


def tracking_data(result):
    """The run's MovingScenario, after checking that ``result`` is a TrackResult (ValueError if not)."""
    for field in ("moving", "time", "goal", "error", "q", "tip"):
        if not hasattr(result, field):
            raise ValueError(f"result must be a TrackResult (from softplan_jax.track); "
                             f"{type(result).__name__} has no {field!r}")
    return result.moving


def obstacles_at(moving, t) -> list[dict]:
    """Every obstacle of the moving scene where it is at time ``t``, as :func:`scene_obstacles` samples them."""
    from ..scenarios._motion import scenario_at

    return scene_obstacles(scenario_at(moving, float(t)))


def _tracking_title(result) -> str:
    held = f", held {result.held_time:.1f} s" if result.reached else ""
    return (f"{result.status} — {result.iterations} steps ({result.time[-1]:.1f} s){held}, "
            f"min clearance {result.min_clearance:.3f}")


def plot_tracking(result, snapshots: int = 3, title=None, view=None, figsize=(14, 5.5)):
    """A tracking run among moving obstacles (:func:`softplan_jax.track`): left,
    the arm and the obstacles at ``snapshots`` times in one 3D view (earlier
    times fainter), the goal's path and the tip path; right, the tip's distance
    to the goal and the smallest clearance over time.

    Returns:
      The matplotlib Figure.
    """
    moving = tracking_data(result)
    if int(snapshots) < 1:
        raise ValueError(f"snapshots must be >= 1, got {snapshots}")
    T = int(result.iterations)
    steps = np.unique(np.round(np.linspace(0, T, int(snapshots))).astype(int))
    n = result.q.shape[1]
    backbones = arm_backbones(result.q[steps])
    core = np.concatenate([backbones.reshape(-1, 3), result.tip, result.goal])
    limits, _ = view_box(core, obstacles_at(moving, result.time[0]))
    plt = pyplot()
    fig = plt.figure(figsize=figsize)
    ax = fig.add_axes((0.0, 0.08, 0.5, 0.8), projection="3d")
    scene = moving.scene._replace(goal=np.asarray(result.goal[-1]))
    setup_axes(ax, limits, auto_view(scene, view))
    colors = snapshot_colors(len(steps))
    arm_lw = radius_linewidth(ax, limits, float(np.asarray(moving.scene.arm_radius)), floor=3.0)
    for k, (step, backbone, color) in enumerate(zip(steps, backbones, colors, strict=True)):
        alpha = 0.35 + 0.65 * (k + 1) / len(steps)
        t = result.time[step]
        for ob in view_box(core, obstacles_at(moving, t))[1]:
            pts = ob["pts"]
            if ob["kind"] == "curve":
                ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=OBSTACLE_COLOR, alpha=alpha,
                        lw=radius_linewidth(ax, limits, ob["radius"], floor=2.0), solid_capstyle="round")
            elif len(pts):
                ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=9, color=POINTS_COLOR, alpha=alpha, depthshade=False)
        draw_arm(ax, backbone, n, color, arm_lw, f"t = {t:.1f} s (step {step})")
        ax.scatter(*result.goal[step], marker="*", s=200, color=GOAL_COLOR, edgecolors=color, linewidths=1.2,
                   depthshade=False, zorder=10)
    ax.plot(result.goal[:, 0], result.goal[:, 1], result.goal[:, 2], color=GOAL_COLOR, lw=1.5, label="goal path")
    ax.plot(result.tip[:, 0], result.tip[:, 1], result.tip[:, 2], ls="--", lw=1.0, color=PATH_COLOR,
            label="tip path")
    ax.scatter(0, 0, 0, marker="s", s=40, color=BASE_COLOR, depthshade=False, label="base")
    ax.plot([], [], color=OBSTACLE_COLOR, lw=2.5, label="obstacles (fainter: earlier)")
    readable_legend(ax, loc="upper left", bbox_to_anchor=(0.0, 1.0), fontsize=8, framealpha=0.85)
    ax2 = fig.add_axes((0.58, 0.14, 0.38, 0.7))
    ax2.plot(result.time, result.error, color="C0", label="|goal - tip|")
    ax2.set_yscale("log")
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("distance to goal [m]", color="C0")
    clearance = np.min(result.clearance, axis=1) if result.clearance.shape[1] else np.full(len(result.time), np.nan)
    ax3 = ax2.twinx()
    ax3.plot(result.time, clearance, color=OBSTACLE_COLOR, label="smallest clearance")
    ax3.set_ylabel("smallest clearance [m]", color=OBSTACLE_COLOR)
    ax3.set_ylim(bottom=0.0)
    if result.reached_step is not None:
        ax2.axvline(result.time[result.reached_step], color="0.5", ls=":", lw=1.0)
    lines = ax2.get_lines()[:1] + ax3.get_lines()[:1]
    ax2.legend(lines, [ln.get_label() for ln in lines], loc="upper right", fontsize=8)
    fig.suptitle(_tracking_title(result) if title is None else title, fontsize=12)
    return fig
