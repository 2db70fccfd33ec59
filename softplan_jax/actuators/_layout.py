"""Where the actuators sit: :class:`ActuatorLayout` (tendons or chambers, their
distance from the backbone and their angles in the twist-free frame, per
segment) and the checks every actuator function makes of an arrangement.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..base._validation import as_float_array, is_concrete

__all__ = ["KINDS", "ActuatorLayout", "actuator_layout", "check_arrangement"]

KINDS = ("tendon", "chamber")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ActuatorLayout:
    """The actuators of an arm (a pytree: ``radius`` and ``angles`` are leaves, ``kind`` static).

    Attributes:
      kind: "tendon" (tendon m of segment i runs from the base to segment i's tip) or
        "chamber" (extensible actuators within each segment).
      radius: (n,) distance of segment i's actuators from the backbone.
      angles: (n, k) their angles [rad] from the base frame's x axis, carried along the
        backbone without twist.
    """

    radius: jax.Array
    angles: jax.Array
    kind: str = dataclasses.field(default="tendon", metadata=dict(static=True))

    @property
    def n_segments(self) -> int:
        return self.angles.shape[0]

    @property
    def count(self) -> int:
        """Actuators per segment, k."""
        return self.angles.shape[1]

    def to_dict(self) -> dict:
        """JSON form: ``{"kind", "count", "radius": [n], "angles": [[k] * n]}``."""
        return {"kind": self.kind, "count": self.count, "radius": np.asarray(self.radius, float).tolist(),
                "angles": np.asarray(self.angles, float).tolist()}


def check_arrangement(radius, angles, n: int):
    """``(radius (n,), angles (n, k))`` from a scalar or (n,) radius and (k,) or (n, k) angles.

    Raises:
      ValueError: a shape that does not fit n segments, fewer than 3 actuators, a radius that is not
        finite and > 0, or (concrete input) angles that are not finite, coincide, or leave a gap of
        180 degrees or more (actuators must surround the backbone to bend it every way).
    """
    radius = as_float_array(radius, "radius")
    angles = as_float_array(angles, "angles")
    if radius.ndim > 1 or (radius.ndim == 1 and radius.shape[0] != n):
        raise ValueError(f"radius must be a scalar or (n,) = ({n},), one per segment; got shape {radius.shape}")
    if angles.ndim not in (1, 2) or (angles.ndim == 2 and angles.shape[0] != n):
        raise ValueError(f"angles must have shape (k,) or (n, k) = ({n}, k); got {angles.shape}")
    k = angles.shape[-1]
    if k < 3:
        raise ValueError(f"angles: a segment needs at least 3 actuators to bend every way and extend; got {k}")
    radius = jnp.broadcast_to(radius, (n,))
    angles = jnp.broadcast_to(angles, (n, k))
    if is_concrete(radius):
        r = np.asarray(radius, np.float64)
        if not np.all(np.isfinite(r)) or np.any(r <= 0):
            raise ValueError(f"radius must be finite and > 0; got {r.tolist()}")
    if is_concrete(angles):
        a = np.asarray(angles, np.float64)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"angles must be finite; got {a.tolist()}")
        wrapped = np.sort(np.mod(a, 2 * math.pi), axis=1)
        gaps = np.diff(np.concatenate([wrapped, wrapped[:, :1] + 2 * math.pi], axis=1), axis=1)
        if np.any(gaps < 1e-9):
            i = int(np.argmax(np.any(gaps < 1e-9, axis=1)))
            raise ValueError(f"angles: two actuators of segment {i} sit at the same angle: {a[i].tolist()}")
        if np.any(gaps >= math.pi):
            i = int(np.argmax(np.any(gaps >= math.pi, axis=1)))
            raise ValueError(f"angles: the actuators of segment {i} leave a gap of {math.degrees(gaps[i].max()):.1f} "
                             f"deg (>= 180) around the backbone: {a[i].tolist()}; they must surround it")
    return radius, angles


def actuator_layout(kind: str, n_segments: int, count: int = 3, radius=0.03, angles=None,
                    dtype=None) -> ActuatorLayout:
    """An :class:`ActuatorLayout`, by default ``count`` actuators evenly spaced around each segment.

    With ``angles=None``, segment i's actuators sit at ``2 pi m / k`` (m = 0..k-1); tendons
    are also turned by ``2 pi i / (k n)`` per segment, so that the ``n k`` tendons, which
    share the spacer disks of the proximal segments, pass through ``n k`` distinct holes.

    Args:
      kind: "tendon" or "chamber".
      n_segments: n.
      count: k >= 3 actuators per segment (ignored when ``angles`` is given).
      radius: scalar or (n,), > 0.
      angles: None, (k,) or (n, k) [rad].
      dtype: of the arrays (default: jax's default float).

    Raises:
      ValueError: an unknown kind, n < 1, or an arrangement :func:`check_arrangement` refuses.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}; got {kind!r}")
    if int(n_segments) != n_segments or n_segments < 1:
        raise ValueError(f"n_segments must be an integer >= 1; got {n_segments}")
    n = int(n_segments)
    if angles is None:
        if int(count) != count or count < 3:
            raise ValueError(f"count: a segment needs at least 3 actuators to bend every way and extend; got {count}")
        k = int(count)
        stagger = 2 * math.pi / (k * n) if kind == "tendon" else 0.0
        angles = 2 * math.pi * np.arange(k)[None, :] / k + stagger * np.arange(n)[:, None]
    dtype = dtype or jnp.result_type(float)
    radius, angles = check_arrangement(radius, angles, n)
    return ActuatorLayout(radius=radius.astype(dtype), angles=angles.astype(dtype), kind=kind)
