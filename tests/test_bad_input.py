"""Bad input is rejected on the host with a ValueError that says what is wrong."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp

GOOD_Q = np.array([[1.0, 0.3, 0.1], [1.0, 0.0, 2.0]])
GOOD_CURVE_COEFFS = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]])
GOOD_POINTS = np.array([[1.0, 0.0, 0.5], [1.0, 1.0, -0.5]])


def good_curve():
    return sp.PolynomialCurve(jnp.asarray(GOOD_CURVE_COEFFS), (-2.0, 2.0))


# every public function that takes a configuration q, as q -> result
Q_CONSUMERS = {
    "segment_point": lambda q: sp.geometry.segment_point(q, 0, 0.5),
    "point_jacobian": lambda q: sp.geometry.point_jacobian(q, 0, 0.5),
    "tip_position": sp.tip_position,
    "tip_jacobian": sp.geometry.tip_jacobian,
    "segment_frames": sp.geometry.segment_frames,
    "backbone_points": sp.geometry.backbone_points,
    "closest_point": lambda q: sp.closest_point(q, good_curve()),
    "closest_point_to_points": lambda q: sp.geometry.closest_point_to_points(q, jnp.asarray(GOOD_POINTS)),
}


def raises_value_error(fn, *patterns):
    """fn() must raise ValueError whose message matches every regex pattern."""
    with pytest.raises(ValueError) as info:
        fn()
    msg = str(info.value)
    assert msg.strip(), "empty ValueError message"
    for p in patterns:
        assert re.search(p, msg, flags=re.IGNORECASE), f"message {msg!r} does not match {p!r}"
    return msg


def _shape_pattern(shape):
    # the message should show the offending shape, e.g. "(2, 4)"
    return re.escape(str(tuple(shape)))


# --------------------------------------------------------------------------
# configurations
# --------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(Q_CONSUMERS))
@pytest.mark.parametrize("shape", [(3,), (2, 2), (2, 4), (1, 2, 3), (3, 1)])
def test_q_wrong_shape(name, shape):
    q = jnp.ones(shape)
    raises_value_error(lambda: Q_CONSUMERS[name](q), r"\bq\b", _shape_pattern(shape))


@pytest.mark.parametrize("name", sorted(Q_CONSUMERS))
def test_q_no_segments(name):
    q = jnp.zeros((0, 3))
    raises_value_error(lambda: Q_CONSUMERS[name](q), r"segment|n\s*(=|>=|≥)|empty|at least")


@pytest.mark.parametrize("name", sorted(Q_CONSUMERS))
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("where", [(0, 0), (1, 1), (1, 2)])
def test_q_non_finite(name, bad, where):
    q = GOOD_Q.copy()
    q[where] = bad
    raises_value_error(lambda: Q_CONSUMERS[name](jnp.asarray(q)), r"nan|inf|finite")


@pytest.mark.parametrize("name", sorted(Q_CONSUMERS))
@pytest.mark.parametrize("L", [0.0, -0.5, -1e-12])
def test_q_non_positive_length(name, L):
    q = GOOD_Q.copy()
    q[1, 0] = L
    raises_value_error(lambda: Q_CONSUMERS[name](jnp.asarray(q)), r"length|\bL(_i)?\b")


def test_q_wrong_shape_under_jit():
    # shapes are static: the error must also come out of jit tracing
    with pytest.raises(ValueError):
        jax.jit(sp.tip_position)(jnp.ones((2, 4)))
    with pytest.raises(ValueError):
        jax.jit(lambda q: sp.closest_point(q, good_curve()).distance)(jnp.ones((3,)))


def test_segment_transform_wrong_shape():
    raises_value_error(lambda: sp.geometry.segment_transform(jnp.ones((2, 3))), r"shape|\(3,\)")
    raises_value_error(lambda: sp.geometry.segment_transform(jnp.asarray([0.0, 0.1, 0.2])), r"length|\bL")
    raises_value_error(lambda: sp.geometry.segment_transform(jnp.asarray([1.0, np.nan, 0.2])), r"nan|finite")


# --------------------------------------------------------------------------
# segment index
# --------------------------------------------------------------------------


@pytest.mark.parametrize("fn", [sp.geometry.segment_point, sp.geometry.point_jacobian])
@pytest.mark.parametrize("i", [2, 3, 17, -1, -3])
def test_unknown_segment_index(fn, i):
    # GOOD_Q has 2 segments, indices 0 and 1 (0-based, no Python wrap-around)
    raises_value_error(lambda: fn(jnp.asarray(GOOD_Q), i, 0.5), r"segment|index", re.escape(str(i)))


# --------------------------------------------------------------------------
# curves
# --------------------------------------------------------------------------

BAD_RANGES = {
    "reversed": (1.0, -1.0),
    "empty": (0.5, 0.5),
    "nan": (np.nan, 1.0),
    "inf": (0.0, np.inf),
    "-inf": (-np.inf, 0.0),
}


@pytest.mark.parametrize("kind", sorted(BAD_RANGES))
def test_polynomial_curve_bad_u_range(kind):
    raises_value_error(
        lambda: sp.PolynomialCurve(jnp.asarray(GOOD_CURVE_COEFFS), BAD_RANGES[kind]),
        r"u_range|u_min|u_max|range",
    )


@pytest.mark.parametrize("kind", sorted(BAD_RANGES))
def test_parametric_curve_bad_u_range(kind):
    def fn(u):
        return jnp.stack([u, 2 * u, 1.0 + 0 * u])

    raises_value_error(lambda: sp.ParametricCurve(fn, BAD_RANGES[kind]), r"u_range|u_min|u_max|range")


def test_bad_u_range_messages_say_which_problem():
    raises_value_error(
        lambda: sp.PolynomialCurve(jnp.asarray(GOOD_CURVE_COEFFS), (1.0, -1.0)), r"revers|order|<|>"
    )
    raises_value_error(
        lambda: sp.PolynomialCurve(jnp.asarray(GOOD_CURVE_COEFFS), (0.5, 0.5)), r"empty|==|equal|zero"
    )
    raises_value_error(
        lambda: sp.PolynomialCurve(jnp.asarray(GOOD_CURVE_COEFFS), (0.0, np.nan)), r"finite|nan"
    )


@pytest.mark.parametrize("shape", [(2, 3), (4, 2), (3,), (3, 0), (1, 3, 2, 2), (6,)])
def test_polynomial_curve_bad_coeffs_shape(shape):
    raises_value_error(
        lambda: sp.PolynomialCurve(jnp.ones(shape), (0.0, 1.0)), r"coeffs", _shape_pattern(shape)
    )


def test_polynomial_curve_non_finite_coeffs():
    c = GOOD_CURVE_COEFFS.copy()
    c[1, 1] = np.nan
    raises_value_error(lambda: sp.PolynomialCurve(jnp.asarray(c), (0.0, 1.0)), r"coeffs", r"nan|finite")


@pytest.mark.parametrize(
    "fn,what",
    [
        (lambda u: jnp.stack([u, u]), "(2,)"),
        (lambda u: jnp.stack([u, u, u, u]), "(4,)"),
        (lambda u: jnp.stack([u, u, u])[:, None], "(3, 1)"),
        (lambda u: u * 2.0, "()"),
        (lambda u: jnp.ones((2, 3)) * u, "(2, 3)"),
    ],
)
def test_parametric_curve_fn_wrong_output_shape(fn, what):
    raises_value_error(lambda: sp.ParametricCurve(fn, (0.0, 1.0)), r"fn|shape|\(3,\)|3 values")


def test_line_segment_bad_endpoints():
    raises_value_error(lambda: sp.line_segment(jnp.zeros(2), jnp.ones(3)), r"shape|\(3,\)")
    raises_value_error(lambda: sp.line_segment(jnp.asarray([0.0, np.nan, 0.0]), jnp.ones(3)), r"nan|finite")


# --------------------------------------------------------------------------
# point sets
# --------------------------------------------------------------------------


def test_empty_point_set():
    raises_value_error(
        lambda: sp.geometry.closest_point_to_points(jnp.asarray(GOOD_Q), jnp.zeros((0, 3))),
        r"points|empty|at least",
    )


@pytest.mark.parametrize("shape", [(4, 2), (3,), (2, 3, 1), (4, 4), (1, 3, 3)])
def test_points_wrong_shape(shape):
    raises_value_error(
        lambda: sp.geometry.closest_point_to_points(jnp.asarray(GOOD_Q), jnp.ones(shape)),
        r"points",
        r"shape|\(N, ?3\)",
    )


def test_points_non_finite():
    p = GOOD_POINTS.copy()
    p[0, 2] = np.inf
    raises_value_error(
        lambda: sp.geometry.closest_point_to_points(jnp.asarray(GOOD_Q), jnp.asarray(p)), r"nan|inf|finite"
    )


def test_fit_polynomial_curve_bad_points():
    raises_value_error(lambda: sp.clouds.fit_polynomial_curve(jnp.zeros((0, 3)), 2), r"points|empty|at least")
    raises_value_error(lambda: sp.clouds.fit_polynomial_curve(jnp.ones((10, 2)), 2), r"shape|\(N, ?3\)")
    # too few points for the degree, and all-identical points
    raises_value_error(
        lambda: sp.clouds.fit_polynomial_curve(jnp.ones((2, 3)) * jnp.arange(2.0)[:, None], 3), r"point|degree"
    )
    raises_value_error(lambda: sp.clouds.fit_polynomial_curve(jnp.ones((6, 3)), 2), r"identical|distinct|same|zero")


def test_good_inputs_are_accepted():
    # the fixtures above are valid, so the failures are about the bad parts
    q = jnp.asarray(GOOD_Q)
    for name in ("segment_point", "tip_position", "segment_frames", "backbone_points"):
        Q_CONSUMERS[name](q)  # eager: value checks run
    sp.geometry.segment_point(q, 1, 0.5)
    sp.ParametricCurve(lambda u: jnp.stack([u, 2 * u, 1.0 + 0 * u]), (0.0, 1.0))
    sp.line_segment(jnp.zeros(3), jnp.ones(3))
    # the closest-point entry points: shapes accepted (abstract evaluation,
    # no compilation; their eager paths are exercised in test_closest.py)
    for name in ("closest_point", "closest_point_to_points", "point_jacobian", "tip_jacobian"):
        jax.eval_shape(Q_CONSUMERS[name], q)
