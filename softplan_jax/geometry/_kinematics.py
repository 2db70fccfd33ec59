"""Piecewise-constant-curvature (PCC) kinematics, exactly as the paper's §2.1-2.2 (Webster & Jones
2010): ``q`` has shape ``(n, 3)``, row i ``[L_i, theta_i, phi_i]``; segment i's tip frame relative
to its base is ``[[R_i, P_i], [0, 1]]`` with the paper's ``R_i = Rz(phi_i) Ry(theta_i)``; segment
0's base is the origin with the identity orientation, z up. One plain, traceable function per
operation (jit at the call site); ``theta = 0`` is an ordinary input (the ratios of
:mod:`softplan_jax.base._numerics`: finite, accurate values and derivatives of every order).
Shapes are checked at trace time, values (finite, ``L > 0``, ``s`` in [0, 1], the segment index)
only when the input is concrete."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import one_minus_cos_over_x, sin_over_x
from ..base._validation import check_configuration, check_fraction, check_segment_index, is_concrete

__all__ = [
    "segment_transform",
    "segment_frames",
    "segment_point",
    "tip_position",
    "point_jacobian",
    "tip_jacobian",
    "backbone_points",
    "motion_bound",
]


def arc_point_local(q_i, s):
    """Point at fraction ``s`` of one segment, in the segment's base frame.

    The bracket of paper §2.2 (``P_si`` before the rotation), rewritten with
    ``x = theta * s`` so that it has no singularity:
    ``L/theta (1 - cos x) = L s (1 - cos x)/x`` and ``L/theta sin x = L s sin(x)/x``.

    Args:
      q_i: (3,) ``[L, theta, phi]``.
      s: scalar fraction.

    Returns:
      (3,) point.
    """
    L, theta, phi = q_i[0], q_i[1], q_i[2]
    x = theta * s
    radial = L * s * one_minus_cos_over_x(x)
    return jnp.stack([radial * jnp.cos(phi), radial * jnp.sin(phi), L * s * sin_over_x(x)])


def _rotation(q_i):
    """The paper's R_i = Rz(phi) Ry(theta) (paper §2.1)."""
    theta, phi = q_i[1], q_i[2]
    ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
    zero = jnp.zeros_like(ct)
    return jnp.stack(
        [
            jnp.stack([cp * ct, -sp, cp * st]),
            jnp.stack([sp * ct, cp, sp * st]),
            jnp.stack([-st, zero, ct]),
        ]
    )


# Arms of up to this many segments compose their frames in an unrolled Python loop; longer
# arms in a lax.scan, whose trace (and compile time) does not grow with the number of segments
# (docs: Performance, "Arms of many segments").
UNROLL_SEGMENTS = 4


def _chain(q):
    """Base frames of all n segments and the tip frame (H_n^0 = prod H_i^{i-1}, paper §2.1).

    Returns:
      ``(R_bases (n, 3, 3), P_bases (n, 3), R_tip (3, 3), P_tip (3,))``.
    """
    if q.shape[0] <= UNROLL_SEGMENTS:
        return _chain_unrolled(q)
    return _chain_scanned(q)


def _chain_unrolled(q):
    """:func:`_chain` as a Python loop over the segments: straight-line code that XLA fuses,
    cheaper to compile and run inside the solvers' loops than a scan for a few segments."""
    R = jnp.eye(3, dtype=q.dtype)
    P = jnp.zeros(3, dtype=q.dtype)
    Rs, Ps = [], []
    for i in range(q.shape[0]):
        Rs.append(R)
        Ps.append(P)
        R_i, P_i = _rotation(q[i]), arc_point_local(q[i], jnp.ones_like(q[i][0]))
        R, P = R @ R_i, P + R @ P_i
    return jnp.stack(Rs), jnp.stack(Ps), R, P


def _chain_scanned(q):
    """:func:`_chain` as a ``lax.scan`` over the segments: one traced segment whatever n.

    The segments' own transforms ``(R_i, P_i)`` are computed side by side (vmap), then
    composed base to tip, ``(R, P) <- (R R_i, P + R P_i)``.
    """
    R_i = jax.vmap(_rotation)(q)
    P_i = jax.vmap(lambda q_i: arc_point_local(q_i, jnp.ones_like(q_i[0])))(q)

    def compose(frame, segment):
        R, P = frame
        R_seg, P_seg = segment
        return (R @ R_seg, P + R @ P_seg), frame

    base = (jnp.eye(3, dtype=q.dtype), jnp.zeros(3, dtype=q.dtype))
    (R, P), (R_bases, P_bases) = jax.lax.scan(compose, base, (R_i, P_i))
    return R_bases, P_bases, R, P


