"""Exact distance from points to a polynomial curve, on the host (NumPy): :func:`curve_distance`
over the curve's whole ``u_range``, and the solvers behind it from
:mod:`softplan_jax.geometry._point_curve` re-exported for the fitting modules
(:func:`closest_parameters`: the roots of the stationarity polynomial, paper eq. 14 with the
arm point fixed; :func:`project_newton`: safeguarded Newton from warm starts)."""

from __future__ import annotations

import numpy as np

from ..base._validation import check_points
from ..geometry._curves import PolynomialCurve
from ..geometry._point_curve import closest_parameters, project_newton

__all__ = ["curve_distance", "closest_parameters", "project_newton"]


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
    u, dist = closest_parameters(np.asarray(curve.coeffs, np.float64), pts, lo, hi)
    return dist, u
