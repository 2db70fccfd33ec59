"""Actuator lengths against the independent oracle (each tendon's path sampled along the
backbone in a parallel-transported frame, a polyline, softplan_jax.testing.oracle_actuators),
round trips through the inverses, Jacobians against finite differences at and near
theta = 0, the segment length limits against sampled configurations, the limit check,
and bad input. No planning here: small programs only."""

from __future__ import annotations

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose, assert_finite

import softplan_jax as sp
from softplan_jax import actuators as A
from softplan_jax.testing import oracle_actuators as O
from softplan_jax.testing import oracle_geometry as G


def random_arm(rng, n, straight=None):
    """A random configuration of n segments (theta in [-2, 2], some segments straight)."""
    q = np.stack([rng.uniform(0.5, 1.5, n), rng.uniform(-2.0, 2.0, n), rng.uniform(-3.0, 3.0, n)], axis=1)
    for i in (straight if straight is not None else [int(rng.integers(n))]):
        q[i, 1] = 0.0
    return q


def layout_for(rng, kind, n, k):
    angles = np.sort(rng.uniform(0, 2 * math.pi / k, (n, 1)) + 2 * math.pi * np.arange(k)[None, :] / k
                     + rng.uniform(-0.3, 0.3, (n, k)), axis=1)
    return A.actuator_layout(kind, n, radius=rng.uniform(0.02, 0.08, n), angles=angles)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_lengths_match_the_sampled_oracle(n):
    """eq. (A1) summed along the tendon vs the polyline of the transported offset (1e-6 relative)."""
    rng = np.random.default_rng(n)
    for kind in ("tendon", "chamber"):
        k = 3 + (n % 3)
        lay = layout_for(rng, kind, n, k)
        for q in (random_arm(rng, n), random_arm(rng, n, straight=range(n))):
            fn = A.tendon_lengths if kind == "tendon" else A.chamber_lengths
            ref = O.tendon_lengths_sampled if kind == "tendon" else O.chamber_lengths_sampled
            got = np.asarray(fn(q, lay.radius, lay.angles))
            want = ref(q, np.asarray(lay.radius), np.asarray(lay.angles), samples=2000)
            assert_allclose(got, want, rtol=1e-6, err_msg=f"{kind}, n = {n}")


def test_the_oracle_sees_the_twist():
    """The oracle is not blind to the frame: with the paper's twisting frame (angles measured from
    R_{i-1}^0's x axis) the distal tendons would have other lengths, and eq. (A1) agrees with the
    transported frame only."""
    q = np.array([[1.0, 0.8, 0.7], [1.0, 0.9, 1.9], [1.0, 0.6, -2.2]])
    lay = A.actuator_layout("tendon", 3, 3, radius=0.05)
    want = O.tendon_lengths_sampled(q, np.asarray(lay.radius), np.asarray(lay.angles), samples=3000)
    # Angles carried by the paper's frames: segment j's base x axis is turned by phi_1 + ... + phi_{j-1}.
    Rs, _ = G.segment_frames(q)
    frames = O.transported_offsets(q, 3000)
    twist = math.atan2(float(frames[2][1][0] @ Rs[2][:, 1]), float(frames[2][1][0] @ Rs[2][:, 0]))
    assert abs(np.mod(twist + q[0, 2] + q[1, 2] + math.pi, 2 * math.pi) - math.pi) < 1e-9  # B_i = F_i Rz(sum phi)
    got = np.asarray(A.tendon_lengths(q, lay.radius, lay.angles))
    assert_allclose(got, want, rtol=1e-6)
    naive = got.copy()
    for t in range(3):  # the same formula with a = phi_i (the frame that turns with phi)
        naive[t] = sum(q[j, 0] - q[j, 1] * 0.05 * np.cos(np.asarray(lay.angles)[t] - q[j, 2]) for j in range(t + 1))
    assert np.max(np.abs(naive - want)) > 1e-3