# ----------------------------------------------------------------------------
# Public functions: one per operation. Each is plain and traceable; jit at the
# call site. Shapes are checked at trace time, values (finite, L > 0, s in
# [0, 1], index in range) only when the input is concrete (not a tracer).

def segment_transform(q_i):
    """The paper's ``R_i`` and ``P_i`` of one segment (paper §2.1).

    Args:
      q_i: (3,) ``[L_i, theta_i, phi_i]``.

    Returns:
      ``(R_i (3, 3), P_i (3,))``; ``P_i = [0, 0, L_i]`` at theta = 0.
    """
    if jnp.shape(q_i) != (3,):
        raise ValueError(f"q_i must be one row [L, theta, phi] of shape (3,); got {jnp.shape(q_i)}")
    q_i = check_configuration(jnp.reshape(q_i, (1, 3)))[0]
    return _rotation(q_i), arc_point_local(q_i, jnp.ones_like(q_i[0]))


def segment_frames(q):
    """Orientation and position of the base of every segment.

    Args:
      q: (n, 3) configuration.

    Returns:
      ``(R_bases (n, 3, 3), P_bases (n, 3))``: the paper's ``R_{i-1}^0`` and
      ``P_{i-1}^0`` for i = 1..n (segment 0's base is the identity at the origin).
    """
    R_bases, P_bases, _, _ = _chain(check_configuration(q))
    return R_bases, P_bases


def segment_point(q, i, s):
    """The paper's ``P_si``: the point at fraction ``s`` of segment ``i`` (0-based).

    Args:
      q: (n, 3) configuration.
      i: segment index (int, may be traced).
      s: scalar fraction in [0, 1].

    Returns:
      (3,) position in the base frame.
    """
    q = check_configuration(q)
    check_segment_index(i, q.shape[0])
    s = check_fraction(s).astype(q.dtype)
    R_bases, P_bases, _, _ = _chain(q)
    return P_bases[i] + R_bases[i] @ arc_point_local(q[i], s)


def _tip(q):
    return _chain(q)[3]


def _point_jacobian(q, i, s):
    return jax.jacfwd(segment_point)(q, i, s).reshape(3, 3 * q.shape[0])


def _tip_jacobian(q):
    return jax.jacfwd(tip_position)(q).reshape(3, 3 * q.shape[0])


# Called on concrete arrays (a script, a notebook), the functions below run as one compiled
# program each (found in the persistent compilation cache on later runs) instead of dozens of
# op-by-op dispatches (docs: "How the planner works inside"); inside a trace (jit,
# grad, vmap) they are traced as they are, so the planner's programs do not change.
_tip_jit = package_jit(_tip, None)
_point_jacobian_jit = package_jit(_point_jacobian, None)
_tip_jacobian_jit = package_jit(_tip_jacobian, None)


def tip_position(q):
    """Position of the arm tip, the translation of ``H_n^0`` (paper §2.1). (n, 3) -> (3,)."""
    q = check_configuration(q)
    return (_tip_jit if is_concrete(q) else _tip)(q)


def point_jacobian(q, i, s):
    """``J_si = dP_si/dq`` by ``jax.jacfwd`` (paper §2.2).

    Returns:
      (3, 3n): columns ``L_1, theta_1, phi_1, L_2, ...`` (``q`` flattened row-major).
    """
    q = check_configuration(q)
    check_segment_index(i, q.shape[0])
    s = check_fraction(s).astype(q.dtype)
    concrete = is_concrete(q) and is_concrete(s) and is_concrete(jnp.asarray(i))
    return (_point_jacobian_jit if concrete else _point_jacobian)(q, i, s)


def tip_jacobian(q):
    """``J_e``: Jacobian of the tip position, (3, 3n), by ``jax.jacfwd``."""
    q = check_configuration(q)
    return (_tip_jacobian_jit if is_concrete(q) else _tip_jacobian)(q)


