"""Figures of planned motions (matplotlib only, host side).

* :func:`plot_snapshots` — the arm at a few iterations in one 3D view, like
  the paper's Figs. 3-5 (obstacle curves, goal, tip path).
* :func:`plot_snapshot_panels` — the same snapshots side by side, the paper's
  panels (a) (b) (c).
* :func:`animate` — an animated GIF of the whole motion (needs pillow).
* :func:`plot_clearance` — true clearance to every obstacle per iteration.
* :func:`plot_cloud_fit` — a point cloud with the curves fitted to it.
* :func:`plot_tracking`, :func:`animate_tracking` — a tracking run among
  moving obstacles (:func:`softplan_jax.track`): snapshots with the obstacles
  where they were, error and clearance over time; a GIF with everything moving.

Every function takes a :class:`~softplan_jax.planner.PlanResult` (what
:func:`softplan_jax.plan` returns) or a single, unbatched
:class:`~softplan_jax.planner.Rollout`, returns the matplotlib Figure and never
calls ``plt.show()``. Figures are made with pyplot (so they display in
notebooks and scripts); without a display pyplot falls back to the Agg backend.
Close figures you do not keep (``plt.close(fig)``).
"""

from __future__ import annotations

import os
import sys

import numpy as np

__all__ = ["plot_snapshots", "plot_snapshot_panels", "animate", "plot_clearance", "plot_cloud_fit"]

# Arm samples per segment for drawing the smooth backbone.
ARM_SAMPLES = 30
# Samples of an obstacle curve over its u_range.
CURVE_SAMPLES = 600

_OBSTACLE_COLOR = "#8c5a2b"  # branch brown
_POINTS_COLOR = "#6b4423"
_GOAL_COLOR = "#f2b705"
_PATH_COLOR = "#444444"
_GLOBAL_COLOR = "#1b9e77"  # the part of the path found by the global search (plan_fallback)
_BASE_COLOR = "black"


# ----------------------------------------------------------------------------
# Host-side data.


def _pyplot():
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


def _trajectory(scenario, result) -> dict:
    """Configurations, tips and outcome of ``result`` as NumPy, trimmed to the
    steps taken."""
    from ..planning.planner import Rollout, result_from_rollout

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


def _backbones(qs) -> np.ndarray:
    """(T, n * ARM_SAMPLES + 1, 3) smooth backbones, the base (origin) first."""
    from ..geometry.kinematics import backbone_points

    out = []
    for q in qs:
        pts = np.asarray(backbone_points(q, ARM_SAMPLES), dtype=float)
        out.append(np.concatenate([np.zeros((1, 3)), pts]))
    return np.stack(out)


def _joint_indices(n_segments: int) -> np.ndarray:
    """Backbone indices of the base and every segment end (the last is the tip)."""
    return np.arange(n_segments + 1) * ARM_SAMPLES


def _obstacles(scenario) -> list[dict]:
    """Every real obstacle as a dict(kind "curve" | "points", pts (N, 3), radius)."""
    from ..geometry.obstacles import obstacle_samples

    return obstacle_samples(scenario, CURVE_SAMPLES)


def _view_box(core: np.ndarray, obstacles: list[dict]):
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


def _radius_linewidth(ax, limits, radius: float, floor: float) -> float:
    """Line width in points that shows a tube of ``radius`` (data units), at
    least ``floor``: approximate, the 3D projection has no exact scale."""
    if radius <= 0:
        return floor
    fig = ax.figure
    width_pts = fig.get_figwidth() * 72.0 * ax.get_position().width
    span = float(np.max(limits[:, 1] - limits[:, 0]))
    # An axis of the box spans roughly 70 % of the axes width at the default view.
    return max(floor, 2.0 * radius / span * 0.7 * width_pts)


def _auto_view(scenario, view):
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


def _setup_axes(ax, limits, view):
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


def _draw_global_part(ax, traj):
    """Over the tip path: its part planned by the global search (plan_fallback), in its own colour."""
    if traj["planner"] != "global" or traj["global_start"] is None:
        return
    tip = traj["tip"][int(traj["global_start"]):]
    ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], lw=1.6, color=_GLOBAL_COLOR, label="tip path (global search)")