@pytest.mark.parametrize("kind", ["tendon", "chamber"])
def test_round_trips(kind):
    """q -> lengths -> q to 1e-10 (theta > 0, phi in [-pi, pi)); for any q (theta < 0, straight
    segments) the same shape and the same lengths."""
    rng = np.random.default_rng(7)
    fn = A.tendon_lengths if kind == "tendon" else A.chamber_lengths
    inv = A.configuration_from_tendons if kind == "tendon" else A.configuration_from_chambers
    for n in (1, 3, 6):
        for k in (3, 5):
            lay = layout_for(rng, kind, n, k)
            q = random_arm(rng, n, straight=[])
            q[:, 1] = np.abs(q[:, 1]) + 0.05
            back = np.asarray(inv(fn(q, lay.radius, lay.angles), lay.radius, lay.angles))
            assert_allclose(back, q, rtol=0, atol=1e-10, err_msg=f"n = {n}, k = {k}")
            q = random_arm(rng, n)  # negative thetas and a straight segment
            lengths = np.asarray(fn(q, lay.radius, lay.angles))
            back = np.asarray(inv(lengths, lay.radius, lay.angles))
            assert np.all(back[:, 1] >= 0) and np.all(np.abs(back[:, 2]) <= math.pi)
            assert_allclose(np.asarray(fn(back, lay.radius, lay.angles)), lengths, rtol=0, atol=1e-12)
            assert_allclose(G.backbone_points(back, 20), G.backbone_points(q, 20), rtol=0, atol=1e-10)


def _central(fn, x, h):
    return G.central_difference(lambda v: np.asarray(fn(jnp.asarray(v)), np.float64), x, h)


@pytest.mark.parametrize("theta", [0.0, 1e-7, 1e-3, 0.7])
def test_jacobians_against_finite_differences(theta):
    """jacfwd and jacrev of the lengths agree with each other and with central differences, at and
    near theta = 0; the inverse's Jacobian near theta = 0 too, and it is finite at theta = 0."""
    lay = A.actuator_layout("tendon", 3, 4, radius=0.04)
    q = np.array([[1.0, theta, 0.4], [0.8, -theta, 2.0], [1.2, theta, -1.0]])
    f = lambda x: A.tendon_lengths(x, lay.radius, lay.angles)
    jf, jr = np.asarray(jax.jacfwd(f)(jnp.asarray(q))), np.asarray(jax.jacrev(f)(jnp.asarray(q)))
    assert_finite(jf)
    assert_allclose(jf, jr, rtol=0, atol=1e-13)
    assert_allclose(jf, _central(f, q, 1e-6), rtol=0, atol=1e-8)
    assert_allclose(np.asarray(A.actuator_jacobian(q, lay)), jf.reshape(12, 9), rtol=0, atol=1e-15)
    lengths = np.asarray(f(q))
    g = lambda x: A.configuration_from_tendons(x, lay.radius, lay.angles)
    J = np.asarray(jax.jacfwd(g)(jnp.asarray(lengths)))
    assert_finite(J, f"inverse Jacobian at theta = {theta}")
    assert_finite(np.asarray(jax.jacrev(g)(jnp.asarray(lengths))))
    if theta >= 1e-3:  # differentiable away from the polar singularity theta = 0
        assert_allclose(J, _central(g, lengths, 1e-8), rtol=0, atol=2e-5 / theta)


def test_values_and_gradients_finite_at_theta_zero_for_chambers():
    lay = A.actuator_layout("chamber", 2, 3, radius=0.05)
    q = jnp.array([[1.0, 0.0, 0.0], [1.0, 0.0, 2.1]])
    lengths = A.chamber_lengths(q, lay.radius, lay.angles)
    assert_allclose(np.asarray(lengths), np.ones((2, 3)), rtol=0, atol=1e-15)
    loss = lambda x: jnp.sum(A.configuration_from_chambers(x, lay.radius, lay.angles) ** 2)
    assert_finite(np.asarray(jax.grad(loss)(lengths)))
    assert_finite(np.asarray(jax.grad(lambda x: jnp.sum(A.chamber_lengths(x, lay.radius, lay.angles)))(q)))


