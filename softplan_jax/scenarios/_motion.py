"""Moving obstacles and moving goals (the paper's future work, §4): a
:class:`MovingScenario` is a :class:`~softplan_jax.scenarios.Scenario` at rest plus a rigid
:class:`CurveMotion` per polynomial curve slot and a :class:`GoalPath`; a moved polynomial is
the polynomial of the moved coefficients (:func:`moved_curves`), so the closest point at time
t is the same exact solve (paper §2.3), and :func:`speed_bounds` proves how fast any point of
an obstacle moves. Only polynomial curves move; point sets and :class:`ParametricCurve`
obstacles stay where they are."""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._validation import as_float_array, host_array, is_concrete
from ..geometry._curves import PolynomialCurve
from ._scenario import Scenario

__all__ = [
    "CurveMotion",
    "GoalPath",
    "MovingScenario",
    "curve_motion",
    "static_motion",
    "goal_path",
    "make_moving_scenario",
    "stack_moving_scenarios",
    "moved_curves",
    "moved_cells",
    "scenario_at",
    "goal_at",
    "goal_velocity",
    "speed_bounds",
    "curve_radius_bound",
]


class CurveMotion(NamedTuple):
    """The rigid motion of curve slots; every field has the slot axis first, ``(m_c, ...)``,
    or none for one curve::

        F_o(u, t) = p + R(a, theta(t)) (F_o(u) - p) + sigma(t) s + t v,
        theta(t) = A sigma(t),   sigma(t) = sin(omega t + phase)

    (``R(a, x)``: rotation by x about the unit axis a through the pivot p, Rodrigues'
    formula). ``A`` > 0 is a branch swaying about its base p; ``s`` an oscillating
    translation (a wire sweeping to and fro); ``v`` a drift. All zeros is a static curve
    (the padding slots' motion).

    Attributes:
      pivot: (m_c, 3) the point p the sway turns about (a branch's base) [m].
      axis: (m_c, 3) the unit sway axis a (zeros: no sway).
      amplitude: (m_c,) sway amplitude A [rad].
      omega: (m_c,) angular frequency of the oscillation [rad/s], >= 0.
      phase: (m_c,) phase of the oscillation [rad].
      shift: (m_c, 3) amplitude s of the oscillating translation [m].
      velocity: (m_c, 3) drift velocity v [m/s].
    """

    pivot: jax.Array
    axis: jax.Array
    amplitude: jax.Array
    omega: jax.Array
    phase: jax.Array
    shift: jax.Array
    velocity: jax.Array


class GoalPath(NamedTuple):
    """A moving goal: ``points`` at ``times``, linear in between, constant
    outside [times[0], times[-1]]; then carried by the motion of curve slot
    ``attach`` (-1: by none).

    Attributes:
      times: (K,) strictly increasing times [s] (K = 1: a fixed goal).
      points: (K, 3) goal positions [m] (in the rest frame of the attached
        curve, if any: a point ON the curve at rest stays on it).
      attach: () int32 curve slot index, or -1.
    """

    times: jax.Array
    points: jax.Array
    attach: jax.Array


class MovingScenario(NamedTuple):
    """A scenario whose curves and goal move (a pytree; vmap over a stack).

    Attributes:
      scene: the Scenario at rest (its ``goal``: the goal path's first sample;
        the planner follows ``goal_path``).
      motion: CurveMotion with one row per polynomial curve slot.
      goal_path: GoalPath.
    """

    scene: Scenario
    motion: CurveMotion
    goal_path: GoalPath

    @property
    def n_segments(self) -> int:
        return self.scene.q0.shape[-2]


def _vector(x, name: str, shape, dtype):
    arr = as_float_array(x, name)
    try:
        arr = jnp.broadcast_to(arr, shape)
    except ValueError:
        raise ValueError(f"{name} must have shape {shape} (or broadcast to it); got {arr.shape}") from None
    if is_concrete(arr) and not bool(np.all(np.isfinite(np.asarray(arr)))):
        raise ValueError(f"{name} contains non-finite values (NaN or inf): {np.asarray(arr).tolist()}")
    return arr.astype(dtype)


