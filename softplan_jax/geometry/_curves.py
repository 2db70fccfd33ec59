"""Curve-like obstacles ``F_o(u) = [f_x(u), f_y(u), f_z(u)]``, u in [u_min, u_max] (paper eq. 10):
:class:`PolynomialCurve` (coefficients ``(3, K)``, lowest degree first; many stack into one padded
batch, ``(m, 3, K)`` plus a mask, so that scenes share one compiled shape), :class:`ParametricCurve`
(any JAX-traceable ``fn(u) -> (3,)``, derivatives by ``jax.jacfwd``) and :func:`line_segment`. Both
classes are pytrees giving ``point``, ``derivative`` and ``second_derivative`` of a scalar u;
``radius`` is the obstacle's thickness, for clearance only. Curves fitted to point clouds (paper
§2.3: "derived from a set of points ... using regression") are made in :mod:`softplan_jax.clouds`."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..base._validation import (
    as_float_array,
    check_finite,
    check_radius,
    check_scale,
    check_u_range,
    host_array,
    is_concrete,
    max_coordinate,
)

# Samples of a ParametricCurve checked for finite values at construction.
_FINITE_CHECK_SAMPLES = 257

__all__ = [
    "PolynomialCurve",
    "ParametricCurve",
    "line_segment",
    "stack_curves",
    "curve_points",
    "taylor_coefficients",
    "check_curve_scale",
]


# Degrees up to this are evaluated by Horner's rule written out term by term (one
# multiply-add per coefficient in the traced program); higher degrees by one product
# with the power basis (:func:`_powers`), whose program does not grow with the degree.
# The two agree to rounding; the split keeps the low-degree scenes (the paper's, random
# suites, fits up to their default max_degree 8) on Horner's arithmetic, bit for bit.
HORNER_MAX_DEGREE = 8


def _polyval(coeffs, u):
    """sum_k coeffs[..., k] u**k for a scalar u; coeffs (..., K)."""
    K = coeffs.shape[-1]
    if K > HORNER_MAX_DEGREE + 1:
        return coeffs @ _powers(jnp.asarray(u, coeffs.dtype), K)
    acc = coeffs[..., -1]
    for k in range(K - 2, -1, -1):
        acc = acc * u + coeffs[..., k]
    return acc


def check_curve_scale(coeffs, u_range, radius, dtype, name: str = "coeffs") -> None:
    """A ValueError (starting with ``name``) when a concrete polynomial curve reaches values
    beyond :func:`~softplan_jax.base._validation.max_coordinate` of ``dtype`` over its range:
    ``sum_k |a_k| R^k`` (R = max |u| over the range) for the curve and its first two
    derivatives, the u-range itself and the radius. Squared distances to it would overflow."""
    if not (is_concrete(coeffs) and is_concrete(u_range)):
        return
    c = np.abs(np.asarray(coeffs, np.float64))
    R = float(np.max(np.abs(np.asarray(u_range, np.float64)), initial=0.0))
    check_scale(u_range, "u_range", dtype, "values")
    check_scale(radius, "radius", dtype, "values")
    k = np.arange(c.shape[-1], dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        powers = R ** k  # R^k, k = 0 .. K-1 (0^0 = 1)
        bounds = [np.sum(c * powers, axis=-1),
                  np.sum((c * k)[..., 1:] * powers[:-1], axis=-1),
                  np.sum((c * k * (k - 1))[..., 2:] * powers[:-2], axis=-1)]
    limit = max_coordinate(dtype)
    for order, b in enumerate(bounds):
        worst = float(np.max(b, initial=0.0))
        if not worst <= limit:  # NaN (inf * 0) counts as too large
            what = ("values", "first derivative", "second derivative")[order]
            if not np.isfinite(worst):
                raise ValueError(f"{name}: the curve's coefficients or u_range are not finite (NaN or inf)")
            raise ValueError(f"{name}: over its u_range the curve reaches {what} up to about {worst:.3g}, beyond the "
                             f"{limit:.2g} that {np.dtype(dtype).name} planning takes (squared distances would "
                             "overflow); rescale the curve or its parameter range")


@partial(jax.custom_jvp, nondiff_argnums=(1,))
def _powers(x, K: int):
    """(K,) the powers x^0 .. x^(K - 1) of a scalar by a cumulative product: one
    reduce_window whatever K (a derivative rule of the same size: d x^k = k x^(k-1) dx)."""
    return jnp.concatenate([jnp.ones((1,), x.dtype), jnp.cumprod(jnp.full((K - 1,), x))])


@_powers.defjvp
def _powers_jvp(K, primals, tangents):
    (x,), (dx,) = primals, tangents
    p = _powers(x, K)
    k = jnp.arange(1, K, dtype=p.dtype)
    return p, jnp.concatenate([jnp.zeros((1,), p.dtype), k * p[:-1]]) * dx


def _polyder(coeffs):
    """Coefficients of the u-derivative, same length K (last column zero)."""
    K = coeffs.shape[-1]
    if K == 1:
        return jnp.zeros_like(coeffs)
    k = jnp.arange(1, K, dtype=coeffs.dtype)
    d = coeffs[..., 1:] * k
    return jnp.concatenate([d, jnp.zeros_like(coeffs[..., :1])], axis=-1)


def taylor_coefficients(coeffs, c):
    """Coefficients of ``p(c + t)`` in t, lowest first, for ``p(u) = sum_k coeffs[..., k] u**k``:
    ``t_j = sum_{k >= j} C(k, j) c^(k - j) coeffs[..., k]`` (the Taylor shift), one matrix
    product whatever the degree. coeffs (..., K), c a scalar; returns (..., K)."""
    K = coeffs.shape[-1]
    j, k = np.indices((K, K))
    upper = k >= j
    binom = np.where(upper, np.vectorize(math.comb)(np.maximum(k, j), j), 0).astype(float)
    pw = _powers(jnp.asarray(c, coeffs.dtype), K)[np.where(upper, k - j, 0)]  # (j, k): c^(k - j)
    return coeffs @ (jnp.asarray(binom, coeffs.dtype) * pw).T


@jax.tree_util.register_pytree_node_class
class PolynomialCurve:
    """``F_o(u) = sum_k coeffs[:, k] u**k`` for u in ``u_range`` (paper eq. 10).

    Args:
      coeffs: (3, K) — row 0 is X(u), row 1 Y(u), row 2 Z(u); column k
        multiplies ``u**k``. A stacked batch has shape (m, 3, K) (see
        :func:`stack_curves`).
      u_range: (u_min, u_max), u_min < u_max.
      radius: obstacle radius (>= 0) used for clearance; default 0.
    """

    def __init__(self, coeffs, u_range, radius=0.0):
        coeffs = as_float_array(coeffs, "coeffs")
        if coeffs.ndim < 2 or coeffs.shape[-2] != 3 or coeffs.shape[-1] < 1:
            raise ValueError(
                "coeffs must have shape (3, K) (rows X, Y, Z; column k multiplies u**k, "
                f"K >= 1); got shape {coeffs.shape}"
            )
        check_finite(coeffs, "coeffs")
        u_range = check_u_range(u_range)
        if u_range.shape[:-1] != coeffs.shape[:-2]:
            raise ValueError(
                f"u_range batch shape {u_range.shape[:-1]} does not match coeffs batch "
                f"shape {coeffs.shape[:-2]}"
            )
        radius = check_radius(radius)
        dtype = jnp.result_type(coeffs.dtype, u_range.dtype)
        check_curve_scale(coeffs, u_range, radius, dtype)
        self.coeffs = coeffs.astype(dtype)
        self.u_range = u_range.astype(dtype)
        self.radius = jnp.broadcast_to(radius, coeffs.shape[:-2]).astype(dtype)

    # pytree protocol: unflattening bypasses validation (leaves may be tracers
    # or placeholders inside jax transformations).
    def tree_flatten(self):
        return (self.coeffs, self.u_range, self.radius), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        obj.coeffs, obj.u_range, obj.radius = children
        return obj

    @property
    def degree(self) -> int:
        """Polynomial degree of the padded coefficient array (K - 1)."""
        return self.coeffs.shape[-1] - 1

    def point(self, u):
        """F_o(u), (3,)."""
        return _polyval(self.coeffs, u)

    def derivative(self, u):
        """dF_o/du, (3,)."""
        return _polyval(_polyder(self.coeffs), u)

    def second_derivative(self, u):
        """d^2F_o/du^2, (3,)."""
        return _polyval(_polyder(_polyder(self.coeffs)), u)

    def second_derivative_bound(self, a, b):
        """A bound on |F_o''| over [a, b] (one curve): the Taylor expansion of F_o'' at
        the centre c, term by term, ``sum_j |F_o^(2+j)(c)| (h/2)^j / j!`` (h = b - a;
        exact for degree <= 2, where F_o'' is constant). The derivatives at c come from
        the Taylor coefficients of F_o at c (:func:`taylor_coefficients`, one matrix
        product), so the program's size does not grow with the degree."""
        c, r = 0.5 * (a + b), 0.5 * (b - a)
        bound = jnp.sqrt(jnp.sum(self.second_derivative(c) ** 2))
        K = self.coeffs.shape[-1]
        if K <= 3:
            return bound
        # |F_o^(2+j)(c)| / j! = (j + 2)(j + 1) |t_{j+2}|, t the Taylor coefficients at c, j >= 1.
        t = taylor_coefficients(self.coeffs, c)[..., 3:]  # (3, K - 3): j = 1 .. K - 3
        j = np.arange(1, K - 2)
        weight = jnp.asarray((j + 2.0) * (j + 1.0), t.dtype)
        r_pow = _powers(r, K - 2)[1:]  # r^j, j = 1 .. K - 3
        return bound + jnp.sum(weight * jnp.sqrt(jnp.sum(t * t, axis=-2)) * r_pow)

    def with_radius(self, radius):
        """The same curves with another radius (unvalidated: works on tracers)."""
        return PolynomialCurve.tree_unflatten(None, [self.coeffs, self.u_range, radius])

    def astype(self, dtype):
        return PolynomialCurve.tree_unflatten(
            None, [jnp.asarray(x, dtype) for x in self.tree_flatten()[0]]
        )

    def __repr__(self):
        return f"PolynomialCurve(coeffs={self.coeffs!r}, u_range={self.u_range!r}, radius={self.radius!r})"


