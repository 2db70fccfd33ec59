"""``time_parametrize``: a plan made into a timed trajectory of its actuators, as short
as their speed and acceleration limits (and an optional tip speed limit) allow.

The path is the spline through the plan's waypoints where the package's swept
check proves it clear (:mod:`._certify`), else the plan's own straight motions
(``path="linear"``: everywhere); consecutive smooth spans form one piece, each
straight motion its own, and the arm is at rest between pieces (a corner of the
polyline cannot be passed at finite acceleration). Each piece is timed by
TOPP-RA (:mod:`._topp`). The trajectory is sampled at ``rate`` Hz and at every
waypoint and box end, so that a straight chord between two samples stays on
the certified path; a piece whose samples' divided differences exceed a limit
(TOPP-RA enforces the limits at its grid points only) is slowed down uniformly
until none does. A tracked run (``softplan_jax.track``) keeps its own time
stamps: its actuator motion is reported against the limits, not re-timed.
"""

from __future__ import annotations

import math

import numpy as np

from ..actuators._layout import ActuatorLayout
from ..actuators._lengths import check_bending_radius
from ..actuators._limits import ActuatorLimits, check_limits, finite_differences
from ._certify import certify_spans
from ._paths import ActuatorPath, Piece, line_piece, plan_waypoints, spline_piece, waypoint_spline
from ._topp import time_piece
from ._trajectory import Trajectory

__all__ = ["time_parametrize", "REFUSED_STATUSES", "LIMIT_MARGIN"]

# A plan that ended so is not timed: its path is not certified collision-free.
REFUSED_STATUSES = ("collided", "start_in_collision", "non_finite")
# The samples' divided differences are kept below (1 - LIMIT_MARGIN) of every limit.
LIMIT_MARGIN = 1e-6
# Rounds of slowing a piece down whose samples exceed a limit.
SLOWDOWN_ROUNDS = 20


