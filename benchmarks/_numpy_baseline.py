"""A NumPy/SciPy peer of the paper's planner: what a competent NumPy user would write.

The same planner as :mod:`softplan_jax.planning._planner` (paper eq. 9), written from the
paper with NumPy and SciPy only (``softplan_jax`` is used to READ scenarios and
default gains and, in :func:`jax_trajectory`, to run the JAX side).
The speed benchmarks (``speed_targets.py``, ``paper_tables.py``,
``paper_tables.py --presets``) compare the library against it, so it is written to be
fast in NumPy's own terms:

* Kinematics, paper §2.1-2.2, vectorised: ``R_i = Rz(phi) Ry(theta)`` (or
  Webster & Jones' ``Rz(phi) Ry(theta) Rz(-phi)``, :func:`rotation_convention`)
  and the arc point ``P_si`` for every sample of every segment in one
  broadcast (:func:`segment_points`). The ratios ``(1 - cos x)/x`` and
  ``sin(x)/x`` use the paper's special case at ``x = 0`` and the half-angle
  form ``1 - cos x = 2 sin^2(x/2)`` elsewhere.
* Jacobians ``J = dP_si/dq`` ANALYTIC (:func:`point_jacobians`, differentiated
  by hand: each segment's arc term plus ``w x (P - P_{k+1})`` for the rotation
  of every segment below the point; the derivative of ``sin(x)/x`` from its
  series near 0), all the step needs in one call; checked against the
  complex-step oracle and central finite differences in the tests.
* Pseudo-inverse with ``numpy.linalg``: by default the damped form
  ``J^T (J J^T + lambda^2 I)^-1`` exactly as ``softplan_jax.base._numerics.damped_pinv``
  (so trajectories can agree), or ``pinv="svd"``: ``numpy.linalg.pinv`` (the
  paper's undamped pseudo-inverse with an SVD cut-off; trajectories differ).
* Closest point segment <-> curve, paper §2.3: ``D(s, u)`` sampled for all
  segments at once (33 arm samples per segment x curve samples ~1/32 apart,
  the curve's built once per run); the grid's discrete local minima within
  its Lipschitz bound of the smallest sample (at most 4 per segment) seed
  ``scipy.optimize.least_squares`` with analytic Jacobians: a descent in the
  box (dogbox on ``F_R(s) - F_o(u)``, the ``lsqnonlin`` analogue), then
  MINPACK Levenberg-Marquardt on the stationarity equations of the case it
  landed in (eqs. 13-14 inside, 15-18 on the edges) from the seed and from the
  descent's point; a saddle (negative curvature) is stepped off both ways;
  plus the four endpoint pairs. About 30-40 solves per tree step (5 curves x
  3 segments). It matches the oracle (``softplan_jax.testing.closest_cases``,
  1,120 cases) to < 1e-9 in every case.
* N-point method: each curve is ``N`` points evenly spaced in u (N = 1: the
  middle), the arm is sampled at s = j/10, j = 1..10 on every segment (one
  broadcast per step), and the nearest pair comes from
  ``scipy.spatial.cKDTree`` (the ``dsearchn`` analogue; the tree of each
  static obstacle is built once) or brute force.
* The same gain functions (attraction saturated at ``v_max``; Khatib
  repulsion ``eta (1/d - 1/d0)/d^2`` with the smooth ``tanh`` cap), the same
  gains (``softplan_jax.default_gains`` converted to floats), the same step
  (``q += dt qdot``, ``L`` clipped) and the same stop rule (``|V_e| < 1e-2``).
  As the paper says (§2.2), a Jacobian is only computed for an obstacle within
  the critical range (nonzero repulsion); beyond it the term is exactly zero.
  Every obstacle's exact closest point is computed at every step, as the JAX
  step does.

Its per-step time against the library's is measured by ``speed_targets.py``; its
agreement with the library over whole runs is tested in ``tests/test_numpy_baseline.py``.
Importing this module changes no jax setting: a caller (the tests, ``paper_tables``)
switches float64 on before creating arrays, as both sides must run in float64 to agree.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize, spatial

import softplan_jax as sp
from softplan_jax.planning import PAPER_STEP, planner_step
from softplan_jax.planning._planner import make_options

__all__ = [
    "NumpyScenario",
    "NumpyClosest",
    "NumpyPlanResult",
    "to_numpy_scenario",
    "numpy_gains",
    "jax_gains",
    "stress_gains",
    "segment_frames",
    "segment_point",
    "tip_position",
    "fd_jacobian",
    "closest_point_curve",
    "closest_point_points",
    "numpy_step",
    "numpy_plan",
    "rotation_convention",
    "jax_trajectory",
]

EPS = np.finfo(np.float64).eps


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------
# Scenario and gains, converted to NumPy.


class NumpyScenario(NamedTuple):
    """A softplan_jax Scenario as plain NumPy (padding dropped).

    Attributes:
      q0: (n, 3) start.
      goal: (3,).
      curves: list of (coeffs (3, K), (u_min, u_max), radius) polynomial curves.
      point_sets: list of ((N, 3) points, radius) point obstacles.
      arm_radius: float.
      L_min, L_max: (n,) length limits.
    """

    q0: np.ndarray
    goal: np.ndarray
    curves: list
    point_sets: list
    arm_radius: float
    L_min: np.ndarray
    L_max: np.ndarray


def to_numpy_scenario(scenario) -> NumpyScenario:
    """Convert a softplan_jax Scenario (or a paper scenario name) to NumPy."""
    if isinstance(scenario, str):
        scenario = sp.paper_scenario(scenario)
    if not isinstance(scenario, sp.Scenario):
        raise ValueError(
            f"scenario must be a Scenario or a paper scenario name, got {type(scenario).__name__}"
        )
    if scenario.q0.ndim != 2:
        raise ValueError("the NumPy baseline takes one scenario, not a batch")
    if scenario.parametric:
        raise ValueError("the NumPy baseline supports polynomial curves and point sets, not ParametricCurves")
    coeffs = np.asarray(scenario.curves.coeffs, np.float64)
    u_range = np.asarray(scenario.curves.u_range, np.float64)
    radius = np.asarray(scenario.curves.radius, np.float64)
    curves = [
        (coeffs[k], (float(u_range[k, 0]), float(u_range[k, 1])), float(radius[k]))
        for k in np.nonzero(np.asarray(scenario.curve_mask))[0]
    ]
    pm = np.asarray(scenario.point_mask)
    pts = np.asarray(scenario.points, np.float64)
    pr = np.asarray(scenario.point_radius, np.float64)
    point_sets = [(pts[k][pm[k]], float(pr[k])) for k in range(pm.shape[0]) if pm[k].any()]
    return NumpyScenario(
        q0=np.asarray(scenario.q0, np.float64),
        goal=np.asarray(scenario.goal, np.float64),
        curves=curves,
        point_sets=point_sets,
        arm_radius=float(scenario.arm_radius),
        L_min=np.asarray(scenario.L_min, np.float64),
        L_max=np.asarray(scenario.L_max, np.float64),
    )


def numpy_gains(gains=None) -> dict:
    """Gains as a dict of Python floats (default: ``softplan_jax.default_gains``)."""
    if gains is None:
        gains = sp.default_gains(jnp.float64)
    if isinstance(gains, sp.Gains):
        gains = gains._asdict()
    return {k: float(np.asarray(v)) for k, v in dict(gains).items()}


def jax_gains(gains=None) -> sp.Gains:
    """Gains as a float64 softplan_jax Gains (default: ``softplan_jax.default_gains``)."""
    return sp.Gains(**{k: jnp.asarray(v, jnp.float64) for k, v in numpy_gains(gains).items()})


def stress_gains() -> dict:
    """The default gains with a wider, stronger repulsion (d0 = 0.25, eta = 5e-3):
    with the defaults the arm is within the repulsion's range on only a few
    steps of the paper's scenarios; these make the closest points matter on
    most steps (the tree: ~90 % of them), to test agreement where it is hard."""
    return dict(numpy_gains(), d0=0.25, eta=5e-3)


# ----------------------------------------------------------------------------
# Kinematics (paper §2.1-2.2), vectorised over sample points.

# Below this |x| the derivative of sin(x)/x comes from its Taylor series: the
# direct (cos x - sin(x)/x)/x loses ~eps/x^2 to cancellation.
_SERIES_BELOW = 0.25
_DB_SERIES = [(-1) ** k * 2 * k / math.factorial(2 * k + 1) for k in range(1, 10)]  # sum_k c_k x^(2k-1)


def _arc_ratios(x):
    """(1 - cos x)/x and sin(x)/x; the paper's special case at x = 0."""
    x = np.asarray(x, np.float64)
    zero = x == 0.0
    xs = np.where(zero, 1.0, x)
    a = np.where(zero, 0.0, 2.0 * np.sin(0.5 * xs) ** 2 / xs)  # 1 - cos x = 2 sin^2(x/2)
    b = np.where(zero, 1.0, np.sin(xs) / xs)
    return a, b


