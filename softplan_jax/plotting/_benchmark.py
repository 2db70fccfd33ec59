"""Benchmark plots: :func:`plot_benchmark`, the collision rate against the cost per step, one
labelled point per method (the exact closest points to a curve against N-point samplings of the
same obstacle)."""

from __future__ import annotations

import numpy as np

from ._scene import pyplot

__all__ = ["plot_benchmark"]


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
        plt = pyplot()
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
