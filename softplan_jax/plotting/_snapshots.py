"""Snapshots of a planned motion and its clearance (matplotlib, host side): the arm at a few
iterations in one 3-D view (:func:`plot_snapshots`, like the paper's Figs. 3-5), side by side
(:func:`plot_snapshot_panels`), beside a top view and the clearance
(:func:`plot_snapshots_with_clearance`), and the true clearance per iteration
(:func:`plot_clearance`); each takes a :class:`~softplan_jax.planning.PlanResult` or an unbatched
Rollout, returns the Figure (made with pyplot; close the ones you do not keep) and never calls
``plt.show()``."""

from __future__ import annotations

import numpy as np

from ._scene import (
    arm_backbones,
    auto_view,
    draw_arm,
    draw_global_part,
    draw_scene,
    draw_shadow,
    pyplot,
    radius_linewidth,
    readable_legend,
    scene_obstacles,
    setup_axes,
    snapshot_colors,
    trajectory_data,
    view_box,
)

__all__ = ["plot_snapshots", "plot_snapshot_panels", "plot_snapshots_with_clearance", "plot_clearance"]


def _resolve_steps(steps, iterations: int) -> list[int]:
    if steps is None:
        steps = [0, iterations // 2, iterations]
    out = []
    for s in steps:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)):
            raise ValueError(f"steps must be integers, got {s!r}")
        s = int(s)
        if s < 0:
            s += iterations + 1
        if not 0 <= s <= iterations:
            raise ValueError(f"step {s} is out of range: the result has iterations 0..{iterations}")
        if s not in out:
            out.append(s)
    if not out:
        raise ValueError("steps is empty")
    return sorted(out)


def _default_title(traj) -> str:
    clr = traj["min_clearance"]
    extra = f", min clearance {clr:.3f}" if np.isfinite(clr) else ""
    how = f" (global search from step {traj['global_start']})" if traj["planner"] == "global" else ""
    return f"{traj['status']} after {traj['iterations']} iterations{how}{extra}"

def _step_label(step: int, iterations: int) -> str:
    if step == iterations and step > 0:
        return f"iteration {step} (final)"
    return f"iteration {step}"


# ----------------------------------------------------------------------------
# Public functions.


def plot_snapshots(scenario, result, steps=None, ax=None, title=None, view=None, figsize=(9, 7)):
    """The arm at a few iterations in one 3D view (the paper's Figs. 3-5).

    Args:
      scenario: the (unbatched) Scenario that was planned.
      result: PlanResult (from :func:`softplan_jax.plan`) or an unbatched Rollout.
      steps: iterations to draw (negative counts from the end); default the
        start, the middle and the final iteration.
      ax: a 3D Axes to draw into (``projection="3d"``); default a new figure.
      title: figure title; default the status, iterations and min clearance.
      view: (elevation, azimuth) in degrees; default elevation 22 and the
        azimuth that looks across the goal's horizontal direction (the arm's
        sideways motion then lies in the picture plane).
      figsize: size of a new figure (inches).

    Returns:
      The matplotlib Figure.
    """
    traj = trajectory_data(scenario, result)
    steps = _resolve_steps(steps, traj["iterations"])
    n = traj["q"].shape[1]
    backbones = arm_backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = view_box(core, scene_obstacles(scenario))
    own_figure = ax is None
    if own_figure:
        plt = pyplot()
        fig = plt.figure(figsize=figsize)
        # Leave the right-hand strip for the legend.
        ax = fig.add_axes((0.0, 0.07, 0.74, 0.82), projection="3d")
    elif getattr(ax, "name", None) != "3d":
        raise ValueError("ax must be a 3D Axes (fig.add_subplot(projection='3d'))")
    fig = ax.figure
    setup_axes(ax, limits, auto_view(scenario, view))
    draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"])
    draw_global_part(ax, traj)
    arm_lw = radius_linewidth(ax, limits, float(np.asarray(scenario.arm_radius)), floor=3.0)
    for step, color, backbone in zip(steps, snapshot_colors(len(steps)), backbones, strict=True):
        draw_shadow(ax, backbone, limits, lw=1.5)
        draw_arm(ax, backbone, n, color, arm_lw, _step_label(step, traj["iterations"]))
    if own_figure:
        readable_legend(ax, loc="upper left", bbox_to_anchor=(0.97, 0.9), fontsize=9, framealpha=0.9)
        fig.suptitle(_default_title(traj) if title is None else title, fontsize=12, y=0.97)
    else:
        readable_legend(ax, loc="upper left", fontsize=8, framealpha=0.85)
        ax.set_title(_default_title(traj) if title is None else title, fontsize=11)
    return fig