@pytest.mark.parametrize("kind", ["tendon", "chamber"])
def test_segment_length_limits_are_necessary(kind):
    """Every sampled configuration whose actuators are within their length limits has its
    segment lengths (tendons: their sums) inside the derived bounds."""
    rng = np.random.default_rng(3)
    lay = A.actuator_layout(kind, 3, 3, radius=0.1)
    lo_hi = {"tendon": (0.5, 2.6), "chamber": (0.7, 1.3)}[kind]
    lim = A.actuator_limits(min_length=lo_hi[0], max_length=lo_hi[1])
    L_min, L_max = A.segment_length_limits(lay, lim)
    fn = A.tendon_lengths if kind == "tendon" else A.chamber_lengths
    inside = 0
    for _ in range(300):
        L = rng.uniform(0.6, 1.4, 3) if kind == "chamber" else rng.uniform(0.3, 1.2, 3)
        q = np.stack([L, rng.uniform(-1.5, 1.5, 3), rng.uniform(-3, 3, 3)], 1)
        lengths = np.asarray(fn(q, lay.radius, lay.angles))
        if np.all(lengths >= lo_hi[0]) and np.all(lengths <= lo_hi[1]):
            inside += 1
            assert np.all(q[:, 0] >= L_min - 1e-12) and np.all(q[:, 0] <= L_max + 1e-12), (q[:, 0], L_min, L_max)
    assert inside > 20


def test_check_limits_names_the_first_violation():
    lay = A.actuator_layout("chamber", 1, 3, radius=0.05)
    t = np.linspace(0, 1, 11)
    lengths = np.ones((11, 1, 3))
    lengths[:, 0, 1] = 1 + 0.05 * t**2  # accelerates at 0.1 m/s^2, speed up to 0.1 m/s
    lengths[7:, 0, 2] = 1.2  # jumps at t = 0.7
    lim = A.actuator_limits(max_length=1.1, max_speed=0.5, max_acceleration=0.2)
    r = A.check_limits(lim, lay, lengths, t)
    assert not r.ok and r.first.startswith("max_speed: chamber 2 of segment 0 at t = 0.600 s")
    assert r.violations["max_length"] == 4 and r.violations["max_speed"] == 1
    assert abs(r.usage["max_speed"] - 2.0 / 0.5) < 1e-9
    ok = A.check_limits(lim, lay, lengths[:7], t[:7])
    assert ok.ok and ok.first is None and abs(ok.usage["max_acceleration"] - 0.1 / 0.2) < 1e-9


# ----------------------------------------------------------------------------
# Bad input: a ValueError naming the field.

