"""Host-side checks of user input, raising ``ValueError`` with a clear message
(not part of the paper's method: the boundary of every public function).

Shapes are always checked (they are static under ``jit``); values (finite,
positive lengths, ordered ranges) are checked only when the input is concrete,
i.e. not a tracer inside ``jit``/``vmap``/``grad``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "is_concrete",
    "as_float_array",
    "check_finite",
    "check_configuration",
    "check_segment_index",
    "check_fraction",
    "check_u_range",
    "check_points",
    "check_radius",
    "check_cloud",
    "max_coordinate",
    "check_scale",
    "MAX_ANGLE",
    "check_int",
    "check_bool",
    "check_number",
]

# Largest |theta|, |phi| of a configuration [rad]: beyond it the planner's products of
# lengths and angles lose every digit (and overflow for extreme values).
MAX_ANGLE = 1e6


def max_coordinate(dtype) -> float:
    """The largest coordinate, length or radius the planner takes in ``dtype``: 1e-4 sqrt(max),
    so that squared distances and their sums never overflow (1.3e150 in float64, 1.8e15 in
    float32)."""
    return float(np.sqrt(np.finfo(np.dtype(dtype)).max)) * 1e-4


def check_scale(x, name: str, dtype, what: str = "coordinates") -> None:
    """A ValueError (message starting with ``name``) when a concrete ``x`` holds a value beyond
    :func:`max_coordinate` of ``dtype`` (inf allowed only where the caller filtered it)."""
    if not is_concrete(x):
        return
    arr = np.abs(np.asarray(x, np.float64))
    if arr.size and float(np.max(arr)) > max_coordinate(dtype):
        raise ValueError(
            f"{name} has {what} up to {float(np.max(arr)):.3g}, beyond the {max_coordinate(dtype):.2g} that "
            f"{np.dtype(dtype).name} planning takes (squared distances would overflow); rescale the scene"
        )


def check_int(value, name: str, minimum: int | None = None) -> int:
    """``value`` as an int; a ValueError naming ``name`` for anything but an int (a bool,
    2.5 and "8" are not) or an int below ``minimum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or (
            minimum is not None and value < minimum):
        raise ValueError(f"{name} must be an int{'' if minimum is None else f' >= {minimum}'}, got {value!r}")
    return int(value)


def check_bool(value, name: str) -> bool:
    """``value`` as a bool; a ValueError naming ``name`` for anything but True or False."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_number(value, name: str, low: float = -np.inf, strict: bool = False) -> float:
    """``value`` as a finite float ``>= low`` (``> low`` when ``strict``); a ValueError naming
    ``name`` for a bool, a string, a non-finite number or one out of range."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not np.isfinite(value) or value < low or (strict and value == low):
        bound = "" if low == -np.inf else f" {'>' if strict else '>='} {low:g}"
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    return float(value)


def is_concrete(x) -> bool:
    """True when ``x`` holds actual values (not a JAX tracer)."""
    return not isinstance(x, jax.core.Tracer)


def host_array(x, dtype=None):
    """``x`` (a NumPy array, nested lists, a NumPy scalar) as a JAX array of ``dtype`` (None: x's
    own, canonicalised as jax does), by a transfer (``jax.device_put``): ``jnp.asarray`` compiles a
    small program for each new shape and dtype, about 15 ms each on a CPU, which the host path of a
    first plan pays many times."""
    return jax.device_put(np.asarray(x, dtype))


def as_float_array(x, name: str):
    """``x`` as a floating JAX array (integers become the default float dtype)."""
    if isinstance(x, jax.core.Tracer):
        return x if jnp.issubdtype(x.dtype, jnp.floating) else x.astype(float)
    fast = _real_host_array(x)
    if fast is not None:
        return fast
    try:
        arr = jnp.asarray(x)
    except OverflowError:  # a Python int beyond 64 bits
        raise ValueError(f"{name} holds an integer too large for an array (beyond 64 bits)") from None
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a numeric array, got {type(x).__name__}: {err}") from None
    if not (jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer)):
        raise ValueError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    if not jnp.issubdtype(arr.dtype, jnp.floating):
        arr = arr.astype(jnp.result_type(float))
    return arr


def _real_host_array(x):
    """``x`` as a floating JAX array by :func:`host_array`, where x is a NumPy array, a NumPy
    scalar or nested lists of real numbers (integers converted in NumPy, as jax converts them);
    None for anything else (a JAX array, a Python scalar, which jax keeps weakly typed, or what
    :func:`as_float_array`'s errors are for)."""
    if isinstance(x, (jax.Array, int, float, bool, complex)):
        return None
    try:
        host = np.asarray(x)
    except (TypeError, ValueError, OverflowError):
        return None
    if host.dtype.kind == "f" and host.dtype.itemsize <= 8:
        return host_array(host)
    if host.dtype.kind in "iu":
        return host_array(host, jnp.result_type(float))
    return None


def check_finite(x, name: str) -> None:
    if is_concrete(x) and not bool(np.all(np.isfinite(np.asarray(x)))):
        raise ValueError(f"{name} contains non-finite values (NaN or inf): {np.asarray(x)!r}")