def points_jacobian(q, segments, s):
    """Jacobians ``J_si = dP_si/dq`` of m arm points (paper §2.2).

    ``s`` is held fixed (the paper's J_si). Used by the planner's eq. (9). Up to
    ``UNROLL_SEGMENTS`` segments, one forward-mode pass through the frames with 3n
    tangents; longer arms segment by segment (:func:`_points_jacobian_by_segment`),
    whose cost grows as m n instead of m n^2.

    Args:
      q: (n, 3) configuration.
      segments: (m,) int segment indices.
      s: (m,) fractions.

    Returns:
      (m, 3, 3n) Jacobians (``q`` flattened row-major).
    """
    q = check_configuration(q)
    n = q.shape[0]
    if n > UNROLL_SEGMENTS:
        return _points_jacobian_by_segment(q, segments, s)

    def points(q):
        R_bases, P_bases, _, _ = _chain(q)
        local = jax.vmap(lambda i, s_k: arc_point_local(q[i], s_k))(segments, s)
        return P_bases[segments] + jnp.einsum("kab,kb->ka", R_bases[segments], local)

    return jax.jacfwd(points)(q).reshape(segments.shape[0], 3, 3 * n)


def _points_jacobian_by_segment(q, segments, s):
    """:func:`points_jacobian` one segment's columns at a time (vmap over points and segments).

    A point x of segment i is ``P_j + R_j (P_seg_j + R_seg_j y)`` for every j < i, where
    ``(R_j, P_j)`` is segment j's base frame, ``(R_seg_j, P_seg_j)`` its own transform and
    ``y`` the point in segment j's tip frame, which q_j does not move. So
    ``dx/dq_j = R_j d(P_seg_j + R_seg_j y)/dq_j`` for j < i, ``R_i d(arc point at s)/dq_i``
    for j = i, and 0 for j > i: each a 3x3 forward-mode Jacobian in q_j alone.
    """
    n = q.shape[0]
    R_bases, P_bases, R_tip, P_tip = _chain(q)
    local = jax.vmap(lambda i, s_k: arc_point_local(q[i], s_k))(segments, s)
    x = P_bases[segments] + jnp.einsum("kab,kb->ka", R_bases[segments], local)
    R_tips = jnp.concatenate([R_bases[1:], R_tip[None]])  # segment j's tip frame
    P_tips = jnp.concatenate([P_bases[1:], P_tip[None]])
    one = jnp.ones((), q.dtype)

    def block(x_k, i, s_k, j):
        y = R_tips[j].T @ (x_k - P_tips[j])
        through = jax.jacfwd(lambda q_j: arc_point_local(q_j, one) + _rotation(q_j) @ y)(q[j])
        on = jax.jacfwd(lambda q_j: arc_point_local(q_j, s_k))(q[j])
        own = jnp.where(j < i, through, jnp.where(j == i, on, jnp.zeros_like(on)))
        return R_bases[j] @ own  # (3, 3): d x / d q_j

    def columns(x_k, i, s_k):
        return jax.vmap(lambda j: block(x_k, i, s_k, j))(jnp.arange(n, dtype=i.dtype))  # (n, 3, 3)

    J = jax.vmap(columns)(x, segments, s)  # (m, n, 3, 3)
    return jnp.transpose(J, (0, 2, 1, 3)).reshape(segments.shape[0], 3, 3 * n)


