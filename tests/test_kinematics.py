"""PCC kinematics (paper section 2.1-2.2) against the NumPy oracle.

Values are compared with ``softplan_jax/testing/oracle.py`` (independent NumPy code from the
paper's formulas); first derivatives with the oracle's complex-step Jacobian
(exact to rounding) AND with central finite differences; second derivatives
with finite differences of Jacobians.  theta = 0 exactly and tiny theta are
ordinary configurations: every value and derivative must be finite and right.
"""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose, assert_finite

import softplan_jax as sp
from softplan_jax.testing import oracle

TWO_PI = 2 * np.pi
SPECIAL_THETAS = [
    0.0,
    1e-12,
    -1e-12,
    1e-8,
    -1e-8,
    1e-4,
    -1e-4,
    np.pi,
    -np.pi,
    TWO_PI,
    -TWO_PI,
    TWO_PI - 1e-9,
    -(TWO_PI - 1e-7),
    TWO_PI - 1e-3,
]


def random_q(rng, n, theta=None):
    """(n, 3) with L in [0.3, 2], theta in [-2pi, 2pi] (or a given value/list),
    phi anywhere (also outside [-pi, pi])."""
    L = rng.uniform(0.3, 2.0, n)
    if theta is None:
        th = rng.uniform(-TWO_PI, TWO_PI, n)
    else:
        th = np.broadcast_to(np.asarray(theta, dtype=np.float64), (n,)).copy()
    ph = rng.uniform(-3 * np.pi, 3 * np.pi, n)
    return np.stack([L, th, ph], axis=1)


