"""Independent NumPy/SciPy reference for the geometry core.

Written from the paper's formulas (paper.md sections 2.1-2.3) and deliberately
NOT importing ``softplan_jax``: the test suite compares the library against
this module, never the library against itself.

Kinematics (paper section 2.1, Webster & Jones 2010)::

    R_i = [[c(phi)c(th), -s(phi), c(phi)s(th)],
           [s(phi)c(th),  c(phi), s(phi)s(th)],
           [-s(th),       0,      c(th)     ]]
    P_i = [(1-cos th) L/th cos phi, (1-cos th) L/th sin phi, sin th L/th]
    P_si = R_{i-1}^0 [(1-cos(th s)) L/th cos phi, ..., sin(th s) L/th] + P_{i-1}^0

The removable singularities at ``th = 0`` are removed analytically, with no
division by theta at all: ``sin(th s)/th = s sinc(th s)`` and
``(1 - cos(th s))/th = (th s^2/2) sinc(th s/2)^2`` (half-angle identity), with
``sinc`` from its Taylor series for |x| < 0.1.  All formulas also accept
complex input, so ``jacobian_complex_step`` gives Jacobians exact to rounding,
at ``th = 0`` included.

Closest point (paper section 2.3): for each segment, the minimum of
``D^2(s, u) = |F_R(s) - F_o(u)|^2`` over ``[0, 1] x [u0, u1]`` from

* a dense 2-D grid; the promising grid local minima are refined by
  ``scipy.optimize.minimize`` (L-BFGS-B with bounds) and then polished with a
  projected Newton iteration on the exact gradient and Hessian;
* dense 1-D scans of the four edges (s = 0, s = 1, u = u0, u = u1), refined
  with ``scipy.optimize.minimize_scalar(method="bounded")`` and 1-D Newton;
* the four corners.

The answer is the minimum over all candidates and all segments.  The oracle is
checked against closed-form answers in ``tests/test_closest.py``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from scipy import ndimage, optimize

# --------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------


def _sinc(x):
    """sin(x)/x; Taylor series (to x**18) for |x| < 0.1, real or complex x.

    The series branch keeps the complex-step derivative free of the
    cancellation in d/dx[sin x / x] = (x cos x - sin x)/x**2 at small x.
    """
    x = np.asarray(x)
    small = np.abs(x) < 0.1
    xs = np.where(small, x, 0.0)
    x2 = xs * xs
    series = np.zeros_like(x2)
    for k in range(9, -1, -1):  # Horner in x**2 of sum (-1)^k x^2k / (2k+1)!
        series = series * x2 + (-1) ** k / math.factorial(2 * k + 1)
    xl = np.where(small, 1.0, x)
    return np.where(small, series, np.sin(xl) / xl)


_SINC_TAYLOR = [(-1) ** k / math.factorial(2 * k + 1) for k in range(10)]


def _sinc_scalar(x):
    """Python-float version of ``_sinc``."""
    if abs(x) < 0.1:
        x2 = x * x
        acc = 0.0
        for c in reversed(_SINC_TAYLOR):
            acc = acc * x2 + c
        return acc
    return math.sin(x) / x


def _arc_coeffs(theta, s):
    """Return a = (1 - cos(th s))/th and b = sin(th s)/th.

    Written without any division by theta:
      b = s sinc(th s),  a = 2 sin(th s/2)^2 / th = (th s^2 / 2) sinc(th s/2)^2,
    so th = 0 needs no special case.  Elementwise on broadcastable real or
    complex arrays.
    """
    if isinstance(theta, (float, np.floating)) and isinstance(s, (float, int, np.floating, np.integer)):
        # Real scalars (the frames of every segment): the same formulas on Python
        # floats, an order of magnitude faster than on 0-d arrays.
        theta, s = float(theta), float(s)
        return 0.5 * theta * s * s * _sinc_scalar(0.5 * theta * s) ** 2, s * _sinc_scalar(theta * s)
    theta = np.asarray(theta)
    s = np.asarray(s)
    b = s * _sinc(theta * s)
    a = 0.5 * theta * s * s * _sinc(0.5 * theta * s) ** 2
    return a, b


def segment_transform(q_i):
    """Paper's (R_i, P_i) for one row q_i = [L, theta, phi]."""
    L, th, ph = q_i[0], q_i[1], q_i[2]
    cp, sp_ = np.cos(ph), np.sin(ph)
    ct, st = np.cos(th), np.sin(th)
    zero = 0.0 * L
    R = np.array(
        [
            [cp * ct, -sp_, cp * st],
            [sp_ * ct, cp, sp_ * st],
            [-st, zero, ct],
        ]
    )
    a, b = _arc_coeffs(th, 1.0)
    P = L * np.array([a * cp, a * sp_, b])
    return R, P


