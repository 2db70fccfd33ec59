"""Shared test helpers (no softplan_jax logic here)."""

from __future__ import annotations

import jax
import numpy as np

import softplan_jax as sp


def assert_allclose(actual, desired, rtol=1e-12, atol=0.0, err_msg=""):
    """np.testing.assert_allclose that also FAILS on any NaN/inf in `actual`.

    (numpy's own helper treats NaN == NaN as equal by default.)
    """
    actual = np.asarray(actual)
    desired = np.asarray(desired)
    bad = ~np.isfinite(actual)
    if bad.any():
        raise AssertionError(
            f"non-finite values in actual at {np.argwhere(bad)[:10].tolist()}: {actual[bad][:10]} {err_msg}"
        )
    if not np.all(np.isfinite(desired)):
        raise AssertionError(f"non-finite values in desired (test bug?) {err_msg}")
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol, equal_nan=False, err_msg=err_msg)


def assert_finite(x, err_msg=""):
    x = np.asarray(x)
    if not np.all(np.isfinite(x)):
        raise AssertionError(f"non-finite values: {x} {err_msg}")


def unpack_stacked(result):
    """Return (curve, mask) from sp.geometry.stack_curves's result.

    The contract says stack_curves returns a PolynomialCurve with stacked
    fields and a bool mask; accept either a ``(curve, mask)`` pair or a curve
    object carrying a ``mask`` attribute.
    """
    if hasattr(result, "coeffs"):
        return result, np.asarray(result.mask)
    curve, mask = result
    return curve, np.asarray(mask)


# The documented per-obstacle form, jax.vmap(lambda c: sp.closest_point(q, c))
# over a stacked PolynomialCurve, jitted once here so that every test file
# with the same shapes shares one compilation.
closest_per_obstacle = jax.jit(lambda q, curves: jax.vmap(lambda c: sp.closest_point(q, c))(curves))