LAY = dict(radius=0.03, angles=2 * np.pi * np.arange(3) / 3)
Q = np.array([[1.0, 0.3, 0.1], [1.0, 0.0, 2.0]])


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(radius=0.0), r"radius must be finite and > 0"),
    (dict(radius=-0.1), r"radius must be finite and > 0"),
    (dict(radius=np.nan), r"radius must be finite and > 0"),
    (dict(radius=[0.1, 0.1, 0.1]), r"radius must be a scalar or \(n,\)"),
    (dict(angles=[0.0, 2.0]), r"angles: a segment needs at least 3 actuators"),
    (dict(angles=[0.0, 0.0, 3.0]), r"angles: two actuators of segment 0 sit at the same angle"),
    (dict(angles=[0.0, 0.5, 1.0]), r"angles: the actuators of segment 0 leave a gap"),
    (dict(angles=[0.0, 2.0, np.inf]), r"angles must be finite"),
    (dict(radius=5.0), r"radius: 5 is not inside segment 0's bending radius"),
])
@pytest.mark.parametrize("fn", [A.tendon_lengths, A.chamber_lengths])
def test_bad_arrangement(fn, kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        fn(Q, **(LAY | kwargs))


def test_bad_inverse_input():
    good = np.asarray(A.tendon_lengths(Q, **LAY))
    with pytest.raises(ValueError, match=r"lengths must have shape \(n, k\)"):
        A.configuration_from_tendons(good[:, :2], **LAY)
    with pytest.raises(ValueError, match=r"lengths contains non-finite"):
        A.configuration_from_tendons(np.where(good > 1.5, np.nan, good), **LAY)
    with pytest.raises(ValueError, match=r"lengths must be > 0"):
        A.configuration_from_chambers(-good, **LAY)
    with pytest.raises(ValueError, match=r"lengths: no configuration realises them: segment 1 would have length"):
        A.configuration_from_tendons(np.array([[1.0, 1.0, 1.0], [0.5, 0.5, 0.5]]), **LAY)
    with pytest.raises(ValueError, match=r"lengths: no configuration realises them: radius"):
        A.configuration_from_chambers(np.array([[1.0, 3.0, 0.2]]), radius=[1.0], angles=LAY["angles"])
    four = 2 * np.pi * np.arange(4) / 4
    lengths = np.array(A.chamber_lengths(Q, 0.03, four))
    lengths[0, 0] += 1e-3  # four chambers: one out of line with the others
    with pytest.raises(ValueError, match=r"no configuration realises them: the closest configuration misses"):
        A.configuration_from_chambers(lengths, 0.03, four)
    A.configuration_from_chambers(lengths, 0.03, four, tolerance=1e-2)  # measured lengths: a looser tolerance


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(max_speed=0.0), r"limits.max_speed must be > 0"),
    (dict(max_acceleration=-1.0), r"limits.max_acceleration must be > 0"),
    (dict(min_length=0.0), r"limits.min_length must be > 0"),
    (dict(max_length=np.nan), r"limits.max_length must not be NaN"),
    (dict(min_length=2.0, max_length=1.0), r"min_length must be below max_length"),
    (dict(max_speed="fast"), r"limits.max_speed must be a number"),
])
def test_bad_limits(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        A.actuator_limits(**kwargs)


def test_bad_layout_and_infeasible_limits():
    with pytest.raises(ValueError, match=r"kind must be one of tendon, chamber"):
        A.actuator_layout("muscle", 3)
    with pytest.raises(ValueError, match=r"count: a segment needs at least 3 actuators"):
        A.actuator_layout("tendon", 3, 2)
    lay = A.actuator_layout("tendon", 3, 3)
    with pytest.raises(ValueError, match=re.escape("limits.max_speed has shape (2,)")):
        A.actuator_limits(max_speed=[0.1, 0.2]).per_actuator(lay)
    # Segment 0's tendons 1 to 1.05 long, segment 1's (through two segments) 3 to 3.5: segment 1 would need
    # 3 - 1.05 <= L_1 <= 3.5 - 1, and segment 2's tendons (4 to 4.2) 4 - (1.05 + 2.5) <= L_2 <= 4.2 - (1 + 1.95).
    lim = A.actuator_limits(min_length=[1.0, 3.0, 4.0], max_length=[1.05, 3.5, 4.2])
    L_min, L_max = A.segment_length_limits(lay, lim)
    assert_allclose(L_min, [1.0, 1.95, 0.45], rtol=1e-12)
    assert_allclose(L_max, [1.05, 2.5, 1.25], rtol=1e-12)
    with pytest.raises(ValueError, match=r"limits: the actuators' length limits admit no length of segment 1"):
        # segment 1's tendons shorter than segment 0's shortest, which they run along
        A.segment_length_limits(lay, A.actuator_limits(min_length=[1.0, 0.5, 0.5], max_length=[1.05, 0.9, 4.2]))
    with pytest.raises(ValueError, match=r"layout: it is for 3 segments; the scene's arm has 2"):
        sp.trajectories.constrain_scenario(sp.make_scenario([1.0, 0.0, 1.0], [], q0=Q), lay, A.actuator_limits())