def _draw_scene(ax, scenario, limits, obstacles, tip_path=None):
    """Obstacles, goal and the base; returns the artists of the tip path."""
    curve_labelled = points_labelled = False
    for ob in obstacles:
        pts = ob["pts"]
        if ob["kind"] == "curve":
            lw = _radius_linewidth(ax, limits, ob["radius"], floor=2.5)
            label = None if curve_labelled else "obstacle curve"
            ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=_OBSTACLE_COLOR, lw=lw, alpha=0.9,
                    solid_capstyle="round", label=label)
            _shadow(ax, pts, limits, lw=1.5)
            curve_labelled = True
        elif len(pts):
            size = _radius_linewidth(ax, limits, ob["radius"], floor=4.0) ** 2
            label = None if points_labelled else "obstacle points"
            ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=size, color=_POINTS_COLOR, alpha=0.8,
                       depthshade=False, label=label)
            points_labelled = True
    goal = np.asarray(scenario.goal, dtype=float)
    # A drop line from the floor to the goal locates it in depth.
    ax.plot([goal[0]] * 2, [goal[1]] * 2, [limits[2, 0], goal[2]], ls=":", lw=1.0, color=_PATH_COLOR,
            alpha=0.7)
    ax.scatter(goal[0], goal[1], limits[2, 0], marker="*", s=60, color="0.55", alpha=0.5, depthshade=False)
    ax.scatter(*goal, marker="*", s=320, color=_GOAL_COLOR, edgecolors="black", linewidths=0.8,
               depthshade=False, label="goal", zorder=10)
    ax.scatter(0, 0, 0, marker="s", s=40, color=_BASE_COLOR, depthshade=False, label="base")
    if tip_path is not None:
        (line,) = ax.plot(tip_path[:, 0], tip_path[:, 1], tip_path[:, 2], ls="--", lw=1.0,
                          color=_PATH_COLOR, label="tip path")
        return line
    return None


def _legend(target, **kw):
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


def _snapshot_colors(k: int):
    """Light (early) to dark (late) blues."""
    from matplotlib import colormaps

    cmap = colormaps["Blues"]
    if k == 1:
        return [cmap(0.95)]
    return [cmap(v) for v in np.linspace(0.4, 0.95, k)]


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


def _shadow(ax, pts, limits, **kw):
    """Faint projection of a polyline onto the floor of the box (a depth cue)."""
    z = np.full(len(pts), limits[2, 0])
    ax.plot(pts[:, 0], pts[:, 1], z, color="0.55", alpha=0.35, zorder=1, **kw)


def _draw_arm(ax, backbone, n_segments, color, lw, label):
    joints = backbone[_joint_indices(n_segments)]
    ax.plot(backbone[:, 0], backbone[:, 1], backbone[:, 2], color=color, lw=lw, label=label,
            solid_capstyle="round", zorder=5)
    ax.plot(joints[:, 0], joints[:, 1], joints[:, 2], ls="none", marker="o", ms=5, color=color,
            markeredgecolor="white", markeredgewidth=0.8, zorder=6)


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
    traj = _trajectory(scenario, result)
    steps = _resolve_steps(steps, traj["iterations"])
    n = traj["q"].shape[1]
    backbones = _backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = _view_box(core, _obstacles(scenario))
    own_figure = ax is None
    if own_figure:
        plt = _pyplot()
        fig = plt.figure(figsize=figsize)
        # Leave the right-hand strip for the legend.
        ax = fig.add_axes((0.0, 0.07, 0.74, 0.82), projection="3d")
    elif getattr(ax, "name", None) != "3d":
        raise ValueError("ax must be a 3D Axes (fig.add_subplot(projection='3d'))")
    fig = ax.figure
    _setup_axes(ax, limits, _auto_view(scenario, view))
    _draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"])
    _draw_global_part(ax, traj)
    arm_lw = _radius_linewidth(ax, limits, float(np.asarray(scenario.arm_radius)), floor=3.0)
    for step, color, backbone in zip(steps, _snapshot_colors(len(steps)), backbones, strict=True):
        _shadow(ax, backbone, limits, lw=1.5)
        _draw_arm(ax, backbone, n, color, arm_lw, _step_label(step, traj["iterations"]))
    if own_figure:
        _legend(ax, loc="upper left", bbox_to_anchor=(0.97, 0.9), fontsize=9, framealpha=0.9)
        fig.suptitle(_default_title(traj) if title is None else title, fontsize=12, y=0.97)
    else:
        _legend(ax, loc="upper left", fontsize=8, framealpha=0.85)
        ax.set_title(_default_title(traj) if title is None else title, fontsize=11)
    return fig


