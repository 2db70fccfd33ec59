"""One polynomial curve fitted to points from initial parameters in [-1, 1], the refinement
both fits share (:func:`fit_from_parameters`): least squares in a Legendre basis for fixed
parameters alternated with an exact projection of every point onto the curve and an affine map
of the parameters back to [-1, 1] (parameter correction, Hoschek 1988), each round also trying
a damped Gauss-Newton step on the orthogonal distances (Wang, Pottmann & Liu 2006); the degree,
unless given, minimises ``BIC = n log(RSS / n) + 3 (d + 1) log(n)`` with ``n = 2 N`` (Schwarz
1978) among the curves that stay near the points. The result: the monomial coefficients of
the paper's ``F_o(u)`` (eq. 10), u in [-1, 1]."""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.polynomial import legendre as _leg
from numpy.polynomial import polynomial as _poly
from scipy.spatial import cKDTree

from ._distance import closest_parameters, project_newton

__all__ = ["fit_from_parameters", "renormalise", "curve_gap", "reparametrise"]

# Parameter-correction rounds per degree, and the relative RSS change that stops them.
_ROUNDS = 20
_ROUND_TOL = 1e-4
# Each round lets the ends grow by this fraction of the parameter range.
_EXTEND = 0.05
# Fits use at most this many points (a seeded random subset); residuals use all.
_MAX_FIT_POINTS = 3000


def _lstsq(t: np.ndarray, P: np.ndarray, degree: int) -> np.ndarray:
    """Least-squares Legendre coefficients (3, degree + 1) of a curve through P
    (M, 3) at parameters t in [-1, 1] (the Legendre basis is well conditioned there)."""
    c, *_ = np.linalg.lstsq(_leg.legvander(t, degree), P, rcond=None)
    return c.T


@functools.lru_cache(maxsize=32)
def _leg_to_mono(K: int) -> np.ndarray:
    """(K, K) matrix M with monomial coefficients = Legendre coefficients @ M."""
    M = np.zeros((K, K))
    for k in range(K):
        m = _leg.leg2poly(np.eye(K)[k])
        M[k, : len(m)] = m
    return M


def _to_monomial(cl: np.ndarray) -> np.ndarray:
    """Legendre coefficients (3, K) -> monomial coefficients (3, K)."""
    return cl @ _leg_to_mono(cl.shape[1])


def _tdm_system(cl: np.ndarray, t: np.ndarray, P: np.ndarray):
    """Normal equations of one Gauss-Newton step on the coefficients for the
    orthogonal distances ("tangent distance minimisation", Wang, Pottmann &
    Liu 2006): each residual is linearised in the curve's normal plane at its
    foot point, so sliding along the curve costs nothing. Returns (H, g) with
    the step solving (H + lambda D) x = g, x flattened from (3, K)."""
    K = cl.shape[1]
    V = _leg.legvander(t, K - 1)  # (M, K)
    dV = np.zeros_like(V)
    for k in range(1, K):
        dV[:, k] = _leg.legval(t, _leg.legder(np.eye(K)[k]))
    tan = dV @ cl.T
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-300)
    Nrm = np.eye(3)[None] - tan[:, :, None] * tan[:, None, :]  # (M, 3, 3), a projector
    r = V @ cl.T - P
    H = np.einsum("iab,ik,il->akbl", Nrm, V, V).reshape(3 * K, 3 * K)
    g = -np.einsum("iab,ib,ik->ak", Nrm, r, V).reshape(3 * K)
    return H, g


def renormalise(u: np.ndarray) -> np.ndarray:
    """Parameters mapped affinely onto [-1, 1] (all zero when they do not spread)."""
    lo, hi = float(u.min()), float(u.max())
    if hi - lo <= 1e-12:
        return np.zeros_like(u)
    return 2.0 * (u - lo) / (hi - lo) - 1.0