def _check_inputs(result, layout, limits, rate, max_tip_speed, path, max_q_speed):
    if not isinstance(layout, ActuatorLayout):
        raise ValueError(f"layout must be an ActuatorLayout (softplan_jax.actuators.actuator_layout); got "
                         f"{type(layout).__name__}")
    if not isinstance(limits, ActuatorLimits):
        raise ValueError(f"limits must be ActuatorLimits (softplan_jax.actuators.actuator_limits); got "
                         f"{type(limits).__name__}")
    q = getattr(result, "q", None)
    if q is None or getattr(result, "status", None) is None:
        raise ValueError(f"result must be a plan's or a tracked run's result (with q and status); got "
                         f"{type(result).__name__}")
    q = np.asarray(q, np.float64)
    if q.ndim != 3 or q.shape[1:] != (layout.n_segments, 3):
        raise ValueError(f"result.q has shape {q.shape}; the layout is for {layout.n_segments} segments")
    if result.status in REFUSED_STATUSES:
        raise ValueError(f"result: the run ended {result.status!r}; only a collision-free path is timed")
    if path not in ("smooth", "linear"):
        raise ValueError(f"path must be 'smooth' or 'linear'; got {path!r}")
    if not (isinstance(rate, int | float) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a finite number of samples per second > 0; got {rate!r}")
    if max_tip_speed is not None and not (math.isfinite(max_tip_speed) and max_tip_speed > 0):
        raise ValueError(f"max_tip_speed must be a finite number > 0 (or None); got {max_tip_speed!r}")
    if not (math.isfinite(max_q_speed) and max_q_speed > 0):
        raise ValueError(f"max_q_speed must be a finite number > 0; got {max_q_speed!r}")
    lim = limits.per_actuator(layout)
    if max_tip_speed is None and not np.any(np.isfinite(lim.max_speed)):
        raise ValueError("limits: timing needs a finite max_speed (or max_tip_speed): without a speed limit "
                         "the motion would take no time")
    return q, lim


def _check_lengths(lengths, layout, limits, t, what: str):
    """ValueError naming the first sample outside the length limits (``what``: where the samples are)."""
    bounds = limits._replace(max_speed=np.inf, max_acceleration=np.inf)
    report = check_limits(bounds, layout, lengths, t)
    if not report.ok:
        raise ValueError(f"limits: the plan leaves the actuators' length limits {what}: {report.first}")


def _pieces(waypoints, path, scenario, options, max_depth):
    """The pieces of the timed path and the indices of the spans timed linear."""
    K = waypoints.q.shape[0] - 1
    if path == "linear":
        return [line_piece(waypoints, k) for k in range(K)], np.arange(K)
    from ..geometry._clearance import contact_tolerance

    spline = waypoint_spline(waypoints)
    dtype = scenario.q0.dtype
    spans = certify_spans(spline, waypoints.s, scenario, options.solver, contact_tolerance(options, dtype), max_depth)
    pieces, run = [], []
    for k, breaks in enumerate([*spans, None]):
        if breaks is not None:
            run.append(breaks)
            continue
        if run:
            pieces.append(spline_piece(spline, run[0][0], run[-1][-1], np.unique(np.concatenate(run))))
            run = []
        if k < K:
            pieces.append(line_piece(waypoints, k))
    linear = np.array([k for k, b in enumerate(spans) if b is None], dtype=int)
    return pieces, linear


class _Profile:
    """One piece's timing: grid s, sdot, piecewise-constant sddot, local times; ``scale`` >= 1
    slows it down uniformly (t -> scale t)."""

    def __init__(self, piece: Piece, s, sd):
        self.piece, self.s, self.sd0 = piece, s, sd
        ds = np.diff(s)
        dt = 2.0 * ds / (sd[1:] + sd[:-1])
        if not np.all(np.isfinite(dt)):
            raise ValueError(f"limits: TOPP-RA left the path at rest inside s = [{piece.s0:.4g}, {piece.s1:.4g}]")
        self.t0 = np.concatenate([[0.0], np.cumsum(dt)])
        self.u0 = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
        self.scale = 1.0

    @property
    def duration(self) -> float:
        return float(self.t0[-1] * self.scale)

    def at_time(self, tau):
        """``(s, sdot)`` at local times tau (scaled)."""
        tau = np.clip(np.asarray(tau, np.float64) / self.scale, 0.0, self.t0[-1])
        i = np.clip(np.searchsorted(self.t0, tau, side="right") - 1, 0, self.s.shape[0] - 2)
        d = tau - self.t0[i]
        s = np.minimum(self.s[i] + self.sd0[i] * d + 0.5 * self.u0[i] * d * d, self.s[i + 1])
        return s, (self.sd0[i] + self.u0[i] * d) / self.scale

    def time_of(self, s_b):
        """Local (scaled) times at which the piece passes the path positions s_b."""
        s_b = np.asarray(s_b, np.float64)
        i = np.clip(np.searchsorted(self.s, s_b, side="right") - 1, 0, self.s.shape[0] - 2)
        h = s_b - self.s[i]
        root = np.sqrt(np.maximum(self.sd0[i] ** 2 + 2.0 * self.u0[i] * h, 0.0))
        denom = self.sd0[i] + root
        d = np.where(denom > 0, 2.0 * h / np.where(denom > 0, denom, 1.0), 0.0)
        return (self.t0[i] + d) * self.scale


def _sample_times(profiles, rate: float):
    """Sample times: every 1/rate s, every break of every piece (uniform samples closer than a
    quarter period to one dropped); with each sample's piece index."""
    starts = np.concatenate([[0.0], np.cumsum([p.duration for p in profiles])])
    total = starts[-1]
    breaks = np.unique(np.concatenate([starts[j] + p.time_of(p.piece.breaks) for j, p in enumerate(profiles)]
                                      + [starts]))
    # One sample for breaks that coincide up to rounding (a piece's end and the next one's start): two samples
    # 1e-15 s apart would turn the rounding of their lengths into huge divided differences.
    breaks = breaks[np.concatenate([np.diff(breaks) > 1e-6 / rate, [True]])]
    uniform = np.arange(int(math.floor(total * rate)) + 1) / rate
    near = np.abs(uniform[:, None] - breaks[None, :]).min(axis=1) < 0.25 / rate
    t = np.unique(np.concatenate([uniform[~near], breaks]))
    t = t[t <= total]
    owner = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(profiles) - 1)
    return t, owner, starts


def _evaluate(profiles, t, owner, starts, layout):
    """q, lengths, speeds, tip at the sample times."""
    from ._paths import path_terms

    n, k = layout.n_segments, layout.count
    q = np.zeros((t.shape[0], n * 3))
    lengths = np.zeros((t.shape[0], n * k))
    speeds, tip = np.zeros_like(lengths), np.zeros((t.shape[0], 3))
    for j, p in enumerate(profiles):
        rows = np.nonzero(owner == j)[0]
        if rows.size == 0:
            continue
        s, sd = p.at_time(t[rows] - starts[j])
        qs, dq = p.piece.q(s, 0), p.piece.q(s, 1)
        l, l1, _, x, _ = path_terms(qs, dq, np.zeros_like(dq), layout)
        q[rows], lengths[rows], speeds[rows], tip[rows] = qs, l, l1 * sd[:, None], x
    return q.reshape(-1, n, 3), lengths.reshape(-1, n, k), speeds.reshape(-1, n, k), tip


