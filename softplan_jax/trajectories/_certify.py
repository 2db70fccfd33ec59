"""The certificate of a smoothed path: the spline through a plan's waypoints,
proven collision-free with the package's swept check before it is timed.

Each span of the spline stays in its exact bounding box in q (the cubic's
extrema); :func:`~softplan_jax.geometry._clearance.swept_clear` from the box's
centre to a corner proves the whole box clear. A box not proven is halved up
to ``max_depth`` times; a span still not proven is timed along the plan's own
straight motion. The argument is on the documentation's actuators page.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..geometry._clearance import swept_clear
from ..geometry._obstacles import radius_and_mask, true_closest

__all__ = ["spline_box", "certify_spans", "BOX_CHUNK"]

# Boxes proven per call (one compilation per scene shape).
BOX_CHUNK = 64


def spline_box(spline, a: float, b: float):
    """``(lo, hi)`` (d,): the exact bounding box of a ``CubicSpline`` over [a, b] (its values at
    the ends and at the roots of its derivative inside)."""
    x, c = spline.x, spline.c  # c (4, m, d): p(s) = sum_k c[k, i] (s - x_i)^(3 - k) on [x_i, x_{i+1}]
    ends = spline(np.array([a, b]))
    lo, hi = ends.min(axis=0), ends.max(axis=0)
    first = max(int(np.searchsorted(x, a, side="right")) - 1, 0)
    last = min(int(np.searchsorted(x, b, side="left")), x.shape[0] - 1)
    for i in range(first, last):
        t_lo, t_hi = max(a, x[i]) - x[i], min(b, x[i + 1]) - x[i]
        A, B, C = 3.0 * c[0, i], 2.0 * c[1, i], c[2, i]
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(B * B - 4.0 * A * C)
            linear = np.where(B != 0, -C / B, np.nan)
            roots = [np.where(A != 0, (-B + root) / (2 * A), linear), np.where(A != 0, (-B - root) / (2 * A), np.nan)]
        for r in roots:
            inside = np.isfinite(r) & (r >= t_lo) & (r <= t_hi)
            rr = np.where(inside, r, 0.0)
            value = ((c[0, i] * rr + c[1, i]) * rr + c[2, i]) * rr + c[3, i]
            lo = np.where(inside, np.minimum(lo, value), lo)
            hi = np.where(inside, np.maximum(hi, value), hi)
    return lo, hi


def _box_clear(center, width, scenario, solver, contact):
    """(B,) bool: every configuration within ``width`` of ``center`` (B, n, 3) is clear."""

    def one(q_c, w):
        truth = true_closest(q_c, scenario, solver)
        radius, mask = radius_and_mask(scenario)
        c = jnp.where(mask, truth.distance - (scenario.arm_radius + radius), jnp.inf)
        return jnp.all(swept_clear(q_c, q_c + w, truth, c, contact) | ~mask)

    return jax.vmap(one)(center, width)


_box_clear_jit = package_jit(_box_clear, "exact", static_argnames=("solver",))


def _prove(boxes, scenario, solver, contact: float, n: int) -> np.ndarray:
    """Prove a list of (lo, hi) boxes (flattened q) clear, BOX_CHUNK at a time: (len,) bool."""
    out = np.zeros(len(boxes), bool)
    dtype = scenario.q0.dtype
    for a in range(0, len(boxes), BOX_CHUNK):
        part = boxes[a:a + BOX_CHUNK]
        lo = np.stack([b[0] for b in part])
        hi = np.stack([b[1] for b in part])
        center, width = 0.5 * (lo + hi), 0.5 * (hi - lo)
        positive = center[:, 0::3].min(axis=1) - width[:, 0::3].max(axis=1) > 0  # every L > 0 in the box
        pad = BOX_CHUNK - len(part)
        center = np.concatenate([center, np.repeat(center[-1:], pad, 0)]).reshape(BOX_CHUNK, n, 3)
        width = np.concatenate([width, np.repeat(width[-1:], pad, 0)]).reshape(BOX_CHUNK, n, 3)
        ok = np.asarray(_box_clear_jit(jnp.asarray(center, dtype), jnp.asarray(width, dtype), scenario, solver=solver,
                                       contact=jnp.asarray(contact, dtype)))
        out[a:a + len(part)] = ok[: len(part)] & positive
    return out


def certify_spans(spline, s, scenario, solver, contact: float, max_depth: int = 4):
    """Prove every span ``[s_k, s_{k+1}]`` of the spline clear, halving unproven boxes.

    Args:
      spline: the ``CubicSpline`` of q (flattened) in s.
      s: (K+1,) the waypoints' path parameter.
      scenario: the planned Scenario.
      solver: its exact closest-point solver options (static).
      contact: the contact tolerance (a clearance at or below it is a collision).
      max_depth: most halvings of a span's box.

    Returns:
      list over the K spans of the proven box ends (an array of s from s_k to s_{k+1}), or
      None where the span is not proven.
    """
    n = spline.c.shape[-1] // 3
    pending = [(k, float(s[k]), float(s[k + 1]), 0) for k in range(len(s) - 1)]
    proven = {k: [] for k in range(len(s) - 1)}
    failed = set()
    while pending:
        ok = _prove([spline_box(spline, a, b) for _, a, b, _ in pending], scenario, solver, contact, n)
        nxt = []
        for (k, a, b, depth), good in zip(pending, ok, strict=True):
            if k in failed:
                continue
            if good:
                proven[k].append((a, b))
            elif depth < max_depth:
                m = 0.5 * (a + b)
                nxt += [(k, a, m, depth + 1), (k, m, b, depth + 1)]
            else:
                failed.add(k)
        pending = [p for p in nxt if p[0] not in failed]
    return [None if k in failed else np.unique(np.array([e for ab in sorted(proven[k]) for e in ab]))
            for k in range(len(s) - 1)]