def motion_bound(q_a, q_b):
    """A sound bound on how far any arm point moves between two configurations.

    The motion is the planner's Euler step, the straight line
    ``q(t) = q_a + t (q_b - q_a)``, t in [0, 1] (docs: Conventions, "Clearance
    and collision"). For every segment i the bound holds for every point
    ``P_si(q(t))``, s in [0, 1], and every t: ``|P_si(q(t)) - P_si(q_a)| <= bound[i]``.
    It is the conservative-advancement bound of continuous collision detection
    for articulated bodies (Schwarzer, Saha & Latombe 2005; Redon et al. 2005),
    derived here for the PCC chain of paper §2.1.

    Derivation. Write ``dq_j = (dL_j, dtheta_j, dphi_j)`` and let
    ``Lbar_j = max(L_j(0), L_j(1))`` bound L_j on the whole motion (it is linear
    in t). A point x on segment i at fraction s moves with
    ``dx/dt = sum_{j <= i} (dx/dq_j) dq_j``, and each partial derivative is
    bounded uniformly in the configuration:

    * ``dphi_j``: ``R_j = Rz(phi_j) Ry(theta_j)`` and ``P_j = Rz(phi_j) p(theta_j)``,
      so phi_j turns segment j and everything after it rigidly about the z axis
      of segment j's base frame, through its base point: ``|dx/dphi_j|`` is the
      distance of x from that axis, at most the backbone length from the base of
      segment j to x, ``<= Lbar_j + ... + Lbar_i``.
    * ``dtheta_j``: in its bending plane segment j's point at fraction s is
      ``L s v(theta s)`` with ``v(a) = (1 - cos a, sin a) / a = (1/a) int_0^a
      (sin t, cos t) dt``, the mean unit tangent. ``v'(a) = (1/a^2) int_0^a
      (e(a) - e(t)) dt`` with ``|e(a) - e(t)| <= a - t``, so ``|v'| <= 1/2`` and a
      point of segment j moves by at most ``L_j s^2 / 2 <= Lbar_j / 2`` per unit
      theta_j. A point after segment j also turns with ``Ry(theta_j)`` at unit
      rate about an axis through segment j's tip: ``|dx/dtheta_j| <= Lbar_j / 2 +
      Lbar_{j+1} + ... + Lbar_i``.
    * ``dL_j``: the point of segment j is ``L s v(theta s)`` with ``|v| <= 1``,
      and the orientations do not depend on L: ``|dx/dL_j| <= 1``.

    Integrating ``|dx/dt|`` over t gives ``|x(t) - x(0)| <= sum_{j<=i} |dL_j| +
    |dtheta_j| (Lbar_j / 2 + Lbar_{j+1} + ... + Lbar_i) + |dphi_j| (Lbar_j + ... + Lbar_i)``.
    The bound grows along the chain, so ``bound[-1]`` bounds the whole arm. If
    the clearance to every obstacle at q_a exceeds ``bound[-1]``, no point of the
    arm can reach an obstacle anywhere on the motion. Length clipping does not
    break this: the planner clips q_b first and then moves on the straight line.

    Args:
      q_a: (n, 3) configuration at the start of the motion.
      q_b: (n, 3) configuration at its end.

    Returns:
      (n,) ``bound[i]``: no point of segments 0..i moves farther than this.
    """
    q_a = check_configuration(q_a)
    q_b = check_configuration(q_b)
    if q_a.shape != q_b.shape:
        raise ValueError(f"q_a and q_b must have the same shape; got {q_a.shape} and {q_b.shape}")
    dq = q_b - q_a
    L_bar = jnp.maximum(q_a[:, 0], q_a[:, 0] + dq[:, 0])  # L_j(t) <= L_bar_j on the whole motion
    dL, dtheta, dphi = jnp.abs(dq[:, 0]), jnp.abs(dq[:, 1]), jnp.abs(dq[:, 2])
    # S[k] = L_bar_0 + ... + L_bar_k: backbone length from the arm base to the tip of segment k.
    S = jnp.cumsum(L_bar)
    S_before = S - L_bar  # backbone length from the arm base to the base of segment k
    # For a point up to the tip of segment i, summed over j <= i:
    #   |dL_j| * 1 + |dtheta_j| * (L_bar_j / 2 + (S_i - S_j)) + |dphi_j| * (S_i - S_before_j)
    # = sum_j (|dL_j| + |dtheta_j| (L_bar_j / 2 - S_j) - |dphi_j| S_before_j) + S_i sum_j (|dtheta_j| + |dphi_j|).
    own = jnp.cumsum(dL + dtheta * (0.5 * L_bar - S) - dphi * S_before)
    return own + S * jnp.cumsum(dtheta + dphi)


def backbone_points(q, points_per_segment: int = 10):
    """Sampled backbone: segment i at s = j/k, j = 1..k (k = points_per_segment).

    This is the arm discretisation of the N-point method (paper Table 1: 10
    points per segment). Returns (n * k, 3), segment-major.
    """
    q = check_configuration(q)
    if int(points_per_segment) < 1:
        raise ValueError(f"points_per_segment must be >= 1, got {points_per_segment}")
    k = int(points_per_segment)
    R_bases, P_bases, _, _ = _chain(q)
    s = jnp.arange(1, k + 1, dtype=q.dtype) / k
    local = jax.vmap(lambda q_i: jax.vmap(lambda s_j: arc_point_local(q_i, s_j))(s))(q)
    pts = P_bases[:, None, :] + jnp.einsum("nab,nkb->nka", R_bases, local)
    return pts.reshape(-1, 3)