def _excess(t, lengths, tip, lim, max_tip_speed):
    """Per sample interval, the factor by which time must stretch to bring the divided differences
    within (1 - LIMIT_MARGIN) of the limits (1: none needed); (T-1,)."""
    flat = lengths.reshape(lengths.shape[0], -1)
    speed, accel = finite_differences(t, flat)
    target = 1.0 - LIMIT_MARGIN
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.max(np.abs(speed) / lim.max_speed.reshape(-1), axis=1) / target
        a = np.sqrt(np.max(np.abs(accel) / lim.max_acceleration.reshape(-1), axis=1) / target)
    need[1:] = np.maximum(need[1:], a)
    need[:-1] = np.maximum(need[:-1], a)
    if max_tip_speed is not None:
        tip_speed = np.linalg.norm(np.diff(tip, axis=0), axis=1) / np.diff(t)
        need = np.maximum(need, tip_speed / (max_tip_speed * target))
    return need


def _initial_grid(piece: Piece, grid: int):
    """TOPP-RA's grid of a piece: ``grid`` intervals between consecutive breaks, and a short first and
    last interval (1e-4 of the first and last span): the piece starts and ends at rest, and with no
    acceleration limit its first interval would otherwise be crossed at half speed on average."""
    b = piece.breaks
    ends = [b[0] + 1e-4 * (b[1] - b[0]), b[-1] - 1e-4 * (b[-1] - b[-2])]
    return np.unique(np.concatenate([np.linspace(x, y, grid + 1) for x, y in zip(b[:-1], b[1:], strict=True)]
                                    + [ends]))


def _refined(profile, tau, split: int = 4):
    """The piece's grid with the intervals around the local times tau (and their neighbours) split."""
    t0 = profile.t0 * profile.scale
    i = np.clip(np.searchsorted(t0, tau, side="right") - 1, 0, t0.shape[0] - 2)
    marked = np.unique(np.clip(np.concatenate([i - 1, i, i + 1]), 0, t0.shape[0] - 2))
    s = profile.s
    extra = [np.linspace(s[m], s[m + 1], split + 1)[1:-1] for m in marked]
    return np.unique(np.concatenate([s, *extra]))


def _time_planned(pieces, layout, lim, max_tip_speed, max_q_speed, rate, grid, refinements: int = 1):
    """Time every piece, sample, and where the samples' divided differences exceed a limit, refine
    TOPP-RA's grid there (``refinements`` rounds), then slow the piece down uniformly."""
    vmax, amax = lim.max_speed.reshape(-1), lim.max_acceleration.reshape(-1)

    def timed(piece, ss):
        path = ActuatorPath(piece, layout)
        return _Profile(piece, *time_piece(piece, path, vmax, amax, max_tip_speed, max_q_speed, ss))

    profiles = [timed(piece, _initial_grid(piece, grid)) for piece in pieces]
    for round_ in range(refinements + SLOWDOWN_ROUNDS):
        t, owner, starts = _sample_times(profiles, rate)
        q, lengths, speeds, tip = _evaluate(profiles, t, owner, starts, layout)
        need = _excess(t, lengths, tip, lim, max_tip_speed)
        if np.all(need <= 1.0):
            return t, q, lengths, speeds, tip, profiles, starts
        for j in np.unique(owner[:-1][need > 1.0]):
            bad = np.nonzero((owner[:-1] == j) & (need > 1.0))[0]
            if round_ < refinements:
                tau = np.concatenate([t[bad], t[bad + 1]]) - starts[j]
                profiles[j] = timed(profiles[j].piece, _refined(profiles[j], tau))
            else:
                profiles[j].scale *= float(np.max(need[bad])) * (1.0 + 1e-9)
    raise ValueError("limits: the timed samples still exceed a limit after slowing down "
                     f"{SLOWDOWN_ROUNDS} times (the limits may be too tight for the plan's resolution)")


def _tracked(result, layout, limits, q, lim):
    """A tracked run's own time stamps; its actuator motion reported against the limits."""
    from ..actuators._lengths import actuator_lengths

    t = np.asarray(result.time, np.float64)
    lengths = np.stack([np.asarray(actuator_lengths(qk, layout), np.float64) for qk in q])
    speeds = np.gradient(lengths, t, axis=0) if t.shape[0] > 1 else np.zeros_like(lengths)
    report = check_limits(limits, layout, lengths, t)
    return Trajectory(t=t - t[0], q=q, lengths=lengths, speeds=speeds, tip=np.asarray(result.tip, np.float64),
                      layout=layout, limits=limits, status=result.status, path="tracked",
                      duration=float(t[-1] - t[0]), stops=np.zeros(0), waypoints=q, waypoint_times=t - t[0],
                      linear_spans=np.zeros(0, int), report=report, max_tip_speed=None)


