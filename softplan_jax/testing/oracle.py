"""Independent NumPy/SciPy reference for the closest point (paper section 2.3), written from the
paper's formulas and importing nothing else of ``softplan_jax`` (nor jax): for each segment the
minimum of ``D^2(s, u) = |F_R(s) - F_o(u)|^2`` over ``[0, 1] x [u0, u1]`` from a dense 2-D grid
(local minima refined by L-BFGS-B and a projected Newton polish), dense scans of the four edges
(refined by bounded 1-D minimisation and Newton) and the four corners, the minimum over every
candidate and segment (:func:`closest_point`, checked against closed-form answers in
``tests/test_closest.py``); the N-point model's nearest pair by brute force
(:func:`closest_point_to_points`); and :mod:`.oracle_geometry`'s kinematics and curves
re-exported, one namespace."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import ndimage, optimize

from .oracle_geometry import (
    OFunc,
    OHelix,
    OPoly,
    arc_coeffs,
    arm_points,
    arm_points_many,
    backbone_points,
    central_difference,
    helix,
    jacobian_complex_step,
    line,
    local_arc,
    moving_curve_points,
    moving_min_clearance,
    point_jacobian,
    rigid_pose,
    segment_frames,
    segment_point,
    segment_point_derivs,
    segment_points,
    segment_transform,
    tip_frame,
    tip_jacobian,
    tip_position,
)

__all__ = [
    # kinematics (paper section 2.1), from oracle_geometry
    "segment_transform", "segment_frames", "tip_frame", "tip_position", "segment_points", "segment_point_derivs",
    "segment_point", "backbone_points", "arm_points", "arm_points_many", "jacobian_complex_step", "point_jacobian",
    "tip_jacobian",
    "central_difference", "arc_coeffs", "local_arc",
    # curves, from oracle_geometry
    "OPoly", "OFunc", "OHelix", "helix", "line",
    # closest point (paper section 2.3) and the N-point model
    "OClosest", "closest_point", "closest_distance", "closest_point_many", "closest_distance_many",
    "closest_point_to_points",
    # moving curves, from oracle_geometry
    "rigid_pose", "moving_curve_points", "moving_min_clearance",
]


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
        p, dp, ddp = local_arc(self.qi, np.atleast_1d(s))
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
        a, b = arc_coeffs(th, s)  # Python floats: its scalar branch
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


class _Grids:
    """The oracle's sample grids: the 2-D grid (s, u) and the edge scans, with the curve's points."""

    def __init__(self, curve, ns, nu, n_edge_s, n_edge_u, u0, u1):
        self.u0, self.u1 = u0, u1
        self.sg, self.ug = np.linspace(0.0, 1.0, ns), np.linspace(u0, u1, nu)
        self.se, self.ue = np.linspace(0.0, 1.0, n_edge_s), np.linspace(u0, u1, n_edge_u)
        self.Cg = curve.point(self.ug)
        self.Cg2 = np.sum(self.Cg * self.Cg, 1)
        self.Ce = curve.point(self.ue)
        self.C_end = curve.point(np.array([u0, u1]))


def _segment_candidates(prob, i, L, speed, g: _Grids, margin_factor, max_seeds, raw: list, jobs: list) -> None:
    """One segment's unrefined candidates (paper §2.3's three cases): its corners into ``raw``,
    its grid and edge-scan local minima, with their margins, into ``jobs``."""
    u0, u1 = g.u0, g.u1
    # corners (case 3)
    for s in (0.0, 1.0):
        for u in (u0, u1):
            raw.append((math.sqrt(prob.f(s, u)), i, s, u))
    # 2-D grid (case 1)
    A = prob.arm(g.sg)[0]
    # |A|^2 + |C|^2 - 2 A.C: only used to pick starts (the candidates'
    # values are recomputed exactly), so its rounding near 0 is harmless
    Dg = np.sqrt(np.maximum(np.sum(A * A, 1)[:, None] + g.Cg2[None, :] - 2.0 * (A @ g.Cg.T), 0.0))
    m2 = margin_factor * 0.5 * (L * (g.sg[1] - g.sg[0]) + speed * (g.ug[1] - g.ug[0]))
    lm = np.argwhere(_grid_local_minima(Dg))
    vals = Dg[lm[:, 0], lm[:, 1]]
    for k in np.argsort(vals)[: 4 * max_seeds]:
        a_, b_ = lm[k]
        jobs.append((vals[k], m2, i, ("2d", g.sg[a_], g.ug[b_])))
    # edges (case 2): s = 0 / 1 scanned in u, u = u0 / u1 scanned in s
    mu = margin_factor * 0.5 * speed * (g.ue[1] - g.ue[0])
    ms = margin_factor * 0.5 * L * (g.se[1] - g.se[0])
    for s_fix in (0.0, 1.0):
        p = prob.arm(s_fix)[0][0]
        dv = np.linalg.norm(g.Ce - p, axis=1)
        for j in _local_minima_1d(dv):
            lo, hi = g.ue[max(j - 1, 0)], g.ue[min(j + 1, g.ue.size - 1)]
            jobs.append((dv[j], mu, i, ("u", s_fix, lo, hi)))
    Ae = prob.arm(g.se)[0]
    for jj, u_fix in enumerate((u0, u1)):
        dv = np.linalg.norm(Ae - g.C_end[jj], axis=1)
        for j in _local_minima_1d(dv):
            lo, hi = g.se[max(j - 1, 0)], g.se[min(j + 1, g.se.size - 1)]
            jobs.append((dv[j], ms, i, ("s", u_fix, lo, hi)))


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
    grids = _Grids(curve, ns, nu, n_edge_s, n_edge_u, u0, u1)
    raw = []  # (D, i, s, u) of every unrefined grid/edge/corner candidate
    jobs = []  # (threshold-able value, margin, i, job)
    for i, prob in enumerate(probs):
        _segment_candidates(prob, i, float(q[i, 0]), speed, grids, margin_factor, max_seeds, raw, jobs)

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
