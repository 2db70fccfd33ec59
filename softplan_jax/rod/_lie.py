"""SO(3) and SE(3) exponentials for the rod's integrator, smooth at the identity: the ratios
``sin x / x``, ``(1 - cos x) / x^2`` and ``(x - sin x) / x^3`` are taken as functions of
``x^2`` (a Taylor series below a dtype-dependent threshold, the closed form above it behind the
double-where shim), so values and derivatives of every order are finite and correct at a
straight rod (Murray, Li & Sastry 1994, sec. 2.2-2.3; jaxlie ``_so3.py``)."""

from __future__ import annotations

import jax.numpy as jnp

from ..base._numerics import series_threshold

__all__ = ["hat", "so3_exp", "se3_exp", "se3_bracket", "arc_rotation_vector"]

# Taylor coefficients in powers of x^2, highest first (Horner):
# sin x / x = 1 - x^2/3! + ...; (1 - cos x)/x^2 = 1/2! - x^2/4! + ...; (x - sin x)/x^3 = 1/3! - x^2/5! + ...
_A = (1 / 362880, -1 / 5040, 1 / 120, -1 / 6, 1.0)
_B = (1 / 3628800, -1 / 40320, 1 / 720, -1 / 24, 1 / 2)
_C = (1 / 39916800, -1 / 362880, 1 / 5040, -1 / 120, 1 / 6)


def _series(coeffs, x2):
    acc = jnp.zeros_like(x2) + coeffs[0]
    for c in coeffs[1:]:
        acc = acc * x2 + c
    return acc


def _ratios(x2):
    """``(sin x / x, (1 - cos x)/x^2, (x - sin x)/x^3)`` of ``x = sqrt(x2)``, smooth in x2."""
    thr = series_threshold(x2.dtype)
    small = x2 < thr * thr
    x = jnp.sqrt(jnp.where(small, jnp.ones_like(x2), x2))  # double-where: no sqrt(0) in either mode
    s, h = jnp.sin(x), jnp.sin(0.5 * x)
    A = jnp.where(small, _series(_A, x2), s / x)
    B = jnp.where(small, _series(_B, x2), 2.0 * h * h / (x * x))
    C = jnp.where(small, _series(_C, x2), (x - s) / (x * x * x))
    return A, B, C


def hat(w):
    """The skew matrix ``[w]x`` (3, 3) of a (3,) vector: ``hat(a) @ b = a x b``."""
    z = jnp.zeros_like(w[0])
    return jnp.stack([jnp.stack([z, -w[2], w[1]]), jnp.stack([w[2], z, -w[0]]), jnp.stack([-w[1], w[0], z])])


def so3_exp(w):
    """Rodrigues' formula: the rotation (3, 3) by the rotation vector w (3,)."""
    A, B, _ = _ratios(jnp.dot(w, w))
    W = hat(w)
    return jnp.eye(3, dtype=w.dtype) + A * W + B * (W @ W)


def se3_exp(xi):
    """The SE(3) exponential of a body twist xi = (omega, v) (6,): ``(R (3, 3), p (3,))`` with
    ``R = exp([omega])`` and ``p = J(omega) v``, ``J = I + B [omega] + C [omega]^2`` (Murray, Li &
    Sastry 1994, eq. 2.36): exact for a rod piece of constant curvature ``omega`` and tangent ``v``."""
    w, v = xi[:3], xi[3:]
    A, B, C = _ratios(jnp.dot(w, w))
    W = hat(w)
    W2 = W @ W
    eye = jnp.eye(3, dtype=xi.dtype)
    return eye + A * W + B * W2, (eye + B * W + C * W2) @ v


def se3_bracket(a, b):
    """The Lie bracket of se(3): ``[(w1, v1), (w2, v2)] = (w1 x w2, w1 x v2 - w2 x v1)`` (6,)."""
    w1, v1, w2, v2 = a[:3], a[3:], b[:3], b[3:]
    return jnp.concatenate([jnp.cross(w1, w2), jnp.cross(w1, v2) - jnp.cross(w2, v1)])


def arc_rotation_vector(a, b):
    """The rotation vector (3,) of the shortest rotation taking unit vector a to unit vector b:
    ``(a x b) angle / sin(angle)``, smooth in (a, b) where they are not opposite (angle < pi).
    ``angle / sin(angle) = 1 / (sin x / x)`` with ``x`` the angle, from ``x^2 = atan2(|a x b|, a . b)^2``."""
    c = jnp.cross(a, b)
    s2 = jnp.dot(c, c)
    cos = jnp.dot(a, b)
    # angle^2 as a smooth function of s2 near 0: angle = atan2(s, cos); for s2 -> 0, angle ~ s / cos.
    thr = 1e-3 if s2.dtype == jnp.float64 else 0.05  # the atan series below is accurate to eps there
    small = (s2 < thr * thr) & (cos > 0)
    s = jnp.sqrt(jnp.where(small, jnp.ones_like(s2), s2))
    angle = jnp.arctan2(s, cos)
    ratio_closed = angle / s  # angle / sin(angle)
    # atan(t)/t with t = s / cos, series in t^2: 1 - t^2/3 + t^4/5 - t^6/7 + t^8/9 (cos > 0 when small)
    t2 = s2 / (cos * cos)
    ratio_series = _series((1 / 9, -1 / 7, 1 / 5, -1 / 3, 1.0), t2) / cos
    return c * jnp.where(small, ratio_series, ratio_closed)
