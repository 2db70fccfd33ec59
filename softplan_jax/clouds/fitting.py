"""Obstacle curves fitted to point clouds from a sensor (paper §2.3).

The paper models a real branch, pipe or wire as a curve ``F_o(u)`` "derived from
a set of points ... using regression". A depth camera or a LiDAR returns those
points unordered, noisy, and often from several obstacles at once (a trunk with
branches, two crossing wires). This module turns such a cloud into polynomial
curves and says how well they fit:

* :func:`fit_curve` — one curve through an unordered cloud;
* :func:`fit_curves` — split a cloud into its curves, one fit per piece;
* :func:`curve_distance` — exact distance from points to a polynomial curve;
* :func:`load_cloud` — read an ``.npy``, ``.csv`` or ``.xyz`` cloud;
* :func:`save_fit_scenario` — a JSON scenario of the fitted curves, with the
  residuals as metadata (what ``softplan fit`` writes).

Method of :func:`fit_curve`:

1. **Order.** A Euclidean minimum spanning tree (MST) of the cloud, built on a
   k-nearest-neighbour graph (after a light local averaging that pulls the
   points towards the centre line). The tree's longest path (its diameter,
   found by two shortest-path sweeps) runs from one end of the obstacle to the
   other; every point takes the parameter of the path node its subtree hangs
   from; parameters are the path's normalised chord length, in [-1, 1] (a
   well-conditioned range for the monomial coefficients).
2. **Refine.** Alternate a least-squares fit of the coefficients for fixed
   parameters (in a Legendre basis, converted to monomials) with an exact
   projection of every point onto the current curve (a slightly extended
   range, so the ends can grow), then an affine map of the parameters back to
   [-1, 1] ("parameter correction", Hoschek 1988; it never increases the sum
   of squared orthogonal distances).
3. **Degree.** Unless given: the degree d in 1..max_degree minimising the
   Bayesian information criterion ``BIC = n log(RSS / n) + 3 (d + 1) log(n)``
   with ``n = 2 N`` (two orthogonal residual components per point) and RSS the
   sum of squared exact point-curve distances (Schwarz 1978).
4. **Quality.** RMS and maximum exact distance of the cloud to the curve
   (:func:`curve_distance`), and the cloud's noise level estimated
   independently of the fit from local principal components (the two small
   eigenvalues of a neighbourhood's covariance are the noise variance across
   the curve). A maximum residual above ``(sqrt(2 ln N) + 2)`` noise levels
   (the largest of N Rayleigh-distributed distances is about
   ``sqrt(2 ln N)`` noise levels) warns with :class:`FitWarning`; a
   ``max_residual`` argument makes it a ``ValueError``.

Method of :func:`fit_curves`: the same MST, cut at edges much longer than the
cloud's point spacing (separate obstacles); short side spurs that noise grows
on the tree are pruned (a leaf branch whose tip stays within a few noise levels
of the rest of the skeleton); the remaining skeleton splits at its junctions
(nodes of degree >= 3; junctions closer than the spur length are one junction);
at each junction the two pieces that continue each other most straightly
(directions more than 150 degrees apart) are joined, so a trunk stays one curve
through its branch points and two crossing wires stay two curves. Each piece is
fitted as above from its skeleton order; a piece whose fit is poor (maximum
residual above the warning level) is split in two and refitted, up to
``max_splits`` times. Residuals are each point's distance to the nearest fitted
curve. ``inflate=True`` adds each curve's maximum residual to its radius, so an
arm clear of the inflated curves is clear of every raw point.

Everything here runs on the host (NumPy/SciPy), not under ``jit``: fitting is a
one-off step before planning. The curves it returns are ordinary
:class:`~softplan_jax.curves.PolynomialCurve` objects with ``u_range`` (-1, 1).
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from numpy.polynomial import legendre as _leg
from numpy.polynomial import polynomial as _poly
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree

from ..geometry.curves import PolynomialCurve
from ..scenarios import write_json_file
from ..base.validation import check_cloud, check_points

__all__ = [
    "CurveFit",
    "CloudFit",
    "FitWarning",
    "fit_curve",
    "fit_curves",
    "curve_distance",
    "load_cloud",
    "fit_scenario_dict",
    "save_fit_scenario",
    "CLOUD_EXTENSIONS",
]

CLOUD_EXTENSIONS = (".npy", ".csv", ".xyz")

# Parameter-correction rounds per degree, and the relative RSS change that stops them.
_ROUNDS = 20
_ROUND_TOL = 1e-4
# Each round lets the ends grow by this fraction of the parameter range.
_EXTEND = 0.05
# Fits use at most this many points (a seeded random subset); residuals use all.
_MAX_FIT_POINTS = 3000
# Rounds of giving points to their nearest curve and refitting (fit_curves).
_RELABEL_ROUNDS = 2
# Structure (ordering, splitting) uses at most this many points.
_MAX_GRAPH_POINTS = 4000


class FitWarning(UserWarning):
    """A fitted curve is far from some of the cloud's points (a poor fit)."""


class CurveFit(NamedTuple):
    """One polynomial curve fitted to (part of) a cloud, with its residuals.

    Attributes:
      curve: the fitted :class:`PolynomialCurve`, coeffs (3, degree + 1),
        u_range (-1, 1); its radius is the requested radius, plus
        ``max_residual`` when inflated.
      degree: polynomial degree.
      indices: (M,) int, indices into the cloud of the points this curve
        explains (nearest to it).
      u: (M,) parameter of each of those points' closest curve point.
      residuals: (M,) exact distance of each of those points to the curve.
      rms_residual: root mean square of ``residuals`` (0 when M = 0).
      max_residual: largest of ``residuals`` (0 when M = 0).
    """

    curve: PolynomialCurve
    degree: int
    indices: np.ndarray
    u: np.ndarray
    residuals: np.ndarray
    rms_residual: float
    max_residual: float

    @property
    def curves(self) -> list:
        """``[curve]``, as :attr:`CloudFit.curves`."""
        return [self.curve]