def plot_snapshot_panels(scenario, result, steps=None, title=None, view=None, figsize=(13, 5.5)):
    """The snapshots side by side, one per panel ((a), (b), (c) as in the paper).

    Args: as :func:`plot_snapshots` (one panel per step, shared limits).

    Returns:
      The matplotlib Figure.
    """
    traj = _trajectory(scenario, result)
    steps = _resolve_steps(steps, traj["iterations"])
    n = traj["q"].shape[1]
    backbones = _backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = _view_box(core, _obstacles(scenario))
    plt = _pyplot()
    fig = plt.figure(figsize=figsize)
    colors = _snapshot_colors(len(steps))
    for k, (step, backbone) in enumerate(zip(steps, backbones, strict=True)):
        ax = fig.add_subplot(1, len(steps), k + 1, projection="3d")
        _setup_axes(ax, limits, _auto_view(scenario, view))
        _draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"][: step + 1] if step > 0 else None)
        arm_lw = _radius_linewidth(ax, limits, float(np.asarray(scenario.arm_radius)), floor=3.0)
        _shadow(ax, backbone, limits, lw=1.5)
        _draw_arm(ax, backbone, n, colors[-1], arm_lw, "arm")
        ax.set_title(f"({chr(ord('a') + k)}) {_step_label(step, traj['iterations'])}", fontsize=10)
        if k == len(steps) - 1:
            handles, labels = ax.get_legend_handles_labels()
            _legend(fig, handles=handles, labels=labels, loc="lower center", ncol=len(labels), fontsize=9,
                    framealpha=0.9)
    fig.suptitle(_default_title(traj) if title is None else title, fontsize=12)
    return fig


def _fit_axis_labels_inside(fig, ax, limits, margin=4.0, tries=12):
    """Shrink the 3-D box (``set_box_aspect(zoom=...)``) until the axis labels and
    tick labels lie inside the figure, ``margin`` pixels from its edges.

    A GIF frame is the whole figure (no tight bounding box as in ``savefig``),
    so a label drawn past the edge is cut off. The camera is fixed during an
    animation, so fitting once at the start is enough. Returns the zoom used.
    """
    aspect = tuple(limits[:, 1] - limits[:, 0])
    zoom = 1.0
    for _ in range(tries):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        W, H = fig.canvas.get_width_height()
        # the 3-D axes' tight box holds the axis labels and the tick labels drawn
        boxes = [ax.get_tightbbox(renderer, bbox_extra_artists=[])]  # the legend is not ours to fit
        boxes += [a.label.get_window_extent(renderer)
                  for a in (ax.xaxis, ax.yaxis, ax.zaxis)]
        if all(b.x0 >= margin and b.y0 >= margin and b.x1 <= W - margin and b.y1 <= H - margin for b in boxes):
            break
        zoom *= 0.93
        ax.set_box_aspect(aspect, zoom=zoom)
    return zoom


def _check_gif_args(name: str, path, fps, max_frames) -> str:
    """The checks :func:`animate` and :func:`animate_tracking` share: pillow installed, a
    ``.gif`` path, fps > 0, max_frames >= 2 (ValueError naming ``name``); returns the path."""
    try:
        import PIL  # noqa: F401
    except ImportError:
        raise ValueError(f"{name} needs pillow to write GIFs: pip install pillow") from None
    path = os.fspath(path)
    if not path.lower().endswith(".gif"):
        raise ValueError(f"{name} writes GIF files; the path must end in .gif, got {path!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be > 0, got {fps!r}")
    if int(max_frames) < 2:
        raise ValueError(f"max_frames must be >= 2, got {max_frames!r}")
    return path


