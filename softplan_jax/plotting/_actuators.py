"""A timed trajectory's actuators against time (matplotlib, host side).

:func:`plot_actuators` draws a :class:`~softplan_jax.trajectories.Trajectory`:
the actuators' lengths, their speeds and (where a limit is set) their
accelerations against time, each panel with its limits drawn, one colour per
segment and one line style per actuator; the stops between pieces are marked.
Speeds are the trajectory's own; accelerations are divided differences of the
samples (what a reader of the file sees).
"""

from __future__ import annotations

import numpy as np

from ._scene import pyplot

__all__ = ["plot_actuators"]

_STYLES = ("-", "--", ":", "-.")


def _limit_lines(ax, t, values, color, signed: bool):
    """Horizontal lines at the finite limits of one segment (values (k,), equal or not)."""
    for v in np.unique(values[np.isfinite(values)]):
        for s in ((-1, 1) if signed else (1,)):
            ax.axhline(s * v, color=color, lw=0.9, ls=(0, (6, 3)), alpha=0.8)


def plot_actuators(traj, title=None, figsize=(10, 8)):
    """The actuators of a timed trajectory against time, with their limits.

    Args:
      traj: a Trajectory (``softplan_jax.time_parametrize`` or ``load_trajectory``).
      title: the figure's title (default: the path, the duration and the tightest limit).
      figsize: inches.

    Returns:
      The matplotlib Figure (2 panels, 3 with an acceleration limit).
    """
    from ..actuators._limits import finite_differences

    for field in ("t", "lengths", "speeds", "layout", "limits", "report"):
        if not hasattr(traj, field):
            raise ValueError(f"traj must be a Trajectory (softplan_jax.time_parametrize); "
                             f"{type(traj).__name__} has no {field!r}")
    plt = pyplot()
    lim = traj.limits.per_actuator(traj.layout)
    n, k = traj.layout.n_segments, traj.layout.count
    with_accel = bool(np.any(np.isfinite(lim.max_acceleration)))
    fig, axes = plt.subplots(3 if with_accel else 2, 1, sharex=True, figsize=figsize)
    colors = plt.get_cmap("tab10")(np.arange(n) % 10)
    _, accel = finite_differences(traj.t, traj.lengths)
    panels = [(traj.lengths, traj.t, "length [m]", (lim.min_length, lim.max_length), False),
              (traj.speeds, traj.t, "speed [m/s]", (lim.max_speed,), True)]
    if with_accel:
        panels.append((accel, traj.t[1:-1], "acceleration [m/s²]", (lim.max_acceleration,), True))
    for ax, (values, t, label, bounds, signed) in zip(axes, panels, strict=True):
        for i in range(n):
            for m in range(k):
                ax.plot(t, values[:, i, m], color=colors[i], ls=_STYLES[m % len(_STYLES)], lw=1.0,
                        label=f"{traj.layout.kind} {m} of segment {i}" if ax is axes[0] else None)
            for b in bounds:
                _limit_lines(ax, t, np.where(b[i] > 0, b[i], np.nan) if b is lim.min_length else b[i], colors[i],
                             signed)
        for stop in traj.stops:
            ax.axvline(stop, color="0.6", lw=0.6, ls=":")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(fontsize=7, ncol=max(1, n), loc="best")
    if title is None:
        r = traj.report
        title = (f"{traj.path} path, {traj.duration:.2f} s, {len(traj.stops)} stop(s); "
                 f"tightest limit: {r.describe() if r.tightest else 'none'}")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig
