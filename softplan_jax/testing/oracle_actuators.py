"""Independent NumPy reference for actuator lengths: each tendon's (or chamber's) path
sampled densely along the backbone, offset from it in a frame carried by parallel
transport, and measured as a polyline.

The backbone and its tangent come from :mod:`.oracle_geometry` (the paper's formulas,
section 2.1); the frame is propagated by a plain loop: at every sample it is turned by
the smallest rotation that takes the previous tangent to the next one (Rodrigues'
formula), which is exactly the twist-free (Bishop) frame along an arc. Nothing of the
closed form of ``softplan_jax.actuators`` (the bending directions, eq. A1) is used.
"""

from __future__ import annotations

import math

import numpy as np

from .oracle_geometry import segment_point_derivs

__all__ = ["transported_offsets", "tendon_lengths_sampled", "chamber_lengths_sampled"]


def _rotate(v, a, b):
    """v turned by the smallest rotation taking unit vector a to unit vector b (Rodrigues), in floats."""
    kx, ky, kz = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]
    s = math.sqrt(kx * kx + ky * ky + kz * kz)
    if s < 1e-300:
        return v
    c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    kx, ky, kz = kx / s, ky / s, kz / s
    dot = kx * v[0] + ky * v[1] + kz * v[2]
    cx, cy, cz = ky * v[2] - kz * v[1], kz * v[0] - kx * v[2], kx * v[1] - ky * v[0]
    return (v[0] * c + cx * s + kx * dot * (1 - c), v[1] * c + cy * s + ky * dot * (1 - c),
            v[2] * c + cz * s + kz * dot * (1 - c))


def transported_offsets(q, samples: int = 4000):
    """Backbone points and the twist-free frame's x and y axes, segment by segment.

    Args:
      q: (n, 3) configuration.
      samples: points per segment (both ends included).

    Returns:
      list over segments of (points (samples, 3), ex (samples, 3), ey (samples, 3)).
    """
    q = np.asarray(q, np.float64)
    s = np.linspace(0.0, 1.0, samples)
    ex, ey, t_prev = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    out = []
    for i in range(q.shape[0]):
        F, dF, _ = segment_point_derivs(q, i, s)
        tangents = (dF / np.linalg.norm(dF, axis=1, keepdims=True)).tolist()
        X, Y = np.empty_like(F), np.empty_like(F)
        for j, t in enumerate(tangents):
            ex, ey, t_prev = _rotate(ex, t_prev, t), _rotate(ey, t_prev, t), t
            X[j], Y[j] = ex, ey
        out.append((F, X, Y))
    return out


def _polyline(points):
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def _offset_path(frames, i, r, alpha):
    P, X, Y = frames[i]
    return P + r * (np.cos(alpha) * X + np.sin(alpha) * Y)


def tendon_lengths_sampled(q, radius, angles, samples: int = 4000):
    """(n, k) polyline lengths of the tendons: tendon m of segment t at (radius[t], angles[t, m])
    from the base to segment t's tip."""
    frames = transported_offsets(q, samples)
    radius, angles = np.asarray(radius, float), np.asarray(angles, float)
    n, k = angles.shape
    out = np.zeros((n, k))
    for t in range(n):
        for m in range(k):
            out[t, m] = sum(_polyline(_offset_path(frames, j, radius[t], angles[t, m])) for j in range(t + 1))
    return out


def chamber_lengths_sampled(q, radius, angles, samples: int = 4000):
    """(n, k) polyline lengths of the chambers: chamber m of segment i at (radius[i], angles[i, m])
    along segment i only."""
    frames = transported_offsets(q, samples)
    radius, angles = np.asarray(radius, float), np.asarray(angles, float)
    n, k = angles.shape
    return np.array([[_polyline(_offset_path(frames, i, radius[i], angles[i, m])) for m in range(k)]
                     for i in range(n)])