def curve_motion(*, pivot=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 0.0), amplitude=0.0, omega=0.0, phase=0.0,
                 shift=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), dtype=None) -> CurveMotion:
    """The motion of ONE curve (the formula: :class:`CurveMotion`).

    Args:
      pivot: (3,) the point the sway turns about [m].
      axis: (3,) the sway axis (normalised here; needed when amplitude != 0).
      amplitude: sway amplitude A [rad].
      omega: angular frequency [rad/s], >= 0 (shared by the sway and the shift).
      phase: phase [rad] (0: at rest at t = 0).
      shift: (3,) amplitude of the oscillating translation [m].
      velocity: (3,) drift [m/s].

    Raises:
      ValueError: non-finite values, wrong shapes, omega < 0, or a sway
        (amplitude != 0) without an axis.
    """
    dtype = dtype or jnp.result_type(float)
    axis = _vector(axis, "axis", (3,), dtype)
    amplitude = _vector(amplitude, "amplitude", (), dtype)
    omega = _vector(omega, "omega", (), dtype)
    norm = float(jnp.linalg.norm(axis))
    if float(omega) < 0:
        raise ValueError(f"omega must be >= 0, got {float(omega)}")
    if float(amplitude) != 0.0 and norm == 0.0:
        raise ValueError("a sway (amplitude != 0) needs a non-zero axis")
    return CurveMotion(
        pivot=_vector(pivot, "pivot", (3,), dtype),
        # A unit axis (to rounding) is kept as given, so that a saved scene reads back bit for bit.
        axis=axis / norm if norm > 0 and abs(norm - 1.0) > 8 * float(jnp.finfo(dtype).eps) else axis,
        amplitude=amplitude,
        omega=omega,
        phase=_vector(phase, "phase", (), dtype),
        shift=_vector(shift, "shift", (3,), dtype),
        velocity=_vector(velocity, "velocity", (3,), dtype),
    )


def static_motion(slots: int, dtype=None) -> CurveMotion:
    """No motion for ``slots`` curve slots (all zeros)."""
    return CurveMotion(*(host_array(r) for r in _zero_rows(slots, dtype or jnp.result_type(float))))


def _zero_rows(slots: int, dtype) -> list:
    """:func:`static_motion`'s fields as NumPy arrays (zeros), in CurveMotion's order."""
    return [np.zeros((slots, *shape), dtype) for shape in ((3,), (3,), (), (), (), (3,), (3,))]


def goal_path(times, points, attach: int = -1, dtype=None) -> GoalPath:
    """A :class:`GoalPath` from samples (validated).

    ``points`` may also be a function ``t -> (3,)`` (JAX-traceable or NumPy),
    sampled at ``times``: the goal then follows it linearly between samples.

    Raises:
      ValueError: wrong shapes, non-finite values, times not strictly increasing.
    """
    dtype = dtype or jnp.result_type(float)
    times = as_float_array(times, "goal times")
    if times.ndim != 1 or times.shape[0] < 1:
        raise ValueError(f"goal times must be a non-empty 1-D array; got shape {times.shape}")
    if not bool(np.all(np.isfinite(np.asarray(times)))):
        raise ValueError(f"goal times contain non-finite values: {np.asarray(times).tolist()}")
    if times.shape[0] > 1 and not bool(np.all(np.diff(np.asarray(times)) > 0)):
        raise ValueError(f"goal times must be strictly increasing; got {np.asarray(times).tolist()}")
    if callable(points):
        points = np.stack([np.asarray(points(float(t)), float) for t in np.asarray(times)])
    points = as_float_array(points, "goal points")
    if points.shape != (times.shape[0], 3):
        raise ValueError(f"goal points must have shape ({times.shape[0]}, 3) (one per time); got {points.shape}")
    if not bool(np.all(np.isfinite(np.asarray(points)))):
        raise ValueError("goal points contain non-finite values (NaN or inf)")
    return GoalPath(host_array(times, dtype), host_array(points, dtype), host_array(int(attach), np.int32))