def kinematic_configs(seed=0, n_random=40, sizes=(1, 2, 3, 4)):
    """Random configurations plus every special theta in every position."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_random):
        n = int(rng.choice(sizes))
        q = random_q(rng, n)
        # sprinkle special values into some rows
        for r in range(n):
            if rng.random() < 0.3:
                q[r, 1] = rng.choice(SPECIAL_THETAS)
        out.append(q)
    for th in SPECIAL_THETAS:
        for n in (1, 3):
            out.append(random_q(rng, n, th))
    # mixed: all special in one config
    out.append(random_q(rng, max(sizes), [0.0, 1e-12, -1e-8, TWO_PI][: max(sizes)]))
    return out


CONFIGS = kinematic_configs()
# smaller set for the derivative tests, n in {1, 3} only: every (function, n)
# pair is one XLA compilation, which dominates the run time
DERIV_CONFIGS = kinematic_configs(seed=1, n_random=12, sizes=(1, 3))


def _j(x):
    return jnp.asarray(x, dtype=jnp.float64)


# jitted entry points (segment index and s traced) so that repeated calls for finite
# differences do not re-dispatch op by op; eager calls are exercised separately.
_point = jax.jit(sp.geometry.segment_point)
_pjac = jax.jit(sp.geometry.point_jacobian)
_jacrev = jax.jit(jax.jacrev(sp.geometry.segment_point))
_hess_q = jax.jit(jax.hessian(sp.geometry.segment_point))
_d1s = jax.jit(jax.jacfwd(sp.geometry.segment_point, argnums=2))
_d2s = jax.jit(jax.jacfwd(jax.jacfwd(sp.geometry.segment_point, argnums=2), argnums=2))
_mixed = jax.jit(jax.jacfwd(sp.geometry.point_jacobian, argnums=2))
_tip = jax.jit(sp.tip_position)
_tjac = jax.jit(sp.geometry.tip_jacobian)
_backbone = jax.jit(sp.geometry.backbone_points, static_argnums=1)
_frames = jax.jit(sp.geometry.segment_frames)


def _sq(q, i, s):
    return jnp.sum(sp.geometry.segment_point(q, i, s) ** 2)


_grad_sq = jax.jit(jax.grad(_sq))


# --------------------------------------------------------------------------
# the oracle on its own (so a wrong oracle cannot hide a wrong library)
# --------------------------------------------------------------------------


class TestOracleKinematics:
    def test_half_circle_tip(self):
        for L, ph in [(1.0, 0.0), (0.7, 1.3), (2.0, -2.5)]:
            tip = oracle.tip_position(np.array([[L, np.pi, ph]]))
            want = [2 * L / np.pi * np.cos(ph), 2 * L / np.pi * np.sin(ph), 0.0]
            np.testing.assert_allclose(tip, want, atol=1e-15)

    def test_full_circle_returns_to_base(self):
        tip = oracle.tip_position(np.array([[1.3, TWO_PI, 0.4]]))
        np.testing.assert_allclose(tip, 0.0, atol=1e-15)

    def test_straight_arm(self):
        q = np.array([[1.0, 0.0, 0.3], [0.5, 0.0, -1.0]])
        np.testing.assert_allclose(oracle.tip_position(q), [0, 0, 1.5], atol=0)
        np.testing.assert_allclose(oracle.segment_point(q, 1, 0.4), [0, 0, 1.2])

    def test_rotation_orthonormal_and_chain_consistent(self):
        rng = np.random.default_rng(3)
        for _ in range(20):
            q = random_q(rng, 4)
            Rs, Ps = oracle.segment_frames(q)
            for R in Rs:
                np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
                assert abs(np.linalg.det(R) - 1) < 1e-14
            # base of segment i+1 == s=1 of segment i == product of H
            for i in range(3):
                np.testing.assert_allclose(oracle.segment_point(q, i, 1.0), Ps[i + 1], atol=1e-14)
            np.testing.assert_allclose(oracle.segment_point(q, 3, 1.0), oracle.tip_position(q), atol=1e-14)

    def test_arc_is_unit_speed_times_L_and_tangent_continuous(self):
        rng = np.random.default_rng(4)
        q = random_q(rng, 3)
        for i in range(3):
            s = np.linspace(0, 1, 7)
            _, dF, ddF = oracle.segment_point_derivs(q, i, s)
            np.testing.assert_allclose(np.linalg.norm(dF, axis=1), q[i, 0], rtol=1e-14)
            # curvature |F''| / L^2 = |theta| / L
            np.testing.assert_allclose(np.linalg.norm(ddF, axis=1), abs(q[i, 1]) * q[i, 0], rtol=1e-13)
        # tangent continuity at segment joints (C1 backbone)
        for i in range(2):
            t_end = oracle.segment_point_derivs(q, i, [1.0])[1][0] / q[i, 0]
            t_start = oracle.segment_point_derivs(q, i + 1, [0.0])[1][0] / q[i + 1, 0]
            np.testing.assert_allclose(t_end, t_start, atol=1e-14)

    def test_s_derivatives_match_fd(self):
        rng = np.random.default_rng(5)
        q = random_q(rng, 2)
        for s in (0.1, 0.5, 0.9):
            F, dF, ddF = oracle.segment_point_derivs(q, 1, [s])
            h = 1e-6
            fd = (oracle.segment_point(q, 1, s + h) - oracle.segment_point(q, 1, s - h)) / (2 * h)
            np.testing.assert_allclose(dF[0], fd, atol=1e-8)
            fd2 = (
                oracle.segment_point_derivs(q, 1, [s + h])[1][0]
                - oracle.segment_point_derivs(q, 1, [s - h])[1][0]
            ) / (2 * h)
            np.testing.assert_allclose(ddF[0], fd2, atol=1e-8)

    def test_small_theta_continuity(self):
        # exact theta = 0 branch agrees with the theta != 0 formula in the limit
        q0 = np.array([[1.2, 0.0, 0.7], [0.8, 0.0, -0.3]])
        for eps in (1e-14, 1e-10, 1e-7):
            q = q0.copy()
            q[:, 1] = eps
            np.testing.assert_allclose(oracle.tip_position(q), oracle.tip_position(q0), atol=3 * eps)

    def test_complex_step_jacobian_matches_fd(self):
        rng = np.random.default_rng(6)
        for th in (0.0, 1e-12, 0.8):
            q = random_q(rng, 2)
            q[0, 1] = th
            J = oracle.point_jacobian(q, 1, 0.6)
            fd = oracle.central_difference(lambda qq: oracle.segment_point(qq, 1, 0.6), q, 1e-6).reshape(
                3, -1
            )
            np.testing.assert_allclose(J, fd, atol=1e-8)


# --------------------------------------------------------------------------
# values
# --------------------------------------------------------------------------


def test_segment_transform_matches_paper():
    rng = np.random.default_rng(10)
    rows = [random_q(rng, 1)[0] for _ in range(30)]
    rows += [random_q(rng, 1, th)[0] for th in SPECIAL_THETAS]
    for row in rows:
        R, P = sp.geometry.segment_transform(_j(row))
        Ro, Po = oracle.segment_transform(row)
        assert R.shape == (3, 3) and P.shape == (3,)
        assert_allclose(R, Ro, atol=1e-14, err_msg=f"R for q_i={row!r}")
        assert_allclose(P, Po, rtol=1e-13, atol=1e-15, err_msg=f"P for q_i={row!r}")


def test_segment_transform_theta_zero_exact():
    R, P = sp.geometry.segment_transform(_j([1.7, 0.0, 0.4]))
    assert_allclose(P, [0.0, 0.0, 1.7], atol=0, rtol=0)
    c, s = np.cos(0.4), np.sin(0.4)
    assert_allclose(R, [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-16)


def test_oracle_arm_points_many_is_the_loop():
    """The oracle's vectorised arm points (the brute-force checks' sampling of a motion) equal
    its one-configuration arm_points on every test configuration of the same segment count,
    theta = 0 included, to rounding."""
    s = np.linspace(0.0, 1.0, 17)
    for n in sorted({q.shape[0] for q in CONFIGS}):
        qs = np.stack([q for q in CONFIGS if q.shape[0] == n])
        loop = np.stack([oracle.arm_points(q, s) for q in qs])
        np.testing.assert_allclose(oracle.arm_points_many(qs, s), loop, rtol=0, atol=1e-14 * qs[..., 0].sum(1).max())


@pytest.mark.parametrize("k", range(len(CONFIGS)))
def test_segment_frames_points_tip_backbone(k):
    q = CONFIGS[k]
    n = q.shape[0]
    qj = _j(q)
    Rb, Pb = _frames(qj)
    Rbo, Pbo = oracle.segment_frames(q)
    assert Rb.shape == (n, 3, 3) and Pb.shape == (n, 3)
    assert_allclose(Rb[0], np.eye(3), atol=0)
    assert_allclose(Pb[0], np.zeros(3), atol=0)
    assert_allclose(Rb, Rbo, atol=1e-13, err_msg=f"frames q={q!r}")
    assert_allclose(Pb, Pbo, atol=1e-13, err_msg=f"frames q={q!r}")

    scale = float(q[:, 0].sum())
    for i in range(n):
        for s in (0.0, 1e-9, 0.25, 0.5, 0.9137, 1.0):
            p = _point(qj, i, s)
            assert p.shape == (3,)
            assert_allclose(
                p,
                oracle.segment_point(q, i, s),
                atol=1e-13 * scale,
                err_msg=f"segment_point q={q!r} i={i} s={s}",
            )
    assert_allclose(_tip(qj), oracle.tip_position(q), atol=1e-13 * scale, err_msg=f"tip q={q!r}")
    for kk in (10, 3):
        bp = _backbone(qj, kk)
        assert bp.shape == (n * kk, 3)
        assert_allclose(bp, oracle.backbone_points(q, kk), atol=1e-13 * scale)
    bp = _backbone(qj, 10)
    assert bp.shape == (n * 10, 3)


def test_eager_calls():
    # the un-jitted path, once per public function
    rng = np.random.default_rng(13)
    q = random_q(rng, 2, [0.0, 0.8])
    qj = _j(q)
    assert_allclose(sp.geometry.segment_point(qj, 1, 0.5), oracle.segment_point(q, 1, 0.5), atol=1e-14)
    assert_allclose(sp.tip_position(qj), oracle.tip_position(q), atol=1e-14)
    assert_allclose(sp.geometry.point_jacobian(qj, 0, 0.5), oracle.point_jacobian(q, 0, 0.5), atol=1e-13)
    assert_allclose(sp.geometry.tip_jacobian(qj), oracle.tip_jacobian(q), atol=1e-13)
    Rb, Pb = sp.geometry.segment_frames(qj)
    Rbo, Pbo = oracle.segment_frames(q)
    assert_allclose(Rb, Rbo, atol=1e-14)
    assert_allclose(Pb, Pbo, atol=1e-14)
    assert_allclose(sp.geometry.backbone_points(qj), oracle.backbone_points(q), atol=1e-14)


def test_concrete_q_closed_over_inside_jit():
    # a user's jitted function that closes over a concrete configuration
    q = jnp.asarray([[1.0, 0.4, 0.2], [1.0, 0.0, 1.0]])
    qn = np.asarray(q)
    assert_allclose(jax.jit(lambda: sp.tip_position(q))(), oracle.tip_position(qn), atol=1e-14)
    assert_allclose(
        jax.jit(lambda s: sp.geometry.segment_point(q, 1, s))(0.5), oracle.segment_point(qn, 1, 0.5), atol=1e-14
    )
    assert_allclose(
        jax.jit(lambda s: sp.geometry.point_jacobian(q, 0, s))(0.5), oracle.point_jacobian(qn, 0, 0.5), atol=1e-13
    )


def test_segment_point_traced_s_and_jit():
    rng = np.random.default_rng(11)
    q = random_q(rng, 3, [0.0, 1.1, -2.0])
    f = jax.jit(sp.geometry.segment_point, static_argnums=1)
    for i in range(3):
        ss = np.linspace(0, 1, 5)
        got = jax.vmap(lambda s, i=i: f(_j(q), i, s))(_j(ss))
        assert_allclose(got, oracle.segment_points(q, i, ss), atol=1e-13)


def test_float32_smoke():
    rng = np.random.default_rng(12)
    for th in (0.0, 1e-12, 0.5, -3.0):
        q = random_q(rng, 3, th)
        q32 = jnp.asarray(q, dtype=jnp.float32)
        p = sp.geometry.segment_point(q32, 2, 0.3)
        assert p.dtype == jnp.float32
        assert_allclose(p, oracle.segment_point(q.astype(np.float32).astype(np.float64), 2, 0.3), atol=2e-5)
        J = sp.geometry.point_jacobian(q32, 2, 0.3)
        assert J.dtype == jnp.float32
        assert_allclose(J, oracle.point_jacobian(q, 2, 0.3), atol=1e-4)


# --------------------------------------------------------------------------
# first derivatives
# --------------------------------------------------------------------------

_jac_cases = []
for _k, _q in enumerate(DERIV_CONFIGS):
    _rng = np.random.default_rng(100 + _k)
    _i = int(_rng.integers(0, _q.shape[0]))
    _jac_cases.append((_k, _i, float(_rng.choice([0.0, 1.0, _rng.uniform()]))))


def _flat_fn(fn, n):
    return lambda x: fn(jnp.reshape(x, (n, 3)))


@pytest.mark.parametrize("k,i,s", _jac_cases)
def test_point_jacobian(k, i, s):
    q = DERIV_CONFIGS[k]
    _check_point_jacobian(q, i, s)


@pytest.mark.parametrize("theta", [0.0, 1e-12, -1e-12, 1e-8, 1e-4])
@pytest.mark.parametrize("s", [0.0, 0.37, 1.0])
def test_point_jacobian_near_theta_zero(theta, s):
    rng = np.random.default_rng(7)
    q = random_q(rng, 3)
    q[:, 1] = theta  # every segment at/near zero bending
    for i in range(3):
        _check_point_jacobian(q, i, s)
    q[1, 1] = 0.9  # mixed
    _check_point_jacobian(q, 2, s)


def _check_point_jacobian(q, i, s):
    n = q.shape[0]
    qj = _j(q)
    msg = f"q={q.tolist()!r} i={i} s={s}"
    J = _pjac(qj, i, s)
    assert J.shape == (3, 3 * n)
    exact = oracle.point_jacobian(q, i, s)  # complex step, exact to rounding
    scale = max(1.0, float(np.abs(exact).max()))
    assert_allclose(J, exact, atol=1e-12 * scale, err_msg="vs oracle " + msg)

    # point_jacobian is the forward-mode one; jacrev is reverse mode
    Jrev = _jacrev(qj, i, s).reshape(3, 3 * n)
    assert_allclose(Jrev, exact, atol=1e-12 * scale, err_msg="jacrev " + msg)
    assert_allclose(J, Jrev, atol=1e-12 * scale, err_msg="jacfwd vs jacrev " + msg)

    # central differences (step 1e-6) of the library and of the oracle
    h = 1e-6
    fd_lib = oracle.central_difference(lambda x: np.asarray(_point(_j(x), i, s)), q, h).reshape(3, 3 * n)
    fd_orc = oracle.central_difference(lambda x: oracle.segment_point(x, i, s), q, h).reshape(3, 3 * n)
    assert_allclose(J, fd_lib, rtol=1e-7, atol=1e-7 * scale, err_msg="FD(lib) " + msg)
    assert_allclose(J, fd_orc, rtol=1e-7, atol=1e-7 * scale, err_msg="FD(oracle) " + msg)


@pytest.mark.parametrize("k", range(0, len(DERIV_CONFIGS), 2))
def test_tip_jacobian(k):
    q = DERIV_CONFIGS[k]
    n = q.shape[0]
    J = _tjac(_j(q))
    assert J.shape == (3, 3 * n)
    exact = oracle.tip_jacobian(q)
    assert_allclose(J, exact, atol=1e-12 * max(1, np.abs(exact).max()), err_msg=f"q={q!r}")
    fd = oracle.central_difference(lambda x: np.asarray(_tip(_j(x))), q, 1e-6)
    assert_allclose(J, fd.reshape(3, 3 * n), rtol=1e-7, atol=1e-7)


def test_tip_jacobian_straight_arm_is_rank_two_in_bending():
    # a straight arm: the Jacobian is finite, its L-columns are all e_z, and
    # it equals the oracle (rank-deficient Jacobians are the planner's problem)
    q = np.array([[1.0, 0.0, 0.3], [1.0, 0.0, -0.2], [1.0, 0.0, 1.0]])
    J = np.asarray(sp.geometry.tip_jacobian(_j(q)))
    assert_finite(J)
    for c in (0, 3, 6):
        assert_allclose(J[:, c], [0, 0, 1], atol=1e-15)
    assert_allclose(J, oracle.tip_jacobian(q), atol=1e-14)


# --------------------------------------------------------------------------
# second derivatives and reverse mode at/near theta = 0
# --------------------------------------------------------------------------


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-7, 1e-5, 1e-3, 0.7, -2.5])
def test_hessian_wrt_q(theta):
    rng = np.random.default_rng(21)
    q = random_q(rng, 3)
    q[:, 1] = theta
    q[0, 1] = theta if theta != 0.7 else 0.0
    n = 3
    for i, s in ((0, 0.6), (1, 1.0), (1, 0.3)):
        msg = f"q={q.tolist()!r} i={i} s={s}"
        Hs = _hess_q(_j(q), i, s)
        Hs = np.asarray(Hs).reshape(3, 3 * n, 3 * n)
        assert_finite(Hs, msg)
        # symmetry
        assert_allclose(Hs, np.swapaxes(Hs, 1, 2), atol=1e-12, err_msg=msg)
        # FD of the oracle's exact Jacobian
        h = 1e-5
        fd_orc = oracle.central_difference(lambda x, i=i, s=s: oracle.point_jacobian(x, i, s), q, h)
        fd_orc = fd_orc.reshape(3, 3 * n, 3 * n)
        assert_allclose(Hs, fd_orc, atol=2e-8, err_msg="vs FD(oracle J) " + msg)
        # FD of the library's Jacobian
        fd_lib = oracle.central_difference(lambda x, i=i, s=s: np.asarray(_pjac(_j(x), i, s)), q, h).reshape(
            3, 3 * n, 3 * n
        )
        assert_allclose(Hs, fd_lib, atol=2e-8, err_msg="vs FD(lib J) " + msg)


@pytest.mark.parametrize("theta", [0.0, 1e-12, -1e-9, 1e-4, 1.3])
def test_s_derivatives(theta):
    rng = np.random.default_rng(22)
    q = random_q(rng, 3)
    q[1, 1] = theta
    for s in (0.0, 0.5, 1.0):
        msg = f"q={q.tolist()!r} s={s}"
        d1 = _d1s(_j(q), 1, jnp.float64(s))
        d2 = _d2s(_j(q), 1, jnp.float64(s))
        _, dF, ddF = oracle.segment_point_derivs(q, 1, [s])
        assert_allclose(d1, dF[0], atol=1e-13, err_msg="dF/ds " + msg)
        assert_allclose(d2, ddF[0], atol=1e-13, err_msg="d2F/ds2 " + msg)
        # FD of the s-derivative (library jacobian in s)
        h = 1e-6
        fd = (
            np.asarray(_d1s(_j(q), 1, jnp.float64(s + h))) - np.asarray(_d1s(_j(q), 1, jnp.float64(s - h)))
        ) / (2 * h)
        assert_allclose(d2, fd, atol=1e-7, err_msg="FD " + msg)
        # mixed d/ds d/dq = FD in s of the Jacobian (oracle)
        mixed = _mixed(_j(q), 1, jnp.float64(s))
        fdm = (oracle.point_jacobian(q, 1, s + h) - oracle.point_jacobian(q, 1, s - h)) / (2 * h)
        assert_allclose(mixed, fdm, atol=1e-7, err_msg="mixed " + msg)


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-6])
def test_reverse_mode_finite_at_theta_zero(theta):
    # reverse mode (jacrev) is also covered by test_point_jacobian*; here a
    # nonlinear scalar through jax.grad and jacfwd-over-jacrev (the
    # Hessian), all at/near theta = 0
    rng = np.random.default_rng(23)
    q = random_q(rng, 3)
    q[:, 1] = theta
    for i, s in itertools.product(range(3), (0.0, 0.5, 1.0)):
        msg = f"q={q.tolist()!r} i={i} s={s}"
        g2 = _grad_sq(_j(q), i, s)
        assert g2.shape == (3, 3)
        p = oracle.segment_point(q, i, s)
        assert_allclose(
            np.asarray(g2).ravel(), 2 * p @ oracle.point_jacobian(q, i, s), atol=1e-13, err_msg=msg
        )
        assert_finite(_hess_q(_j(q), i, s), msg)
    # the tip (= last segment at s = 1): gradient, and the Hessian against FD
    gt = _grad_sq(_j(q), 2, 1.0)
    assert_allclose(np.asarray(gt).ravel(), 2 * oracle.tip_position(q) @ oracle.tip_jacobian(q), atol=1e-13)
    Ht = np.asarray(_hess_q(_j(q), 2, 1.0)).reshape(3, 9, 9)
    fd = oracle.central_difference(oracle.tip_jacobian, q, 1e-5).reshape(3, 9, 9)
    assert_allclose(Ht, fd, atol=2e-8)


# --------------------------------------------------------------------------
# arms of many segments: the frames composed in a lax.scan
# --------------------------------------------------------------------------

MANY = 12  # above geometry._kinematics.UNROLL_SEGMENTS: the scanned chain


def _many_q(seed, n=MANY):
    """A long arm of short segments, theta = 0 exactly and near it in some rows."""
    q = random_q(np.random.default_rng(seed), n)
    q[:, 0] *= 3.0 / n
    q[::4, 1] = 0.0
    q[1::4, 1] = 1e-9
    return q


def test_many_segments_take_the_scan():
    from softplan_jax.geometry import _kinematics as K

    assert K.UNROLL_SEGMENTS < MANY

    def size(n):
        return len(jax.make_jaxpr(K._chain)(jnp.ones((n, 3))).jaxpr.eqns)

    assert size(MANY) == size(40)  # the trace does not grow with the segments
    q = _j(_many_q(0))
    for a, b in zip(K._chain_scanned(q), K._chain_unrolled(q), strict=True):
        assert_allclose(a, b, atol=1e-15)


def test_many_segments_values_match_oracle():
    q = _many_q(1)
    qj = _j(q)
    Rb, Pb = _frames(qj)
    Rbo, Pbo = oracle.segment_frames(q)
    assert_allclose(Rb, Rbo, atol=1e-13)
    assert_allclose(Pb, Pbo, atol=1e-13)
    assert_allclose(_tip(qj), oracle.tip_position(q), atol=1e-13)
    for i, s in ((0, 0.3), (5, 0.0), (MANY - 1, 1.0), (MANY - 2, 0.77)):
        assert_allclose(_point(qj, i, s), oracle.segment_point(q, i, s), atol=1e-13)
    assert_allclose(_backbone(qj, 3), oracle.backbone_points(q, 3), atol=1e-13)


@pytest.mark.parametrize("i,s", [(0, 0.5), (4, 0.0), (7, 1.0), (MANY - 1, 1.0)])
def test_many_segments_jacobians(i, s):
    """jacfwd and jacrev through the scan against the oracle's complex step and finite
    differences, with rows at theta = 0."""
    _check_point_jacobian(_many_q(2), i, s)


@pytest.mark.parametrize("straight", [True, False])
def test_many_segments_points_jacobian(straight):
    """The planner's Jacobians, segment by segment on a long arm, against the oracle's complex
    step, on the straight arm (every theta = 0) and a bent one; the tip's gradient too."""
    from softplan_jax.geometry._kinematics import points_jacobian

    q_np = np.asarray(sp.scenarios.default_start(MANY, 3.0 / MANY)) if straight else _many_q(4)
    q = _j(q_np)
    segments, s = jnp.array([0, 4, 5, MANY - 1, MANY - 1], jnp.int32), jnp.array([0.5, 0.0, 1.0, 0.3, 1.0])
    J = jax.jit(points_jacobian)(q, segments, s)
    assert J.shape == (5, 3, 3 * MANY)
    for k in range(5):
        exact = oracle.point_jacobian(q_np, int(segments[k]), float(s[k]))
        assert_allclose(J[k], exact, atol=1e-13 * max(1.0, np.abs(exact).max()))
    g = jax.jit(jax.grad(lambda q: jnp.sum(sp.tip_position(q) ** 2)))(q)
    assert_allclose(np.asarray(g).ravel(), 2 * oracle.tip_position(q_np) @ oracle.tip_jacobian(q_np), atol=1e-12)
    # reverse mode through the Jacobians (a rollout loss's gradient) against central differences
    weights = jnp.asarray(np.random.default_rng(5).normal(size=J.shape))
    loss = jax.jit(lambda q: jnp.sum(weights * points_jacobian(q, segments, s)))
    fd = oracle.central_difference(lambda x: np.asarray(loss(_j(x))), q_np, 1e-6)
    assert_allclose(jax.jit(jax.grad(loss))(q), fd, rtol=1e-6, atol=1e-6)


def test_many_segments_float32():
    q = _many_q(3)
    q32 = jnp.asarray(q, dtype=jnp.float32)
    p = sp.geometry.segment_point(q32, MANY - 1, 0.6)
    assert p.dtype == jnp.float32
    assert_allclose(p, oracle.segment_point(q.astype(np.float32).astype(np.float64), MANY - 1, 0.6), atol=2e-5)
    J = sp.geometry.point_jacobian(q32, MANY - 1, 0.6)
    assert J.dtype == jnp.float32
    assert_allclose(J, oracle.point_jacobian(q, MANY - 1, 0.6), atol=1e-4)