def _arc_ratio_derivatives(x):
    """a, b = :func:`_arc_ratios` and their x-derivatives:
    a' = b - a/x (no cancellation: a/x -> 1/2 at 0), b' = (cos x - b)/x (Taylor
    series for |x| < 0.25). Broadcasts; returns (a, b, a', b')."""
    x = np.asarray(x, np.float64)
    a, b = _arc_ratios(x)
    zero = x == 0.0
    xs = np.where(zero, 1.0, x)
    da = b - np.where(zero, 0.5, a / xs)
    x2 = x * x
    series = np.zeros_like(x)
    for c in reversed(_DB_SERIES):
        series = series * x2 + c
    small = np.abs(x) < _SERIES_BELOW
    db = np.where(small, x * series, (np.cos(xs) - b) / xs)
    return a, b, da, db


def _arc_local(L, theta, phi, s):
    """The bracket of the paper's P_si: [(1-cos(theta s)) L/theta cos(phi), ...,
    sin(theta s) L/theta] = L s [a cos(phi), a sin(phi), b], a, b of x = theta s.
    Broadcasts; returns (..., 3)."""
    a, b = _arc_ratios(theta * s)
    Ls = L * s
    return np.stack([Ls * a * np.cos(phi), Ls * a * np.sin(phi), Ls * b], axis=-1)


# The rotation convention of the segment frames: "paper" (R_i = Rz(phi) Ry(theta), paper §2.1, as
# softplan_jax) or "webster_jones" (R_i = Rz(phi) Ry(theta) Rz(-phi), Webster & Jones 2010, eq. 3).
# Switch it with ``with rotation_convention("webster_jones"): ...`` (benchmarks/paper_tables.py --presets).
_CONVENTION = ["paper"]


@contextlib.contextmanager
def rotation_convention(name: str):
    """Plan with the segment rotation ``name`` ("paper" or "webster_jones") inside the block.

    The arc of segment i in its base frame is the same in both conventions;
    only the frame handed to segment i + 1 differs (W&J rotates back by
    -phi_i). So W&J(q) has the geometry of paper(q') with phi'_1 = phi_1,
    phi'_i = phi_i - phi_{i-1}; the planner's pseudo-inverse step in q is not
    the same step in q' (the minimum-norm solution depends on the
    coordinates), so the paths differ."""
    if name not in ("paper", "webster_jones"):
        raise ValueError(f"unknown rotation convention {name!r}; choose 'paper' or 'webster_jones'")
    old = _CONVENTION[0]
    _CONVENTION[0] = name
    try:
        yield
    finally:
        _CONVENTION[0] = old