class CloudFit(NamedTuple):
    """Curves fitted to a whole cloud (:func:`fit_curves`).

    Attributes:
      fits: tuple of :class:`CurveFit`, one per obstacle curve.
      labels: (N,) int, index into ``fits`` of each point's nearest curve.
      residuals: (N,) exact distance of each point to its nearest curve.
      rms_residual: root mean square of ``residuals``.
      max_residual: largest of ``residuals``.
      noise: the cloud's noise level (standard deviation per axis), estimated
        from local principal components, independent of the fit.
      tolerance: the maximum residual above which a fit counts as poor (warns),
        ``(sqrt(2 ln N) + 2) * max(noise, 1e-4 * extent)``.
    """

    fits: tuple
    labels: np.ndarray
    residuals: np.ndarray
    rms_residual: float
    max_residual: float
    noise: float
    tolerance: float

    @property
    def curves(self) -> list:
        """The fitted curves, a list of :class:`PolynomialCurve`."""
        return [f.curve for f in self.fits]

    @classmethod
    def from_fit(cls, fit) -> CloudFit:
        """``fit`` itself if a CloudFit; a CurveFit as a one-curve CloudFit (every point
        labelled 0; the cloud-level coverage figures NaN)."""
        if isinstance(fit, CloudFit):
            return fit
        if isinstance(fit, CurveFit):
            n = int(fit.indices.size)
            return cls((fit,), np.zeros(n, int), fit.residuals, fit.rms_residual, fit.max_residual, math.nan,
                       math.nan)
        raise ValueError(f"fit must be a CloudFit (fit_curves) or a CurveFit (fit_curve), got {type(fit).__name__}")


# ----------------------------------------------------------------------------
# Input.




def _check_degree(degree, max_degree: int):
    if degree is not None:
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 1:
            raise ValueError(f"degree must be an integer >= 1 (or None to choose it), got {degree!r}")
        return int(degree)
    if isinstance(max_degree, bool) or not isinstance(max_degree, (int, np.integer)) or max_degree < 1:
        raise ValueError(f"max_degree must be an integer >= 1, got {max_degree!r}")
    return None


def _check_points_for_degree(n: int, degree, what: str = "the cloud") -> None:
    need = 2 * (degree + 1) if degree is not None else 4
    if n < need:
        if degree is None:
            raise ValueError(f"{what} has {n} point(s); fitting a curve needs at least {need}")
        raise ValueError(
            f"{what} has {n} point(s); fitting degree {degree} needs at least {need} "
            f"(twice the {degree + 1} coefficients per axis)"
        )


