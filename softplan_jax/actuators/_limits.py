"""Actuator limits: :class:`ActuatorLimits` (length range, speed, acceleration, per
actuator or per segment), their check on a sampled motion (:func:`check_limits`,
speeds and accelerations by divided differences of the samples, the first
violation named) and the segment length limits that follow from them
(:func:`segment_length_limits`, the box the planner clips ``L`` to).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._layout import ActuatorLayout

__all__ = ["ActuatorLimits", "actuator_limits", "LimitReport", "check_limits", "finite_differences",
           "segment_length_limits", "actuator_name"]

_FIELDS = ("min_length", "max_length", "max_speed", "max_acceleration")
_UNITS = {"min_length": "m", "max_length": "m", "max_speed": "m/s", "max_acceleration": "m/s^2"}


class ActuatorLimits(NamedTuple):
    """Limits of the actuators (host-side NumPy; each a scalar, (n,) per segment or (n, k) per
    actuator; +inf, or 0 for ``min_length``, where there is none).

    Attributes:
      min_length, max_length: range of every actuator's length [m].
      max_speed: largest |d length / dt| [m/s].
      max_acceleration: largest |d^2 length / dt^2| [m/s^2].
    """

    min_length: np.ndarray
    max_length: np.ndarray
    max_speed: np.ndarray
    max_acceleration: np.ndarray

    def per_actuator(self, layout: ActuatorLayout) -> ActuatorLimits:
        """Every field broadcast to the layout's (n, k) (ValueError if a shape does not fit)."""
        n, k = layout.n_segments, layout.count
        out = {}
        for name in _FIELDS:
            v = np.asarray(getattr(self, name), np.float64)
            if v.ndim == 1:
                v = v[:, None]
            try:
                out[name] = np.broadcast_to(v, (n, k)).copy()
            except ValueError:
                raise ValueError(f"limits.{name} has shape {np.shape(getattr(self, name))}; use a scalar, (n,) = "
                                 f"({n},) per segment or (n, k) = ({n}, {k}) per actuator") from None
        return ActuatorLimits(**out)

    def to_dict(self) -> dict:
        """JSON form: each field a number or nested lists, null for no limit."""
        def clean(v):
            v = np.asarray(v, float)
            if v.ndim == 0:
                return None if not math.isfinite(float(v)) or (float(v) == 0.0) else float(v)
            return [clean(x) for x in v]

        return {name: clean(getattr(self, name)) for name in _FIELDS} | {"units": dict(_UNITS)}


def _limit(value, name: str, default: float):
    if value is None:
        return np.asarray(default, np.float64)
    try:
        v = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"limits.{name} must be a number or an array of numbers; got {value!r}") from None
    if v.ndim > 2:
        raise ValueError(f"limits.{name} must be a scalar, (n,) or (n, k); got shape {v.shape}")
    if np.any(np.isnan(v)) or np.any(v == -math.inf):
        raise ValueError(f"limits.{name} must not be NaN or -inf; got {v.tolist()}")
    v = np.where(np.isposinf(v) if name != "min_length" else False, default, v)
    if np.any(v <= 0):
        raise ValueError(f"limits.{name} must be > 0; got {v.tolist()}")
    return v


def actuator_limits(min_length=None, max_length=None, max_speed=None, max_acceleration=None) -> ActuatorLimits:
    """:class:`ActuatorLimits` from numbers or arrays (None: no limit), validated.

    Raises:
      ValueError: a limit <= 0, NaN, of more than 2 dimensions, or ``min_length >= max_length``.
    """
    lim = ActuatorLimits(_limit(min_length, "min_length", 0.0), _limit(max_length, "max_length", math.inf),
                         _limit(max_speed, "max_speed", math.inf), _limit(max_acceleration, "max_acceleration", math.inf))
    if min_length is not None and np.isposinf(lim.min_length).any():
        raise ValueError("limits.min_length must be finite")
    try:
        lo, hi = np.broadcast_arrays(lim.min_length, lim.max_length)
    except ValueError:
        raise ValueError(f"limits.min_length {lim.min_length.shape} and max_length {lim.max_length.shape} "
                         "have shapes that do not fit together") from None
    if np.any(lo >= hi):
        raise ValueError(f"limits: min_length must be below max_length; got {lim.min_length.tolist()} and "
                         f"{lim.max_length.tolist()}")
    return lim