def segment_frames(q):
    """Base orientation/position of every segment: (n, 3, 3), (n, 3)."""
    q = np.asarray(q)
    n = q.shape[0]
    dt = np.result_type(q.dtype, np.float64)
    Rs = np.zeros((n, 3, 3), dtype=dt)
    Ps = np.zeros((n, 3), dtype=dt)
    R = np.eye(3, dtype=dt)
    P = np.zeros(3, dtype=dt)
    for i in range(n):
        Rs[i] = R
        Ps[i] = P
        Ri, Pi = segment_transform(q[i])
        P = P + R @ Pi  # H_i^0 = H_{i-1}^0 H_i^{i-1}
        R = R @ Ri
    return Rs, Ps


def tip_frame(q):
    """(R_n^0, P_n^0) = product of all H_i^{i-1}."""
    q = np.asarray(q)
    dt = np.result_type(q.dtype, np.float64)
    H = np.eye(4, dtype=dt)
    for i in range(q.shape[0]):
        Ri, Pi = segment_transform(q[i])
        Hi = np.eye(4, dtype=dt)
        Hi[:3, :3] = Ri
        Hi[:3, 3] = Pi
        H = H @ Hi
    return H[:3, :3], H[:3, 3]


def tip_position(q):
    return tip_frame(q)[1]


def _local_arc(q_i, s):
    """Local arc point(s) and s-derivatives for segment row q_i, s array (m,)."""
    L, th, ph = q_i[0], q_i[1], q_i[2]
    s = np.asarray(s)
    a, b = _arc_coeffs(th, s)
    cp, sp_ = np.cos(ph), np.sin(ph)
    p = L * np.stack([a * cp, a * sp_, b], axis=-1)
    # d/ds: [sin(th s) L cos phi, sin(th s) L sin phi, cos(th s) L]
    sn, cs = np.sin(th * s), np.cos(th * s)
    dp = L * np.stack([sn * cp, sn * sp_, cs], axis=-1)
    # d2/ds2: th L [cos(th s) cos phi, cos(th s) sin phi, -sin(th s)]
    ddp = th * L * np.stack([cs * cp, cs * sp_, -sn], axis=-1)
    return p, dp, ddp


def segment_points(q, i, s):
    """Points of segment i at fractions s (array (m,)) -> (m, 3)."""
    return segment_point_derivs(q, i, s)[0]


def segment_point_derivs(q, i, s):
    """(F, dF/ds, d2F/ds2), each (m, 3), for segment i at fractions s (m,)."""
    q = np.asarray(q)
    Rs, Ps = segment_frames(q)
    s = np.atleast_1d(np.asarray(s))
    p, dp, ddp = _local_arc(q[i], s)
    R, P = Rs[i], Ps[i]
    return p @ R.T + P, dp @ R.T, ddp @ R.T


def segment_point(q, i, s):
    """Single point (3,) at fraction s of segment i (paper's P_si)."""
    return segment_points(q, i, np.array([s]))[0]


def backbone_points(q, k=10):
    q = np.asarray(q)
    s = np.arange(1, k + 1) / k
    return np.concatenate([segment_points(q, i, s) for i in range(q.shape[0])])


def jacobian_complex_step(fn, q, h=1e-30):
    """d fn(q) / d q.ravel() by the complex-step method (exact to rounding)."""
    q = np.asarray(q, dtype=np.float64)
    cols = []
    for k in range(q.size):
        qc = q.astype(np.complex128).ravel()
        qc[k] += 1j * h
        cols.append(np.imag(np.asarray(fn(qc.reshape(q.shape)))) / h)
    return np.stack(cols, axis=-1)


def point_jacobian(q, i, s):
    """Exact (3, 3n) Jacobian of segment_point wrt row-major flattened q."""
    return jacobian_complex_step(lambda qq: segment_point(qq, i, s), q)


def tip_jacobian(q):
    return jacobian_complex_step(tip_position, q)


