"""Independent NumPy/SciPy reference for the arm's kinematics (paper section 2.1, Webster &
Jones 2010; complex-step Jacobians exact to rounding, theta = 0 included), the obstacle curves
(``OPoly``, ``OFunc``, the helix) and the clearance to moving curves sampled in space and time,
written from the paper's formulas and importing nothing else of ``softplan_jax`` (nor jax);
:mod:`.oracle` builds the closest point on it and re-exports every name listed here."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

__all__ = [
    # kinematics (paper section 2.1)
    "segment_transform", "segment_frames", "tip_frame", "tip_position", "segment_points", "segment_point_derivs",
    "segment_point", "backbone_points", "arm_points", "arm_points_many", "jacobian_complex_step", "point_jacobian",
    "tip_jacobian",
    "central_difference", "arc_coeffs", "local_arc",
    # curves
    "OPoly", "OFunc", "OHelix", "helix", "line",
    # moving curves
    "rigid_pose", "moving_curve_points", "moving_min_clearance",
]

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
    xl = np.where(small, 1.0, x)
    out = np.asarray(np.sin(xl) / xl)
    if small.any():  # the series on the small entries only (the brute-force checks call this often)
        x2 = x[small] * x[small]
        series = np.zeros_like(x2)
        for k in range(9, -1, -1):  # Horner in x**2 of sum (-1)^k x^2k / (2k+1)!
            series = series * x2 + (-1) ** k / math.factorial(2 * k + 1)
        out[small] = series
    return out


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


def arc_coeffs(theta, s):
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
    """Paper's (R_i, P_i) for one row q_i = [L, theta, phi]::

        R_i = [[c(phi)c(th), -s(phi), c(phi)s(th)],
               [s(phi)c(th),  c(phi), s(phi)s(th)],
               [-s(th),       0,      c(th)     ]]
        P_i = [(1-cos th) L/th cos phi, (1-cos th) L/th sin phi, sin th L/th]

    with no division by theta: ``sin(th)/th = sinc(th)`` and ``(1 - cos th)/th =
    (th/2) sinc(th/2)^2`` (half-angle identity), ``sinc`` from its Taylor series for
    |x| < 0.1; complex input works too (complex-step Jacobians).
    """
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
    a, b = arc_coeffs(th, 1.0)
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


def _local_points(q_i, s):
    """Local arc points of segment row q_i at fractions s (m,) -> (m, 3) (paper eq. (2))."""
    L, th, ph = q_i[0], q_i[1], q_i[2]
    a, b = arc_coeffs(th, np.asarray(s))
    cp, sp_ = np.cos(ph), np.sin(ph)
    return L * np.stack([a * cp, a * sp_, b], axis=-1)


def local_arc(q_i, s):
    """Local arc point(s) and s-derivatives for segment row q_i, s array (m,)."""
    L, th, ph = q_i[0], q_i[1], q_i[2]
    s = np.asarray(s)
    p = _local_points(q_i, s)
    cp, sp_ = np.cos(ph), np.sin(ph)
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
    p, dp, ddp = local_arc(q[i], s)
    R, P = Rs[i], Ps[i]
    return p @ R.T + P, dp @ R.T, ddp @ R.T


def segment_point(q, i, s):
    """Single point (3,) at fraction s of segment i (paper's P_si):
    ``R_{i-1}^0 [(1-cos(th s)) L/th cos phi, ..., sin(th s) L/th] + P_{i-1}^0``."""
    return segment_points(q, i, np.array([s]))[0]


def backbone_points(q, k=10):
    q = np.asarray(q)
    s = np.arange(1, k + 1) / k
    return arm_points(q, s)


def arm_points(q, s):
    """Every segment's points at fractions s (m,), segment after segment -> (n m, 3): the
    points of :func:`segment_points`, the frames computed once."""
    q = np.asarray(q)
    Rs, Ps = segment_frames(q)
    return np.concatenate([_local_points(q[i], s) @ Rs[i].T + Ps[i] for i in range(q.shape[0])])


def arm_points_many(qs, s):
    """:func:`arm_points` of K configurations at once: qs (K, n, 3) -> (K, n m, 3). The same
    formulas (paper eqs. (1)-(2)) broadcast over K, for the brute-force checks that sample
    many configurations of a motion (equal to a loop of :func:`arm_points` to rounding)."""
    qs = np.asarray(qs, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    K, n = qs.shape[:2]
    R = np.broadcast_to(np.eye(3), (K, 3, 3))
    P = np.zeros((K, 3))
    out = []
    for i in range(n):
        L, th, ph = qs[:, i, 0], qs[:, i, 1], qs[:, i, 2]
        a, b = arc_coeffs(th[:, None], s[None, :])  # (K, m)
        cp, sp_ = np.cos(ph)[:, None], np.sin(ph)[:, None]
        local = L[:, None, None] * np.stack([a * cp, a * sp_, b], axis=-1)  # (K, m, 3)
        out.append(local @ np.swapaxes(R, 1, 2) + P[:, None, :])  # R p + P, point by point
        Ri, Pi = segment_transform(qs[:, i].T)  # (3, 3, K), (3, K)
        P = P + np.einsum("kij,jk->ki", R, Pi)  # H_i^0 = H_{i-1}^0 H_i^{i-1}
        R = np.einsum("kij,jlk->kil", R, Ri)
    return np.concatenate(out, axis=1)


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


# ----------------------------------------------------------------------------
# Moving curves: the rigid motion of softplan_jax.scenarios._motion, written
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
    :func:`moving_curve_points`: the library's rigid motion written independently, the rotation
    as SciPy's matrix exponential of the axis' cross-product matrix). Returns the smallest
    sampled distance minus the radii."""
    qs = np.asarray(qs, dtype=np.float64)
    s = np.linspace(0.0, 1.0, arm_samples)
    best = np.inf
    T = qs.shape[0]
    steps = [(k, k + 1) for k in range(T - 1)] or [(0, 0)]
    taus = np.linspace(0.0, 1.0, substeps + 1)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    if len(coeffs) != len(u_ranges) or len(coeffs) != len(motions) or len(coeffs) != radii.size:
        raise ValueError("coeffs, u_ranges, radii and motions must have one entry per curve")
    if not len(coeffs):
        return best
    for a, b in steps:
        arms = arm_points_many(qs[a] + taus[:, None, None] * (qs[b] - qs[a]), s)
        for tau, arm in zip(taus, arms, strict=True):
            t = float(times[a]) + tau * (float(times[b]) - float(times[a]))
            pts = np.stack([moving_curve_points(c, ur, m, t, curve_samples)
                            for c, ur, m in zip(coeffs, u_ranges, motions, strict=True)])  # (curves, n, 3)
            # Squared distances plane by plane ((dx + dy) + dz), the least per curve, then its root.
            d2 = sum((arm[:, None, None, k] - pts[None, :, :, k]) ** 2 for k in range(3))  # (arm, curves, n)
            d = np.sqrt(d2.min(axis=(0, 2)))
            best = min(best, float(np.min(d - radii - float(arm_radius))))
    return best
