"""One polynomial curve through an unordered, noisy point cloud (paper §2.3): :func:`fit_curve`
orders the points along the longest path of their spanning tree, refines the fit by parameter
correction (:mod:`._refine`), chooses the degree by BIC unless given, and reports the RMS and
maximum exact residuals against the cloud's noise level (warning with :class:`FitWarning`
above ``(sqrt(2 ln N) + 2)`` noise levels); :func:`fit_polynomial_curve` is the plain
least-squares fit of an ORDERED cloud in its normalised chord length, u in [0, 1]."""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from ..base._validation import check_cloud, check_points, is_concrete
from ..geometry._curves import PolynomialCurve
from ._distance import closest_parameters
from ._graph import (
    attach,
    cloud_scales,
    diameter_path,
    graph_subset,
    noise_level,
    path_parameters,
    residual_tolerance,
    smooth_cloud,
    spanning_tree,
)
from ._refine import fit_from_parameters

__all__ = [
    "FitWarning",
    "CurveFit",
    "fit_curve",
    "fit_polynomial_curve",
    "warn_if_poor",
    "check_degree",
    "check_points_for_degree",
    "check_nonneg",
    "make_fit",
    "resolve_dtype",
    "report_fit",
]


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
        """``[curve]``, as :attr:`~softplan_jax.clouds.CloudFit.curves`."""
        return [self.curve]


# Highest degree a fit takes. The least squares are in the power basis on u in [-1, 1], whose
# conditioning grows like (1 + sqrt 2)^d: about 5e7 at d = 20, 1e23 at d = 60, where the fitted
# coefficients (up to 1e19 for a cloud of size 1) cancel to garbage in float64.
MAX_FIT_DEGREE = 20
_DEGREE_ADVICE = (f"a fit takes degree <= {MAX_FIT_DEGREE}: beyond it the power-basis least squares lose "
                  "float64 precision (conditioning about (1 + sqrt 2)^degree); let fit_curves split the cloud "
                  "into several curves, or fit pieces of it separately")


def check_degree(degree, max_degree: int):
    """The degree as an int, or None to choose it by BIC (then ``max_degree`` is checked); else a
    ValueError (also above :data:`MAX_FIT_DEGREE`, saying why)."""
    if degree is not None:
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 1:
            raise ValueError(f"degree must be an integer >= 1 (or None to choose it), got {degree!r}")
        if degree > MAX_FIT_DEGREE:
            raise ValueError(f"degree = {degree} is too high: {_DEGREE_ADVICE}")
        return int(degree)
    if isinstance(max_degree, bool) or not isinstance(max_degree, (int, np.integer)) or max_degree < 1:
        raise ValueError(f"max_degree must be an integer >= 1, got {max_degree!r}")
    if max_degree > MAX_FIT_DEGREE:
        raise ValueError(f"max_degree = {max_degree} is too high: {_DEGREE_ADVICE}")
    return None


def check_points_for_degree(n: int, degree, what: str = "the cloud") -> None:
    """A ValueError unless n points can fit the degree (twice its coefficients per axis; 4 if it is chosen)."""
    need = 2 * (degree + 1) if degree is not None else 4
    if n < need:
        if degree is None:
            raise ValueError(f"{what} has {n} point(s); fitting a curve needs at least {need}")
        raise ValueError(
            f"{what} has {n} point(s); fitting degree {degree} needs at least {need} "
            f"(twice the {degree + 1} coefficients per axis)"
        )