def animate(scenario, result, path, fps=15, max_frames=200, hold=1.0, title=None, view=None,
            figsize=(8, 6), dpi=80):
    """Write an animated GIF of the motion (matplotlib's PillowWriter).

    Args:
      scenario, result: as :func:`plot_snapshots`.
      path: output file; must end in ``.gif``.
      fps: frames per second (> 0).
      max_frames: at most this many planner steps are shown (evenly
        subsampled; the start and the final step always).
      hold: seconds the final frame is held.
      title: title prefix; default none.

    The 3-D box is shrunk as needed so that the axis labels and tick labels
    lie inside every frame.

    Returns:
      ``path``.

    Raises:
      ValueError: bad arguments, or pillow is not installed.
    """
    path = _check_gif_args("animate", path, fps, max_frames)
    from matplotlib.animation import FuncAnimation, PillowWriter

    traj = _trajectory(scenario, result)
    T = traj["iterations"]
    steps = np.unique(np.round(np.linspace(0, T, min(T + 1, int(max_frames)))).astype(int))
    n = traj["q"].shape[1]
    backbones = _backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = _view_box(core, _obstacles(scenario))
    plt = _pyplot()
    fig = plt.figure(figsize=figsize)
    try:
        ax = fig.add_axes((0.0, 0.04, 0.76, 0.86), projection="3d")
        _setup_axes(ax, limits, _auto_view(scenario, view))
        path_line = _draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"][:1])
        arm_lw = _radius_linewidth(ax, limits, float(np.asarray(scenario.arm_radius)), floor=3.0)
        color = _snapshot_colors(1)[0]
        (arm,) = ax.plot([], [], [], color=color, lw=arm_lw, solid_capstyle="round", label="arm")
        (joints,) = ax.plot([], [], [], ls="none", marker="o", ms=5, color=color,
                            markeredgecolor="white", markeredgewidth=0.8)
        (shadow,) = ax.plot([], [], [], color="0.55", alpha=0.35, lw=1.5, zorder=1)
        _legend(ax, loc="upper left", bbox_to_anchor=(0.97, 0.9), fontsize=8, framealpha=0.9)
        prefix = "" if title is None else f"{title}\n"
        text = fig.suptitle("", fontsize=11, y=0.97)
        frames = list(range(len(steps))) + [len(steps) - 1] * int(round(hold * fps))
        fig.set_dpi(dpi)  # fit the labels at the resolution of the frames
        _fit_axis_labels_inside(fig, ax, limits)

        def update(k):
            b = backbones[k]
            arm.set_data_3d(b[:, 0], b[:, 1], b[:, 2])
            shadow.set_data_3d(b[:, 0], b[:, 1], np.full(len(b), limits[2, 0]))
            j = b[_joint_indices(n)]
            joints.set_data_3d(j[:, 0], j[:, 1], j[:, 2])
            tip = traj["tip"][: steps[k] + 1]
            path_line.set_data_3d(tip[:, 0], tip[:, 1], tip[:, 2])
            status = f" — {traj['status']}" if steps[k] == T else ""
            text.set_text(f"{prefix}iteration {steps[k]} / {T}{status}")
            return arm, joints, shadow, path_line, text

        anim = FuncAnimation(fig, update, frames=frames, blit=False)
        anim.save(path, writer=PillowWriter(fps=fps), dpi=dpi)
    finally:
        plt.close(fig)
    return path