def actuator_name(kind: str, i: int, m: int) -> str:
    """``"tendon 2 of segment 0"`` (0-based, as in code)."""
    return f"{kind} {m} of segment {i}"


def finite_differences(t, lengths):
    """Speeds and accelerations of sampled lengths by divided differences.

    Args:
      t: (T,) increasing times.
      lengths: (T, ...) samples.

    Returns:
      ``(speed (T-1, ...), acceleration (T-2, ...))``: ``(l_{j+1} - l_j) / (t_{j+1} - t_j)``
      and ``2 l[t_{j-1}, t_j, t_{j+1}]`` (twice the second divided difference). For a motion
      whose speed is continuous, each is a weighted mean of the true speed, resp. acceleration,
      so neither exceeds the true maximum.
    """
    t = np.asarray(t, np.float64)
    lengths = np.asarray(lengths, np.float64)
    shape = (-1,) + (1,) * (lengths.ndim - 1)
    dt = np.diff(t).reshape(shape)
    speed = np.diff(lengths, axis=0) / dt
    accel = 2.0 * np.diff(speed, axis=0) / (dt[1:] + dt[:-1])
    return speed, accel


class LimitReport(NamedTuple):
    """A motion checked against its actuator limits.

    Attributes:
      ok: every sample within every limit.
      first: the first violation in time, in words (None: none).
      usage: limit name -> the largest fraction of it used (> 1: exceeded), over every
        actuator and sample (``min_length``: the limit over the shortest length).
      tightest: the name of the limit with the largest usage (None: no finite limit).
      where: limit name -> (time or sample index, actuator name) of that largest usage.
      violations: limit name -> number of samples at which it is exceeded.
    """

    ok: bool
    first: str | None
    usage: dict
    tightest: str | None
    where: dict
    violations: dict

    def describe(self, name: str | None = None) -> str:
        """``"max_speed 99.9 % (tendon 2 of segment 1 at t = 3.20 s)"`` for a limit (default: the tightest)."""
        name = name or self.tightest
        if name is None:
            return "no finite limit"
        when, who = self.where[name]
        return f"{name} {100 * self.usage[name]:.1f} % ({who} at {when})"


