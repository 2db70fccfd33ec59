"""Actuator lengths of a PCC arm and their inverses: tendons threaded through
spacer disks along the whole arm, and extensible chambers within each segment.

An actuator at distance ``r`` from the backbone and angle ``alpha`` of the
twist-free frame runs, on segment i's arc, a length

    ``c_i(r, alpha) = L_i - theta_i r cos(alpha - a_i)``          (A1)

with ``a_i = phi_1 + ... + phi_i`` (Webster & Jones 2010, eq. 9; valid while
``r |theta_i| < L_i``). A chamber of segment i has length (A1); a tendon
ending at segment i's tip has the sum of (A1) over j <= i. The inverses solve
(A1), linear in ``(L_i, r theta_i cos a_i, r theta_i sin a_i)``, segment by
segment. The derivation is on the documentation's actuators page.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._numerics import safe_norm, solve_small
from ..base._validation import as_float_array, check_configuration, check_finite, is_concrete
from ._layout import ActuatorLayout, check_arrangement

__all__ = [
    "bending_directions",
    "tendon_lengths",
    "chamber_lengths",
    "configuration_from_tendons",
    "configuration_from_chambers",
    "actuator_lengths",
    "configuration_from_lengths",
    "actuator_jacobian",
    "check_bending_radius",
    "check_realisable",
    "length_function",
]

# Relative residual of the least squares (k > 3) above which lengths are not realised by any configuration.
REALISE_TOLERANCE = 1e-9


def bending_directions(q):
    """``a_i = phi_1 + ... + phi_i``: the direction segment i bends towards, measured in the
    twist-free frame carried from the base (module docstring). (n, 3) -> (n,)."""
    return jnp.cumsum(q[:, 2])


def _offset_lengths(q, radius, angles):
    """(A1) for every set of actuators t (radius[t], angles[t]) on every segment j:
    ``C[t, j, m] = L_j - theta_j r_t cos(alpha_tm - a_j)``. (n, 3), (n,), (n, k) -> (n, n, k)."""
    a = bending_directions(q)
    L, theta = q[:, 0], q[:, 1]
    u, v = theta * jnp.cos(a), theta * jnp.sin(a)  # theta (cos a, sin a): smooth in q
    bend = u[None, :, None] * jnp.cos(angles)[:, None, :] + v[None, :, None] * jnp.sin(angles)[:, None, :]
    return L[None, :, None] - radius[:, None, None] * bend


def _tendons(q, radius, angles):
    n = q.shape[0]
    C = _offset_lengths(q, radius, angles)
    through = jnp.arange(n)[None, :] <= jnp.arange(n)[:, None]  # tendon set t runs through segments j <= t
    return jnp.sum(jnp.where(through[:, :, None], C, 0.0), axis=1)


def _chambers(q, radius, angles):
    C = _offset_lengths(q, radius, angles)
    n = q.shape[0]
    return C[jnp.arange(n), jnp.arange(n)]


def _safe_atan2(y, x):
    """atan2 with value and gradient 0 at (0, 0) (double-where shim: no NaN in reverse mode)."""
    zero = (x == 0) & (y == 0)
    return jnp.where(zero, 0.0, jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


def _segment_solve(b, angles):
    """``(L, r u, r v)`` of one segment from its k actuator lengths b: the rows
    ``[1, -cos alpha_m, -sin alpha_m]`` of (A1) solved exactly (k = 3) or by least squares."""
    A = jnp.stack([jnp.ones_like(angles), -jnp.cos(angles), -jnp.sin(angles)], axis=-1)
    if angles.shape[0] == 3:
        return solve_small(A, b)
    return solve_small(A.T @ A, A.T @ b)


def _configuration(y, radius):
    """q from the per-segment ``(L, r u, r v)`` rows y (n, 3)."""
    u, v = y[:, 1] / radius, y[:, 2] / radius
    theta = safe_norm(jnp.stack([u, v], axis=-1))
    a = _safe_atan2(v, u)
    phi = jnp.diff(a, prepend=jnp.zeros((1,), a.dtype))
    phi = jnp.mod(phi + math.pi, 2.0 * math.pi) - math.pi
    return jnp.stack([y[:, 0], theta, phi], axis=-1)


def _from_chambers(lengths, radius, angles):
    y = jax.vmap(_segment_solve)(lengths, angles)
    return _configuration(y, radius)


def _from_tendons(lengths, radius, angles):
    n = lengths.shape[0]
    rows = []
    for t in range(n):  # segment after segment: the proximal segments' share of tendon set t first
        b = lengths[t]
        for j, y in enumerate(rows):
            bend = y[1] * jnp.cos(angles[t]) + y[2] * jnp.sin(angles[t])  # r_j (u_j cos + v_j sin)
            b = b - (y[0] - radius[t] / radius[j] * bend)
        rows.append(_segment_solve(b, angles[t]))
    return _configuration(jnp.stack(rows), radius)


def length_function(kind: str):
    """The plain traceable map ``(q (n, 3), radius (n,), angles (n, k)) -> (n, k)`` of a kind of
    actuator ("tendon" or "chamber"), without the host-side checks: for callers that trace it
    inside their own programs (derivatives along a path)."""
    return _tendons if kind == "tendon" else _chambers


_tendons_jit = package_jit(_tendons, None)
_chambers_jit = package_jit(_chambers, None)
_from_tendons_jit = package_jit(_from_tendons, None)
_from_chambers_jit = package_jit(_from_chambers, None)


def _arrangement(q_or_lengths, radius, angles, n: int):
    """radius (n,), angles (n, k) as arrays of the input's dtype, validated (layout.check_arrangement)."""
    radius, angles = check_arrangement(radius, angles, n)
    dtype = q_or_lengths.dtype
    return radius.astype(dtype), angles.astype(dtype)