def plot_snapshot_panels(scenario, result, steps=None, title=None, view=None, figsize=(13, 5.5)):
    """The snapshots side by side, one per panel ((a), (b), (c) as in the paper).

    Args: as :func:`plot_snapshots` (one panel per step, shared limits).

    Returns:
      The matplotlib Figure.
    """
    traj = trajectory_data(scenario, result)
    steps = _resolve_steps(steps, traj["iterations"])
    n = traj["q"].shape[1]
    backbones = arm_backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = view_box(core, scene_obstacles(scenario))
    plt = pyplot()
    fig = plt.figure(figsize=figsize)
    colors = snapshot_colors(len(steps))
    for k, (step, backbone) in enumerate(zip(steps, backbones, strict=True)):
        ax = fig.add_subplot(1, len(steps), k + 1, projection="3d")
        setup_axes(ax, limits, auto_view(scenario, view))
        draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"][: step + 1] if step > 0 else None)
        arm_lw = radius_linewidth(ax, limits, float(np.asarray(scenario.arm_radius)), floor=3.0)
        draw_shadow(ax, backbone, limits, lw=1.5)
        draw_arm(ax, backbone, n, colors[-1], arm_lw, "arm")
        ax.set_title(f"({chr(ord('a') + k)}) {_step_label(step, traj['iterations'])}", fontsize=10)
        if k == len(steps) - 1:
            handles, labels = ax.get_legend_handles_labels()
            readable_legend(fig, handles=handles, labels=labels, loc="lower center", ncol=len(labels), fontsize=9,
                    framealpha=0.9)
    fig.suptitle(_default_title(traj) if title is None else title, fontsize=12)
    return fig

def plot_snapshots_with_clearance(scenario, result, steps=None, title=None, view=None, figsize=(17, 5.2)):
    """The 3D snapshots beside a top view (x-y) and the true clearance vs iteration.

    The 3D view is :func:`plot_snapshots`; the top view draws the same arm
    snapshots, tip path, obstacles and goal projected on the x-y plane; the
    right panel is :func:`plot_clearance` with the minimum marked.

    Args:
      scenario: the (unbatched) Scenario that was planned.
      result: PlanResult (with ``clearance``) or an unbatched Rollout.
      steps, view: as :func:`plot_snapshots`.
      title: figure title; default the status, iterations and min clearance.
      figsize: figure size (inches).

    Returns:
      The matplotlib Figure.
    """
    plt = pyplot()
    traj = trajectory_data(scenario, result)
    fig = plt.figure(figsize=figsize)
    ax3 = fig.add_subplot(1, 3, 1, projection="3d")
    plot_snapshots(scenario, result, steps=steps, ax=ax3, title="3D view", view=view)
    ax_top = fig.add_subplot(1, 3, 2)
    for k, ob in enumerate(scene_obstacles(scenario)):
        style = dict(color="0.35", lw=2.0) if ob["kind"] == "curve" else dict(color="0.35", ls="none", marker=".")
        ax_top.plot(ob["pts"][:, 0], ob["pts"][:, 1], label="obstacles" if k == 0 else None, **style)
    sel = _resolve_steps(steps, traj["iterations"])
    for step, color, backbone in zip(sel, snapshot_colors(len(sel)), arm_backbones(traj["q"][sel]), strict=True):
        ax_top.plot(backbone[:, 0], backbone[:, 1], color=color, lw=2.5, label=_step_label(step, traj["iterations"]))
    ax_top.plot(traj["tip"][:, 0], traj["tip"][:, 1], color="k", lw=0.8, ls=":", label="tip path")
    goal = np.asarray(scenario.goal, float)
    ax_top.plot(goal[0], goal[1], marker="*", color="gold", mec="k", ms=14, ls="none", label="goal")
    ax_top.set_aspect("equal", adjustable="datalim")
    ax_top.set_xlabel("X")
    ax_top.set_ylabel("Y")
    ax_top.grid(alpha=0.3)
    ax_top.set_title("top view (x-y)", fontsize=11)
    ax_top.legend(fontsize=7, loc="best")
    ax_c = fig.add_subplot(1, 3, 3)
    plot_clearance(result, scenario, ax=ax_c, title="true clearance")
    if traj["clearance"] is not None and traj["clearance"].size:
        c = traj["clearance"][: traj["iterations"] + 1]
        c = c[:, ~np.all(np.isinf(c), axis=0)]
        if c.size:
            k_min = int(np.argmin(np.min(c, axis=1)))
            ax_c.plot(k_min, float(np.min(c)), marker="v", color="crimson", ms=8, ls="none")
            ax_c.annotate(f"min {float(np.min(c)):.3f}", (k_min, float(np.min(c))), textcoords="offset points",
                          xytext=(6, 6), fontsize=8, color="crimson")
    fig.suptitle(_default_title(traj) if title is None else title, fontsize=12)
    fig.tight_layout()
    return fig