def central_difference(fn, x, h):
    """Central differences of fn (array-valued) wrt every entry of x.

    Returns an array of shape fn(x).shape + x.shape.
    """
    x = np.asarray(x, dtype=np.float64)
    out = []
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = h
        e = e.reshape(x.shape)
        out.append((np.asarray(fn(x + e)) - np.asarray(fn(x - e))) / (2 * h))
    res = np.stack(out, axis=-1)
    return res.reshape(res.shape[:-1] + x.shape)


# --------------------------------------------------------------------------
# Curves
# --------------------------------------------------------------------------


@dataclasses.dataclass
class OPoly:
    """Polynomial curve, coeffs (3, K), lowest degree first."""

    coeffs: np.ndarray
    u0: float
    u1: float

    def __post_init__(self):
        self.coeffs = np.asarray(self.coeffs, dtype=np.float64)
        c = self.coeffs
        K = c.shape[1]
        k = np.arange(K)
        self._d1 = (c * k)[:, 1:] if K > 1 else np.zeros((3, 1))
        self._d2 = (c * k * (k - 1))[:, 2:] if K > 2 else np.zeros((3, 1))

    @staticmethod
    def _horner(c, u):
        u = np.asarray(u, dtype=np.float64)
        out = np.zeros(u.shape + (3,))
        for k in range(c.shape[1] - 1, -1, -1):
            out = out * u[..., None] + c[:, k]
        return out

    def point(self, u):
        return self._horner(self.coeffs, u)

    def d1(self, u):
        return self._horner(self._d1, u)

    def d2(self, u):
        return self._horner(self._d2, u)

    @property
    def speed_bound(self):
        u = np.linspace(self.u0, self.u1, 2001)
        return float(np.max(np.linalg.norm(self.d1(u), axis=-1)))


@dataclasses.dataclass
class OFunc:
    """Any smooth curve given by vectorised f, f', f'' (u (m,) -> (m, 3))."""

    f: Callable
    df: Callable
    ddf: Callable
    u0: float
    u1: float

    def point(self, u):
        return self.f(np.asarray(u, dtype=np.float64))

    def d1(self, u):
        return self.df(np.asarray(u, dtype=np.float64))

    def d2(self, u):
        return self.ddf(np.asarray(u, dtype=np.float64))

    @property
    def speed_bound(self):
        u = np.linspace(self.u0, self.u1, 2001)
        return float(np.max(np.linalg.norm(self.d1(u), axis=-1)))


@dataclasses.dataclass
class OHelix:
    """(r cos u, r sin u, pitch u), u in [u0, u1] (picklable, unlike OFunc)."""

    u0: float
    u1: float
    radius: float = 1.0
    pitch: float = 0.2

    def point(self, u):
        u = np.asarray(u, dtype=np.float64)
        r = self.radius
        return np.stack([r * np.cos(u), r * np.sin(u), self.pitch * u], -1)

    def d1(self, u):
        u = np.asarray(u, dtype=np.float64)
        r = self.radius
        return np.stack([-r * np.sin(u), r * np.cos(u), self.pitch * np.ones_like(u)], -1)

    def d2(self, u):
        u = np.asarray(u, dtype=np.float64)
        r = self.radius
        return np.stack([-r * np.cos(u), -r * np.sin(u), np.zeros_like(u)], -1)

    @property
    def speed_bound(self):
        return float(np.hypot(self.radius, self.pitch))


def helix(u0, u1, radius=1.0, pitch=0.2):
    return OHelix(float(u0), float(u1), radius, pitch)