def check_bending_radius(q, radius, kind: str) -> None:
    """ValueError unless every actuator lies inside its segment's bending radius,
    ``r |theta_j| < L_j`` for every actuator through segment j (concrete input only).

    Args:
      q: (n, 3) configuration (NumPy or concrete JAX).
      radius: (n,) actuator radius of each segment's actuators.
      kind: "tendon" (the tendons of segments t >= j run through segment j) or "chamber".
    """
    if not (is_concrete(q) and is_concrete(radius)):
        return
    q, radius = np.asarray(q, np.float64), np.asarray(radius, np.float64)
    through = np.maximum.accumulate(radius[::-1])[::-1] if kind == "tendon" else radius
    bad = through * np.abs(q[:, 1]) >= q[:, 0]
    if bad.any():
        j = int(np.argmax(bad))
        raise ValueError(
            f"radius: {through[j]:g} is not inside segment {j}'s bending radius L/|theta| = "
            f"{q[j, 0] / max(abs(q[j, 1]), 1e-300):.4g} (L = {q[j, 0]:.4g}, theta = {q[j, 1]:.4g}); "
            "an actuator there would fold over the backbone's centre of curvature")


def tendon_lengths(q, radius, angles):
    """Length of every tendon from the base: tendon m of segment i ends at segment i's tip
    and runs through segments 1..i, its length the sum of (A1) over them (module docstring).

    Args:
      q: (n, 3) configuration ``[L_i, theta_i, phi_i]``.
      radius: scalar or (n,): the distance of segment i's tendons from the backbone, > 0.
      angles: (k,) or (n, k), k >= 3: the tendons' angles [rad] from the base frame's x axis,
        carried along the backbone without twist (the same for every segment, or per segment).

    Returns:
      (n, k): row i the lengths of segment i's tendons.

    Raises:
      ValueError: bad shapes, fewer than 3 tendons, radius <= 0, angles that do not surround the
        backbone, or (concrete input) a tendon outside a segment's bending radius.
    """
    q = check_configuration(q)
    radius, angles = _arrangement(q, radius, angles, q.shape[0])
    check_bending_radius(q, radius, "tendon")
    return (_tendons_jit if is_concrete(q) else _tendons)(q, radius, angles)


def chamber_lengths(q, radius, angles):
    """Length of every extensible actuator (pneumatic or hydraulic chamber) of every segment:
    (A1), the paper's actuator ``L_0i + l_i`` split among k chambers around the backbone.

    Args:
      q: (n, 3) configuration.
      radius: scalar or (n,), > 0: the chambers' distance from the backbone.
      angles: (k,) or (n, k), k >= 3: their angles [rad] in the twist-free frame.

    Returns:
      (n, k) chamber lengths.

    Raises:
      ValueError: as :func:`tendon_lengths`.
    """
    q = check_configuration(q)
    radius, angles = _arrangement(q, radius, angles, q.shape[0])
    check_bending_radius(q, radius, "chamber")
    return (_chambers_jit if is_concrete(q) else _chambers)(q, radius, angles)


def _check_lengths(lengths, n_k):
    lengths = as_float_array(lengths, "lengths")
    if lengths.ndim != 2 or lengths.shape[1] < 3:
        raise ValueError(f"lengths must have shape (n, k) with k >= 3 actuators per segment; got {lengths.shape}")
    if n_k is not None and lengths.shape != n_k:
        raise ValueError(f"lengths has shape {lengths.shape}; the layout has {n_k[0]} segments of {n_k[1]} actuators")
    check_finite(lengths, "lengths")
    if is_concrete(lengths) and np.any(np.asarray(lengths) <= 0):
        raise ValueError(f"lengths must be > 0; got min {float(np.min(np.asarray(lengths))):g}")
    return lengths


