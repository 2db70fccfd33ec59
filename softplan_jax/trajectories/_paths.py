"""The geometric path a plan is timed along, and its derivatives in actuator space.

A plan is a polyline in configuration space, ``q_0 .. q_K``; the planner's
certificate covers the straight motions ``q_k -> q_{k+1}``. The path parameter
``s`` is the cumulative Euclidean length of the polyline in q (``s_k`` at
waypoint k, q flattened row-major). Two paths through the waypoints are
offered: the polyline itself (one straight motion per piece,
:func:`line_piece`), and the cubic spline of q in s through every waypoint
(:func:`waypoint_spline`: SciPy's ``CubicSpline``, not-a-knot ends), which has
no corners and must be certified again (:mod:`._certify`). :class:`ActuatorPath`
presents a piece of either to TOPP-RA (``toppra``) as a path in actuator-length
space: the lengths ``l(q(s))`` and their exact first and second derivatives in
s (``jax.jvp``), so that TOPP-RA's joint velocity and acceleration constraints
act on the actuators themselves.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..actuators._layout import ActuatorLayout
from ..actuators._lengths import length_function
from ..base._compilation_cache import package_jit
from ..geometry._kinematics import tip_position

__all__ = ["Waypoints", "plan_waypoints", "waypoint_spline", "Piece", "line_piece", "spline_piece", "path_terms",
           "ActuatorPath"]


class Waypoints(NamedTuple):
    """A plan's configurations with their path parameter.

    Attributes:
      q: (K+1, n, 3) waypoints, consecutive repeats removed.
      s: (K+1,) cumulative Euclidean length of the polyline in q (flattened), s[0] = 0.
    """

    q: np.ndarray
    s: np.ndarray


def plan_waypoints(q) -> Waypoints:
    """The plan's configurations (T, n, 3) as :class:`Waypoints` (a step that does not move is dropped).

    Raises:
      ValueError: the plan does not move (fewer than two distinct configurations).
    """
    q = np.asarray(q, np.float64)
    flat = q.reshape(q.shape[0], -1)
    step = np.linalg.norm(np.diff(flat, axis=0), axis=1)
    keep = np.concatenate([[True], step > 0])
    q, step = q[keep], step[step > 0]
    if q.shape[0] < 2:
        raise ValueError("result: the plan does not move (one configuration); there is nothing to time")
    return Waypoints(q=q, s=np.concatenate([[0.0], np.cumsum(step)]))


def waypoint_spline(waypoints: Waypoints):
    """The cubic spline of q (flattened) in s through every waypoint (not-a-knot ends;
    a straight line for two waypoints): a ``scipy.interpolate.CubicSpline``."""
    from scipy.interpolate import CubicSpline

    flat = waypoints.q.reshape(waypoints.q.shape[0], -1)
    if flat.shape[0] == 2:
        return CubicSpline(waypoints.s, flat, bc_type="natural", axis=0)
    return CubicSpline(waypoints.s, flat, bc_type="not-a-knot", axis=0)


class Piece(NamedTuple):
    """One piece of the timed path, from rest to rest.

    Attributes:
      kind: "smooth" (the spline) or "linear" (one straight motion of the plan).
      s0, s1: its range of the path parameter.
      q: ``q(ss, order)`` -> (len(ss), 3n): the configuration (order 0) or its
        first or second derivative in s.
      breaks: the values of s in [s0, s1] that must be samples of the timed trajectory
        (waypoints, ends of certified boxes): a straight chord between two samples then
        stays within one certified region.
    """

    kind: str
    s0: float
    s1: float
    q: object
    breaks: np.ndarray


def line_piece(waypoints: Waypoints, k: int) -> Piece:
    """The plan's straight motion ``q_k -> q_{k+1}`` as a piece."""
    s0, s1 = float(waypoints.s[k]), float(waypoints.s[k + 1])
    qa = waypoints.q[k].reshape(-1)
    slope = (waypoints.q[k + 1].reshape(-1) - qa) / (s1 - s0)

    def q(ss, order=0):
        ss = np.atleast_1d(np.asarray(ss, np.float64))
        if order == 0:
            return qa[None, :] + (ss[:, None] - s0) * slope[None, :]
        return np.broadcast_to(slope if order == 1 else np.zeros_like(slope), (ss.shape[0], slope.shape[0]))

    return Piece("linear", s0, s1, q, np.array([s0, s1]))