def _rotation(axis, angle):
    """Rodrigues: R = I + sin(x) K + (1 - cos x) K^2 for the unit axis (zeros: I)."""
    x, y, z = axis[0], axis[1], axis[2]
    zero = jnp.zeros_like(x)
    K = jnp.stack([jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]), jnp.stack([-y, x, zero])])
    eye = jnp.eye(3, dtype=axis.dtype)
    return eye + jnp.sin(angle) * K + (1.0 - jnp.cos(angle)) * (K @ K)


def _pose(motion: CurveMotion, t):
    """(R (3, 3), offset (3,)) of one slot at time t: x -> R (x - p) + p + offset."""
    sigma = jnp.sin(motion.omega * t + motion.phase)
    R = _rotation(motion.axis, motion.amplitude * sigma)
    return R, sigma * motion.shift + t * motion.velocity


def _move_point(motion: CurveMotion, t, x):
    R, offset = _pose(motion, t)
    return R @ (x - motion.pivot) + motion.pivot + offset


def moved_curves(curves: PolynomialCurve, motion: CurveMotion, t) -> PolynomialCurve:
    """The curve stack at time t: coefficients ``R (C - p e_0^T) + (p + offset) e_0^T``
    (a rigid motion of a polynomial is the polynomial of the moved coefficients)."""

    def one(coeffs, m):
        R, offset = _pose(m, t)
        centred = coeffs.at[:, 0].add(-m.pivot)
        return (R @ centred).at[:, 0].add(m.pivot + offset)

    coeffs = jax.vmap(one)(curves.coeffs, motion)
    return PolynomialCurve.tree_unflatten(None, [coeffs, curves.u_range, curves.radius])


def moved_cells(cells, motion: CurveMotion, t):
    """The warm start's per-curve data (:func:`~softplan_jax.geometry._warm_start.curve_data`,
    vmapped over the polynomial stack) at time t: the curvature bound and the
    u-grid are invariant under a rigid motion; the grid points move and the
    rounding scale ``1 + max |F_o|`` is recomputed from them."""

    def one(C_grid, m):
        R, offset = _pose(m, t)
        return (C_grid - m.pivot) @ R.T + m.pivot + offset

    C_grid = jax.vmap(one)(cells.C_grid, motion)
    size = 1.0 + jnp.max(jnp.sqrt(jnp.sum(C_grid * C_grid, axis=-1)), axis=-1)
    return cells._replace(C_grid=C_grid, size=size)


def goal_at(moving: MovingScenario, t):
    """The goal g(t) (3,) (see :class:`GoalPath`)."""
    path = moving.goal_path
    g = jnp.stack([jnp.interp(t, path.times, path.points[:, k]) for k in range(3)])
    m_c = moving.motion.amplitude.shape[0]
    if m_c == 0:
        return g
    slot = jnp.clip(path.attach, 0, m_c - 1)
    m = jax.tree_util.tree_map(lambda x: x[slot], moving.motion)
    return jnp.where(path.attach >= 0, _move_point(m, t, g), g)


def goal_velocity(moving: MovingScenario, t):
    """dg/dt (3,) (forward-mode; the interpolation's slope, 0 beyond its ends)."""
    return jax.jvp(lambda s: goal_at(moving, s), (t,), (jnp.ones_like(t),))[1]


def scenario_at(moving: MovingScenario, t) -> Scenario:
    """The Scenario at time t: the curves moved, the goal g(t); everything else at rest."""
    scene = moving.scene
    return scene._replace(curves=moved_curves(scene.curves, moving.motion, t), goal=goal_at(moving, t))