def _refine(P: np.ndarray, t0: np.ndarray, degree: int):
    """Fit a curve of the given degree from initial parameters t0: alternate
    an exact projection of the points, an affine map of their parameters to
    [-1, 1] and a least-squares fit for those parameters ("parameter
    correction", Hoschek 1988: never increases the sum of squared distances),
    each round also trying a damped Gauss-Newton step on the orthogonal
    distances (:func:`_tdm_system`, Levenberg-Marquardt damping; kept only
    when it lowers that sum; it converges in a few rounds where parameter
    correction alone needs hundreds).

    Returns (monomial coeffs (3, degree + 1) with u_range (-1, 1), rss)."""
    lo_x, hi_x = -1.0 - _EXTEND, 1.0 + _EXTEND
    t = np.clip(t0, -1.0, 1.0)
    rss = math.inf
    lam = 1e-6
    for round_ in range(_ROUNDS):
        cl = _lstsq(t, P, degree)
        # exact (global) projection in the first round, warm-started Newton after it
        project = closest_parameters if round_ == 0 else functools.partial(project_newton, u0=t)
        u0, d0 = project(_to_monomial(cl), P, lo=lo_x, hi=hi_x)
        r0 = float(np.sum(d0**2))
        H, g = _tdm_system(cl, t, P)
        diag = np.diag(H).copy()
        diag = np.where(diag > 0, diag, max(float(diag.max()), 1e-300))
        try:
            step = np.linalg.solve(H + lam * np.diag(diag), g)
            u1, d1 = project(_to_monomial(cl + step.reshape(cl.shape)), P, lo=lo_x, hi=hi_x)
            r1 = float(np.sum(d1**2))
        except np.linalg.LinAlgError:
            r1 = math.inf
        if r1 < r0:
            u, r = u1, r1
            lam = max(lam / 10.0, 1e-12)
        else:
            u, r = u0, r0
            lam = min(lam * 100.0, 1e6)
        t = renormalise(u)
        done = rss - r <= _ROUND_TOL * rss and float(u.min()) >= -1.0 and float(u.max()) <= 1.0
        rss = min(rss, r)
        if done:
            break
    coeffs = _to_monomial(_lstsq(t, P, degree))
    _, dist = closest_parameters(coeffs, P, -1.0, 1.0)
    return coeffs, float(np.sum(dist**2))


def _bic(rss: float, n_points: int, degree: int, floor: float) -> float:
    n = 2 * n_points
    return n * math.log(max(rss, floor) / n) + 3 * (degree + 1) * math.log(n)


def curve_gap(coeffs: np.ndarray, cloud_tree, samples: int = 256) -> float:
    """Largest distance from the curve (dense samples over [-1, 1]) to the
    nearest cloud point: large when the curve wanders where there are no points."""
    u = np.linspace(-1.0, 1.0, samples)
    F = np.stack([_poly.polyval(u, coeffs[a]) for a in range(3)], axis=1)
    return float(cloud_tree.query(F)[0].max())


def fit_from_parameters(P: np.ndarray, t0: np.ndarray, degree, max_degree: int, extent: float, gap_tol: float):
    """Fit one curve to P (M, 3) from initial parameters t0 (M,): the given degree,
    or the BIC-best of 1..max_degree (stopping after two degrees without gain)
    among the curves that stay within ``gap_tol`` of the points everywhere
    (a high degree may swing out between points); if none does, the one
    that strays least. Returns (coeffs (3, d + 1), degree)."""
    rng = np.random.default_rng(0)
    if P.shape[0] > _MAX_FIT_POINTS:
        keep = rng.choice(P.shape[0], _MAX_FIT_POINTS, replace=False)
        P, t0 = P[keep], t0[keep]
    n = P.shape[0]
    if degree is not None:
        coeffs, _ = _refine(P, t0, degree)
        return coeffs, degree
    cloud_tree = cKDTree(P)
    top = max(1, min(max_degree, n // 2 - 1))
    floor = n * (1e-9 * extent) ** 2
    best = None  # (bic, coeffs, degree) among curves within gap_tol
    straying = None  # (gap, coeffs, degree)
    worse = 0
    for d in range(1, top + 1):
        coeffs, rss = _refine(P, t0, d)
        gap = curve_gap(coeffs, cloud_tree)
        if gap > gap_tol:
            if straying is None or gap < straying[0]:
                straying = (gap, coeffs, d)
            continue
        b = _bic(rss, n, d, floor)
        if best is None or b < best[0]:
            best = (b, coeffs, d)
            worse = 0
        else:
            worse += 1
            if worse >= 2:
                break
    chosen = best if best is not None else straying
    return chosen[1], chosen[2]


def reparametrise(coeffs: np.ndarray, a: float, b: float) -> np.ndarray:
    """Monomial coefficients of G(t) = F(a + (t + 1)(b - a) / 2), t in [-1, 1]
    (exact: interpolation at degree + 1 Chebyshev points)."""
    K = coeffs.shape[1]
    t = np.cos(np.pi * (np.arange(K) + 0.5) / K)
    u = a + (t + 1.0) * (b - a) / 2.0
    vals = np.stack([_poly.polyval(u, coeffs[i]) for i in range(3)], axis=1)
    return _to_monomial(_lstsq(t, vals, K - 1))