def spline_piece(spline, s0: float, s1: float, breaks) -> Piece:
    """The spline restricted to [s0, s1] as a piece (``breaks``: the values of s to sample)."""

    def q(ss, order=0):
        return spline(np.atleast_1d(np.asarray(ss, np.float64)), order)

    return Piece("smooth", float(s0), float(s1), q, np.asarray(breaks, np.float64))


def _terms(q, dq, ddq, radius, angles, kind: str):
    """Per row: lengths l, dl/ds, d2l/ds2 (flattened, n k each), tip, dtip/ds."""
    n = radius.shape[0]
    fn = length_function(kind)

    def one(q, dq, ddq):
        q, dq, ddq = q.reshape(n, 3), dq.reshape(n, 3), ddq.reshape(n, 3)
        lengths = lambda x: fn(x, radius, angles).reshape(-1)
        l, l1 = jax.jvp(lengths, (q,), (dq,))
        # d2 l/ds2 = d2l/dq2 [q', q'] + dl/dq q''
        _, l2 = jax.jvp(lambda x: jax.jvp(lengths, (x,), (dq,))[1], (q,), (dq,))
        _, l2b = jax.jvp(lengths, (q,), (ddq,))
        tip, tip1 = jax.jvp(tip_position, (q,), (dq,))
        return l, l1, l2 + l2b, tip, tip1

    return jax.vmap(one)(q, dq, ddq)


_terms_jit = package_jit(_terms, None, static_argnames=("kind",))


def path_terms(q, dq, ddq, layout: ActuatorLayout):
    """Actuator lengths and their s-derivatives along a path, with the tip.

    Args:
      q, dq, ddq: (N, 3n) configurations and their first and second derivatives in s.
      layout: the actuators.

    Returns:
      NumPy ``(l, dl/ds, d2l/ds2)`` each (N, n k), ``tip`` (N, 3) and ``dtip/ds`` (N, 3).
      Evaluated in batches of a power of two (at least 64) so that paths of any length share
      a few compilations.
    """
    q = np.asarray(q, np.float64)
    N = q.shape[0]
    size = max(64, 1 << max(N - 1, 1).bit_length())
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], size - N, axis=0)]) if N < size else a
    dtype = layout.radius.dtype
    out = _terms_jit(*(jnp.asarray(pad(np.asarray(a, np.float64)), dtype) for a in (q, dq, ddq)), layout.radius,
                 layout.angles, kind=layout.kind)
    return tuple(np.asarray(x, np.float64)[:N] for x in out)


class ActuatorPath:
    """A :class:`Piece` as a ``toppra`` geometric path in actuator-length space (dof n k).

    Implements ``toppra.interpolator.AbstractGeometricPath``'s interface (``__call__(ss,
    order)``, ``dof``, ``path_interval``, ``waypoints``) without importing toppra.
    """

    def __init__(self, piece: Piece, layout: ActuatorLayout):
        self.piece, self.layout = piece, layout
        self._cache = {}

    def terms(self, ss):
        """:func:`path_terms` at the path positions ss (cached per array)."""
        ss = np.atleast_1d(np.asarray(ss, np.float64))
        key = ss.tobytes()
        if key not in self._cache:
            self._cache[key] = path_terms(*(self.piece.q(ss, o) for o in range(3)), self.layout)
        return self._cache[key]

    def __call__(self, path_positions, order: int = 0):
        scalar = np.ndim(path_positions) == 0
        out = self.terms(path_positions)[order]
        return out[0] if scalar else out

    @property
    def dof(self) -> int:
        return self.layout.n_segments * self.layout.count

    @property
    def path_interval(self):
        return np.array([self.piece.s0, self.piece.s1])

    @property
    def waypoints(self):
        return None

    def eval(self, ss):
        return self(ss, 0)

    def evald(self, ss):
        return self(ss, 1)

    def evaldd(self, ss):
        return self(ss, 2)