def line(a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return OPoly(np.stack([a, b - a], axis=1), 0.0, 1.0)


# --------------------------------------------------------------------------
# Closest point
# --------------------------------------------------------------------------


@dataclasses.dataclass
class OClosest:
    distance: float
    segment: int
    s: float
    u: float
    arm_point: np.ndarray
    obstacle_point: np.ndarray
    # every refined candidate (d, segment, s, u), sorted by d
    candidates: list


class _SegmentProblem:
    """D^2(s, u) for one arm segment (given by its base frame) and a curve.

    Vectorised methods (``arm``, ``crv``) serve the grids; the scalar methods
    (``f``, ``fg``, ``fgh``) are written with ``math`` on Python floats because
    the refinement calls them thousands of times.
    """

    def __init__(self, q, i, curve, frames=None):
        q = np.asarray(q, dtype=np.float64)
        Rs, Ps = segment_frames(q) if frames is None else frames
        self.R, self.P, self.qi = Rs[i], Ps[i], q[i]
        self.curve = curve
        self.u0, self.u1 = float(curve.u0), float(curve.u1)
        L, th, ph = (float(v) for v in q[i])
        self._L, self._th = L, th
        self._cp, self._sp = math.cos(ph), math.sin(ph)
        self._Rl = [[float(v) for v in row] for row in self.R]
        self._Pl = [float(v) for v in self.P]
        if isinstance(curve, OPoly):
            c = curve.coeffs
            self._c0 = [[float(v) for v in row] for row in c]
            self._c1 = [[float(v) for v in row] for row in curve._d1]
            self._c2 = [[float(v) for v in row] for row in curve._d2]
        else:
            self._c0 = None

    # ---- vectorised
    def arm(self, s):
        p, dp, ddp = _local_arc(self.qi, np.atleast_1d(s))
        return p @ self.R.T + self.P, dp @ self.R.T, ddp @ self.R.T

    def crv(self, u):
        u = np.atleast_1d(u)
        return self.curve.point(u), self.curve.d1(u), self.curve.d2(u)

    # ---- scalar
    def _rot(self, v, add_p):
        R = self._Rl
        out = [
            R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
            R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
            R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2],
        ]
        if add_p:
            P = self._Pl
            out = [out[0] + P[0], out[1] + P[1], out[2] + P[2]]
        return out

    def arm_s(self, s, order=0):
        L, th, cp, sp_ = self._L, self._th, self._cp, self._sp
        a, b = _arc_coeffs(th, s)  # Python floats: its scalar branch
        A = self._rot((L * a * cp, L * a * sp_, L * b), True)
        if order == 0:
            return A
        sn, cs = math.sin(th * s), math.cos(th * s)
        dA = self._rot((L * sn * cp, L * sn * sp_, L * cs), False)
        tl = th * L
        ddA = self._rot((tl * cs * cp, tl * cs * sp_, -tl * sn), False)
        return A, dA, ddA

    @staticmethod
    def _horner3(c, u):
        out = []
        for row in c:
            acc = 0.0
            for k in range(len(row) - 1, -1, -1):
                acc = acc * u + row[k]
            out.append(acc)
        return out

    def crv_s(self, u, order=0):
        if self._c0 is not None:
            C = self._horner3(self._c0, u)
            if order == 0:
                return C
            return C, self._horner3(self._c1, u), self._horner3(self._c2, u)
        ua = np.array([u], dtype=np.float64)
        C = [float(v) for v in self.curve.point(ua)[0]]
        if order == 0:
            return C
        return (
            C,
            [float(v) for v in self.curve.d1(ua)[0]],
            [float(v) for v in self.curve.d2(ua)[0]],
        )

    def f(self, s, u):
        A = self.arm_s(float(s))
        C = self.crv_s(float(u))
        d0, d1, d2 = A[0] - C[0], A[1] - C[1], A[2] - C[2]
        return d0 * d0 + d1 * d1 + d2 * d2

    def fg(self, x):
        f, g, _ = self.fgh_t(float(x[0]), float(x[1]))
        return f, np.array(g)

    def fgh(self, s, u):
        f, g, H = self.fgh_t(s, u)
        return f, np.array(g), np.array(H)

    def fgh_t(self, s, u):
        A, dA, ddA = self.arm_s(float(s), 1)
        C, dC, ddC = self.crv_s(float(u), 1)
        d = [A[0] - C[0], A[1] - C[1], A[2] - C[2]]

        def dot(x, y):
            return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]

        g = (2 * dot(d, dA), -2 * dot(d, dC))
        h01 = -2 * dot(dA, dC)
        H = (
            (2 * (dot(dA, dA) + dot(d, ddA)), h01),
            (h01, 2 * (dot(dC, dC) - dot(d, ddC))),
        )
        return dot(d, d), g, H