@jax.tree_util.register_pytree_node_class
class ParametricCurve:
    """Any JAX-traceable curve ``fn(u) -> (3,)`` on ``u_range``.

    Derivatives in u come from ``jax.jacfwd``. The function is static (part of
    the pytree structure): two ParametricCurves with different functions
    compile separately.

    Example: a helix ``ParametricCurve(lambda u: jnp.stack([jnp.cos(u),
    jnp.sin(u), 0.2 * u]), (0.0, 6.0))``.
    """

    def __init__(self, fn: Callable, u_range, radius=0.0):
        if not callable(fn):
            raise ValueError(f"fn must be a callable u -> (3,), got {type(fn).__name__}")
        u_range = check_u_range(u_range)
        if u_range.shape != (2,):
            raise ValueError(f"u_range of a ParametricCurve must have shape (2,); got {u_range.shape}")
        radius = check_radius(radius)
        if jnp.ndim(radius) != 0:
            raise ValueError(f"radius of a ParametricCurve must be a scalar; got shape {jnp.shape(radius)}")
        try:
            out = jax.eval_shape(fn, jax.ShapeDtypeStruct((), u_range.dtype))
        except Exception as err:  # noqa: BLE001 - any failure to trace is a bad fn
            raise ValueError(f"fn could not be traced with a scalar u: {type(err).__name__}: {err}") from None
        if not hasattr(out, "shape") or tuple(out.shape) != (3,):
            shape = getattr(out, "shape", type(out).__name__)
            raise ValueError(f"fn(u) must return 3 values [X, Y, Z] (shape (3,)); got {shape}")
        if not jnp.issubdtype(out.dtype, jnp.floating):
            raise ValueError(f"fn(u) must return floating values; got dtype {out.dtype}")
        if is_concrete(u_range):
            # A sampled check: a curve that is NaN or infinite somewhere in its range would make
            # every distance to it NaN (and a NaN clearance is never "clear").
            u = jnp.linspace(u_range[0], u_range[1], _FINITE_CHECK_SAMPLES, dtype=u_range.dtype)
            pts = np.asarray(jax.vmap(fn)(u))
            bad = ~np.all(np.isfinite(pts), axis=-1)
            if bad.any():
                raise ValueError(
                    f"fn(u) is not finite inside u_range at u = {float(u[np.argmax(bad)]):.6g} "
                    f"({int(bad.sum())} of {_FINITE_CHECK_SAMPLES} samples); "
                    "restrict u_range to where the curve is defined"
                )
        self.fn = fn
        self.u_range = u_range
        self.radius = radius.astype(u_range.dtype)

    def tree_flatten(self):
        return (self.u_range, self.radius), self.fn

    @classmethod
    def tree_unflatten(cls, fn, children):
        obj = object.__new__(cls)
        obj.fn = fn
        obj.u_range, obj.radius = children
        return obj

    def point(self, u):
        return jnp.asarray(self.fn(u), dtype=jnp.result_type(u))

    def derivative(self, u):
        return jax.jacfwd(self.point)(u)

    def second_derivative(self, u):
        return jax.jacfwd(jax.jacfwd(self.point))(u)

    def astype(self, dtype):
        return ParametricCurve.tree_unflatten(
            self.fn, [jnp.asarray(self.u_range, dtype), jnp.asarray(self.radius, dtype)]
        )

    def __repr__(self):
        return f"ParametricCurve(fn={self.fn!r}, u_range={self.u_range!r}, radius={self.radius!r})"