def time_parametrize(result, layout: ActuatorLayout, limits: ActuatorLimits, scenario=None, *, path: str = "smooth",
                     rate: float = 100.0, max_tip_speed: float | None = None, options=None, grid: int = 32,
                     max_depth: int = 4, max_q_speed: float = 100.0) -> Trajectory:
    """Time a plan along its certified path as fast as the actuator limits allow (TOPP-RA).

    Planned results (``softplan_jax.plan``, ``plan_fallback``): the path through the plan's
    configurations is timed from rest to rest under the actuators' speed and acceleration
    limits (and ``max_tip_speed``), by TOPP-RA on a path in actuator-length space (module
    docstring). ``path="smooth"`` (default) takes the cubic spline through the waypoints
    where ``softplan_jax.geometry._clearance.swept_clear`` proves it clear in ``scenario``
    and the plan's straight motions elsewhere; ``"linear"`` the straight motions throughout,
    stopping at every waypoint. A tracked run (``softplan_jax.track``) keeps its time
    stamps; its :class:`~.trajectory.Trajectory` ``report`` says where the limits are exceeded.

    Args:
      result: a PlanResult or TrackResult whose status is not collided, start_in_collision or
        non_finite.
      layout: the actuators (``softplan_jax.actuators.actuator_layout``), n segments as the plan.
      limits: their limits (``softplan_jax.actuators.actuator_limits``); a finite ``max_speed``
        (or ``max_tip_speed``) is needed.
      scenario: the planned Scenario (required by ``path="smooth"``: the spline is proven clear in it).
      path: "smooth" or "linear".
      rate: samples per second (every waypoint and stop is a sample too).
      max_tip_speed: a limit on the tip's speed [m/s], or None.
      options: the plan's PlanOptions (its solver and contact tolerance; default ``make_options()``).
      grid: TOPP-RA grid points per span between waypoints.
      max_depth: most halvings of a span's box when proving the spline clear.
      max_q_speed: bound on ``|dq/dt|`` [1/s] that binds only where the actuators barely move.

    Returns:
      :class:`~.trajectory.Trajectory` (for a plan: every sample within every limit).

    Raises:
      ValueError: bad arguments, a refused status, a plan that leaves the actuators' length
        limits or bending radius (the first violation named), or limits that admit no timing.
    """
    q, lim = _check_inputs(result, layout, limits, rate, max_tip_speed, path, max_q_speed)
    if hasattr(result, "time") and hasattr(result, "moving"):
        return _tracked(result, layout, limits, q, lim)
    if path == "smooth" and scenario is None:
        raise ValueError("scenario: path='smooth' proves the spline clear in the planned scene; pass scenario= "
                         "(or path='linear')")
    if int(grid) != grid or grid < 1 or int(max_depth) != max_depth or max_depth < 0:
        raise ValueError(f"grid must be an integer >= 1 and max_depth >= 0; got {grid}, {max_depth}")
    from ..actuators._lengths import actuator_lengths

    for k, qk in enumerate(q):
        try:
            check_bending_radius(qk, np.asarray(layout.radius), layout.kind)
        except ValueError as err:
            raise ValueError(f"layout: at step {k} of the plan: {err}") from None
    _check_lengths(np.stack([np.asarray(actuator_lengths(qk, layout)) for qk in q]), layout, limits, None,
                   "(sample = step of the plan)")
    waypoints = plan_waypoints(q)
    if options is None:
        from ..planning._planner import make_options

        options = make_options()
    pieces, linear = _pieces(waypoints, path, scenario, options, max_depth)
    t, qs, lengths, speeds, tip, profiles, starts = _time_planned(pieces, layout, lim, max_tip_speed, max_q_speed,
                                                                   rate, grid)
    for k in range(0, qs.shape[0], max(1, qs.shape[0] // 200)):  # the spline's samples inside the bending radius
        check_bending_radius(qs[k], np.asarray(layout.radius), layout.kind)
    _check_lengths(lengths, layout, limits, t, "along the timed path")
    kind = "linear" if linear.size == waypoints.q.shape[0] - 1 else "smooth" if linear.size == 0 else "mixed"
    way_t = np.concatenate([starts[j] + p.time_of(waypoints.s[(waypoints.s >= p.piece.s0) & (waypoints.s < p.piece.s1)])
                            for j, p in enumerate(profiles)] + [starts[-1:]])
    return Trajectory(t=t, q=qs, lengths=lengths, speeds=speeds, tip=tip, layout=layout, limits=limits,
                      status=str(result.status), path=kind, duration=float(t[-1]), stops=starts[1:-1],
                      waypoints=waypoints.q, waypoint_times=way_t, linear_spans=linear,
                      report=check_limits(limits, layout, lengths, t), max_tip_speed=max_tip_speed)