def _polish(prob, s, u, iters=30):
    """Projected Newton on D^2 from (s, u); never accepts an uphill step.

    Pure-Python 2x2 algebra (called thousands of times).
    """
    lo = (0.0, prob.u0)
    hi = (1.0, prob.u1)
    x = [min(max(float(s), lo[0]), hi[0]), min(max(float(u), lo[1]), hi[1])]
    f, g, H = prob.fgh_t(x[0], x[1])
    for _ in range(iters):
        # active set: at a bound with the gradient pointing outwards
        free = [not ((x[k] <= lo[k] and g[k] > 0) or (x[k] >= hi[k] and g[k] < 0)) for k in (0, 1)]
        if free[0] and free[1]:
            det = H[0][0] * H[1][1] - H[0][1] * H[1][0]
            if not (det > 0 and H[0][0] > 0):
                break
            step = [
                -(H[1][1] * g[0] - H[0][1] * g[1]) / det,
                -(H[0][0] * g[1] - H[1][0] * g[0]) / det,
            ]
        elif free[0] or free[1]:
            k = 0 if free[0] else 1
            if not H[k][k] > 0:
                break
            step = [0.0, 0.0]
            step[k] = -g[k] / H[k][k]
        else:
            break
        if not (math.isfinite(step[0]) and math.isfinite(step[1])):
            break
        t = 1.0
        improved = False
        for _ls in range(30):
            xn = [min(max(x[k] + t * step[k], lo[k]), hi[k]) for k in (0, 1)]
            fn_ = prob.f(xn[0], xn[1])
            if fn_ <= f:
                improved = True
                break
            t *= 0.5
        if not improved:
            break
        moved = max(abs(xn[0] - x[0]), abs(xn[1] - x[1]))
        x = xn
        f, g, H = prob.fgh_t(x[0], x[1])
        if moved == 0.0:
            break
    return f, x[0], x[1]


def _grid_local_minima(D):
    """Boolean mask of (non-strict) local minima of a 2-D array, 8-neighbour."""
    return D <= ndimage.minimum_filter(D, size=3, mode="constant", cval=np.inf)


def _local_minima_1d(v):
    pad = np.concatenate([[np.inf], v, [np.inf]])
    return np.nonzero((v <= pad[:-2]) & (v <= pad[2:]))[0]


def _refine_2d(prob, s0, u0_):
    """L-BFGS-B with bounds on D^2 from a grid seed, then Newton polish."""
    x0 = np.array([s0, u0_])
    res = optimize.minimize(
        prob.fg,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, 1.0), (prob.u0, prob.u1)],
        options={"ftol": 1e-16, "gtol": 1e-14, "maxiter": 500},
    )
    x = np.clip(res.x, [0.0, prob.u0], [1.0, prob.u1])
    return _polish(prob, x[0], x[1])


def _refine_edge(prob, kind, fixed, lo, hi):
    """Bounded Brent on one edge (s or u fixed), then 1-D Newton polish."""
    if kind == "u":  # s fixed, search u
        fun = lambda u: prob.f(fixed, u)  # noqa: E731
    else:  # u fixed, search s
        fun = lambda s: prob.f(s, fixed)  # noqa: E731
    r = optimize.minimize_scalar(fun, bounds=(lo, hi), method="bounded", options={"xatol": 1e-13})
    x = float(np.clip(r.x, lo, hi))
    s, u = (fixed, x) if kind == "u" else (x, fixed)
    return [(prob.f(s, u), s, u), _polish_edge(prob, kind, fixed, x)]


def _polish_edge(prob, kind, fixed, x, iters=30):
    lo, hi = (prob.u0, prob.u1) if kind == "u" else (0.0, 1.0)
    j = 1 if kind == "u" else 0

    def pt(v):
        return (fixed, v) if kind == "u" else (v, fixed)

    f, g, H = prob.fgh_t(*pt(x))
    for _ in range(iters):
        gj, hj = g[j], H[j][j]
        if not hj > 0:
            break
        step = -gj / hj
        t = 1.0
        ok = False
        for _ls in range(30):
            xn = min(max(x + t * step, lo), hi)
            fn_ = prob.f(*pt(xn))
            if fn_ <= f:
                ok = True
                break
            t *= 0.5
        if not ok or xn == x:
            break
        x = xn
        f, g, H = prob.fgh_t(*pt(x))
    s, u = pt(x)
    return f, s, u