def _usage(values, limit, lower: bool):
    """Fraction of the limit used at every sample (values (S, n, k), limit (n, k))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if lower:
            u = np.where(limit > 0, limit / np.maximum(values, 1e-300), 0.0)
        else:
            u = np.where(np.isfinite(limit), np.abs(values) / limit, 0.0)
    return np.broadcast_to(u, values.shape)


def check_limits(limits: ActuatorLimits, layout: ActuatorLayout, lengths, t=None) -> LimitReport:
    """Check sampled actuator lengths against the limits, naming the first violation.

    Lengths are checked at every sample; with times ``t``, speeds and accelerations too, by
    :func:`finite_differences` of the samples (what a reader of the samples sees). A sample
    counts as within a limit up to a relative 1e-9 (rounding).

    Args:
      limits: the limits (scalars, (n,) or (n, k)).
      layout: the actuators (for the shapes and the names).
      lengths: (T, n, k) actuator lengths.
      t: (T,) increasing times, or None (lengths only).

    Returns:
      :class:`LimitReport`.
    """
    lim = limits.per_actuator(layout)
    lengths = np.asarray(lengths, np.float64)
    n, k = layout.n_segments, layout.count
    if lengths.ndim != 3 or lengths.shape[1:] != (n, k):
        raise ValueError(f"lengths must have shape (T, {n}, {k}); got {lengths.shape}")
    # name -> (values, limit, a lower limit?, index of the sample a value is reported at: an acceleration
    # is centred on the middle of its three samples)
    series = {"min_length": (lengths, lim.min_length, True, 0), "max_length": (lengths, lim.max_length, False, 0)}
    stamps = np.arange(lengths.shape[0]) if t is None else np.asarray(t, np.float64)
    if t is not None:
        if stamps.shape != (lengths.shape[0],) or np.any(np.diff(stamps) <= 0):
            raise ValueError("t must be (T,) strictly increasing times, one per sample")
        speed, accel = finite_differences(stamps, lengths)
        series["max_speed"] = (speed, lim.max_speed, False, 0)
        series["max_acceleration"] = (accel, lim.max_acceleration, False, 1)
    usage, where, violations, first = {}, {}, {}, None
    for name, (values, limit, lower, offset) in series.items():
        if not np.any(limit > 0) if lower else not np.any(np.isfinite(limit)):
            continue
        u = _usage(values, limit, lower)
        flat = int(np.argmax(u))
        j, i, m = np.unravel_index(flat, u.shape)
        usage[name] = float(u[j, i, m])
        when = f"sample {j + offset}" if t is None else f"t = {stamps[j + offset]:.3f} s"
        where[name] = (when, actuator_name(layout.kind, int(i), int(m)))
        over = u > 1.0 + 1e-9
        violations[name] = int(np.sum(np.any(over, axis=(1, 2))))
        if over.any():
            j0 = int(np.argmax(np.any(over, axis=(1, 2))))
            i0, m0 = np.unravel_index(int(np.argmax(u[j0])), u.shape[1:])
            value = float(values[j0, i0, m0])
            j0 += offset
            when0 = f"sample {j0}" if t is None else f"t = {stamps[j0]:.3f} s"
            text = (f"{name}: {actuator_name(layout.kind, int(i0), int(m0))} at {when0}: "
                    f"{abs(value):.6g} {'<' if lower else '>'} {float(limit[i0, m0]):.6g} {_UNITS[name]}")
            if first is None or stamps[j0] < first[0]:
                first = (stamps[j0], text)
    tightest = max(usage, key=usage.get) if usage else None
    return LimitReport(ok=first is None, first=None if first is None else first[1], usage=usage, tightest=tightest,
                       where=where, violations=violations)


def segment_length_limits(layout: ActuatorLayout, limits: ActuatorLimits):
    """The segment length limits that follow from the actuators' length limits: outside them no
    configuration keeps every actuator within its range (a necessary condition; inside, the
    full check decides).

    Actuators that surround the backbone (every gap between neighbours < 180 deg, which
    :func:`~softplan_jax.actuators._layout.check_arrangement` requires) have convex weights
    ``w_m`` with ``sum w_m (cos alpha_m, sin alpha_m) = 0``, so by eq. (A1)
    ``sum_m w_m c(r, alpha_m) = L``: a segment's length is a mean of its chambers' lengths,
    and ``L_1 + ... + L_i`` a mean of segment i's tendon lengths. Hence chambers:
    ``min_m lo_im <= L_i <= max_m hi_im``; tendons: the same bounds on the cumulative length,
    which give ``L_i <= hi_i - (L_min_1 + ... + L_min_{i-1})`` and
    ``L_i >= lo_i - (L_max_1 + ... + L_max_{i-1})``.

    Args:
      layout: the actuators.
      limits: their limits.

    Returns:
      ``(L_min (n,), L_max (n,))`` NumPy; 0 and +inf where there is no bound.

    Raises:
      ValueError: the limits admit no segment length (``limits`` infeasible).
    """
    lim = limits.per_actuator(layout)
    lo = np.min(lim.min_length, axis=1)
    hi = np.max(lim.max_length, axis=1)
    if layout.kind == "chamber":
        L_min, L_max = lo, hi
    else:
        L_min, L_max = np.zeros_like(lo), np.zeros_like(hi)
        below_min, below_max = 0.0, 0.0
        for i in range(lo.shape[0]):
            L_max[i] = hi[i] - below_min
            L_min[i] = max(lo[i] - below_max, 0.0)
            below_min += L_min[i]
            below_max += L_max[i]
    bad = L_min >= L_max
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"limits: the actuators' length limits admit no length of segment {i} "
                         f"(it would need {L_min[i]:.4g} <= L <= {L_max[i]:.4g})")
    return L_min, L_max