def _bernstein_matrix(K: int) -> np.ndarray:
    """M (K, K): Bernstein coefficients on [0, 1] = M @ power coefficients in x
    (beta_i = sum_{j <= i} C(i, j) / C(n, j) b_j, n = K - 1)."""
    n = K - 1
    M = np.zeros((K, K))
    for i in range(K):
        for j in range(i + 1):
            M[i, j] = math.comb(i, j) / math.comb(n, j)
    return M


def curve_radius_bound(curves: PolynomialCurve, centre):
    """(m,) a bound on ``max_u |F_o(u) - centre|`` over each curve's u-range:
    the largest distance of a Bernstein control point from ``centre`` (m, 3)
    (the curve lies in their convex hull), with a rounding margin."""
    K = curves.coeffs.shape[-1]
    M = jnp.asarray(_bernstein_matrix(K), curves.coeffs.dtype)
    k = np.arange(K)
    binom = jnp.asarray(np.array([[math.comb(a, b) for b in range(K)] for a in range(K)], float),
                        curves.coeffs.dtype)

    dtype = curves.coeffs.dtype
    expo = jnp.asarray(np.clip(k[:, None] - k[None, :], 0, None), dtype)
    upper = jnp.asarray(k[:, None] >= k[None, :])
    powers = jnp.asarray(k[None, :], dtype)

    def one(coeffs, u_range, c):
        u0, h = u_range[0], u_range[1] - u_range[0]
        # power coefficients in x, u = u0 + h x: b_j = sum_{k >= j} a_k C(k, j) u0^(k - j) h^j
        T = jnp.where(upper, binom * u0**expo, 0.0) * h**powers  # (k, j)
        b = coeffs @ T  # (3, K) in x
        beta = b @ M.T  # (3, K) Bernstein control points
        dist = jnp.sqrt(jnp.sum((beta - c[:, None]) ** 2, axis=0))
        scale = 1.0 + jnp.sum(jnp.abs(coeffs)) * (1.0 + jnp.abs(u0) + jnp.abs(h)) ** (K - 1)
        return jnp.max(dist) + 64 * jnp.finfo(coeffs.dtype).eps * scale

    return jax.vmap(one)(curves.coeffs, curves.u_range, centre)


def speed_bounds(moving: MovingScenario):
    """(m,) a bound on the speed of every point of every obstacle slot [m/s]
    (slot order of :func:`~softplan_jax.geometry._obstacles.radius_and_mask`: polynomial
    curves, point sets, parametric curves; the last two are static: 0).

    ``|v| + omega (|s| + A r_max)`` per polynomial curve: for every point of the curve and every
    interval of length h, ``|F_o(u, t + h') - F_o(u, t)| <= h (|v| + omega (|s| + A r_max))`` for
    ``0 <= h' <= h``, since ``|R(a, x) r - R(a, y) r| <= |x - y| |r|``, ``|sigma'| <= omega`` and
    ``|theta'| <= A omega``, with ``r_max >= max_u |F_o(u) - p|`` from the convex hull of the
    curve's Bernstein control points on its u-range (:func:`curve_radius_bound`: a proof, not
    a sample).
    """
    scene, m = moving.scene, moving.motion
    dtype = scene.q0.dtype
    m_p, m_f = scene.points.shape[0], len(scene.parametric)
    parts = []
    if scene.curves.coeffs.shape[0]:
        r_max = curve_radius_bound(scene.curves.astype(dtype), m.pivot)
        norm = lambda x: jnp.sqrt(jnp.sum(x * x, axis=-1))  # noqa: E731
        parts.append(norm(m.velocity) + m.omega * (norm(m.shift) + jnp.abs(m.amplitude) * r_max))
    parts.append(jnp.zeros((m_p + m_f,), dtype))
    return jnp.concatenate(parts)