def check_configuration(q):
    """Validate a configuration ``q`` of shape (n, 3), rows [L_i, theta_i, phi_i].

    Returns the configuration as a float array.
    """
    q = as_float_array(q, "q")
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(
            f"q must have shape (n, 3) with rows [L_i, theta_i, phi_i]; got shape {q.shape}"
        )
    if q.shape[0] < 1:
        raise ValueError("q must describe at least one segment (n >= 1); got n = 0")
    if is_concrete(q):
        check_finite(q, "q")
        check_scale(np.asarray(q)[:, 0], "q", q.dtype, "segment lengths")
        angles = np.abs(np.asarray(q, np.float64)[:, 1:])
        if angles.size and float(angles.max()) > MAX_ANGLE:
            raise ValueError(f"q has angles theta/phi up to {float(angles.max()):.3g} rad, beyond {MAX_ANGLE:g} rad: "
                             "give angles in radians, reduced modulo 2 pi")
        lengths = np.asarray(q)[:, 0]
        if np.any(lengths <= 0):
            bad = [int(k) for k in np.nonzero(lengths <= 0)[0]]
            raise ValueError(
                f"segment lengths L_i must be > 0; got L = {lengths.tolist()} (bad segments {bad})"
            )
    return q


def check_segment_index(i, n: int):
    if is_concrete(i):
        i_arr = np.asarray(i)
        if i_arr.ndim != 0 or not np.issubdtype(i_arr.dtype, np.integer):
            raise ValueError(f"segment index i must be an integer scalar, got {i!r}")
        if not 0 <= int(i_arr) < n:
            raise ValueError(f"segment index i = {int(i_arr)} is out of range for n = {n} segments")
    return i


def check_fraction(s):
    s = as_float_array(s, "s")
    if s.ndim != 0:
        raise ValueError(f"s must be a scalar fraction of the segment, got shape {s.shape}")
    check_finite(s, "s")
    if is_concrete(s) and not 0.0 <= float(s) <= 1.0:
        raise ValueError(f"s is a fraction of the segment and must lie in [0, 1]; got {float(s)}")
    return s


def check_u_range(u_range, name: str = "u_range"):
    """Validate a parameter range ``(u_min, u_max)`` with u_min < u_max, both finite."""
    u_range = as_float_array(u_range, name)
    if u_range.shape[-1:] != (2,):
        raise ValueError(f"{name} must be (u_min, u_max); got shape {u_range.shape}")
    if is_concrete(u_range):
        arr = np.asarray(u_range)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite; got {arr.tolist()}")
        if np.any(arr[..., 0] >= arr[..., 1]):
            if np.any(arr[..., 0] == arr[..., 1]):
                raise ValueError(f"{name} is empty (u_min == u_max); got {arr.tolist()}")
            raise ValueError(f"{name} is reversed (u_min > u_max); got {arr.tolist()}")
    return u_range


def check_points(points, name: str = "points"):
    """Validate an (N, 3) point set with N >= 1."""
    points = as_float_array(points, name)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3); got shape {points.shape}")
    if points.shape[0] == 0:
        raise ValueError(f"{name} is empty: a point-set obstacle needs at least one point")
    check_finite(points, name)
    return points


def check_radius(radius, name: str = "radius"):
    radius = as_float_array(radius, name)
    if is_concrete(radius):
        arr = np.asarray(radius)
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"{name} must be finite and >= 0; got {arr.tolist()}")
    return radius


# Largest |coordinate| of a cloud to fit: squared distances of larger ones overflow float64 (1.8e308).
_CLOUD_MAX_COORDINATE = 1e150


def check_cloud(points, name: str = "points") -> np.ndarray:
    """Validate a point cloud: a finite (N, 3) array of numbers, not all one point.

    Returns it as float64 NumPy (fits run on the host in float64).
    """
    try:
        arr = np.asarray(points)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be an (N, 3) array of numbers: {err}") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name} must be an (N, 3) array of real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (one row x, y, z per point); got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} is empty: a point cloud needs points")
    arr = arr.astype(np.float64)
    bad = ~np.all(np.isfinite(arr), axis=1)
    if not bad.any() and arr.size:
        big = float(np.max(np.abs(arr)))
        if big > _CLOUD_MAX_COORDINATE:
            raise ValueError(
                f"{name} has coordinates up to {big:.3g}: a fit squares distances, which overflow float64 "
                f"beyond about {_CLOUD_MAX_COORDINATE:.0e}; rescale the cloud (e.g. to metres) first"
            )
    if bad.any():
        rows = np.nonzero(bad)[0]
        shown = ", ".join(str(int(r)) for r in rows[:10]) + (", ..." if rows.size > 10 else "")
        raise ValueError(
            f"{name} has {rows.size} row(s) with NaN or inf (rows {shown}); drop them first, e.g. "
            "points[np.isfinite(points).all(axis=1)]"
        )
    extent = float(np.max(np.ptp(arr, axis=0)))
    scale = float(np.max(np.abs(arr)))
    if extent <= 1e-12 * max(scale, 1.0):
        raise ValueError(f"{name}: all {arr.shape[0]} points are identical: no curve can be fitted")
    return arr
