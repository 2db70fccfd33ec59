"""Several curves in one cloud, a trunk with branches, crossing wires or separate obstacles
(paper §2.3): :func:`fit_curves` cuts the cloud's spanning tree at long edges, splits each
part's skeleton into curves at its junctions (:mod:`._skeleton`), fits each piece
(:mod:`._refine`), halves a poorly fitting piece up to ``max_splits`` times, and returns
ordinary :class:`~softplan_jax.PolynomialCurve` objects with ``u_range`` (-1, 1) and each
point's distance to its nearest curve."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.polynomial import polynomial as _poly
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..base._validation import check_cloud
from ._distance import closest_parameters
from ._graph import Scales, cloud_scales, graph_subset, spanning_tree
from ._one_curve import (
    CurveFit,
    check_degree,
    check_nonneg,
    check_points_for_degree,
    make_fit,
    report_fit,
    resolve_dtype,
)
from ._refine import curve_gap, fit_from_parameters, renormalise, reparametrise
from ._skeleton import component_chains

__all__ = ["CloudFit", "fit_curves"]

# Rounds of giving points to their nearest curve and refitting (fit_curves).
_RELABEL_ROUNDS = 2


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


def _fit_and_split(P, groups, degree, max_degree, sc: Scales, max_splits: int, min_pts: int):
    """Fit every group; then rounds of: give each cloud point to its nearest
    curve and refit every curve to its own points (from their foot-point
    parameters), so that points near a junction end up on the curve they
    belong to; after ``_RELABEL_ROUNDS`` such rounds, a curve whose points are
    farther than the tolerance, or which strays from the cloud, is split at its middle (u = 0, with a small
    overlap) into two, up to ``max_splits`` times. Returns a list of
    (coeffs, degree)."""
    fits = [fit_from_parameters(P[m], t0, degree, max_degree, sc.extent, sc.gap_tol) for m, t0 in groups]
    cloud_tree = cKDTree(P)
    splits = 0
    for round_ in range(_RELABEL_ROUNDS + max_splits):
        fits = _close_junctions(fits, sc.spur)
        U, D = zip(*[closest_parameters(c, P, -1.0, 1.0) for c, _ in fits], strict=True)
        U, D = np.stack(U, axis=1), np.stack(D, axis=1)  # (N, m)
        labels = np.argmin(D, axis=1)
        new, changed = [], False
        for k, (coeffs, d) in enumerate(fits):
            mine = np.nonzero(labels == k)[0]
            if mine.size < min_pts:
                changed = changed or mine.size > 0
                continue  # explains (almost) nothing: dropped, its points go to other curves
            u = U[mine, k]
            poor = float(D[mine, k].max()) > sc.tol or curve_gap(coeffs, cloud_tree) > sc.gap_tol
            halves = []
            if poor and splits < max_splits and round_ >= _RELABEL_ROUNDS:
                for lo, hi in ((-1.0, 0.05), (-0.05, 1.0)):
                    sel = (u >= lo) & (u <= hi)
                    halves.append((mine[sel], 2.0 * (u[sel] - lo) / (hi - lo) - 1.0))
            if halves and all(h[0].size >= min_pts for h in halves):
                new.extend(fit_from_parameters(P[m], t, degree, max_degree, sc.extent, sc.gap_tol) for m, t in halves)
                splits += 1
                changed = True
            elif mine.size < len(P) and np.any(labels != k):
                # refit to its own points only
                new.append(fit_from_parameters(P[mine], renormalise(u), degree, max_degree, sc.extent, sc.gap_tol))
                changed = True
            else:
                new.append((coeffs, d))
        if not new:
            break
        fits = new
        if not changed:
            break
    return _close_junctions(fits, sc.spur)


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
                dist = float(closest_parameters(c, p, -1.0, 1.0)[1][0])
                if dist < reach and dist < best[0]:
                    best = (dist, end)
                    speed = float(np.linalg.norm([_poly.polyval(end, _poly.polyder(coeffs[i])) for i in range(3)]))
                    if speed <= 0:
                        continue
                    # extrapolate up to twice the distance, keep the parameter nearest the other curve
                    us = end + np.sign(end) * np.linspace(0.0, 2.0 * dist / speed, 41)
                    pts = np.stack([_poly.polyval(us, coeffs[i]) for i in range(3)], axis=1)
                    dd = closest_parameters(c, pts, -1.0, 1.0)[1]
                    best = (float(dd.min()), float(us[int(np.argmin(dd))]))
            if best[1] != end:
                lo, hi = (best[1], hi) if end < 0 else (lo, best[1])
        out.append((reparametrise(coeffs, lo, hi) if (lo, hi) != (-1.0, 1.0) else coeffs, d))
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
    polynomial curve each (the method: the documentation's 'Obstacles from
    point clouds'). Each point's residual is
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
    out_dtype = resolve_dtype(points, dtype)
    P = check_cloud(points)
    degree = check_degree(degree, max_degree)
    check_points_for_degree(P.shape[0], degree)
    max_residual = check_nonneg(max_residual, "max_residual")
    radius = check_nonneg(radius, "radius")
    if isinstance(max_splits, bool) or not isinstance(max_splits, (int, np.integer)) or max_splits < 0:
        raise ValueError(f"max_splits must be an integer >= 0, got {max_splits!r}")
    need = 2 * ((degree or 1) + 1)
    if min_points is None:
        min_points = max(10, need)
    elif isinstance(min_points, bool) or not isinstance(min_points, (int, np.integer)) or min_points < need:
        raise ValueError(f"min_points must be an integer >= {need}, got {min_points!r}")
    G, gidx = graph_subset(P)
    sc = cloud_scales(P, G)
    groups = _groups(P, G, gidx, sc, min_points)
    fits_raw = _fit_and_split(P, groups, degree, max_degree, sc, max_splits, min_points)
    result = _cloud_fit(P, fits_raw, sc, radius, inflate, out_dtype)
    report_fit(result.max_residual, sc.tol, sc.noise, max_residual, warn, "fit_curves")
    return result


def _groups(P, G, gidx, sc: Scales, min_points: int) -> list:
    """The cloud's curve-like pieces: ``[(member indices into P, initial parameters), ...]``.
    Separate obstacles: the graph points' spanning tree cut at edges much longer than the
    point spacing, both the cloud's and the local one at the edge's two ends (sampling is
    often sparser along parts of a curve); then each part's skeleton split at its junctions."""
    n = P.shape[0]
    T_raw = spanning_tree(G).tocoo()
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
        for members, t_members in component_chains(G[nodes], sc):
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
    return groups


def _cloud_fit(P, fits_raw: list, sc: Scales, radius, inflate: bool, out_dtype) -> CloudFit:
    """The CloudFit of the fitted curves: every point against its nearest curve; curves nobody
    is nearest to are dropped."""
    n = P.shape[0]
    D = np.stack([closest_parameters(c, P, -1.0, 1.0)[1] for c, _ in fits_raw], axis=1)  # (N, m)
    labels = np.argmin(D, axis=1)
    used = np.unique(labels)
    remap = -np.ones(len(fits_raw), int)
    remap[used] = np.arange(used.size)
    fits = tuple(
        make_fit(fits_raw[k][0], fits_raw[k][1], P, np.nonzero(labels == k)[0], radius, inflate, out_dtype)
        for k in used
    )
    residuals = D[np.arange(n), labels]
    return CloudFit(
        fits=fits,
        labels=remap[labels],
        residuals=residuals,
        rms_residual=float(np.sqrt(np.mean(residuals**2))),
        max_residual=float(residuals.max()),
        noise=sc.noise,
        tolerance=sc.tol,
    )