def make_moving_scenario(scenario: Scenario, motions=None, goal=None) -> MovingScenario:
    """A :class:`MovingScenario` from a Scenario at rest.

    Args:
      scenario: one (unbatched) Scenario.
      motions: None (nothing moves), a list with one entry per polynomial
        curve of the scene (a :class:`CurveMotion` from :func:`curve_motion`,
        or None for a static curve), or a dict {curve index: CurveMotion}.
        Padding slots never move.
      goal: None (the scenario's goal, fixed), a :class:`GoalPath` (from
        :func:`goal_path`), or a (3,) point.

    Raises:
      ValueError: a motion for a curve the scene does not have, a goal
        attached to a slot that is padding or out of range, bad types.
    """
    if not isinstance(scenario, Scenario) or scenario.q0.ndim != 2:
        raise ValueError("make_moving_scenario takes one (unbatched) Scenario")
    dtype = scenario.q0.dtype
    m_c = scenario.curves.coeffs.shape[0]
    n_real = int(np.asarray(scenario.curve_mask).sum())
    if motions is None:
        motions = {}
    if isinstance(motions, (list, tuple)):
        if len(motions) != n_real:
            raise ValueError(f"motions must have one entry per polynomial curve ({n_real}); got {len(motions)}")
        motions = {k: m for k, m in enumerate(motions) if m is not None}
    if not isinstance(motions, dict):
        raise ValueError(f"motions must be None, a list or a dict; got {type(motions).__name__}")
    rows = _zero_rows(m_c, dtype)  # NumPy, then one transfer per field (host_array)
    real = np.flatnonzero(np.asarray(scenario.curve_mask))
    for k, m in motions.items():
        if not isinstance(k, (int, np.integer)) or not 0 <= int(k) < n_real:
            raise ValueError(f"motion for curve {k!r}: the scene has {n_real} polynomial curves (0-based)")
        if not isinstance(m, CurveMotion):
            raise ValueError(f"motion for curve {k} must be a CurveMotion (softplan_jax.curve_motion); "
                             f"got {type(m).__name__}")
        slot = int(real[int(k)])
        for r, v in zip(rows, m, strict=True):
            r[slot] = np.asarray(v, dtype)
    rows = CurveMotion(*(host_array(r) for r in rows))
    if goal is None:
        path = goal_path([0.0], np.asarray(scenario.goal)[None], dtype=dtype)
    elif isinstance(goal, GoalPath):
        path = GoalPath(host_array(goal.times, dtype), host_array(goal.points, dtype), host_array(goal.attach, np.int32))
    else:
        path = goal_path([0.0], np.asarray(goal, dtype).reshape(1, -1), dtype=dtype)
    attach = int(path.attach)
    if attach != -1:
        if not 0 <= attach < n_real:
            raise ValueError(f"the goal is attached to curve {attach}; the scene has {n_real} polynomial curves")
        path = path._replace(attach=host_array(int(real[attach]), np.int32))
    # The scene's own goal: the goal path's first sample (where the goal is at rest).
    return MovingScenario(scenario._replace(goal=host_array(np.asarray(path.points)[0])), rows, path)


def stack_moving_scenarios(movings) -> MovingScenario:
    """Stack moving scenarios of one shape (same slots, degree, segment count and
    goal-sample count) along a new leading axis, for vmap."""
    movings = list(movings)
    if not movings:
        raise ValueError("stack_moving_scenarios needs at least one scenario")
    shapes = {jax.tree_util.tree_structure(m) for m in movings}
    leaf_shapes = {tuple(x.shape for x in jax.tree_util.tree_leaves(m)) for m in movings}
    if len(shapes) != 1 or len(leaf_shapes) != 1:
        raise ValueError("stack_moving_scenarios needs scenarios of one shape (pad them with make_scenario's "
                         "curve_slots/degree and give every goal path the same number of samples)")
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *movings)
