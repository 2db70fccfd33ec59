"""Exact distance from points to a polynomial curve, on the host (NumPy). The stationarity condition
``(F(u) - p) . F'(u) = 0`` (paper eq. 14 with the arm point fixed at p) is a polynomial of degree
2d - 1 in u, whose roots and the range's ends give the global minimum to rounding
(:func:`closest_parameters`); :func:`project_newton` is the cheap local version,
:func:`point_curve_distance` combines both for one point (what the scene checks and the
reachability proofs use), and :func:`point_curve_lower_bound` is a cheap bound from below."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import polynomial as _poly

__all__ = ["closest_parameters", "project_newton", "point_curve_distance", "point_curve_lower_bound",
           "point_curve_lower_bounds"]

# Samples of the guard grid of point_curve_distance (each polished by Newton).
_GUARD_SAMPLES = 64


def _trim(coeffs: np.ndarray) -> np.ndarray:
    """Drop highest-degree columns that are zero in all three rows (padding)."""
    K = coeffs.shape[1]
    while K > 1 and not np.any(coeffs[:, K - 1]):
        K -= 1
    return coeffs[:, :K]


def closest_parameters(coeffs: np.ndarray, points: np.ndarray, lo: float, hi: float, chunk: int = 20000):
    """Exact closest parameter on ``F(u) = sum_k coeffs[:, k] u**k``, u in [lo, hi].

    The stationarity condition (F(u) - p) . F'(u) = 0 (paper eq. 14 with the
    arm point fixed at p) is a polynomial of degree 2d - 1 in u; its roots
    (eigenvalues of the companion matrix, all points at once) and both ends
    are the candidates, and the one nearest p wins. Rounding in a root moves
    the distance only to second order, and the minimum is over actual
    distances, so the answer is the global minimum to rounding.

    Args:
      coeffs: (3, K) float64.
      points: (N, 3) float64.

    Returns:
      (u (N,), distance (N,)).
    """
    coeffs = _trim(np.asarray(coeffs, np.float64))
    points = np.asarray(points, np.float64)
    d = coeffs.shape[1] - 1
    if d == 0:
        dist = np.linalg.norm(points - coeffs[:, 0], axis=1)
        return np.full(points.shape[0], 0.5 * (lo + hi)), dist
    deriv = np.stack([_poly.polyder(c) for c in coeffs])  # (3, d)
    # G(u) = sum_a F_a F'_a - sum_a p_a F'_a(u): degree 2d - 1, top coefficient point-independent.
    A = sum(np.convolve(coeffs[a], deriv[a]) for a in range(3))  # length 2d
    A = np.pad(A, (0, 2 * d - A.shape[0]))
    m = 2 * d - 1
    us, ds = [], []
    for start in range(0, points.shape[0], chunk):
        P = points[start : start + chunk]
        n = P.shape[0]
        G = np.broadcast_to(A, (n, 2 * d)).copy()
        G[:, :d] -= P @ deriv  # (n, d)
        cand = [np.full((n, 1), lo), np.full((n, 1), hi)]
        lead = G[:, -1]
        if m >= 1 and np.all(np.abs(lead) > 0):
            if m == 1:
                roots = (-G[:, 0] / lead)[:, None]
            else:
                comp = np.zeros((n, m, m))
                comp[:, 1:, :-1] = np.eye(m - 1)
                comp[:, :, -1] = -G[:, :m] / lead[:, None]
                roots = np.linalg.eigvals(comp).real
            cand.append(np.clip(roots, lo, hi))
        U = np.concatenate(cand, axis=1)  # (n, c)
        F = np.stack([_poly.polyval(U, coeffs[a]) for a in range(3)], axis=-1)  # (n, c, 3)
        d2 = np.sum((F - P[:, None, :]) ** 2, axis=-1)
        k = np.argmin(d2, axis=1)
        us.append(U[np.arange(n), k])
        ds.append(np.sqrt(d2[np.arange(n), k]))
    return np.concatenate(us), np.concatenate(ds)


def project_newton(coeffs: np.ndarray, points: np.ndarray, u0: np.ndarray, lo: float, hi: float, iters: int = 6):
    """Closest parameters by safeguarded Newton on (F(u) - p) . F'(u) = 0 from
    warm starts u0, each step kept only where it brings the point closer (so
    the distance never exceeds that at u0). Local, cheap; the refinement's
    inner loop uses it, every reported residual uses :func:`closest_parameters`.

    Returns (u (N,), distance (N,))."""
    c1 = np.stack([_poly.polyder(c) for c in coeffs]) if coeffs.shape[1] > 1 else np.zeros((3, 1))
    c2 = np.stack([_poly.polyder(c) for c in c1]) if c1.shape[1] > 1 else np.zeros((3, 1))

    def ev(c, u):
        return np.stack([_poly.polyval(u, c[a]) for a in range(3)], axis=1)

    u = np.clip(u0, lo, hi)
    r = ev(coeffs, u) - points
    f = np.sum(r * r, axis=1)
    for _ in range(iters):
        F1, F2 = ev(c1, u), ev(c2, u)
        g = np.sum(r * F1, axis=1)
        h = np.sum(F1 * F1, axis=1) + np.sum(r * F2, axis=1)
        h = np.where(h > 0, h, np.sum(F1 * F1, axis=1) + 1e-300)
        u_t = np.clip(u - g / h, lo, hi)
        r_t = ev(coeffs, u_t) - points
        f_t = np.sum(r_t * r_t, axis=1)
        better = f_t < f
        u = np.where(better, u_t, u)
        r = np.where(better[:, None], r_t, r)
        f = np.where(better, f_t, f)
    return u, np.sqrt(f)


def point_curve_distance(coeffs, u_range, p) -> float:
    """Exact distance from one point p (3,) to the curve ``sum_k coeffs[:, k] u**k``
    (coeffs (3, K)) over u in ``u_range``: the smallest of :func:`closest_parameters`
    (roots of the stationarity polynomial and the ends) and a grid of
    ``_GUARD_SAMPLES`` values of u, both polished by :func:`project_newton` (a
    polished candidate is never farther than its start). Every candidate is an
    actual curve point, so the result is never below the true distance by more
    than rounding."""
    coeffs = np.asarray(coeffs, np.float64)
    p = np.asarray(p, np.float64).reshape(1, 3)
    lo, hi = (float(x) for x in np.asarray(u_range, np.float64))
    u_root, _ = closest_parameters(coeffs, p, lo, hi)
    starts = np.concatenate([u_root, np.linspace(lo, hi, _GUARD_SAMPLES)])
    _, d = project_newton(_trim(coeffs), np.repeat(p, starts.shape[0], axis=0), starts, lo, hi)
    return float(np.min(d))


def point_curve_lower_bound(coeffs, u_range, p, samples: int = 257) -> float:
    """A bound from below on the distance from one point p (3,) to the curve ``sum_k
    coeffs[:, k] u**k`` over u in ``u_range``, from ``samples`` evenly spaced curve points:
    every u lies within h / 2 of a sample (h their spacing), and the curve moves at most
    ``M h / 2`` meanwhile, ``M = sum_k k |c_k| R**(k - 1)`` (R the largest |u| of the range)
    bounding its speed, so ``|p - F(u)| >= min_i |p - F(u_i)| - M h / 2``. Lowered by a
    relative 1e-9 for rounding. Cheap (one evaluation of the samples): a curve whose bound
    clears a threshold needs no exact :func:`point_curve_distance`."""
    coeffs = np.asarray(coeffs, np.float64)[None]
    return float(point_curve_lower_bounds(coeffs, np.reshape(u_range, (1, 2)), p, samples)[0])


def point_curve_lower_bounds(coeffs, u_range, p, samples: int = 257) -> np.ndarray:
    """:func:`point_curve_lower_bound` of m curves at once: ``coeffs`` (m, 3, K), ``u_range``
    (m, 2); returns (m,). Each curve's degree is its own (zero columns of highest degree are
    padding)."""
    coeffs = np.asarray(coeffs, np.float64)
    p = np.asarray(p, np.float64).reshape(3)
    u_range = np.asarray(u_range, np.float64).reshape(-1, 2)
    lo, hi = u_range[:, 0], u_range[:, 1]
    u = np.linspace(lo, hi, samples, axis=-1)  # (m, samples)
    F = np.stack([_poly.polyval(u, coeffs[:, a].T[..., None], tensor=False) for a in range(3)], axis=-1)
    nearest = np.min(np.linalg.norm(F - p, axis=-1), axis=-1, initial=np.inf)
    R = np.maximum(np.abs(lo), np.abs(hi))
    bounds = np.empty(coeffs.shape[0])
    for i, c in enumerate(coeffs):  # the speed bound and rounding term over the curve's own degree
        c = _trim(c)
        k = np.arange(c.shape[1])
        speed = float(np.sum(k[1:] * np.linalg.norm(c[:, 1:], axis=0) * R[i] ** (k[1:] - 1)))
        slack = 0.5 * speed * (hi[i] - lo[i]) / (samples - 1)
        near = float(nearest[i])
        bounds[i] = near - slack - 1e-9 * (1.0 + near + slack + float(np.abs(c).sum()) * (1.0 + R[i]) ** k[-1])
    return bounds
