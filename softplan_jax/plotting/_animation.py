"""Animated GIFs of a planned motion (:func:`animate`) and of a tracking run
(:func:`animate_tracking`), with matplotlib's PillowWriter (pillow needed) on the host; both share
one frame-and-writer loop (the argument checks, at most ``max_frames`` steps evenly spaced with
the start and the last, one 3-D axes whose box shrinks until the labels fit every frame, the
caption, the last frame held ``hold`` seconds), and each says only what its frames show."""

from __future__ import annotations

import os

import numpy as np

from ._scene import (
    BASE_COLOR,
    GOAL_COLOR,
    OBSTACLE_COLOR,
    PATH_COLOR,
    POINTS_COLOR,
    arm_backbones,
    auto_view,
    draw_scene,
    joint_indices,
    pyplot,
    radius_linewidth,
    readable_legend,
    scene_obstacles,
    setup_axes,
    snapshot_colors,
    trajectory_data,
    view_box,
)
from ._tracking import obstacles_at, tracking_data

__all__ = ["animate", "animate_tracking"]


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


def _frame_steps(iterations: int, max_frames) -> np.ndarray:
    """The steps shown of 0 .. ``iterations``: at most ``max_frames``, evenly spaced, the first and the last."""
    return np.unique(np.round(np.linspace(0, iterations, min(iterations + 1, int(max_frames)))).astype(int))


def _arm_artists(ax, limits, arm_radius):
    """The animated arm: its backbone line (width from ``arm_radius``) and joint markers, empty until a frame
    sets them."""
    arm_lw = radius_linewidth(ax, limits, float(np.asarray(arm_radius)), floor=3.0)
    color = snapshot_colors(1)[0]
    (arm,) = ax.plot([], [], [], color=color, lw=arm_lw, solid_capstyle="round", label="arm")
    (joints,) = ax.plot([], [], [], ls="none", marker="o", ms=5, color=color, markeredgecolor="white",
                        markeredgewidth=0.8)
    return arm, joints


def _show_arm(arm, joints, backbone, n_segments):
    """Move the artists of :func:`_arm_artists` to ``backbone`` (n_segments * ARM_SAMPLES + 1, 3)."""
    arm.set_data_3d(backbone[:, 0], backbone[:, 1], backbone[:, 2])
    j = backbone[joint_indices(n_segments)]
    joints.set_data_3d(j[:, 0], j[:, 1], j[:, 2])


def _show_tip_path(line, tips, step):
    """The tip path up to and including ``step``."""
    tip = tips[: step + 1]
    line.set_data_3d(tip[:, 0], tip[:, 1], tip[:, 2])