def line_segment(a, b, radius=0.0) -> PolynomialCurve:
    """The straight segment from ``a`` (u = 0) to ``b`` (u = 1) as a degree-1 curve."""
    a = as_float_array(a, "a")
    b = as_float_array(b, "b")
    if a.shape != (3,) or b.shape != (3,):
        raise ValueError(f"line_segment endpoints must have shape (3,); got {a.shape} and {b.shape}")
    check_finite(a, "a")
    check_finite(b, "b")
    if is_concrete(a) and is_concrete(b) and np.array_equal(np.asarray(a), np.asarray(b)):
        raise ValueError(f"line_segment: a and b are the same point {np.asarray(a).tolist()}; a segment needs length > 0 "
                         "(use a point obstacle, an (1, 3) array, for a single point)")
    return PolynomialCurve(jnp.stack([a, b - a], axis=1), jnp.array([0.0, 1.0], dtype=a.dtype), radius)


def stack_curves(curves, size: int | None = None, degree: int | None = None):
    """Stack polynomial curves into one padded batch.

    Args:
      curves: sequence of single :class:`PolynomialCurve` (may be empty when
        ``size`` is given).
      size: number of obstacle slots m (>= len(curves)); default len(curves).
      degree: padded degree (>= every curve's degree); default the largest.

    Returns:
      ``(batch, mask)``: a PolynomialCurve with coeffs (m, 3, degree + 1),
      u_range (m, 2) and radius (m,), and a bool mask (m,) that is False for
      padding slots (whose coefficients are zero and u_range (0, 1)).
    """
    curves = list(curves)
    for k, c in enumerate(curves):
        if not isinstance(c, PolynomialCurve) or c.coeffs.ndim != 2:
            raise ValueError(
                f"curves[{k}] is {type(c).__name__}; only single PolynomialCurves can be stacked "
                "(ParametricCurves are planned one by one)"
            )
    size = len(curves) if size is None else int(size)
    if size < len(curves):
        raise ValueError(f"size = {size} must be >= the number of curves ({len(curves)})")
    max_deg = max((c.degree for c in curves), default=0)
    degree = max_deg if degree is None else int(degree)
    if degree < max_deg:
        raise ValueError(f"degree = {degree} is smaller than the largest curve degree {max_deg}")
    dtype = jnp.result_type(*[c.coeffs.dtype for c in curves]) if curves else jnp.result_type(float)
    coeffs = np.zeros((size, 3, degree + 1))
    u_range = np.tile(np.array([0.0, 1.0]), (size, 1))
    radius = np.zeros(size)
    mask = np.zeros(size, dtype=bool)
    for k, c in enumerate(curves):
        coeffs[k, :, : c.degree + 1] = np.asarray(c.coeffs)
        u_range[k] = np.asarray(c.u_range)
        radius[k] = float(c.radius)
        mask[k] = True
    batch = PolynomialCurve.tree_unflatten(
        None, [host_array(coeffs, dtype), host_array(u_range, dtype), host_array(radius, dtype)]
    )
    return batch, host_array(mask)


def curve_points(curve, n_points: int):
    """N points evenly spaced in u: N = 1 the middle of the range, N >= 2 both ends.

    This is the obstacle model of the N-point method (paper §3). Returns (N, 3).
    """
    n_points = int(n_points)
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    u0, u1 = curve.u_range[..., 0], curve.u_range[..., 1]
    if n_points == 1:
        u = jnp.reshape(0.5 * (u0 + u1), (1,))
    else:
        u = u0 + (u1 - u0) * jnp.linspace(0.0, 1.0, n_points, dtype=curve.u_range.dtype)
    return jax.vmap(curve.point)(u)