def _rotation(theta, phi):
    """The paper's R_i (§2.1), (..., 3, 3); Webster & Jones' Rz(phi) Ry(theta) Rz(-phi)
    inside :func:`rotation_convention` ("webster_jones")."""
    ct, st, cp, sn = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi)
    R = np.empty(np.shape(theta) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = cp * ct, -sn, cp * st
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = sn * ct, cp, sn * st
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = -st, 0.0, ct
    if _CONVENTION[0] == "webster_jones":
        Rz_minus = np.zeros(np.shape(phi) + (3, 3))
        Rz_minus[..., 0, 0], Rz_minus[..., 0, 1] = cp, sn
        Rz_minus[..., 1, 0], Rz_minus[..., 1, 1] = -sn, cp
        Rz_minus[..., 2, 2] = 1.0
        R = R @ Rz_minus
    return R


def segment_frames(q):
    """Base frames of every segment and the tip (H_n^0 = prod H_i^{i-1}, paper §2.1).

    Args:
      q: (..., n, 3).

    Returns:
      R_bases (..., n, 3, 3), P_bases (..., n, 3), R_tip (..., 3, 3), P_tip (..., 3).
    """
    q = np.asarray(q, np.float64)
    batch = q.shape[:-2]
    arcs = _arc_local(q[..., 0], q[..., 1], q[..., 2], 1.0)  # (..., n, 3): every segment at once
    Rots = _rotation(q[..., 1], q[..., 2])  # (..., n, 3, 3)
    R = np.broadcast_to(np.eye(3), batch + (3, 3))
    P = np.zeros(batch + (3,))
    Rs, Ps = [], []
    for i in range(q.shape[-2]):  # the chain itself is sequential (n = 3)
        Rs.append(R)
        Ps.append(P)
        P = P + np.einsum("...ab,...b->...a", R, arcs[..., i, :])
        R = R @ Rots[..., i, :, :]
    return np.stack(Rs, axis=-3), np.stack(Ps, axis=-2), R, P


def segment_point(q, i: int, s: float):
    """The paper's P_si: point at fraction s of segment i (0-based). q (..., n, 3) -> (..., 3)."""
    q = np.asarray(q, np.float64)
    Rs, Ps, _, _ = segment_frames(q[..., : i + 1, :])
    local = _arc_local(q[..., i, 0], q[..., i, 1], q[..., i, 2], s)
    return Ps[..., i, :] + np.einsum("...ab,...b->...a", Rs[..., i, :, :], local)


def tip_position(q):
    """Tip position, (..., n, 3) -> (..., 3)."""
    return segment_frames(q)[3]


def segment_points(q, s, frames=None):
    """P_si at the fractions ``s`` on every segment, in one broadcast.

    Args:
      q: (n, 3) configuration.
      s: (k,) fractions, the same on every segment, or (n, k).
      frames: optional ``segment_frames(q)``.

    Returns:
      (n, k, 3).
    """
    q = np.asarray(q, np.float64)
    Rs, Ps = (frames or segment_frames(q))[:2]
    s = np.broadcast_to(np.asarray(s, np.float64), (q.shape[0], np.shape(s)[-1]))
    local = _arc_local(q[:, 0, None], q[:, 1, None], q[:, 2, None], s)  # (n, k, 3)
    return Ps[:, None, :] + np.einsum("nab,nkb->nka", Rs, local)


def backbone_points(q, points_per_segment: int = 10, frames=None):
    """(n k, 3) arm samples at s = j/k, j = 1..k, of every segment (paper Table 1)."""
    s = np.arange(1, points_per_segment + 1) / points_per_segment
    return segment_points(q, s, frames).reshape(-1, 3)


def point_jacobians(q, segment, s, frames=None):
    """Analytic Jacobians d P_si / d q.ravel() of the points (segment[m], s[m]).

    Differentiated by hand from the PCC kinematics (paper §2.1). Segment k
    moves the point through its own arc, ``R_k^0 d a_k / d q_k`` (with
    ``a_k = L s [a(x) cos phi, a(x) sin phi, b(x)]``, ``x = theta s``, s = 1 for
    k < i), and, for k < i, through its rotation R_k, which turns everything
    beyond its end ``P_{k+1}`` about the world axis ``w``:
    ``w x (P - P_{k+1})``, with ``w_theta = R_k^0 [-sin phi, cos phi, 0]`` and
    ``w_phi = R_k^0 e_z`` (the paper's R_i) or ``R_k^0 e_z - R_{k+1}^0 e_z``
    (Webster & Jones' R_i: the trailing Rz(-phi) turns back). L enters only
    the arc. Exact at theta = 0 (series branch of :func:`_arc_ratio_derivatives`).

    Args:
      q: (n, 3) configuration.
      segment: (m,) segment indices (0-based); s: (m,) fractions.
      frames: optional ``segment_frames(q)``.

    Returns:
      (m, 3, 3n), columns L_1, theta_1, phi_1, L_2, ... (row-major q).
    """
    q = np.asarray(q, np.float64)
    n = q.shape[0]
    Rs, Ps, R_tip, P_tip = frames or segment_frames(q)
    seg = np.atleast_1d(np.asarray(segment, int))
    s = np.atleast_1d(np.asarray(s, np.float64))
    k = np.arange(n)
    before = k[None, :] < seg[:, None]  # (m, n): segments wholly below the point
    sk = np.where(before, 1.0, np.where(k[None, :] == seg[:, None], s[:, None], 0.0))  # (m, n); 0 beyond
    L, th, ph = q[:, 0], q[:, 1], q[:, 2]
    a, b, da, db = _arc_ratio_derivatives(th * sk)
    cp, sn = np.cos(ph), np.sin(ph)
    zero = np.zeros_like(a)
    d_L = sk[..., None] * np.stack([a * cp, a * sn, b], -1)  # (m, n, 3) local frame of segment k
    d_th = (L * sk * sk)[..., None] * np.stack([da * cp, da * sn, db], -1)
    d_ph = (L * sk)[..., None] * np.stack([-a * sn, a * cp, zero], -1)
    cols = np.einsum("nab,mnbp->mnap", Rs, np.stack([d_L, d_th, d_ph], -1))  # (m, n, 3 xyz, 3 params)
    # The rotation of segment k < i turns the part of the arm beyond P_{k+1}.
    P_next = np.concatenate([Ps[1:], P_tip[None]], 0)  # (n, 3): the end of each segment
    points = Ps[seg] + np.einsum("mab,mb->ma", Rs[seg], _arc_local(L[seg], th[seg], ph[seg], s))
    lever = np.where(before[..., None], points[:, None, :] - P_next[None], 0.0)  # (m, n, 3)
    w_th = np.einsum("nab,nb->na", Rs, np.stack([-sn, cp, np.zeros(n)], -1))
    w_ph = Rs[:, :, 2]
    if _CONVENTION[0] == "webster_jones":
        w_ph = w_ph - np.concatenate([Rs[1:], R_tip[None]], 0)[:, :, 2]
    cols[..., 1] += np.cross(w_th[None], lever)
    cols[..., 2] += np.cross(w_ph[None], lever)
    return cols.transpose(0, 2, 1, 3).reshape(len(seg), 3, 3 * n)


def point_jacobian(q, i: int, s: float, frames=None):
    """d P_si / d q.ravel(), (3, 3n), analytic (:func:`point_jacobians`)."""
    return point_jacobians(q, [i], [s], frames)[0]


def tip_jacobian(q, frames=None):
    """d tip / d q.ravel(), (3, 3n), analytic: the point at s = 1 of the last segment."""
    q = np.asarray(q, np.float64)
    return point_jacobian(q, q.shape[0] - 1, 1.0, frames)


def fd_jacobian(fn, q):
    """Central finite-difference Jacobian d fn(q) / d q.ravel(), (3, 3n).

    Not used by the planner (its Jacobians are analytic); kept to check them.
    ``fn`` maps a batch (B, n, 3) to (B, 3); the 2 * 3n perturbed
    configurations are evaluated in one call. Step ``eps^(1/3) max(1, |q_k|)``.
    """
    q = np.asarray(q, np.float64)
    flat = q.ravel()
    m = flat.size
    h = np.cbrt(EPS) * np.maximum(1.0, np.abs(flat))
    h = (flat + h) - flat  # exactly representable steps
    Q = np.tile(flat, (2 * m, 1))
    idx = np.arange(m)
    Q[idx, idx] += h
    Q[m + idx, idx] -= h
    vals = fn(Q.reshape((2 * m,) + q.shape))
    return ((vals[:m] - vals[m:]) / (2.0 * h)[:, None]).T


def damped_pinv(J, damping: float):
    """J^T (J J^T + damping^2 I)^-1, as softplan_jax.base._numerics.damped_pinv."""
    A = J @ J.T + damping * damping * np.eye(J.shape[0])
    return np.linalg.solve(A, J).T


# ----------------------------------------------------------------------------
# Closest points (paper §2.3).


class NumpyClosest(NamedTuple):
    """Closest pair between the arm and one obstacle (fields as softplan_jax.ClosestPoint)."""

    distance: float
    segment: int
    s: float
    u: float
    arm_point: np.ndarray
    obstacle_point: np.ndarray


def _arc_ratios_scalar(x: float):
    """:func:`_arc_ratios` for one Python float (the solvers' inner loop)."""
    if x == 0.0:
        return 0.0, 1.0
    h = math.sin(0.5 * x)
    return 2.0 * h * h / x, math.sin(x) / x


class _Arc:
    """F_Ri(s) of one segment and its s-derivatives (scalar s)."""

    def __init__(self, q_i, R, P):
        self.L, self.th = float(q_i[0]), float(q_i[1])
        self.cp, self.sp = math.cos(q_i[2]), math.sin(q_i[2])
        self.R, self.P = R, P

    def point(self, s):
        a, b = _arc_ratios_scalar(self.th * s)
        Ls = self.L * s
        return self.P + self.R @ np.array([Ls * a * self.cp, Ls * a * self.sp, Ls * b])

    def derivatives(self, s):
        # d/ds of the paper's bracket: L [sin(th s) cos phi, sin(th s) sin phi, cos(th s)];
        # d2/ds2: L th [cos(th s) cos phi, cos(th s) sin phi, -sin(th s)].
        x = self.th * s
        sx, cx = math.sin(x), math.cos(x)
        d1 = self.R @ np.array([self.L * sx * self.cp, self.L * sx * self.sp, self.L * cx])
        d2 = self.R @ np.array([self.L * self.th * cx * self.cp, self.L * self.th * cx * self.sp,
                                -self.L * self.th * sx])
        return d1, d2


class _Curve:
    """F_o(u) = sum_k coeffs[:, k] u^k (paper eq. 10), its u-derivatives, and its
    samples on the seeding grid (obstacles are static: built once per run)."""

    def __init__(self, coeffs, u_range, grid_u: int | None = None):
        c = np.asarray(coeffs, np.float64)
        K = c.shape[1]
        self.c0 = c
        self.c1 = c[:, 1:] * np.arange(1, K) if K > 1 else np.zeros((3, 1))
        K1 = self.c1.shape[1]
        self.c2 = self.c1[:, 1:] * np.arange(1, K1) if K1 > 1 else np.zeros((3, 1))
        self.u_lo, self.u_hi = float(u_range[0]), float(u_range[1])
        if grid_u is None:  # samples about CURVE_SPACING apart along the curve
            fine = self.points(np.linspace(self.u_lo, self.u_hi, 257))
            length = float(np.sum(np.linalg.norm(np.diff(fine, axis=0), axis=1)))
            grid_u = int(np.clip(math.ceil(length / CURVE_SPACING) + 1, *GRID_U_RANGE))
        self.u_grid = np.linspace(self.u_lo, self.u_hi, grid_u)
        self.grid = self.points(self.u_grid)  # (U, 3)
        du = self.u_grid[1] - self.u_grid[0] if grid_u > 1 else 0.0
        # max |F_o'| over the range: on the grid, plus du max|F_o''| for between the samples.
        self.speed = float(np.max(np.linalg.norm(self._horner(self.c1, self.u_grid), axis=0))
                           + du * np.max(np.linalg.norm(self._horner(self.c2, self.u_grid), axis=0)))
        self.du = du

    @staticmethod
    def _horner(c, u):
        """sum_k c[:, k] u^k; u scalar -> (3,), u (U,) -> (3, U)."""
        if np.ndim(u):
            c = c[:, :, None]  # (3, K, 1): broadcasts against u (U,)
        acc = c[:, -1] * np.ones_like(u, dtype=np.float64)
        for k in range(c.shape[1] - 2, -1, -1):
            acc = acc * u + c[:, k]
        return acc

    def point(self, u):
        return self._horner(self.c0, u)

    def derivative(self, u):
        return self._horner(self.c1, u)

    def second_derivative(self, u):
        return self._horner(self.c2, u)

    def points(self, us):
        """F_o at every u of ``us``, (U, 3)."""
        return self._horner(self.c0, np.asarray(us, np.float64)).T

    def sample(self, n_points: int):
        """N points evenly spaced in u (N = 1: the middle), (N, 3)."""
        if n_points == 1:
            us = np.array([0.5 * (self.u_lo + self.u_hi)])
        else:
            us = self.u_lo + (self.u_hi - self.u_lo) * np.linspace(0.0, 1.0, n_points)
        return self.points(us)


# The solves. least_squares with the analytic Jacobian, twice from each seed:
# (1) descent in the box: trf on the residual r(s, u) = F_R(s) - F_o(u) with
#     bounds [0, 1] x [u_min, u_max] (the lsqnonlin analogue; it cannot climb to
#     a saddle and lands on the box's edge when the minimum is there), to 1e-10;
# (2) polish: MINPACK's Levenberg-Marquardt (lmder) on the stationarity
#     equations of the case (1) landed in -- eqs. 13-14 inside, 15-16 on
#     u = u_min/u_max, 17-18 on s = 0/1 -- square, with a zero residual at the
#     solution, so it converges quadratically to rounding.
_DESCENT = dict(method="dogbox", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=60)
_LSQ = dict(method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
GRID_S = 33  # seeding grid: arm samples per segment (s = 0, 1/32, ..., 1)
CURVE_SPACING = 1.0 / 32.0  # curve samples about this far apart (a unit segment's arm spacing) ...
GRID_U_RANGE = (17, 1025)  # ... but no fewer / more than these
MAX_SEEDS = 4  # most seeds per segment-curve pair
_AT_BOUND = 1e-7  # a descent result this close (relative) to a bound is on it


def _descend(arc: _Arc, curve: _Curve, s0: float, u0: float):
    """Step (1): min |F_R(s) - F_o(u)|^2 over the box by least_squares (trf, bounds,
    Jacobian [F_R'(s), -F_o'(u)]) from (s0, u0) -> (s, u) in the box."""
    res = optimize.least_squares(
        lambda x: arc.point(x[0]) - curve.point(x[1]), np.array([s0, u0]),
        jac=lambda x: np.stack([arc.derivatives(x[0])[0], -curve.derivative(x[1])], axis=1),
        bounds=([0.0, curve.u_lo], [1.0, curve.u_hi]), **_DESCENT,
    )
    return float(res.x[0]), float(res.x[1])


def _solve_interior(arc: _Arc, curve: _Curve, s0: float, u0: float):
    """Case 1: the stationarity equations (paper eqs. 13-14),
    g = [(F_R - F_o)^T F_R', (F_o - F_R)^T F_o'] = 0, by least_squares with their
    Jacobian (the Hessian of D^2/2). Unbounded; returns (s, u), possibly outside the box."""
    cache = {}

    def parts(x):
        key = (x[0], x[1])
        if key not in cache:
            cache.clear()
            r = arc.point(x[0]) - curve.point(x[1])
            A1, A2 = arc.derivatives(x[0])
            C1, C2 = curve.derivative(x[1]), curve.second_derivative(x[1])
            g = np.array([r @ A1, -(r @ C1)])
            H = np.array([[A1 @ A1 + r @ A2, -(A1 @ C1)], [-(A1 @ C1), C1 @ C1 - r @ C2]])
            cache[key] = (g, H)
        return cache[key]

    res = optimize.least_squares(lambda x: parts(x)[0], np.array([s0, u0]), jac=lambda x: parts(x)[1], **_LSQ)
    return float(res.x[0]), float(res.x[1])


def _solve_edge(residual_and_jac, t0):
    """Case 2: one boundary equation (paper eqs. 15-18) by 1-D least_squares (unbounded)."""
    res = optimize.least_squares(
        lambda t: np.array([residual_and_jac(t[0])[0]]), np.array([t0]),
        jac=lambda t: np.array([[residual_and_jac(t[0])[1]]]), **_LSQ,
    )
    return float(res.x[0])


def _solve_s_edge(arc: _Arc, p, s0):
    """dD^2/ds = 0 with the curve point p fixed (u = u_min or u_max, eqs. 15-16) -> s."""

    def res_s(s):
        r = arc.point(s) - p
        A1, A2 = arc.derivatives(s)
        return r @ A1, A1 @ A1 + r @ A2

    return _solve_edge(res_s, s0)


def _solve_u_edge(curve: _Curve, p, u0):
    """dD^2/du = 0 with the arm point p fixed (s = 0 or 1, eqs. 17-18) -> u."""

    def res_u(u):
        r = curve.point(u) - p
        C1 = curve.derivative(u)
        return r @ C1, C1 @ C1 + r @ curve.second_derivative(u)

    return _solve_edge(res_u, u0)


def _grid_seeds(D, bound, max_seeds: int):
    """Seeds from the sampled distances D (n, S, U): the discrete local minima
    (8-neighbourhood, grid edges included) within ``bound`` of the smallest
    sample, at most ``max_seeds`` (the smallest) per segment.

    The sample nearest the exact minimiser is within ``bound`` of the exact
    minimum (D is Lipschitz), so its basin's seed passes the test."""
    n, S, U = D.shape
    Dp = np.pad(D, ((0, 0), (1, 1), (1, 1)), constant_values=np.inf)
    is_min = D <= D.min() + bound
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                is_min &= D <= Dp[:, 1 + di: 1 + di + S, 1 + dj: 1 + dj + U]
    seeds = []
    for i in range(n):
        a, b = np.nonzero(is_min[i])
        order = np.argsort(D[i, a, b], kind="stable")[:max_seeds]
        seeds += [(i, int(a[j]), int(b[j])) for j in order]
    return seeds


def _polish(arc: _Arc, curve: _Curve, s1: float, u1: float):
    """Step (2): the exact stationary points near where the descent landed:
    eqs. 13-14 (inside), and eqs. 17-18 / 15-16 if it is on (or within a
    relative 1e-7 of) s = 0, 1 / u = u_min, u_max -- both, as a minimum may sit
    just inside an edge. -> list of (s, u) in the box, the descent's point first."""
    lo, hi = curve.u_lo, curve.u_hi
    s2, u2 = _solve_interior(arc, curve, s1, u1)
    out = [(s1, u1), (s2, u2)]
    for b in (0.0, 1.0):  # near an edge, or the interior solution is beyond it
        if abs(s1 - b) <= _AT_BOUND or (s2 - b) * (b - 0.5) > 0:
            out.append((b, _solve_u_edge(curve, arc.point(b), u1)))
    for b in (lo, hi):
        if abs(u1 - b) <= _AT_BOUND * (hi - lo) or (u2 - b) * (b - 0.5 * (lo + hi)) > 0:
            out.append((_solve_s_edge(arc, curve.point(b), s1), b))
    return [(s, u) for s, u in out if 0.0 <= s <= 1.0 and lo <= u <= hi]


def _negative_curvature(arc: _Arc, curve: _Curve, s: float, u: float, cell):
    """Half a grid cell along the Hessian's negative-curvature direction at (s, u)
    (in units of the grid's (ds, du)), or None if the Hessian of D^2/2 there is
    positive semi-definite (to rounding)."""
    r = arc.point(s) - curve.point(u)
    A1, A2 = arc.derivatives(s)
    C1, C2 = curve.derivative(u), curve.second_derivative(u)
    scale = np.array(cell)
    H = np.array([[A1 @ A1 + r @ A2, -(A1 @ C1)], [-(A1 @ C1), C1 @ C1 - r @ C2]]) * np.outer(scale, scale)
    w, V = np.linalg.eigh(H)
    if w[0] >= -1e-9 * max(abs(w[1]), np.finfo(np.float64).tiny):
        return None
    return 0.5 * scale * V[:, 0]


def _closest_arm_curve(q, frames, arm_grid, s_grid, curve: _Curve, max_seeds: int = MAX_SEEDS):
    """All three cases of paper §2.3 for every segment and one curve -> (d2, i, s, u, arc).

    Seeds from the sampled D(s, u) of every segment at once (:func:`_grid_seeds`);
    from each, a descent in the box and the polish of the case it landed in
    (:func:`_descend`, :func:`_polish`); plus the four endpoint pairs of every
    segment (case 3). The minimum over all candidates."""
    Rs, Ps = frames[:2]
    n = arm_grid.shape[0]
    D = np.sqrt(np.sum((arm_grid[:, :, None, :] - curve.grid[None, None]) ** 2, axis=-1))  # (n, S, U)
    bound = 0.5 * (float(np.max(q[:, 0])) * (s_grid[1] - s_grid[0]) + curve.speed * curve.du) * (1.0 + 1e-9)
    arcs = [_Arc(q[i], Rs[i], Ps[i]) for i in range(n)]
    cands = [(i, s_c, u_c) for i in range(n) for s_c in (0.0, 1.0) for u_c in (curve.u_lo, curve.u_hi)]
    cell = (float(s_grid[1] - s_grid[0]), curve.du)
    for i, a, b in _grid_seeds(D, bound, max_seeds):
        s0, u0 = float(s_grid[a]), float(curve.u_grid[b])
        found = _polish(arcs[i], curve, s0, u0)  # Newton from the seed itself
        s1, u1 = _descend(arcs[i], curve, s0, u0)
        found += _polish(arcs[i], curve, s1, u1)
        # A stationary point with negative curvature is a saddle (e.g. where a segment
        # leaves its neighbour's tangent towards the curve): step off it both ways and descend.
        for s2, u2 in found[:]:
            v = _negative_curvature(arcs[i], curve, s2, u2, cell)
            if v is not None:
                for sign in (1.0, -1.0):
                    s3 = min(max(s2 + sign * v[0], 0.0), 1.0)
                    u3 = min(max(u2 + sign * v[1], curve.u_lo), curve.u_hi)
                    found += _polish(arcs[i], curve, *_descend(arcs[i], curve, s3, u3))
        cands += [(i, s, u) for s, u in found]
    best = None
    for i, s, u in sorted(cands, key=lambda c: c[0]):  # ties: the lower segment
        r = arcs[i].point(s) - curve.point(u)
        d2 = float(r @ r)
        if best is None or d2 < best[0]:
            best = (d2, i, s, u, arcs[i])
    return best


def closest_point_curve(q, coeffs, u_range, frames=None, *, curve: _Curve | None = None,
                        arm_grid=None) -> NumpyClosest:
    """Exact closest point between the arm and one polynomial curve (paper §2.3).

    Args:
      q: (n, 3) configuration.
      coeffs: (3, K) curve coefficients, lowest degree first.
      u_range: (u_min, u_max).
      frames: optional ``segment_frames(q)`` (reused within a planner step).
      curve: optional prebuilt ``_Curve(coeffs, u_range)`` (static obstacles).
      arm_grid: optional ``segment_points(q, linspace(0, 1, GRID_S), frames)``
        (shared by every curve of a planner step).
    """
    q = np.asarray(q, np.float64)
    frames = frames or segment_frames(q)
    curve = curve if curve is not None else _Curve(coeffs, u_range)
    s_grid = np.linspace(0.0, 1.0, GRID_S)
    if arm_grid is None:
        arm_grid = segment_points(q, s_grid, frames)
    _, i, s, u, arc = _closest_arm_curve(q, frames, arm_grid, s_grid, curve)
    a, o = arc.point(s), curve.point(u)
    return NumpyClosest(float(np.linalg.norm(a - o)), i, s, u, a, o)


def closest_point_points(q, points, tree=None, points_per_segment: int = 10,
                         nn: str = "kdtree", arm=None) -> NumpyClosest:
    """The N-point method: nearest pair between arm samples and obstacle points.

    ``nn="kdtree"`` queries a ``scipy.spatial.cKDTree`` of the obstacle points
    (the dsearchn analogue; pass a prebuilt ``tree`` for static obstacles),
    ``nn="brute"`` compares all pairs. ``u`` is the index of the obstacle point.
    ``arm``: optional ``backbone_points(q, points_per_segment)`` (shared by every
    obstacle of a planner step).
    """
    arm = backbone_points(q, points_per_segment) if arm is None else arm
    points = np.asarray(points, np.float64)
    if nn == "kdtree":
        tree = tree if tree is not None else spatial.cKDTree(points)
        d, idx = tree.query(arm)
        a = int(np.argmin(d))
        p = int(idx[a])
    elif nn == "brute":
        d2 = np.sum((arm[:, None, :] - points[None, :, :]) ** 2, axis=-1)
        a, p = np.unravel_index(int(np.argmin(d2)), d2.shape)
    else:
        raise ValueError(f"unknown nn {nn!r}; choose 'kdtree' or 'brute'")
    k = points_per_segment
    return NumpyClosest(float(np.linalg.norm(arm[a] - points[p])), int(a // k), float(a % k + 1) / k,
                        float(p), arm[a], points[p])


# ----------------------------------------------------------------------------
# Planner (paper eq. 9).


def attraction(V_e, g: dict):
    """F_e(V_e) = k_att V_e, saturated to speed v_max (as softplan_jax.planning._planner.attraction)."""
    speed = g["k_att"] * float(np.linalg.norm(V_e))
    return g["k_att"] * V_e / max(1.0, speed / g["v_max"])


def repulsion(V_s, clearance: float, g: dict, kind: str = "khatib"):
    """F_s(V_s) as softplan_jax.planning._planner.repulsion: Khatib's eta (1/d - 1/d0)/d^2 for
    d < d0 (0 beyond), smoothly capped with rep_max tanh(. / rep_max); or
    rep_max exp(-d/d0). d is floored at 1e-3 d0."""
    d = max(clearance, 1e-3 * g["d0"])
    if kind == "khatib":
        raw = g["eta"] * (1.0 / d - 1.0 / g["d0"]) / (d * d) if d < g["d0"] else 0.0
        # rep_max = inf: no cap (the "paper" preset).
        mag = raw if math.isinf(g["rep_max"]) else g["rep_max"] * math.tanh(raw / g["rep_max"])
    elif kind == "exponential":
        mag = g["rep_max"] * math.exp(-d / g["d0"])
    else:
        raise ValueError(f"unknown repulsion {kind!r}; choose 'khatib' or 'exponential'")
    return mag * V_s / max(float(np.linalg.norm(V_s)), np.finfo(np.float64).tiny)


class _Prepared(NamedTuple):
    """Per-scenario, per-method obstacle models (built once; obstacles are static)."""

    scenario: NumpyScenario
    method: str
    curve_models: list  # curve method: (coeffs, u_range, radius, _Curve); points: (points, tree, radius)
    point_models: list  # (points, tree, radius)


def _prepare(scenario: NumpyScenario, method: str, n_points: int, nn: str) -> _Prepared:
    if method not in ("curve", "points"):
        raise ValueError(f"unknown method {method!r}; choose 'curve' or 'points'")
    if int(n_points) < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")

    def pts_model(pts, radius):
        return (pts, spatial.cKDTree(pts) if nn == "kdtree" else None, radius)

    if method == "curve":
        curve_models = [(c, ur, r, _Curve(c, ur)) for c, ur, r in scenario.curves]
    else:
        curve_models = [pts_model(_Curve(c, ur).sample(int(n_points)), r) for c, ur, r in scenario.curves]
    point_models = [pts_model(p, r) for p, r in scenario.point_sets]
    return _Prepared(scenario, method, curve_models, point_models)


def numpy_step(q, prep: _Prepared, g: dict, pinv: str = "damped", repulsion_kind: str = "khatib",
               nn: str = "kdtree", points_per_segment: int = 10):
    """One planner step, paper eq. (9): qdot = J_e^+ F_e(V_e) - sum_j J_sj^+ F_sj(V_sj);
    q <- q + dt qdot with L clipped. Returns (q_next, list of NumpyClosest)."""
    sc = prep.scenario
    q = np.asarray(q, np.float64)
    n = q.shape[0]
    if pinv == "damped":
        inv = lambda J: damped_pinv(J, g["damping"])  # noqa: E731
    elif pinv == "svd":
        inv = np.linalg.pinv
    else:
        raise ValueError(f"unknown pinv {pinv!r}; choose 'damped' or 'svd'")
    frames = segment_frames(q)
    V_e = sc.goal - frames[3]
    qdot = inv(tip_jacobian(q, frames)) @ attraction(V_e, g)
    cps, radii = [], []
    if prep.method == "curve" and prep.curve_models:
        arm_grid = segment_points(q, np.linspace(0.0, 1.0, GRID_S), frames)  # shared by every curve
        for coeffs, u_range, radius, curve in prep.curve_models:
            cps.append(closest_point_curve(q, coeffs, u_range, frames, curve=curve, arm_grid=arm_grid))
            radii.append(radius)
    point_models = prep.point_models if prep.method == "curve" else prep.curve_models + prep.point_models
    arm = backbone_points(q, points_per_segment, frames) if point_models else None  # shared by all
    for pts, tree, radius in point_models:
        cps.append(closest_point_points(q, pts, tree, points_per_segment, nn, arm=arm))
        radii.append(radius)
    forces = [repulsion(cp.obstacle_point - cp.arm_point, cp.distance - sc.arm_radius - radius, g, repulsion_kind)
              for cp, radius in zip(cps, radii, strict=True)]
    # The Jacobian only within the critical range (paper §2.2): all of them in one call.
    active = [j for j, F in enumerate(forces) if np.any(F != 0.0)]
    if active:
        Js = point_jacobians(q, [cps[j].segment for j in active], [cps[j].s for j in active], frames)
        for J, j in zip(Js, active, strict=True):
            qdot = qdot - inv(J) @ forces[j]
    q_next = q + g["dt"] * qdot.reshape(n, 3)
    q_next[:, 0] = np.clip(q_next[:, 0], sc.L_min, sc.L_max)
    return q_next, cps


class NumpyPlanResult(NamedTuple):
    """Result of :func:`numpy_plan`.

    Attributes:
      q: (steps + 1, n, 3) configurations, start first.
      tip: (steps + 1, 3).
      iterations: planner steps taken.
      reached: |goal - tip| < goal_tolerance at the end.
      step_times: (steps,) wall time of each planner step [s].
      final_error: |goal - tip| at the end.
      active: (steps,) number of obstacles within the repulsion's range
        (nonzero repulsion) at each step.
    """

    q: np.ndarray
    tip: np.ndarray
    iterations: int
    reached: bool
    step_times: np.ndarray
    final_error: float
    active: np.ndarray


def numpy_plan(scenario, method: str = "curve", n_points: int = 10, max_steps: int = 300, gains=None, *,
               goal_tolerance: float = 1e-2, pinv: str = "damped", repulsion_kind: str = "khatib",
               nn: str = "kdtree", points_per_segment: int = 10, stop_at_goal: bool = True,
               progress: str | None = None) -> NumpyPlanResult:
    """Plan with the NumPy baseline.

    Args:
      scenario: a paper scenario name ("sim1", "sim2", "tree"), a softplan_jax
        Scenario, or a NumpyScenario.
      method: "curve" (exact closest points) or "points" (N-point model).
      n_points: N of the N-point model.
      max_steps: the most planner steps.
      gains: softplan_jax Gains or a dict; None = softplan_jax.default_gains.
      goal_tolerance: stop when |goal - tip| < goal_tolerance (checked at the
        start and after every step), as softplan_jax's rollout.
      pinv: "damped" (as softplan_jax) or "svd" (numpy.linalg.pinv).
      nn: "kdtree" or "brute" (N-point nearest-pair search).
      stop_at_goal: False runs all max_steps.
      progress: a label to print progress to stderr with, or None.

    Returns:
      NumpyPlanResult.
    """
    sc = scenario if isinstance(scenario, NumpyScenario) else to_numpy_scenario(scenario)
    g = numpy_gains(gains)
    prep = _prepare(sc, method, n_points, nn)
    q = sc.q0.copy()
    qs, times, active = [q], [], []
    err = float(np.linalg.norm(sc.goal - tip_position(q)))
    t_last = time.perf_counter()
    for k in range(int(max_steps)):
        if stop_at_goal and err < goal_tolerance:
            break
        t0 = time.perf_counter()
        q_next, cps = numpy_step(q, prep, g, pinv, repulsion_kind, nn, points_per_segment)
        times.append(time.perf_counter() - t0)
        radii = [m[2] for m in prep.curve_models + prep.point_models]
        active.append(sum(cp.distance - sc.arm_radius - r < g["d0"]
                          for cp, r in zip(cps, radii, strict=True)))
        q = q_next
        err = float(np.linalg.norm(sc.goal - tip_position(q)))
        qs.append(q)
        if progress and time.perf_counter() - t_last > 5.0:
            _log(f"  [{progress}] NumPy step {k + 1}/{max_steps}, |V_e| = {err:.4f}, "
                 f"median {1e3 * np.median(times):.1f} ms/step")
            t_last = time.perf_counter()
    qs = np.stack(qs)
    return NumpyPlanResult(qs, tip_position(qs), len(times), bool(err < goal_tolerance),
                           np.asarray(times), err, np.asarray(active, int))


# ----------------------------------------------------------------------------
# The JAX side, agreement and timing.


def jax_trajectory(scenario, method: str, n_points: int, steps: int, gains=None,
                   goal_tolerance: float = 1e-2):
    """The JAX planner stepped with the jitted ``planner_step`` on the host, with the
    same stop rule; returns (steps_taken + 1, n, 3)."""
    opts = make_options(method, n_points, goal_tolerance=goal_tolerance, **PAPER_STEP)
    gains = jax_gains(gains)
    goal = np.asarray(scenario.goal)
    q = scenario.q0
    qs = [np.asarray(q)]
    for _ in range(int(steps)):
        if np.linalg.norm(goal - np.asarray(sp.tip_position(q))) < goal_tolerance:
            break
        q = _planner_step_timed_first(q, scenario, gains, opts)
        qs.append(np.asarray(q))
    return np.stack(qs)


_FIRST_CALL_S: dict = {}


def _shape_key(scenario, opts):
    return (opts, tuple(np.shape(x) for x in jax.tree_util.tree_leaves(scenario)))


def _planner_step_timed_first(q, scenario, gains, opts):
    """planner_step; the first call per (options, scenario shapes), i.e. the
    compilation, is timed into _FIRST_CALL_S."""
    key = _shape_key(scenario, opts)
    if key in _FIRST_CALL_S:
        return planner_step(q, scenario, gains, opts)
    t0 = time.perf_counter()
    out = planner_step(q, scenario, gains, opts).block_until_ready()
    _FIRST_CALL_S[key] = time.perf_counter() - t0
    return out


def _time_jax_step(scenario, method, n_points, states, repeats: int):
    """Median wall time of the jitted planner_step over the given states (compile excluded)."""
    opts = make_options(method, n_points, **PAPER_STEP)  # the paper's step, as the NumPy peer
    gains = sp.default_gains(jnp.float64)
    _planner_step_timed_first(states[0], scenario, gains, opts).block_until_ready()
    compile_s = _FIRST_CALL_S[_shape_key(scenario, opts)]  # first call (compile) wherever it happened
    for q in states[:3]:  # warm-up
        planner_step(q, scenario, gains, opts).block_until_ready()
    times = []
    for _ in range(repeats):
        for q in states:
            t0 = time.perf_counter()
            planner_step(q, scenario, gains, opts).block_until_ready()
            times.append(time.perf_counter() - t0)
    return float(np.median(times)), compile_s, len(times)