def _check_nonneg(x, name: str):
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {x!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be finite and >= 0, got {x!r}")
    return v


def load_cloud(path) -> np.ndarray:
    """Read a point cloud from a file: ``.npy`` (an (N, 3) array), ``.csv``
    (comma-separated x, y, z per line; an optional header line) or ``.xyz``
    (whitespace-separated x y z per line). Lines starting with ``#`` are comments.

    Args:
      path: file path.

    Returns:
      (N, 3) float64 array (validated as by :func:`fit_curves`).
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in CLOUD_EXTENSIONS:
        raise ValueError(
            f"cannot read point cloud {path!r}: unknown extension {ext or '(none)'!r}; "
            f"use one of {', '.join(CLOUD_EXTENSIONS)}"
        )
    if not os.path.exists(path):
        raise ValueError(f"point cloud file not found: {path}")
    if os.path.isdir(path):
        raise ValueError(f"point cloud path {path} is a directory")
    try:
        if ext == ".npy":
            try:
                arr = np.load(path, allow_pickle=False)
            except ValueError as err:
                raise ValueError(f"{path} is not a NumPy .npy array file (or holds Python objects): {err}") from None
            if not isinstance(arr, np.ndarray):
                raise ValueError(f"{path} does not hold one array")
        else:
            arr = _read_text_cloud(path, "," if ext == ".csv" else None)
    except OSError as err:
        raise ValueError(f"cannot read point cloud {path}: {err.strerror or err}") from None
    return check_cloud(arr, f"point cloud {path}")


def _read_text_cloud(path: str, delimiter) -> np.ndarray:
    """Rows of numbers from a text file; a first non-numeric line is a header."""
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file (expected numbers x, y, z per line)") from None
    rows = []
    for k, line in enumerate(lines):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = [f.strip() for f in (text.split(delimiter) if delimiter else text.split())]
        try:
            values = [float(f) for f in fields]
        except ValueError:
            if not rows and all(not _is_number(f) for f in fields):
                continue  # a header line
            raise ValueError(f"{path}, line {k + 1}: not numbers: {text[:80]!r}") from None
        if rows and len(values) != len(rows[0]):
            raise ValueError(
                f"{path}, line {k + 1}: {len(values)} values, but earlier lines have {len(rows[0])}"
            )
        rows.append(values)
    if not rows:
        raise ValueError(f"point cloud {path} is empty (no rows of numbers)")
    return np.asarray(rows, dtype=np.float64)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# ----------------------------------------------------------------------------
# Exact point-curve distance.


def _trim(coeffs: np.ndarray) -> np.ndarray:
    """Drop highest-degree columns that are zero in all three rows (padding)."""
    K = coeffs.shape[1]
    while K > 1 and not np.any(coeffs[:, K - 1]):
        K -= 1
    return coeffs[:, :K]


def _closest_u(coeffs: np.ndarray, points: np.ndarray, lo: float, hi: float, chunk: int = 20000):
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


def _project_newton(coeffs: np.ndarray, points: np.ndarray, u0: np.ndarray, lo: float, hi: float, iters: int = 6):
    """Closest parameters by safeguarded Newton on (F(u) - p) . F'(u) = 0 from
    warm starts u0, each step kept only where it brings the point closer (so
    the distance never exceeds that at u0). Local, cheap; the refinement's
    inner loop uses it, every reported residual uses :func:`_closest_u`.

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


def curve_distance(curve: PolynomialCurve, points):
    """Exact distance from each point to a polynomial curve (its centre line).

    Global minimum over the curve's whole ``u_range``, from the roots of the
    stationarity polynomial (paper eq. 14 with a fixed point) and the two ends.
    Host-side (NumPy), not traceable.

    Args:
      curve: a single :class:`PolynomialCurve` (coeffs (3, K)).
      points: (N, 3).

    Returns:
      ``(distance, u)``: (N,) float64 distances and (N,) parameters of the
      closest curve points.
    """
    if not isinstance(curve, PolynomialCurve) or curve.coeffs.ndim != 2:
        raise ValueError("curve_distance needs a single PolynomialCurve (coeffs of shape (3, K))")
    # Any (N, 3) finite points, repeated ones and a single one included (a query, not a cloud to fit).
    pts = np.asarray(check_points(points), np.float64) if np.size(points) else np.zeros((0, 3))
    lo, hi = (float(x) for x in np.asarray(curve.u_range))
    u, dist = _closest_u(np.asarray(curve.coeffs, np.float64), pts, lo, hi)
    return dist, u


# ----------------------------------------------------------------------------
# Noise level and graphs.


def _noise_level(P: np.ndarray) -> float:
    """Noise standard deviation (per axis) of a curve-like cloud from local PCA.

    Across a curve the cloud's spread is the noise: the two smallest
    eigenvalues of a neighbourhood's covariance are about sigma^2 each. The
    neighbourhood must be longer than it is thick, so the smallest k in
    (8, 16, 32, 64) whose median neighbourhood is elongated (largest / middle
    eigenvalue > 9) is used; the median over points ignores junctions.
    """
    n = P.shape[0]
    if n < 4:
        return 0.0
    tree = cKDTree(P)
    sample = P if n <= 2000 else P[np.random.default_rng(0).choice(n, 2000, replace=False)]
    est = 0.0
    for k in (8, 16, 32, 64):
        kk = min(k, n)
        _, idx = tree.query(sample, kk)
        nb = P[idx]  # (m, k, 3)
        nb = nb - nb.mean(axis=1, keepdims=True)
        cov = np.einsum("mki,mkj->mij", nb, nb) / max(kk - 1, 1)
        ev = np.linalg.eigvalsh(cov)  # ascending
        small = 0.5 * (ev[:, 0] + ev[:, 1])
        est = math.sqrt(max(float(np.median(small)), 0.0))
        if np.median(ev[:, 2]) > 9.0 * np.median(ev[:, 1]) or kk == n:
            break
    return est


def _tolerance(noise: float, n: int, extent: float) -> float:
    """Largest acceptable maximum residual: (sqrt(2 ln N) + 2) noise levels,
    with a floor of 1e-4 of the cloud's extent for noise-free clouds."""
    return (math.sqrt(2.0 * math.log(max(n, 2))) + 2.0) * max(noise, 1e-4 * extent)


def _spanning_tree(P: np.ndarray, k: int = 10):
    """Euclidean minimum spanning tree over a kNN graph, made connected.

    Returns a symmetric CSR matrix of edge lengths (duplicate points get a tiny
    positive length so that they stay connected).
    """
    n = P.shape[0]
    k = min(k, n - 1)
    tree = cKDTree(P)
    dist, idx = tree.query(P, k + 1)
    tiny = 1e-12 * max(float(np.max(np.ptp(P, axis=0))), 1e-300)
    rows = [np.repeat(np.arange(n), k)]
    cols = [idx[:, 1:].ravel()]
    wts = [np.maximum(dist[:, 1:].ravel(), tiny)]
    G = coo_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    G = G.maximum(G.T)
    ncomp, labels = connected_components(G, directed=False)
    while ncomp > 1:  # Boruvka: join every component to its nearest other component
        extra_r, extra_c, extra_w = [], [], []
        for c in range(ncomp):
            inside = np.nonzero(labels == c)[0]
            outside = np.nonzero(labels != c)[0]
            d, j = cKDTree(P[outside]).query(P[inside])
            b = int(np.argmin(d))
            extra_r.append(inside[b])
            extra_c.append(outside[j[b]])
            extra_w.append(max(float(d[b]), tiny))
        E = coo_matrix((extra_w, (extra_r, extra_c)), shape=(n, n)).tocsr()
        G = G.maximum(E).maximum(E.T)
        ncomp, labels = connected_components(G, directed=False)
    T = minimum_spanning_tree(G)
    return T.maximum(T.T).tocsr()


def _smooth(P: np.ndarray, k: int = 10, rounds: int = 2) -> np.ndarray:
    """Local averaging over k nearest neighbours (of the raw cloud), a few
    rounds: pulls noisy points towards the centre line so that the spanning
    tree grows fewer noise spurs. Used for structure only, never for fits."""
    n = P.shape[0]
    k = min(k, n)
    if k < 3:
        return P
    _, idx = cKDTree(P).query(P, k)
    Q = P
    for _ in range(rounds):
        Q = Q[idx].mean(axis=1)
    return Q


def _tree_path(T, a: int, b: int) -> np.ndarray:
    """Node sequence of the unique tree path from a to b."""
    _, pred = dijkstra(T, directed=False, indices=a, return_predecessors=True)
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return np.asarray(path[::-1])


def _diameter_path(T) -> np.ndarray:
    """Longest path of a tree (two farthest-node sweeps)."""
    d0 = dijkstra(T, directed=False, indices=0)
    a = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
    da = dijkstra(T, directed=False, indices=a)
    b = int(np.argmax(np.where(np.isfinite(da), da, -1)))
    return _tree_path(T, a, b)


def _attach(T, nodes: np.ndarray) -> np.ndarray:
    """For every node of tree T, the node of ``nodes`` its subtree hangs from
    (the nearest of ``nodes`` along the tree)."""
    _, _, src = dijkstra(T, directed=False, indices=nodes, min_only=True, return_predecessors=True)
    return src


def _path_parameters(Q: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Normalised chord length in [-1, 1] along a (smoothed) node path."""
    pts = Q[path]
    w = max(1, min(5, len(path) // 20))
    if w > 1:  # moving average so that zig-zags of the path do not count as length
        kernel = np.ones(2 * w + 1) / (2 * w + 1)
        padded = np.pad(pts, ((w, w), (0, 0)), mode="edge")
        pts = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(3)], axis=1)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    if s[-1] <= 0:
        return np.linspace(-1.0, 1.0, len(path))
    return 2.0 * s / s[-1] - 1.0


# ----------------------------------------------------------------------------
# Fitting one curve from initial parameters.


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


def _renormalise(u: np.ndarray) -> np.ndarray:
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
        project = _closest_u if round_ == 0 else functools.partial(_project_newton, u0=t)
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
        t = _renormalise(u)
        done = rss - r <= _ROUND_TOL * rss and float(u.min()) >= -1.0 and float(u.max()) <= 1.0
        rss = min(rss, r)
        if done:
            break
    coeffs = _to_monomial(_lstsq(t, P, degree))
    _, dist = _closest_u(coeffs, P, -1.0, 1.0)
    return coeffs, float(np.sum(dist**2))


def _bic(rss: float, n_points: int, degree: int, floor: float) -> float:
    n = 2 * n_points
    return n * math.log(max(rss, floor) / n) + 3 * (degree + 1) * math.log(n)


def _curve_gap(coeffs: np.ndarray, cloud_tree, samples: int = 256) -> float:
    """Largest distance from the curve (dense samples over [-1, 1]) to the
    nearest cloud point: large when the curve wanders where there are no points."""
    u = np.linspace(-1.0, 1.0, samples)
    F = np.stack([_poly.polyval(u, coeffs[a]) for a in range(3)], axis=1)
    return float(cloud_tree.query(F)[0].max())


def _fit_from_parameters(P: np.ndarray, t0: np.ndarray, degree, max_degree: int, extent: float, gap_tol: float):
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
        gap = _curve_gap(coeffs, cloud_tree)
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


def _make_fit(coeffs, degree, P_all, indices, radius, inflate, dtype) -> CurveFit:
    pts = P_all[indices]
    u, dist = _closest_u(coeffs, pts, -1.0, 1.0) if len(pts) else (np.zeros(0), np.zeros(0))
    rms = float(np.sqrt(np.mean(dist**2))) if len(dist) else 0.0
    mx = float(dist.max()) if len(dist) else 0.0
    r = radius + (mx if inflate else 0.0)
    curve = PolynomialCurve(jnp.asarray(coeffs, dtype), jnp.asarray([-1.0, 1.0], dtype), r)
    return CurveFit(curve, int(degree), np.asarray(indices), u, dist, rms, mx)


def _resolve_dtype(points, dtype):
    if dtype is not None:
        return jnp.dtype(dtype)
    src = getattr(points, "dtype", None)
    if src is not None and jnp.issubdtype(src, jnp.floating):
        return jnp.dtype(jnp.result_type(src))  # float64 only when x64 is on
    return jnp.dtype(jnp.result_type(float))


def _report(max_res: float, tol: float, noise: float, max_residual, warn: bool, what: str) -> None:
    if max_residual is not None and max_res > max_residual:
        raise ValueError(
            f"{what}: the farthest cloud point is {max_res:.4g} from the fitted curve(s), above "
            f"max_residual = {max_residual:.4g} (estimated noise level {noise:.3g}); the cloud may hold "
            "several obstacles (use fit_curves), outliers, or a shape a polynomial of this degree cannot follow"
        )
    if warn and max_res > tol:
        warnings.warn(
            f"{what}: poor fit: the farthest cloud point is {max_res:.4g} from the fitted curve(s), "
            f"{max_res / max(noise, 1e-300):.1f} times the cloud's estimated noise level {noise:.3g} "
            f"(expected below {tol:.3g}). Check for outliers or several obstacles (fit_curves), raise "
            "max_degree, or pass inflate=True to keep planning safe with respect to the raw points.",
            FitWarning,
            stacklevel=3,
        )


def warn_if_poor(curve: PolynomialCurve, points, what: str) -> None:
    """FitWarning when an (ordered) fit's farthest point is far beyond the noise
    level (twice the tolerance of :func:`fit_curve`: the chord-length
    parameter of an ordered fit costs some accuracy by itself), with the
    hint that the points may not be in order."""
    P = np.asarray(points, np.float64)
    if P.shape[0] < 4:
        return
    lo, hi = (float(x) for x in np.asarray(curve.u_range))
    _, dist = _closest_u(np.asarray(curve.coeffs, np.float64), P, lo, hi)
    noise = _noise_level(P)
    tol = 2.0 * _tolerance(noise, P.shape[0], float(np.max(np.ptp(P, axis=0))))
    mx = float(dist.max())
    if mx > tol:
        warnings.warn(
            f"{what}: poor fit: the farthest point is {mx:.4g} from the curve, {mx / max(noise, 1e-300):.1f} "
            f"times the cloud's estimated noise level {noise:.3g} (expected below {tol:.3g}). If the points are "
            "not ordered along the obstacle, use fit_curve (or ordered=False); for several obstacles in one "
            "cloud use fit_curves; otherwise raise the degree.",
            FitWarning,
            stacklevel=3,
        )


# ----------------------------------------------------------------------------
# Public fits.


def fit_curve(
    points,
    degree: int | None = None,
    *,
    max_degree: int = 8,
    max_residual=None,
    radius=0.0,
    inflate: bool = False,
    warn: bool = True,
    dtype=None,
) -> CurveFit:
    """Fit one polynomial curve to an UNORDERED, noisy point cloud.

    The order along the obstacle is recovered from the cloud's minimum spanning
    tree (its longest path), parameters are refined by projecting the points on
    the fit, and the degree is chosen by BIC unless given (method: module
    docstring). For a cloud that holds several obstacles use :func:`fit_curves`.

    Args:
      points: (N, 3) cloud in any order, finite, not all identical,
        N >= 2 (degree + 1).
      degree: polynomial degree >= 1; None = choose by BIC in 1..max_degree.
      max_degree: highest degree tried when ``degree`` is None.
      max_residual: if given, a ValueError when some point is farther than
        this from the fitted curve.
      radius: obstacle radius of the returned curve (>= 0).
      inflate: add the maximum residual to the radius (safe w.r.t. the raw points).
      warn: warn (:class:`FitWarning`) when the maximum residual is large against
        the estimated noise level.
      dtype: dtype of the returned curve; default that of ``points`` when it is
        a float array, else JAX's default float.

    Returns:
      :class:`CurveFit` (``.curve`` is the PolynomialCurve, u_range (-1, 1)).
    """
    out_dtype = _resolve_dtype(points, dtype)
    P = check_cloud(points)
    degree = _check_degree(degree, max_degree)
    _check_points_for_degree(P.shape[0], degree)
    max_residual = _check_nonneg(max_residual, "max_residual")
    radius = _check_nonneg(radius, "radius")
    G, gidx = _graph_subset(P)
    sc = _scales(P, G)

    Q = _smooth(G)
    T = _spanning_tree(Q)
    path = _diameter_path(T)
    t_path = _path_parameters(Q, path)
    t_graph = _param_of_attached(path, t_path, _attach(T, path))
    t0 = _extend_parameters(P, G, gidx, t_graph)
    coeffs, d = _fit_from_parameters(P, t0, degree, max_degree, sc.extent, sc.gap_tol)
    fit = _make_fit(coeffs, d, P, np.arange(P.shape[0]), radius, inflate, out_dtype)
    _report(fit.max_residual, sc.tol, sc.noise, max_residual, warn, "fit_curve")
    return fit


class _Scales(NamedTuple):
    """Length scales of a cloud that the fits and the splitting use."""

    extent: float  # largest side of the bounding box
    noise: float  # noise level (local PCA)
    tol: float  # largest acceptable maximum residual
    spacing: float  # median distance to the 6th nearest neighbour
    cut: float  # spanning-tree edges longer than this separate obstacles
    spur: float  # side branches of the tree shorter than this are noise
    gap_tol: float  # a fitted curve may stray this far from the nearest point


def _scales(P: np.ndarray, G: np.ndarray) -> _Scales:
    extent = float(np.max(np.ptp(P, axis=0)))
    noise = _noise_level(P)
    tol = _tolerance(noise, P.shape[0], extent)
    spacing = _neighbour_spacing(G)
    cut = max(4.0 * spacing, 10.0 * noise)
    spur = max(4.0 * spacing, 8.0 * noise)
    return _Scales(extent, noise, tol, spacing, cut, spur, tol + 0.5 * cut)


def _param_of_attached(path: np.ndarray, t_path: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Parameter of every tree node: that of the path node it hangs from."""
    lookup = np.full(int(max(path.max(), src.max())) + 1, 0.0)
    lookup[path] = t_path
    return lookup[src]


def _graph_subset(P: np.ndarray):
    """At most _MAX_GRAPH_POINTS points for the structure (seeded random subset)."""
    n = P.shape[0]
    if n <= _MAX_GRAPH_POINTS:
        return P, np.arange(n)
    idx = np.sort(np.random.default_rng(0).choice(n, _MAX_GRAPH_POINTS, replace=False))
    return P[idx], idx


def _extend_parameters(P, G, gidx, t_graph):
    """Parameters of all points: the graph points' own, others their nearest graph point's."""
    if G.shape[0] == P.shape[0]:
        return t_graph
    _, j = cKDTree(G).query(P)
    return t_graph[j]


# ----------------------------------------------------------------------------
# Several curves in one cloud.


def _neighbour_spacing(P: np.ndarray, k: int = 6) -> float:
    """Median distance to the k-th nearest neighbour: the cloud's local point spacing."""
    k = min(k, P.shape[0] - 1)
    if k < 1:
        return 0.0
    d, _ = cKDTree(P).query(P, k + 1)
    return float(np.median(d[:, k]))


class _Tree:
    """Adjacency lists of a (forest) graph given as a symmetric CSR matrix."""

    def __init__(self, T):
        T = T.tocsr()
        self.n = T.shape[0]
        self.adj = [T.indices[T.indptr[i] : T.indptr[i + 1]].tolist() for i in range(self.n)]
        self.w = [T.data[T.indptr[i] : T.indptr[i + 1]].tolist() for i in range(self.n)]

    def weight(self, i, j):
        return self.w[i][self.adj[i].index(j)]


def _walk(tree: _Tree, alive: np.ndarray, deg: np.ndarray, start: int, first: int):
    """Nodes from ``start`` through ``first`` along degree-2 nodes to the next
    node whose degree is not 2 (included). Returns (nodes, length)."""
    nodes = [start, first]
    length = tree.weight(start, first)
    prev, cur = start, first
    while deg[cur] == 2:
        nxt = [j for j in tree.adj[cur] if alive[j] and j != prev][0]
        length += tree.weight(cur, nxt)
        nodes.append(nxt)
        prev, cur = cur, nxt
    return nodes, length


def _prune(tree: _Tree, nodes: np.ndarray, Q: np.ndarray, spur: float) -> np.ndarray:
    """Skeleton of one tree component: remove leaf branches whose tip lies within
    ``spur`` of the rest of the skeleton (noise spurs), repeatedly, never
    turning a junction into an end. Returns the alive mask (n,)."""
    alive = np.zeros(tree.n, bool)
    alive[nodes] = True
    while True:
        deg = np.array([sum(alive[j] for j in tree.adj[i]) if alive[i] else 0 for i in range(tree.n)])
        if not np.any(deg >= 3):
            return alive
        leaf_branches = []  # (junction, nodes without the junction, length)
        for leaf in np.nonzero(alive & (deg == 1))[0]:
            nb = [j for j in tree.adj[leaf] if alive[j]][0]
            walk, length = _walk(tree, alive, deg, int(leaf), nb)
            if deg[walk[-1]] >= 3:
                leaf_branches.append((walk[-1], walk[:-1], length))
        in_branch = np.zeros(tree.n, bool)
        for _, b, _ in leaf_branches:
            in_branch[b] = True
        core = np.nonzero(alive & ~in_branch)[0]
        if core.size == 0:
            return alive
        core_tree = cKDTree(Q[core])
        by_junction = {}
        for jn, b, length in leaf_branches:
            tip_dist = core_tree.query(Q[b[0]])[0]
            by_junction.setdefault(jn, []).append((tip_dist < spur, length, b))
        removed = False
        for jn, items in by_junction.items():
            cut = [it for it in items if it[0]]
            keep_needed = 2 - (deg[jn] - len(cut))  # the junction must keep degree >= 2
            cut.sort(key=lambda it: it[1])
            if keep_needed > 0:
                cut = cut[: max(len(cut) - keep_needed, 0)]
            for _, _, b in cut:
                alive[b] = False
                removed = True
        if not removed:
            return alive


def _pieces(tree: _Tree, alive: np.ndarray):
    """Split a skeleton at its junctions: list of (nodes, length), each a path
    from a junction or end to the next junction or end."""
    deg = np.array([sum(alive[j] for j in tree.adj[i]) if alive[i] else 0 for i in range(tree.n)])
    stops = np.nonzero(alive & (deg != 2))[0]
    seen = set()
    out = []
    for s in stops:
        for nb in tree.adj[s]:
            if not alive[nb]:
                continue
            walk, length = _walk(tree, alive, deg, int(s), nb)
            key = (min(walk[0], walk[-1]), max(walk[0], walk[-1]), walk[1] if walk[0] < walk[-1] else walk[-2])
            if key in seen:
                continue
            seen.add(key)
            out.append((walk, length))
    if not out and alive.any():  # a single node
        out.append(([int(np.nonzero(alive)[0][0])], 0.0))
    return out, deg


class _UnionFind:
    def __init__(self, n):
        self.p = list(range(n))

    def find(self, i):
        while self.p[i] != i:
            self.p[i] = self.p[self.p[i]]
            i = self.p[i]
        return i

    def union(self, a, b):
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        self.p[ra] = rb
        return True


def _chains(pieces, deg, Q, spur: float, min_angle_deg: float = 150.0):
    """Join skeleton pieces through junctions into obstacle curves.

    Junctions joined by a piece shorter than ``spur`` are one junction (its
    short pieces belong to it). At each junction, pairs of pieces whose
    directions away from it are more than ``min_angle_deg`` apart are joined,
    straightest pair first. Returns a list of node sequences (ordered)."""
    junctions = sorted({int(n) for walk, _ in pieces for n in (walk[0], walk[-1]) if deg[n] >= 3})
    jid = {n: k for k, n in enumerate(junctions)}
    uf = _UnionFind(len(junctions))
    internal = set()
    for p, (walk, length) in enumerate(pieces):
        a, b = walk[0], walk[-1]
        if a in jid and b in jid and length < spur:
            uf.union(jid[a], jid[b])
            internal.add(p)
    cluster_of = {n: uf.find(jid[n]) for n in junctions}
    centre = {}
    for n, c in cluster_of.items():
        centre.setdefault(c, []).append(Q[n])
    centre = {c: np.mean(v, axis=0) for c, v in centre.items()}
    # Incident piece ends per cluster, with the piece's direction away from it.
    ends = {}
    for p, (walk, _length) in enumerate(pieces):
        if p in internal:
            continue
        for side, node in ((0, walk[0]), (1, walk[-1])):
            if node not in cluster_of:
                continue
            c = cluster_of[node]
            seq = walk if side == 0 else walk[::-1]
            pts = Q[seq]
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            lo, hi = spur, 4.0 * spur
            sel = (s >= min(lo, 0.5 * s[-1])) & (s <= min(hi, s[-1]))
            if not sel.any():
                sel = s >= 0.5 * s[-1]
            v = pts[sel].mean(axis=0) - centre[c]
            nv = np.linalg.norm(v)
            ends.setdefault(c, []).append((p, side, v / nv if nv > 0 else v))
    links = {}  # (piece, side) -> (piece, side)
    uf_p = _UnionFind(len(pieces))
    cos_max = math.cos(math.radians(min_angle_deg))
    for items in ends.values():
        pairs = []
        for i in range(len(items)):
            for j in range(i + 1, len(items)):
                cs = float(np.dot(items[i][2], items[j][2]))
                if cs < cos_max and items[i][0] != items[j][0]:
                    pairs.append((cs, i, j))
        pairs.sort()
        used = set()
        for _, i, j in pairs:
            if i in used or j in used:
                continue
            (pi, si, _), (pj, sj, _) = items[i], items[j]
            if not uf_p.union(pi, pj):
                continue  # would close a loop
            used.update((i, j))
            links[(pi, si)] = (pj, sj)
            links[(pj, sj)] = (pi, si)
    chains = []
    done = set()
    order = [p for p in range(len(pieces)) if p not in internal]
    # Start at piece ends that are not linked (chain ends); then any left (none: no loops).
    for p in order:
        for side in (0, 1):
            if p in done or (p, side) in links:
                continue
            seq = []
            cur, enter = p, side
            while True:
                walk = pieces[cur][0]
                seq.extend(walk if enter == 0 else walk[::-1])
                done.add(cur)
                out = (cur, 1 - enter)
                if out not in links:
                    break
                cur, enter = links[out]
            chains.append(np.asarray(seq))
    return chains


def _component_chains(C: np.ndarray, sc: _Scales):
    """The obstacle curves of one connected group of points C (M, 3): a list of
    (member indices into C, initial parameters in [-1, 1]). Points near a
    junction belong to every curve through it."""
    Q = _smooth(C)
    T = _spanning_tree(Q)
    tree = _Tree(T)
    alive = _prune(tree, np.arange(C.shape[0]), Q, sc.spur)
    pieces, deg = _pieces(tree, alive)
    chains = _chains(pieces, deg, Q, sc.spur)
    src = _attach(T, np.nonzero(alive)[0])  # every point -> the skeleton node it hangs from
    node_chains = {}
    for k, seq in enumerate(chains):
        for node in seq:
            node_chains.setdefault(int(node), []).append(k)
    # A point hanging from a node shared by several chains (a junction) goes to
    # the chain whose other nodes are nearest.
    trees = [cKDTree(Q[seq]) if len(seq) else None for seq in chains]
    owner = np.full(C.shape[0], -1)
    for i in range(C.shape[0]):
        ks = node_chains.get(int(src[i]), [])
        if len(ks) == 1:
            owner[i] = ks[0]
        elif ks:
            owner[i] = min(ks, key=lambda k: _distance_excluding(trees[k], chains[k], Q[i], int(src[i])))
    out = []
    for k, seq in enumerate(chains):
        members = np.nonzero(owner == k)[0]
        if len(seq) < 2 or members.size == 0:
            continue
        t_seq = _path_parameters(Q, seq)
        _, j = trees[k].query(Q[members])
        out.append((members, t_seq[j]))
    return out


def _distance_excluding(tree, seq, p, node: int) -> float:
    """Distance from p to the nearest node of a chain other than ``node``."""
    d, j = tree.query(p, k=min(2, len(seq)))
    d, j = np.atleast_1d(d), np.atleast_1d(j)
    for dist, idx in zip(d, j, strict=True):
        if int(seq[idx]) != node:
            return float(dist)
    return math.inf


def _fit_and_split(P, groups, degree, max_degree, sc: _Scales, max_splits: int, min_pts: int):
    """Fit every group; then rounds of: give each cloud point to its nearest
    curve and refit every curve to its own points (from their foot-point
    parameters), so that points near a junction end up on the curve they
    belong to; after ``_RELABEL_ROUNDS`` such rounds, a curve whose points are
    farther than the tolerance, or which strays from the cloud, is split at its middle (u = 0, with a small
    overlap) into two, up to ``max_splits`` times. Returns a list of
    (coeffs, degree)."""
    fits = [_fit_from_parameters(P[m], t0, degree, max_degree, sc.extent, sc.gap_tol) for m, t0 in groups]
    cloud_tree = cKDTree(P)
    splits = 0
    for round_ in range(_RELABEL_ROUNDS + max_splits):
        fits = _close_junctions(fits, sc.spur)
        U, D = zip(*[_closest_u(c, P, -1.0, 1.0) for c, _ in fits], strict=True)
        U, D = np.stack(U, axis=1), np.stack(D, axis=1)  # (N, m)
        labels = np.argmin(D, axis=1)
        new, changed = [], False
        for k, (coeffs, d) in enumerate(fits):
            mine = np.nonzero(labels == k)[0]
            if mine.size < min_pts:
                changed = changed or mine.size > 0
                continue  # explains (almost) nothing: dropped, its points go to other curves
            u = U[mine, k]
            poor = float(D[mine, k].max()) > sc.tol or _curve_gap(coeffs, cloud_tree) > sc.gap_tol
            halves = []
            if poor and splits < max_splits and round_ >= _RELABEL_ROUNDS:
                for lo, hi in ((-1.0, 0.05), (-0.05, 1.0)):
                    sel = (u >= lo) & (u <= hi)
                    halves.append((mine[sel], 2.0 * (u[sel] - lo) / (hi - lo) - 1.0))
            if halves and all(h[0].size >= min_pts for h in halves):
                new.extend(_fit_from_parameters(P[m], t, degree, max_degree, sc.extent, sc.gap_tol) for m, t in halves)
                splits += 1
                changed = True
            elif mine.size < len(P) and np.any(labels != k):
                # refit to its own points only
                new.append(_fit_from_parameters(P[mine], _renormalise(u), degree, max_degree, sc.extent, sc.gap_tol))
                changed = True
            else:
                new.append((coeffs, d))
        if not new:
            break
        fits = new
        if not changed:
            break
    return _close_junctions(fits, sc.spur)


def _reparametrise(coeffs: np.ndarray, a: float, b: float) -> np.ndarray:
    """Monomial coefficients of G(t) = F(a + (t + 1)(b - a) / 2), t in [-1, 1]
    (exact: interpolation at degree + 1 Chebyshev points)."""
    K = coeffs.shape[1]
    t = np.cos(np.pi * (np.arange(K) + 0.5) / K)
    u = a + (t + 1.0) * (b - a) / 2.0
    vals = np.stack([_poly.polyval(u, coeffs[i]) for i in range(3)], axis=1)
    return _to_monomial(_lstsq(t, vals, K - 1))


def _close_junctions(fits, reach: float):
    """Extend a curve end that stops short of another curve (a branch that
    grows from a trunk, within ``reach``) along its own polynomial until it
    meets that curve, so no false gap opens at a junction."""
    out = []
    for k, (coeffs, d) in enumerate(fits):
        others = [c for j, (c, _) in enumerate(fits) if j != k]
        lo, hi = -1.0, 1.0
        for end in (-1.0, 1.0):
            p = np.array([_poly.polyval(end, coeffs[i]) for i in range(3)])[None]
            best = (math.inf, end)
            for c in others:
                dist = float(_closest_u(c, p, -1.0, 1.0)[1][0])
                if dist < reach and dist < best[0]:
                    best = (dist, end)
                    speed = float(np.linalg.norm([_poly.polyval(end, _poly.polyder(coeffs[i])) for i in range(3)]))
                    if speed <= 0:
                        continue
                    # extrapolate up to twice the distance, keep the parameter nearest the other curve
                    us = end + np.sign(end) * np.linspace(0.0, 2.0 * dist / speed, 41)
                    pts = np.stack([_poly.polyval(us, coeffs[i]) for i in range(3)], axis=1)
                    dd = _closest_u(c, pts, -1.0, 1.0)[1]
                    best = (float(dd.min()), float(us[int(np.argmin(dd))]))
            if best[1] != end:
                lo, hi = (best[1], hi) if end < 0 else (lo, best[1])
        out.append((_reparametrise(coeffs, lo, hi) if (lo, hi) != (-1.0, 1.0) else coeffs, d))
    return out


def fit_curves(
    points,
    degree: int | None = None,
    *,
    max_degree: int = 8,
    max_residual=None,
    radius=0.0,
    inflate: bool = False,
    warn: bool = True,
    min_points: int | None = None,
    max_splits: int = 3,
    dtype=None,
) -> CloudFit:
    """Split an unordered, noisy cloud into its curve-like obstacles and fit each.

    A trunk with branches, two crossing wires, or separate wires become one
    polynomial curve each (method: module docstring). Each point's residual is
    its exact distance to the nearest fitted curve.

    Args:
      points: (N, 3) cloud in any order, finite, not all identical.
      degree: degree of every curve (>= 1); None = each chosen by BIC in 1..max_degree.
      max_degree: highest degree tried when ``degree`` is None.
      max_residual: if given, a ValueError when some point is farther than
        this from every fitted curve.
      radius: obstacle radius of every curve (>= 0).
      inflate: add each curve's maximum residual (over the points nearest to
        it) to its radius, so that an arm clear of the curves is clear of
        every raw point.
      warn: warn (:class:`FitWarning`) when the maximum residual is large
        against the estimated noise level.
      min_points: smallest group of points fitted as a curve; smaller
        isolated groups are left unfitted (they show in the residuals);
        default max(10, 2 (degree + 1)).
      max_splits: how many times a poorly fitting piece may be halved.
      dtype: dtype of the curves (as for :func:`fit_curve`).

    Returns:
      :class:`CloudFit`; ``.curves`` are the PolynomialCurves, for
      :func:`~softplan_jax.make_scenario`.
    """
    out_dtype = _resolve_dtype(points, dtype)
    P = check_cloud(points)
    degree = _check_degree(degree, max_degree)
    _check_points_for_degree(P.shape[0], degree)
    max_residual = _check_nonneg(max_residual, "max_residual")
    radius = _check_nonneg(radius, "radius")
    if isinstance(max_splits, bool) or not isinstance(max_splits, (int, np.integer)) or max_splits < 0:
        raise ValueError(f"max_splits must be an integer >= 0, got {max_splits!r}")
    need = 2 * ((degree or 1) + 1)
    if min_points is None:
        min_points = max(10, need)
    elif isinstance(min_points, bool) or not isinstance(min_points, (int, np.integer)) or min_points < need:
        raise ValueError(f"min_points must be an integer >= {need}, got {min_points!r}")
    n = P.shape[0]
    G, gidx = _graph_subset(P)
    sc = _scales(P, G)

    # Separate obstacles: cut the raw cloud's spanning tree at edges much longer
    # than the point spacing, both the cloud's and the local one at the edge's
    # two ends (sampling is often sparser along parts of a curve).
    T_raw = _spanning_tree(G).tocoo()
    k = min(6, G.shape[0] - 1)
    local = cKDTree(G).query(G, k + 1)[0][:, k]
    long_edge = T_raw.data > np.maximum(sc.cut, 2.5 * (local[T_raw.row] + local[T_raw.col]))
    T_raw.data[long_edge] = 0.0
    T_raw = T_raw.tocsr()
    T_raw.eliminate_zeros()
    ncomp, comp = connected_components(T_raw, directed=False)
    near = cKDTree(G).query(P)[1] if G.shape[0] != n else None  # cloud point -> graph point

    groups = []  # (member indices into P, initial parameters)
    for c in range(ncomp):
        nodes = np.nonzero(comp == c)[0]
        if nodes.size < min_points * G.shape[0] / n:
            continue  # a few isolated points: left unfitted (they show in the residuals)
        for members, t_members in _component_chains(G[nodes], sc):
            members = nodes[members]
            if near is not None:  # every cloud point takes its nearest graph point's chain
                lookup = np.full(G.shape[0], np.nan)
                lookup[members] = t_members
                full = np.nonzero(np.isfinite(lookup[near]))[0]
                members, t_members = full, lookup[near[full]]
            else:
                members = gidx[members]
            if members.size >= min_points:
                groups.append((members, t_members))

    if not groups:
        raise ValueError(
            f"no group of at least min_points = {min_points} connected points was found in the cloud "
            f"({n} points, spacing {sc.spacing:.3g}); lower min_points or check the cloud"
        )
    fits_raw = _fit_and_split(P, groups, degree, max_degree, sc, max_splits, min_points)
    D = np.stack([_closest_u(c, P, -1.0, 1.0)[1] for c, _ in fits_raw], axis=1)  # (N, m)
    # Residuals: every point against its nearest curve; curves nobody is nearest to are dropped.
    labels = np.argmin(D, axis=1)
    used = np.unique(labels)
    remap = -np.ones(len(fits_raw), int)
    remap[used] = np.arange(used.size)
    fits = tuple(
        _make_fit(fits_raw[k][0], fits_raw[k][1], P, np.nonzero(labels == k)[0], radius, inflate, out_dtype)
        for k in used
    )
    residuals = D[np.arange(n), labels]
    labels = remap[labels]
    result = CloudFit(
        fits=fits,
        labels=labels,
        residuals=residuals,
        rms_residual=float(np.sqrt(np.mean(residuals**2))),
        max_residual=float(residuals.max()),
        noise=sc.noise,
        tolerance=sc.tol,
    )
    _report(result.max_residual, sc.tol, sc.noise, max_residual, warn, "fit_curves")
    return result


# ----------------------------------------------------------------------------
# Scenario files with the fit's residuals.


def fit_scenario_dict(fit, goal, q0=None, *, name: str | None = None, metadata: dict | None = None) -> dict:
    """The JSON structure of a scenario whose obstacles are fitted curves, with
    the fit's residuals as ``metadata`` (top level: the whole cloud; each
    obstacle: its own points). ``load_scenario`` reads it; metadata is not part
    of the Scenario.

    Args:
      fit: a :class:`CloudFit` (or a :class:`CurveFit`).
      goal: (3,) goal of the tip.
      q0: (n, 3) start; None = the default straight arm.
      name: optional scenario name.
      metadata: extra top-level metadata (JSON-serialisable), e.g. the cloud's path.

    Returns:
      dict in the ``softplan-scenario/1`` format.
    """
    from ..scenarios import make_scenario, scenario_to_dict

    cf = CloudFit.from_fit(fit)
    scenario = make_scenario(goal, [f.curve for f in cf.fits], q0)
    data = scenario_to_dict(scenario, name)
    for ob, f in zip(data["obstacles"], cf.fits, strict=True):
        ob["metadata"] = {
            "fit": {
                "degree": f.degree,
                "points": int(f.indices.size),
                "rms_residual": f.rms_residual,
                "max_residual": f.max_residual,
            }
        }
    top = {
        "points": int(cf.residuals.size),
        "curves": len(cf.fits),
        "rms_residual": cf.rms_residual,
        "max_residual": cf.max_residual,
        "degree_criterion": "BIC (Schwarz 1978) unless the degree was given",
        "residual": "exact distance from each cloud point to its nearest fitted curve (centre line)",
    }
    if math.isfinite(cf.noise):
        top["noise"] = cf.noise
        top["tolerance"] = cf.tolerance
    meta = {"fit": top}
    if metadata:
        meta.update(metadata)
    data["metadata"] = meta
    return data


def save_fit_scenario(fit, path, goal, q0=None, *, name: str | None = None, metadata: dict | None = None,
                      overwrite: bool = False) -> None:
    """Write :func:`fit_scenario_dict` as a JSON scenario file (whole or not at
    all); refuses to replace an existing file unless ``overwrite=True``."""
    write_json_file(path, fit_scenario_dict(fit, goal, q0, name=name, metadata=metadata), overwrite)