def closest_point(
    q,
    curve,
    ns=81,
    nu=None,
    n_edge_s=1001,
    n_edge_u=None,
    max_seeds=8,
    margin_factor=2.0,
):
    """Closest pair between the arm backbone and the curve (radii ignored).

    Every point of ``[0, 1] x [u0, u1]`` lies within half a grid cell of a
    node, so ``D(node) <= D(x) + margin`` with ``margin = (L ds + |F_o'|max du)
    / 2``; grid (and edge-scan) local minima within ``margin_factor * margin``
    of the best value over ALL segments are refined, the rest cannot hold the
    global minimum (up to the basin-assignment caveat of any grid method).

    Args:
      q: (n, 3) configuration.
      curve: ``OPoly`` or ``OFunc``.
    Returns:
      ``OClosest`` with the global minimum and the sorted candidate list.
    """
    q = np.asarray(q, dtype=np.float64)
    n = q.shape[0]
    speed = curve.speed_bound
    u0, u1 = float(curve.u0), float(curve.u1)
    length_bound = speed * (u1 - u0)
    if nu is None:
        nu = int(np.clip(np.ceil(length_bound / 0.015), 150, 2000))
    if n_edge_u is None:
        n_edge_u = int(np.clip(np.ceil(length_bound / 0.002), 1001, 10001))
    frames = segment_frames(q)
    probs = [_SegmentProblem(q, i, curve, frames) for i in range(n)]

    sg = np.linspace(0.0, 1.0, ns)
    ug = np.linspace(u0, u1, nu)
    se = np.linspace(0.0, 1.0, n_edge_s)
    ue = np.linspace(u0, u1, n_edge_u)
    Cg = curve.point(ug)
    Cg2 = np.sum(Cg * Cg, 1)
    Ce = curve.point(ue)
    C_end = curve.point(np.array([u0, u1]))

    raw = []  # (D, i, s, u) of every unrefined grid/edge/corner candidate
    jobs = []  # (threshold-able value, margin, i, job)
    for i, prob in enumerate(probs):
        L = float(q[i, 0])
        # corners (case 3)
        for s in (0.0, 1.0):
            for u in (u0, u1):
                raw.append((math.sqrt(prob.f(s, u)), i, s, u))
        # 2-D grid (case 1)
        A = prob.arm(sg)[0]
        # |A|^2 + |C|^2 - 2 A.C: only used to pick starts (the candidates'
        # values are recomputed exactly), so its rounding near 0 is harmless
        Dg = np.sqrt(np.maximum(np.sum(A * A, 1)[:, None] + Cg2[None, :] - 2.0 * (A @ Cg.T), 0.0))
        m2 = margin_factor * 0.5 * (L * (sg[1] - sg[0]) + speed * (ug[1] - ug[0]))
        lm = np.argwhere(_grid_local_minima(Dg))
        vals = Dg[lm[:, 0], lm[:, 1]]
        for k in np.argsort(vals)[: 4 * max_seeds]:
            a_, b_ = lm[k]
            jobs.append((vals[k], m2, i, ("2d", sg[a_], ug[b_])))
        # edges (case 2): s = 0 / 1 scanned in u, u = u0 / u1 scanned in s
        mu = margin_factor * 0.5 * speed * (ue[1] - ue[0])
        ms = margin_factor * 0.5 * L * (se[1] - se[0])
        for s_fix in (0.0, 1.0):
            p = prob.arm(s_fix)[0][0]
            dv = np.linalg.norm(Ce - p, axis=1)
            for j in _local_minima_1d(dv):
                lo, hi = ue[max(j - 1, 0)], ue[min(j + 1, n_edge_u - 1)]
                jobs.append((dv[j], mu, i, ("u", s_fix, lo, hi)))
        Ae = prob.arm(se)[0]
        for jj, u_fix in enumerate((u0, u1)):
            dv = np.linalg.norm(Ae - C_end[jj], axis=1)
            for j in _local_minima_1d(dv):
                lo, hi = se[max(j - 1, 0)], se[min(j + 1, n_edge_s - 1)]
                jobs.append((dv[j], ms, i, ("s", u_fix, lo, hi)))

    best_raw = min([r[0] for r in raw] + [j[0] for j in jobs])
    all_c = list(raw)
    n_2d = [0] * n
    for val, margin, i, job in sorted(jobs, key=lambda t: t[0]):
        if val > best_raw + margin:
            continue
        prob = probs[i]
        if job[0] == "2d":
            if n_2d[i] >= max_seeds:
                continue
            n_2d[i] += 1
            cands = [(prob.f(job[1], job[2]), job[1], job[2]), _refine_2d(prob, job[1], job[2])]
        else:
            cands = _refine_edge(prob, *job)
        for f, s, u in cands:
            all_c.append((math.sqrt(max(f, 0.0)), i, float(s), float(u)))

    all_c.sort(key=lambda t: t[0])
    d, i, s, u = all_c[0]
    A = probs[i].arm(s)[0][0]
    C = curve.point(np.array([u]))[0]
    return OClosest(float(np.linalg.norm(A - C)), i, s, u, A, C, all_c)