def plot_clearance(result, scenario=None, ax=None, labels=None, title=None, figsize=(7, 4)):
    """True clearance (surface to surface) to every obstacle vs iteration.

    Obstacles are in the slot order of :mod:`softplan_jax.geometry._obstacles`.

    Args:
      result: PlanResult, or an unbatched Rollout (padding slots dropped).
      scenario: optional; names the obstacles by kind ("curve 1", "points 1",
        "parametric 1") instead of "obstacle 1", "obstacle 2", ...
      ax: a 2D Axes to draw into; default a new figure.
      labels: one name per obstacle (overrides the names above).
      title: axes title.

    Returns:
      The matplotlib Figure.
    """
    clearance = getattr(result, "clearance", None)
    if clearance is None:
        raise ValueError(
            f"result must be a PlanResult or a Rollout; {type(result).__name__} has no clearance"
        )
    c = np.asarray(clearance, dtype=float)
    if c.ndim != 2:
        raise ValueError(f"plot one result at a time: clearance must be (steps + 1, m), got shape {c.shape}")
    it = int(np.asarray(result.iterations))
    c = c[: it + 1]
    c = c[:, ~np.all(np.isinf(c), axis=0)]  # padding slots of a Rollout
    if labels is None and scenario is not None:
        from ..geometry._obstacles import obstacle_labels

        labels = obstacle_labels(scenario)
        if len(labels) != c.shape[1]:
            raise ValueError(f"the scenario has {len(labels)} obstacles, the result {c.shape[1]}")
    if labels is None:
        labels = [f"obstacle {k + 1}" for k in range(c.shape[1])]
    elif len(labels) != c.shape[1]:
        raise ValueError(f"{len(labels)} labels for {c.shape[1]} obstacles")
    if ax is None:
        plt = pyplot()
        fig, ax = plt.subplots(figsize=figsize)
    fig = ax.figure
    steps = np.arange(c.shape[0])
    for k in range(c.shape[1]):
        ax.plot(steps, c[:, k], lw=1.5, label=labels[k])
    ax.axhline(0.0, color="crimson", lw=1.0, ls="--", label="contact")
    ax.set_xlabel("iteration")
    ax.set_ylabel("true clearance")
    ax.set_xlim(0, max(1, c.shape[0] - 1))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    status = getattr(result, "status", None)
    if title is None and isinstance(status, str):
        title = f"clearance per obstacle ({status} after {it} iterations)"
    if title:
        ax.set_title(title, fontsize=11)
    return fig