def check_realisable(lengths, q, radius, angles, kind: str, tolerance: float = REALISE_TOLERANCE) -> None:
    """ValueError unless the configuration ``q`` found by an inverse realises ``lengths``: segment
    lengths > 0, every actuator inside its segment's bending radius, and (k > 3) the least-squares
    residual at most ``tolerance`` times the largest length (concrete input only)."""
    if not all(is_concrete(x) for x in (lengths, q, radius, angles)):
        return
    q_np = np.asarray(q, np.float64)
    if not np.all(np.isfinite(q_np)):
        raise ValueError("lengths: no configuration realises them (the solve is singular or overflowed)")
    if np.any(q_np[:, 0] <= 0):
        j = int(np.argmax(q_np[:, 0] <= 0))
        raise ValueError(f"lengths: no configuration realises them: segment {j} would have length "
                         f"L = {q_np[j, 0]:.4g} <= 0 (the {kind}s' lengths are too short for their layout)")
    try:
        check_bending_radius(q_np, np.asarray(radius), kind)
    except ValueError as err:
        raise ValueError(f"lengths: no configuration realises them: {err}") from None
    fn = _tendons_jit if kind == "tendon" else _chambers_jit
    back = np.asarray(fn(jnp.asarray(q), radius, angles))
    scale = float(np.max(np.abs(np.asarray(lengths))))
    residual = float(np.max(np.abs(back - np.asarray(lengths))))
    if residual > tolerance * scale:
        t, m = np.unravel_index(int(np.argmax(np.abs(back - np.asarray(lengths)))), back.shape)
        raise ValueError(f"lengths: no configuration realises them: the closest configuration misses {kind} {m} of "
                         f"segment {t} by {residual:.3g} (more than {tolerance:g} x the largest length; pass a "
                         "larger tolerance for measured lengths)")


def _inverse(lengths, radius, angles, kind: str, tolerance: float):
    """The inverse of a kind's lengths, checked (the two public inverses)."""
    lengths = _check_lengths(lengths, None)
    radius, angles = _arrangement(lengths, radius, angles, lengths.shape[0])
    if angles.shape[1] != lengths.shape[1]:
        raise ValueError(f"lengths has {lengths.shape[1]} {kind}s per segment, angles {angles.shape[1]}")
    if kind == "tendon":
        fn = _from_tendons_jit if is_concrete(lengths) else _from_tendons
    else:
        fn = _from_chambers_jit if is_concrete(lengths) else _from_chambers
    q = fn(lengths, radius, angles)
    check_realisable(lengths, q, radius, angles, kind, tolerance)
    return q


def configuration_from_tendons(lengths, radius, angles, tolerance: float = REALISE_TOLERANCE):
    """The configuration whose tendons have ``lengths`` (the inverse of :func:`tendon_lengths`).

    Exact for k = 3 tendons per segment, least squares for k > 3 (module docstring). Returns
    the configuration with ``theta_i >= 0`` and ``phi_i`` in [-pi, pi) (``a_i = 0`` for a
    straight segment); values and gradients are finite at ``theta = 0``.

    Args:
      lengths: (n, k) tendon lengths from the base, > 0.
      radius, angles: as :func:`tendon_lengths`.
      tolerance: largest least-squares residual (k > 3), relative to the largest length.

    Returns:
      (n, 3) configuration.

    Raises:
      ValueError: bad shapes or values, or (concrete input) lengths no configuration realises.
    """
    return _inverse(lengths, radius, angles, "tendon", tolerance)


def configuration_from_chambers(lengths, radius, angles, tolerance: float = REALISE_TOLERANCE):
    """The configuration whose chambers have ``lengths`` (the inverse of :func:`chamber_lengths`);
    as :func:`configuration_from_tendons`, segment by segment.

    Args:
      lengths: (n, k) chamber lengths, > 0.
      radius, angles: as :func:`chamber_lengths`.
      tolerance: largest least-squares residual (k > 3), relative to the largest length.

    Returns:
      (n, 3) configuration.
    """
    return _inverse(lengths, radius, angles, "chamber", tolerance)


def actuator_lengths(q, layout: ActuatorLayout):
    """The lengths of a layout's actuators: :func:`tendon_lengths` or :func:`chamber_lengths`.
    (n, 3) -> (n, k)."""
    fn = tendon_lengths if layout.kind == "tendon" else chamber_lengths
    return fn(q, layout.radius, layout.angles)


def configuration_from_lengths(lengths, layout: ActuatorLayout, tolerance: float = REALISE_TOLERANCE):
    """The inverse of :func:`actuator_lengths`. (n, k) -> (n, 3)."""
    fn = configuration_from_tendons if layout.kind == "tendon" else configuration_from_chambers
    return fn(lengths, layout.radius, layout.angles, tolerance)


def actuator_jacobian(q, layout: ActuatorLayout):
    """``d lengths / d q`` by ``jax.jacfwd``: (n k, 3 n), lengths and q flattened row-major
    (columns ``L_1, theta_1, phi_1, L_2, ...``)."""
    q = check_configuration(q)
    fn = length_function(layout.kind)
    radius, angles = _arrangement(q, layout.radius, layout.angles, q.shape[0])
    n, k = angles.shape
    return jax.jacfwd(fn)(q, radius, angles).reshape(n * k, 3 * n)