def check_nonneg(x, name: str):
    """``x`` as a finite float >= 0 (None stays None); else a ValueError naming it."""
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {x!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be finite and >= 0, got {x!r}")
    return v


def make_fit(coeffs, degree, P_all, indices, radius, inflate, dtype) -> CurveFit:
    """The :class:`CurveFit` of monomial coefficients on u in [-1, 1] over the points ``P_all[indices]``:
    their exact residuals, and the radius grown by the largest of them when ``inflate``."""
    pts = P_all[indices]
    u, dist = closest_parameters(coeffs, pts, -1.0, 1.0) if len(pts) else (np.zeros(0), np.zeros(0))
    rms = float(np.sqrt(np.mean(dist**2))) if len(dist) else 0.0
    mx = float(dist.max()) if len(dist) else 0.0
    r = radius + (mx if inflate else 0.0)
    curve = PolynomialCurve(jnp.asarray(coeffs, dtype), jnp.asarray([-1.0, 1.0], dtype), r)
    return CurveFit(curve, int(degree), np.asarray(indices), u, dist, rms, mx)


def resolve_dtype(points, dtype):
    """The curves' dtype: ``dtype`` if given, else that of ``points`` when a float array, else JAX's default."""
    if dtype is not None:
        return jnp.dtype(dtype)
    src = getattr(points, "dtype", None)
    if src is not None and jnp.issubdtype(src, jnp.floating):
        return jnp.dtype(jnp.result_type(src))  # float64 only when x64 is on
    return jnp.dtype(jnp.result_type(float))


def report_fit(max_res: float, tol: float, noise: float, max_residual, warn: bool, what: str) -> None:
    """A ValueError when the farthest point is beyond ``max_residual``; a :class:`FitWarning` (if ``warn``)
    when it is beyond the tolerance ``tol``."""
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
    _, dist = closest_parameters(np.asarray(curve.coeffs, np.float64), P, lo, hi)
    noise = noise_level(P)
    tol = 2.0 * residual_tolerance(noise, P.shape[0], float(np.max(np.ptp(P, axis=0))))
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
    out_dtype = resolve_dtype(points, dtype)
    P = check_cloud(points)
    degree = check_degree(degree, max_degree)
    check_points_for_degree(P.shape[0], degree)
    max_residual = check_nonneg(max_residual, "max_residual")
    radius = check_nonneg(radius, "radius")
    G, gidx = graph_subset(P)
    sc = cloud_scales(P, G)

    Q = smooth_cloud(G)
    T = spanning_tree(Q)
    path = diameter_path(T)
    t_path = path_parameters(Q, path)
    t_graph = _param_of_attached(path, t_path, attach(T, path))
    t0 = _extend_parameters(P, G, gidx, t_graph)
    coeffs, d = fit_from_parameters(P, t0, degree, max_degree, sc.extent, sc.gap_tol)
    fit = make_fit(coeffs, d, P, np.arange(P.shape[0]), radius, inflate, out_dtype)
    report_fit(fit.max_residual, sc.tol, sc.noise, max_residual, warn, "fit_curve")
    return fit


def _param_of_attached(path: np.ndarray, t_path: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Parameter of every tree node: that of the path node it hangs from."""
    lookup = np.full(int(max(path.max(), src.max())) + 1, 0.0)
    lookup[path] = t_path
    return lookup[src]


def _extend_parameters(P, G, gidx, t_graph):
    """Parameters of all points: the graph points' own, others their nearest graph point's."""
    if G.shape[0] == P.shape[0]:
        return t_graph
    _, j = cKDTree(G).query(P)
    return t_graph[j]


def fit_polynomial_curve(points, degree: int = 3, radius=0.0, *, ordered: bool = True) -> PolynomialCurve:
    """Fit a polynomial curve to an ordered point cloud by least squares.

    The parameter is the normalised cumulative chord length, so u runs over
    [0, 1] from the first point to the last. Ordered means the points follow
    the obstacle from one end to the other (a branch scanned along its length).
    When the fit is far from some points against the cloud's noise level (as
    when the points are NOT in order), a :class:`FitWarning` says so. For
    unordered clouds pass ``ordered=False`` (or use :func:`fit_curve`, which
    also reports residuals, and :func:`~softplan_jax.clouds.fit_curves` for
    several obstacles in one cloud).

    Args:
      points: (N, 3), N >= degree + 1, not all identical.
      degree: polynomial degree >= 1.
      radius: obstacle radius (>= 0).
      ordered: False = the points are in any order: delegate to
        :func:`fit_curve` (u_range (-1, 1) then).

    Returns:
      PolynomialCurve with coeffs (3, degree + 1) and u_range (0, 1).
    """
    degree = check_degree(degree, MAX_FIT_DEGREE)
    if degree is None:
        raise ValueError("degree must be an integer >= 1, got None")
    if not ordered:
        return fit_curve(points, degree, radius=radius).curve
    points = check_points(points)
    if points.shape[0] < degree + 1:
        raise ValueError(
            f"fitting degree {degree} needs at least {degree + 1} points; got {points.shape[0]}"
        )
    chord = jnp.linalg.norm(jnp.diff(points, axis=0), axis=1)
    total = jnp.sum(chord)
    if is_concrete(total) and float(total) == 0.0:
        raise ValueError("points are all identical: no curve can be fitted")
    u = jnp.concatenate([jnp.zeros(1, points.dtype), jnp.cumsum(chord)]) / total
    V = u[:, None] ** jnp.arange(degree + 1, dtype=u.dtype)  # Vandermonde, lowest power first
    coeffs, *_ = jnp.linalg.lstsq(V, points)
    curve = PolynomialCurve(coeffs.T, jnp.array([0.0, 1.0], dtype=points.dtype), radius)
    if is_concrete(coeffs):
        warn_if_poor(curve, points, "fit_polynomial_curve")
    return curve