def plot_clearance(result, scenario=None, ax=None, labels=None, title=None, figsize=(7, 4)):
    """True clearance (surface to surface) to every obstacle vs iteration.

    Obstacles are in the slot order of :mod:`softplan_jax.obstacles`.

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
        from ..geometry.obstacles import obstacle_labels

        labels = obstacle_labels(scenario)
        if len(labels) != c.shape[1]:
            raise ValueError(f"the scenario has {len(labels)} obstacles, the result {c.shape[1]}")
    if labels is None:
        labels = [f"obstacle {k + 1}" for k in range(c.shape[1])]
    elif len(labels) != c.shape[1]:
        raise ValueError(f"{len(labels)} labels for {c.shape[1]} obstacles")
    if ax is None:
        plt = _pyplot()
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


# ----------------------------------------------------------------------------
# Benchmark plots (benchmarks/batch_sweep.py).


def plot_benchmark(labels, cost_s, collision_rate, success_rate=None, highlight="curve", ax=None, title=None,
                   xlabel="time per scenario-step", ylabel="collision rate", figsize=(7.5, 5)):
    """Collision rate against per-step cost, one labelled point per method (log x-axis).

    Args:
      labels: method names, e.g. ``["curve", "N=1", "N=10"]``.
      cost_s: per-step cost of each method in seconds (> 0).
      collision_rate: fraction of scenarios that collided, in [0, 1].
      success_rate: optional fractions reached without collision, shown in the labels.
      highlight: the label drawn as the reference method (a star); None for none.
      ax: a 2D Axes to draw into; default a new figure.
      title, xlabel, ylabel: texts.

    Returns:
      The matplotlib Figure.
    """
    labels = [str(x) for x in labels]
    cost = np.asarray(cost_s, dtype=float)
    coll = np.asarray(collision_rate, dtype=float)
    if cost.shape != (len(labels),) or coll.shape != (len(labels),):
        raise ValueError(f"need one cost and one collision rate per label ({len(labels)}); "
                         f"got shapes {cost.shape} and {coll.shape}")
    if not np.all(np.isfinite(cost) & (cost > 0)):
        raise ValueError(f"costs must be finite and > 0 (log axis); got {cost.tolist()}")
    succ = None if success_rate is None else np.asarray(success_rate, dtype=float)
    if succ is not None and succ.shape != (len(labels),):
        raise ValueError(f"need one success rate per label; got shape {succ.shape}")
    if ax is None:
        plt = _pyplot()
        fig, ax = plt.subplots(figsize=figsize)
    fig = ax.figure
    ref = np.array([lab == highlight for lab in labels])
    others = ~ref
    ax.plot(cost[others], 100 * coll[others], "o:", color="#3b75af", ms=7, lw=1.0, alpha=0.9,
            label="N-point obstacle model (in order of N)")
    if ref.any():
        ax.plot(cost[ref], 100 * coll[ref], "*", color="#d62728", ms=18, markeredgecolor="black",
                label="curve (exact closest points)")
    ax.set_xscale("log")
    top = max(5.0, 100 * float(np.nanmax(coll)) * 1.2)
    ax.set_ylim(-0.05 * top, top)
    ax.set_xlim(float(cost.min()) / 2, float(cost.max()) * 3)
    texts = [lab if succ is None else f"{lab} ({100 * succ[k]:.0f}% ok)" for k, lab in enumerate(labels)]
    _place_labels(ax, cost, 100 * coll, texts, fontsize=8)
    ax.set_xlabel(f"{xlabel} (s, log scale)")
    ax.set_ylabel(f"{ylabel} (%)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right", title="labels: method (success rate)" if succ is not None else None,
              title_fontsize=8)
    if title:
        ax.set_title(title, fontsize=11)
    return fig


def _place_labels(ax, x, y, texts, fontsize=8):
    """Annotate points, choosing for each (left to right) the offset whose label box
    overlaps the labels and points already placed the least (boxes estimated in points)."""
    fig = ax.figure
    to_pt = 72.0 / fig.dpi
    xy = ax.transData.transform(np.column_stack([x, y])) * to_pt  # display points
    char_w, h = 0.65 * fontsize, 1.3 * fontsize
    offsets = [(7, 5, "left", "bottom"), (7, -5, "left", "top"), (-7, 5, "right", "bottom"),
               (-7, -5, "right", "top"), (7, 14, "left", "bottom"), (7, -14, "left", "top"),
               (-7, 14, "right", "bottom"), (-7, -14, "right", "top")]
    placed = [(px - 4, py - 4, px + 4, py + 4) for px, py in xy]  # the markers

    def box(k, off):
        dx, dy, ha, va = off
        w = char_w * len(texts[k])
        x0 = xy[k, 0] + dx - (w if ha == "right" else 0.0)
        y0 = xy[k, 1] + dy - (h if va == "top" else 0.0)
        return (x0, y0, x0 + w, y0 + h)

    def overlap(a, b):
        return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))

    for k in np.argsort(xy[:, 0]):
        best = min(offsets, key=lambda off: sum(overlap(box(k, off), p) for j, p in enumerate(placed) if j != k))
        placed.append(box(k, best))
        dx, dy, ha, va = best
        ax.annotate(texts[k], (x[k], y[k]), textcoords="offset points", xytext=(dx, dy), ha=ha, va=va,
                    fontsize=fontsize, arrowprops=dict(arrowstyle="-", lw=0.6, color="0.45", shrinkA=0, shrinkB=4))


__all__.append("plot_benchmark")


# ----------------------------------------------------------------------------
# Point clouds and the curves fitted to them (softplan_jax.fitting).


def plot_cloud_fit(points, fit, ax=None, title=None, max_points: int = 6000, figsize=(8, 6.5)):
    """The raw cloud (grey dots) with the fitted curves over it, one colour per
    curve, each labelled with its degree and residuals.

    Args:
      points: (N, 3) the cloud that was fitted.
      fit: a :class:`~softplan_jax.fitting.CloudFit` or
        :class:`~softplan_jax.fitting.CurveFit`.
      ax: a 3D Axes to draw on; None = a new figure.
      title: figure title; None = a summary of the fit.
      max_points: draw at most this many cloud points (a seeded random subset).

    Returns:
      The matplotlib Figure.
    """
    from ..clouds import CloudFit
    from ..base.validation import check_cloud

    P = check_cloud(points)
    cf = CloudFit.from_fit(fit)
    plt = _pyplot()
    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d", computed_zorder=False)  # curves drawn over the cloud
    else:
        fig = ax.figure
    shown = P
    if P.shape[0] > max_points:
        shown = P[np.random.default_rng(0).choice(P.shape[0], max_points, replace=False)]
    ax.scatter(shown[:, 0], shown[:, 1], shown[:, 2], s=2, color="0.5", alpha=0.3, depthshade=False,
               label=f"cloud ({P.shape[0]} points)", zorder=1)
    colors = plt.get_cmap("tab10")
    for k, f in enumerate(cf.fits):
        coeffs = np.asarray(f.curve.coeffs, dtype=float)
        lo, hi = (float(x) for x in np.asarray(f.curve.u_range))
        u = np.linspace(lo, hi, CURVE_SAMPLES)
        pts = np.stack([np.polynomial.polynomial.polyval(u, coeffs[a]) for a in range(3)], axis=-1)
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=colors(k % 10), lw=2.0, zorder=2 + k,
                label=f"curve {k}: degree {f.degree}, rms {f.rms_residual:.3g}, max {f.max_residual:.3g}")
    lo, hi = P.min(axis=0), P.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1e-9) * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_xlabel("X")
    ax.set_ylabel("Y")
    ax.set_zlabel("Z")
    if title is None:
        title = f"{len(cf.fits)} curve(s) fitted; max residual {cf.max_residual:.3g}, rms {cf.rms_residual:.3g}"
        if np.isfinite(cf.noise):
            title += f"\nestimated noise level {cf.noise:.3g} (poor fit above {cf.tolerance:.3g})"
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", fontsize=8)
    return fig


# ----------------------------------------------------------------------------
# Snapshot, top view and clearance side by side (issue 10: a 3D perspective alone hides clearance).


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
    plt = _pyplot()
    traj = _trajectory(scenario, result)
    fig = plt.figure(figsize=figsize)
    ax3 = fig.add_subplot(1, 3, 1, projection="3d")
    plot_snapshots(scenario, result, steps=steps, ax=ax3, title="3D view", view=view)
    ax_top = fig.add_subplot(1, 3, 2)
    for k, ob in enumerate(_obstacles(scenario)):
        style = dict(color="0.35", lw=2.0) if ob["kind"] == "curve" else dict(color="0.35", ls="none", marker=".")
        ax_top.plot(ob["pts"][:, 0], ob["pts"][:, 1], label="obstacles" if k == 0 else None, **style)
    sel = _resolve_steps(steps, traj["iterations"])
    for step, color, backbone in zip(sel, _snapshot_colors(len(sel)), _backbones(traj["q"][sel]), strict=True):
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


# ----------------------------------------------------------------------------
# Moving scenes (softplan_jax.tracking).


def _tracking_data(result):
    for field in ("moving", "time", "goal", "error", "q", "tip"):
        if not hasattr(result, field):
            raise ValueError(f"result must be a TrackResult (from softplan_jax.track); "
                             f"{type(result).__name__} has no {field!r}")
    return result.moving


def _obstacles_at(moving, t) -> list[dict]:
    from ..scenarios.motion import scenario_at

    return _obstacles(scenario_at(moving, float(t)))


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
    moving = _tracking_data(result)
    if int(snapshots) < 1:
        raise ValueError(f"snapshots must be >= 1, got {snapshots}")
    T = int(result.iterations)
    steps = np.unique(np.round(np.linspace(0, T, int(snapshots))).astype(int))
    n = result.q.shape[1]
    backbones = _backbones(result.q[steps])
    core = np.concatenate([backbones.reshape(-1, 3), result.tip, result.goal])
    limits, _ = _view_box(core, _obstacles_at(moving, result.time[0]))
    plt = _pyplot()
    fig = plt.figure(figsize=figsize)
    ax = fig.add_axes((0.0, 0.08, 0.5, 0.8), projection="3d")
    scene = moving.scene._replace(goal=np.asarray(result.goal[-1]))
    _setup_axes(ax, limits, _auto_view(scene, view))
    colors = _snapshot_colors(len(steps))
    arm_lw = _radius_linewidth(ax, limits, float(np.asarray(moving.scene.arm_radius)), floor=3.0)
    for k, (step, backbone, color) in enumerate(zip(steps, backbones, colors, strict=True)):
        alpha = 0.35 + 0.65 * (k + 1) / len(steps)
        t = result.time[step]
        for ob in _view_box(core, _obstacles_at(moving, t))[1]:
            pts = ob["pts"]
            if ob["kind"] == "curve":
                ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=_OBSTACLE_COLOR, alpha=alpha,
                        lw=_radius_linewidth(ax, limits, ob["radius"], floor=2.0), solid_capstyle="round")
            elif len(pts):
                ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=9, color=_POINTS_COLOR, alpha=alpha, depthshade=False)
        _draw_arm(ax, backbone, n, color, arm_lw, f"t = {t:.1f} s (step {step})")
        ax.scatter(*result.goal[step], marker="*", s=200, color=_GOAL_COLOR, edgecolors=color, linewidths=1.2,
                   depthshade=False, zorder=10)
    ax.plot(result.goal[:, 0], result.goal[:, 1], result.goal[:, 2], color=_GOAL_COLOR, lw=1.5, label="goal path")
    ax.plot(result.tip[:, 0], result.tip[:, 1], result.tip[:, 2], ls="--", lw=1.0, color=_PATH_COLOR,
            label="tip path")
    ax.scatter(0, 0, 0, marker="s", s=40, color=_BASE_COLOR, depthshade=False, label="base")
    ax.plot([], [], color=_OBSTACLE_COLOR, lw=2.5, label="obstacles (fainter: earlier)")
    _legend(ax, loc="upper left", bbox_to_anchor=(0.0, 1.0), fontsize=8, framealpha=0.85)
    ax2 = fig.add_axes((0.58, 0.14, 0.38, 0.7))
    ax2.plot(result.time, result.error, color="C0", label="|goal - tip|")
    ax2.set_yscale("log")
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("distance to goal [m]", color="C0")
    clearance = np.min(result.clearance, axis=1) if result.clearance.shape[1] else np.full(len(result.time), np.nan)
    ax3 = ax2.twinx()
    ax3.plot(result.time, clearance, color=_OBSTACLE_COLOR, label="smallest clearance")
    ax3.set_ylabel("smallest clearance [m]", color=_OBSTACLE_COLOR)
    ax3.set_ylim(bottom=0.0)
    if result.reached_step is not None:
        ax2.axvline(result.time[result.reached_step], color="0.5", ls=":", lw=1.0)
    lines = ax2.get_lines()[:1] + ax3.get_lines()[:1]
    ax2.legend(lines, [ln.get_label() for ln in lines], loc="upper right", fontsize=8)
    fig.suptitle(_tracking_title(result) if title is None else title, fontsize=12)
    return fig


def animate_tracking(result, path, fps=15, max_frames=200, hold=1.0, title=None, view=None, figsize=(8, 6),
                     dpi=80):
    """An animated GIF of a tracking run: the arm, the moving obstacles and the
    moving goal at every shown step (arguments as :func:`animate`).

    Returns:
      ``path``.
    """
    path = _check_gif_args("animate_tracking", path, fps, max_frames)
    moving = _tracking_data(result)
    from matplotlib.animation import FuncAnimation, PillowWriter

    T = int(result.iterations)
    steps = np.unique(np.round(np.linspace(0, T, min(T + 1, int(max_frames)))).astype(int))
    n = result.q.shape[1]
    backbones = _backbones(result.q[steps])
    core = np.concatenate([backbones.reshape(-1, 3), result.tip, result.goal])
    limits, first = _view_box(core, _obstacles_at(moving, result.time[0]))
    shapes = [_view_box(core, _obstacles_at(moving, result.time[s]))[1] for s in steps]
    plt = _pyplot()
    fig = plt.figure(figsize=figsize)
    try:
        ax = fig.add_axes((0.0, 0.04, 0.76, 0.86), projection="3d")
        _setup_axes(ax, limits, _auto_view(moving.scene._replace(goal=np.asarray(result.goal[0])), view))
        lines = []
        for k, ob in enumerate(first):
            if ob["kind"] == "curve":
                (ln,) = ax.plot([], [], [], color=_OBSTACLE_COLOR, lw=_radius_linewidth(ax, limits, ob["radius"], 2.5),
                                solid_capstyle="round", label="obstacle" if k == 0 else None)
            else:
                (ln,) = ax.plot([], [], [], ls="none", marker="o", ms=3, color=_POINTS_COLOR)
            lines.append(ln)
        color = _snapshot_colors(1)[0]
        arm_lw = _radius_linewidth(ax, limits, float(np.asarray(moving.scene.arm_radius)), floor=3.0)
        (arm,) = ax.plot([], [], [], color=color, lw=arm_lw, solid_capstyle="round", label="arm")
        (joints,) = ax.plot([], [], [], ls="none", marker="o", ms=5, color=color, markeredgecolor="white",
                            markeredgewidth=0.8)
        (goal,) = ax.plot([], [], [], ls="none", marker="*", ms=16, color=_GOAL_COLOR, markeredgecolor="black",
                          label="goal")
        (tip_path,) = ax.plot([], [], [], ls="--", lw=1.0, color=_PATH_COLOR, label="tip path")
        ax.scatter(0, 0, 0, marker="s", s=40, color=_BASE_COLOR, depthshade=False, label="base")
        _legend(ax, loc="upper left", bbox_to_anchor=(0.97, 0.9), fontsize=8, framealpha=0.9)
        prefix = "" if title is None else f"{title}\n"
        text = fig.suptitle("", fontsize=11, y=0.97)
        frames = list(range(len(steps))) + [len(steps) - 1] * int(round(hold * fps))
        fig.set_dpi(dpi)
        _fit_axis_labels_inside(fig, ax, limits)

        def update(k):
            s = steps[k]
            for ln, ob in zip(lines, shapes[k], strict=True):
                pts = ob["pts"]
                ln.set_data_3d(pts[:, 0], pts[:, 1], pts[:, 2])
            b = backbones[k]
            arm.set_data_3d(b[:, 0], b[:, 1], b[:, 2])
            j = b[_joint_indices(n)]
            joints.set_data_3d(j[:, 0], j[:, 1], j[:, 2])
            g = result.goal[s]
            goal.set_data_3d([g[0]], [g[1]], [g[2]])
            tip = result.tip[: s + 1]
            tip_path.set_data_3d(tip[:, 0], tip[:, 1], tip[:, 2])
            status = f" — {result.status}" if s == T else ""
            text.set_text(f"{prefix}t = {result.time[s]:.1f} s, step {s} / {T}, "
                          f"|goal - tip| = {result.error[s]:.3f}{status}")
            return (*lines, arm, joints, goal, tip_path, text)

        anim = FuncAnimation(fig, update, frames=frames, blit=False)
        anim.save(path, writer=PillowWriter(fps=fps), dpi=dpi)
    finally:
        plt.close(fig)
    return path


__all__ += ["plot_tracking", "animate_tracking"]