def _write_frames(path, steps, iterations, status, limits, view_scene, view, fps, hold, title, figsize, dpi,
                  draw):
    """Write the GIF of both animations and return ``path``.

    One 3-D axes with ``limits``, seen from ``view`` (default: across ``view_scene``'s goal direction);
    ``draw(ax)`` adds the artists and returns ``show(k)``, which moves them to frame k (step ``steps[k]``)
    and returns (the artists, the caption). The caption is written under ``title`` and ends in ``status``
    at the last step (``iterations``); the last frame is held ``hold`` seconds; the 3-D box is shrunk so
    that the axis labels lie inside the frame. The figure is closed in every case.
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    plt = pyplot()
    fig = plt.figure(figsize=figsize)
    try:
        ax = fig.add_axes((0.0, 0.04, 0.76, 0.86), projection="3d")
        setup_axes(ax, limits, auto_view(view_scene, view))
        show = draw(ax)
        readable_legend(ax, loc="upper left", bbox_to_anchor=(0.97, 0.9), fontsize=8, framealpha=0.9)
        prefix = "" if title is None else f"{title}\n"
        text = fig.suptitle("", fontsize=11, y=0.97)
        frames = list(range(len(steps))) + [len(steps) - 1] * int(round(hold * fps))
        fig.set_dpi(dpi)  # fit the labels at the resolution of the frames
        _fit_axis_labels_inside(fig, ax, limits)

        def update(k):
            artists, caption = show(k)
            done = f" — {status}" if steps[k] == iterations else ""
            text.set_text(f"{prefix}{caption}{done}")
            return (*artists, text)

        anim = FuncAnimation(fig, update, frames=frames, blit=False)
        anim.save(path, writer=PillowWriter(fps=fps), dpi=dpi)
    finally:
        plt.close(fig)
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
    traj = trajectory_data(scenario, result)
    T = traj["iterations"]
    steps = _frame_steps(T, max_frames)
    n = traj["q"].shape[1]
    backbones = arm_backbones(traj["q"][steps])
    core = np.concatenate([backbones.reshape(-1, 3), traj["tip"], np.asarray(scenario.goal, float)[None]])
    limits, obstacles = view_box(core, scene_obstacles(scenario))

    def draw(ax):
        path_line = draw_scene(ax, scenario, limits, obstacles, tip_path=traj["tip"][:1])
        arm, joints = _arm_artists(ax, limits, scenario.arm_radius)
        (shadow,) = ax.plot([], [], [], color="0.55", alpha=0.35, lw=1.5, zorder=1)

        def show(k):
            b = backbones[k]
            _show_arm(arm, joints, b, n)
            shadow.set_data_3d(b[:, 0], b[:, 1], np.full(len(b), limits[2, 0]))
            _show_tip_path(path_line, traj["tip"], steps[k])
            return (arm, joints, shadow, path_line), f"iteration {steps[k]} / {T}"

        return show

    return _write_frames(path, steps, T, traj["status"], limits, scenario, view, fps, hold, title, figsize, dpi,
                         draw)


def animate_tracking(result, path, fps=15, max_frames=200, hold=1.0, title=None, view=None, figsize=(8, 6),
                     dpi=80):
    """An animated GIF of a tracking run: the arm, the moving obstacles and the
    moving goal at every shown step (arguments as :func:`animate`).

    Returns:
      ``path``.
    """
    path = _check_gif_args("animate_tracking", path, fps, max_frames)
    moving = tracking_data(result)
    T = int(result.iterations)
    steps = _frame_steps(T, max_frames)
    n = result.q.shape[1]
    backbones = arm_backbones(result.q[steps])
    core = np.concatenate([backbones.reshape(-1, 3), result.tip, result.goal])
    limits, first = view_box(core, obstacles_at(moving, result.time[0]))
    shapes = [view_box(core, obstacles_at(moving, result.time[s]))[1] for s in steps]

    def draw(ax):
        lines = []
        for k, ob in enumerate(first):
            if ob["kind"] == "curve":
                (ln,) = ax.plot([], [], [], color=OBSTACLE_COLOR, lw=radius_linewidth(ax, limits, ob["radius"], 2.5),
                                solid_capstyle="round", label="obstacle" if k == 0 else None)
            else:
                (ln,) = ax.plot([], [], [], ls="none", marker="o", ms=3, color=POINTS_COLOR)
            lines.append(ln)
        arm, joints = _arm_artists(ax, limits, moving.scene.arm_radius)
        (goal,) = ax.plot([], [], [], ls="none", marker="*", ms=16, color=GOAL_COLOR, markeredgecolor="black",
                          label="goal")
        (tip_path,) = ax.plot([], [], [], ls="--", lw=1.0, color=PATH_COLOR, label="tip path")
        ax.scatter(0, 0, 0, marker="s", s=40, color=BASE_COLOR, depthshade=False, label="base")

        def show(k):
            s = steps[k]
            for ln, ob in zip(lines, shapes[k], strict=True):
                pts = ob["pts"]
                ln.set_data_3d(pts[:, 0], pts[:, 1], pts[:, 2])
            _show_arm(arm, joints, backbones[k], n)
            g = result.goal[s]
            goal.set_data_3d([g[0]], [g[1]], [g[2]])
            _show_tip_path(tip_path, result.tip, s)
            caption = f"t = {result.time[s]:.1f} s, step {s} / {T}, |goal - tip| = {result.error[s]:.3f}"
            return (*lines, arm, joints, goal, tip_path), caption

        return show

    view_scene = moving.scene._replace(goal=np.asarray(result.goal[0]))
    return _write_frames(path, steps, T, result.status, limits, view_scene, view, fps, hold, title, figsize, dpi,
                         draw)