def closest_distance(q, curve, **kw):
    return closest_point(q, curve, **kw).distance


def closest_point_many(jobs):
    """[(q, curve), ...] -> [OClosest, ...] (one task for a process pool)."""
    return [closest_point(q, c) for q, c in jobs]


def closest_distance_many(jobs):
    return [closest_point(q, c).distance for q, c in jobs]


def closest_point_to_points(q, points, k=10):
    """N-point method brute force: arm at s = j/k, j = 1..k, per segment."""
    q = np.asarray(q, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    B = backbone_points(q, k)
    D = np.linalg.norm(B[:, None, :] - points[None, :, :], axis=-1)
    a, b = np.unravel_index(np.argmin(D), D.shape)
    seg, j = divmod(int(a), k)
    return OClosest(float(D[a, b]), seg, (j + 1) / k, int(b), B[a], points[b], [])


# ----------------------------------------------------------------------------
# Moving curves (issue 23): the rigid motion of softplan_jax.scenarios.motion, written
# independently (the rotation as scipy.linalg.expm of the axis' cross-product
# matrix, the curve sampled in NumPy), and a brute force over space AND time.


def rigid_pose(axis, amplitude, omega, phase, shift, velocity, t):
    """(R (3, 3), offset (3,)) of the motion x -> R (x - pivot) + pivot + offset at time t:
    R = expm(A sin(omega t + phase) [axis]x), offset = sin(omega t + phase) shift + t velocity."""
    from scipy.linalg import expm

    a = np.asarray(axis, dtype=np.float64)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    sigma = math.sin(float(omega) * t + float(phase))
    R = expm(float(amplitude) * sigma * K)
    return R, sigma * np.asarray(shift, dtype=np.float64) + t * np.asarray(velocity, dtype=np.float64)


def moving_curve_points(coeffs, u_range, motion: dict, t, n: int):
    """``n`` points of a polynomial curve (coeffs (3, K), lowest degree first), evenly
    spaced in u over ``u_range``, moved to time t. ``motion``: pivot, axis, amplitude,
    omega, phase, shift, velocity (one slot)."""
    u = np.linspace(float(u_range[0]), float(u_range[1]), n)
    pts = OPoly(coeffs, float(u_range[0]), float(u_range[1])).point(u)
    R, offset = rigid_pose(motion["axis"], motion["amplitude"], motion["omega"], motion["phase"],
                           motion["shift"], motion["velocity"], t)
    p = np.asarray(motion["pivot"], dtype=np.float64)
    return (pts - p) @ R.T + p + offset


def moving_min_clearance(qs, times, coeffs, u_ranges, radii, motions, arm_radius=0.0, substeps=4,
                         arm_samples=30, curve_samples=300):
    """Brute-force smallest clearance of a motion among moving curves: each step k -> k+1
    (q linear, time linear from times[k] to times[k+1]) at ``substeps + 1`` instants, the
    arm at ``arm_samples`` points per segment (this module's kinematics), each curve at
    ``curve_samples`` points at that instant. ``motions``: a list of per-curve dicts (see
    :func:`moving_curve_points`). Returns the smallest sampled distance minus the radii."""
    qs = np.asarray(qs, dtype=np.float64)
    s = np.linspace(0.0, 1.0, arm_samples)
    best = np.inf
    T = qs.shape[0]
    steps = [(k, k + 1) for k in range(T - 1)] or [(0, 0)]
    for a, b in steps:
        for tau in np.linspace(0.0, 1.0, substeps + 1):
            q = qs[a] + tau * (qs[b] - qs[a])
            t = float(times[a]) + tau * (float(times[b]) - float(times[a]))
            arm = np.concatenate([segment_points(q, i, s) for i in range(q.shape[0])])
            for c, ur, r, m in zip(coeffs, u_ranges, radii, motions, strict=True):
                pts = moving_curve_points(c, ur, m, t, curve_samples)
                d = np.sqrt(((arm[:, None, :] - pts[None]) ** 2).sum(-1)).min()
                best = min(best, d - float(r) - float(arm_radius))
    return best
