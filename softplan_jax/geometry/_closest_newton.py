"""The Newton kernel of the closest-point solvers, and the default (reduced) solver (paper §2.3).
:func:`pair_terms` writes the gradient and Hessian of ``D^2 / 2`` (eqs. 13-18) once, and every
Newton loop shares one trust-region update (:func:`trust_region_radius`). The reduced solver
(:func:`solve_pair_reduced`) uses that a PCC segment (:class:`Segment`) is a circular arc:
``g(u) = min_s D_i(s, u)^2`` is exact in closed form (:func:`project_to_arc`; it contains the
s-boundary problems, eqs. 17-18), u = u_min and u = u_max are sampled (eqs. 15-16 and the endpoint
pairs), and the interior case is Newton on dD^2/du = 0 at s = s*(u) (eq. 14, with the Schur
complement of the 2x2 Hessian of eqs. 13-14 as its curvature; :func:`reduced_newton`) from the
smallest local minima of g on a u-grid and of an arm-side profile. The entry points and the
derivatives with respect to q are in :mod:`softplan_jax.geometry._closest`."""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._numerics import (
    atan_over_x,
    curvature_floor,
    one_minus_cos_over_x,
    safe_norm,
    sin_over_x,
    solver_tolerance,
)

__all__ = [
    "Segment",
    "PairTerms",
    "pair_terms",
    "trust_region_radius",
    "trust_region_step_1d",
    "local_minima_1d",
    "u_samples",
    "project_to_arc",
    "arc_distance2",
    "reduced_newton_step",
    "reduced_newton",
    "reduced_newton_loop",
    "solve_pair_reduced",
    "first_order_converged",
]


class Segment(NamedTuple):
    """Segment i as the closest-point solvers see it, with what is fixed during a
    planner step computed once (:meth:`from_frame`) instead of in every Newton
    iteration: the base point, the bending plane's two directions in world
    coordinates, and the trigonometric ratios of theta. ``point(s)`` is the
    paper's F_Ri(s) (§2.3). Fields may carry a leading segment axis.

    Attributes:
      L, theta: () the segment's length and bending angle (its row of q).
      P: (3,) its base point P_{i-1}^0.
      bend: (3,) the bending direction ``R_{i-1}^0 (cos phi, sin phi, 0)``.
      axis: (3,) the base tangent ``R_{i-1}^0 (0, 0, 1)``.
      sin_ratio: () ``sin(theta) / theta``; cos_ratio: () ``(1 - cos theta) / theta^2``
        (both finite at theta = 0; :func:`project_to_arc`'s end test).
      normal: (3,) the bending plane's normal ``R_{i-1}^0 (-sin phi, cos phi, 0)``.
      cos_theta: () ``cos(theta)``; tip: (3,) the segment's end ``F_Ri(1)``
        (both for :func:`arc_distance2`).
    """

    L: jax.Array
    theta: jax.Array
    P: jax.Array
    bend: jax.Array
    axis: jax.Array
    sin_ratio: jax.Array
    cos_ratio: jax.Array
    normal: jax.Array
    cos_theta: jax.Array
    tip: jax.Array

    @classmethod
    def from_frame(cls, q_i, R, P):
        """From a row of q (..., 3) and the segment's base frame R (..., 3, 3), P (..., 3)
        (:func:`~softplan_jax.geometry._kinematics.segment_frames`); leading axes are kept."""
        L, theta, phi = q_i[..., 0], q_i[..., 1], q_i[..., 2]
        cp, sp = jnp.cos(phi)[..., None], jnp.sin(phi)[..., None]
        bend = R[..., :, 0] * cp + R[..., :, 1] * sp
        normal = R[..., :, 1] * cp - R[..., :, 0] * sp
        axis = R[..., :, 2]
        sin_ratio = sin_over_x(theta)
        half = sin_over_x(0.5 * theta)  # sin_over_x(t/2)^2 / 2 = (1 - cos t)/t^2
        cos_ratio = 0.5 * half * half
        # F_Ri(1) = P + L (theta cos_ratio bend + sin_ratio axis) (paper §2.2 at s = 1).
        tip = P + (L * theta * cos_ratio)[..., None] * bend + (L * sin_ratio)[..., None] * axis
        return cls(L, theta, P, bend, axis, sin_ratio, cos_ratio, normal, jnp.cos(theta), tip)

    def point(self, s):
        # F_Ri(s), paper §2.3: P + R (r cos phi, r sin phi, a) with the radial and axial
        # parts r = L s (1 - cos x)/x, a = L s sin(x)/x of paper §2.2 (x = theta s).
        x = self.theta * s
        Ls = self.L * s
        return self.P + (Ls * one_minus_cos_over_x(x)) * self.bend + (Ls * sin_over_x(x)) * self.axis

    def derivatives(self, s):
        # dF/ds = L (sin x bend + cos x axis), d2F/ds2 = L theta (cos x bend - sin x axis), x = theta s.
        x = self.theta * s
        sx, cx = jnp.sin(x), jnp.cos(x)
        return self.L * (sx * self.bend + cx * self.axis), (self.L * self.theta) * (cx * self.bend - sx * self.axis)


class PairTerms(NamedTuple):
    """Paper eqs. 13-18 at one (s, u): the terms of f = |F_Ri(s) - F_o(u)|^2 / 2.

    Attributes:
      r: (3,) F_Ri(s) - F_o(u).
      A1, A2: (3,) dF_Ri/ds, d2F_Ri/ds2.
      C1, C2: (3,) dF_o/du, d2F_o/du2.
      gs, gu: () df/ds = r . A1 (eq. 13; eqs. 15-16 on the u bounds) and
        df/du = -r . C1 (eq. 14; eqs. 17-18 on the s bounds).
      a, b, c: () the Hessian [[a, b], [b, c]] of f: a = A1.A1 + r.A2,
        b = -A1.C1, c = C1.C1 - r.C2.
    """

    r: jax.Array
    A1: jax.Array
    A2: jax.Array
    C1: jax.Array
    C2: jax.Array
    gs: jax.Array
    gu: jax.Array
    a: jax.Array
    b: jax.Array
    c: jax.Array


def pair_terms(seg: Segment, curve, s, u) -> PairTerms:
    """The Newton kernel: gradient and Hessian of |F_Ri(s) - F_o(u)|^2 / 2
    (paper eqs. 13-18), the one place where they are written out."""
    r = seg.point(s) - curve.point(u)
    A1, A2 = seg.derivatives(s)
    C1, C2 = curve.derivative(u), curve.second_derivative(u)
    return PairTerms(
        r, A1, A2, C1, C2,
        gs=jnp.dot(r, A1),
        gu=-jnp.dot(r, C1),
        a=jnp.dot(A1, A1) + jnp.dot(r, A2),
        b=-jnp.dot(A1, C1),
        c=jnp.dot(C1, C1) - jnp.dot(r, C2),
    )


def trust_region_radius(better, grow, radius):
    """The trust-region update shared by every Newton loop: an accepted step
    (``better``) doubles the radius (at most 1, a fraction of the box) where
    ``grow``, else keeps it; a rejected step shrinks it fourfold."""
    return jnp.where(better, jnp.where(grow, jnp.minimum(2.0 * radius, 1.0), radius), 0.25 * radius)


def trust_region_step_1d(x, step, radius, width, lo, hi):
    """A 1-D Newton step capped to the trust radius (``radius * width``) and
    clipped to [lo, hi]. Returns (trial point, whether the step was uncapped)."""
    cap = radius * width
    full = jnp.abs(step) <= cap
    return jnp.clip(x + jnp.clip(step, -cap, cap), lo, hi), full


def local_minima_1d(vals, k: int):
    """Indices (k,) of the k smallest local minima of a 1-D array (non-minima last, by
    index; distinct indices). k passes of argmin, not ``lax.top_k`` (a sort on CPU):
    the same indices, cheaper (docs: "How the planner works inside")."""
    inf = jnp.full((1,), jnp.inf, vals.dtype)
    padded = jnp.concatenate([inf, vals, inf])
    is_min = (vals <= padded[:-2]) & (vals <= padded[2:])
    score = jnp.where(is_min, vals, jnp.finfo(vals.dtype).max)
    picks = []
    for _ in range(k):
        i = jnp.argmin(score)
        picks.append(i)
        score = score.at[i].set(jnp.inf)
    return jnp.stack(picks).astype(jnp.int32)


def u_samples(curve, n: int):
    """n sorted values of u over [u_min, u_max], both ends included: half evenly
    spaced in u, half evenly spaced in arc length along the curve (from a
    4n-point polyline). A steep or long stretch of the curve gets samples as
    dense in space as a flat one, and a slow stretch (near a parabola's
    vertex, say) keeps its share too."""
    u_lo, u_hi = curve.u_range[0], curve.u_range[1]
    dtype = u_lo.dtype
    n_len = n // 2
    uniform = u_lo + (u_hi - u_lo) * jnp.linspace(0.0, 1.0, n - n_len, dtype=dtype)
    u_fine = u_lo + (u_hi - u_lo) * jnp.linspace(0.0, 1.0, 4 * n, dtype=dtype)
    pts = jax.vmap(curve.point)(u_fine)
    cum = jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(safe_norm(jnp.diff(pts, axis=0)))])
    total = cum[-1]
    t = (jnp.arange(n_len, dtype=dtype) + 0.5) / n_len
    by_length = jnp.interp(t * total, cum, u_fine)
    by_length = jnp.where(total > 0, by_length, u_lo + (u_hi - u_lo) * t)
    # Clipped: u_lo + (u_hi - u_lo) * 1 can round one ulp past u_hi.
    return jnp.clip(jnp.sort(jnp.concatenate([uniform, by_length])), u_lo, u_hi)


# ----------------------------------------------------------------------------
# The reduced solver: the minimum over s in closed form, Newton in u.


def project_to_arc(seg: Segment, p):
    """Global minimiser s* in [0, 1] of |F_Ri(s) - p|^2 and its value, in closed form.

    A PCC segment is a circular arc (a straight line at theta = 0). With x the
    component of p along the bending direction (cos phi, sin phi, 0) and z the
    axial one, both in the segment's base frame (``seg.bend``, ``seg.axis``), the squared distance to the
    arc point at angle a = theta s is, up to terms free of a,
    ``-(2 L / theta^2) h(a)`` with ``h(a) = (L - x theta) cos a + z theta sin a``,
    maximal over the whole circle at ``a* = atan2(z theta, L - x theta)``. If
    ``a*`` (or ``a* +- 2 pi`` when |theta| > pi) lies on the arc it is the
    minimiser; otherwise the minimiser is the end with the larger h:
    ``h(theta) - h(0) = theta^2 [z sin(theta)/theta - (L - x theta)(1 - cos theta)/theta^2]``,
    whose bracket is finite at theta = 0. For ``L - x theta > 0`` the ratio
    ``a*/theta`` is written ``z / (L - x theta) atan(w)/w`` with
    ``w = z theta / (L - x theta)``, exact and finite down to theta = 0, where
    it is the projection on the straight segment.
    """
    L, theta = seg.L, seg.theta
    d = p - seg.P
    x = jnp.dot(d, seg.bend)
    z = jnp.dot(d, seg.axis)
    X = L - x * theta
    pos = X > 0
    X_safe = jnp.where(pos, X, 1.0)
    s_pos = z / X_safe * atan_over_x(z * theta / X_safe)
    a_star = jnp.arctan2(z * theta, X)
    s_neg = a_star / jnp.where(pos, 1.0, theta)  # theta != 0 when L - x theta <= 0
    s_a = jnp.where(pos, s_pos, s_neg)
    big = jnp.abs(theta) > 1.0
    theta_big = jnp.where(big, theta, 1.0)
    two_pi = 2.0 * jnp.pi
    s_b = (a_star + two_pi) / theta_big
    s_c = (a_star - two_pi) / theta_big

    def on_arc(v):
        return (v >= 0.0) & (v <= 1.0)

    # The end with the larger h (the segment's ratios, computed once per step).
    far_end = z * seg.sin_ratio - X * seg.cos_ratio > 0
    s_end = jnp.where(far_end, 1.0, 0.0).astype(L.dtype)
    s_star = jnp.where(
        on_arc(s_a), s_a, jnp.where(big & on_arc(s_b), s_b, jnp.where(big & on_arc(s_c), s_c, s_end))
    )
    return s_star, jnp.sum((seg.point(s_star) - p) ** 2)


def arc_distance2(seg: Segment, p):
    """``min_s |F_Ri(s) - p|^2`` over s in [0, 1]: :func:`project_to_arc`'s value
    without its minimiser, in square roots and divisions only (no trigonometry).

    With x, y, z the components of ``d = p - P`` along the bending direction,
    the plane's normal and the base tangent, the arc lies on the circle of
    radius ``r = L / theta`` centred at ``P + r bend`` in the plane y = 0; the
    distance from p to the whole circle is ``y^2 + (rho - r)^2`` with
    ``rho - r = (theta (x^2 + z^2) - 2 x L) / (S + L)``, ``S = sqrt((L - x
    theta)^2 + (z theta)^2)`` (the difference ``rho - r`` multiplied out, free of
    cancellation and finite at theta = 0, where it is ``-x``: the line). The
    circle's nearest point, at angle ``a* = atan2(z theta, L - x theta)``, lies on
    the arc (a in [0, theta], or [theta, 0]) iff ``A = z >= 0`` and ``B = z cos
    theta <= (L - x theta) sin(theta)/theta`` when |theta| <= pi (sin a* and
    sin(a* - theta) of the right signs), iff A or B when pi < |theta| < 2 pi (the
    gap is the complement), and always when |theta| >= 2 pi. Otherwise the
    minimum is at an end: the smaller of ``|d|^2`` and ``|p - F_Ri(1)|^2``.
    """
    L, theta = seg.L, seg.theta
    d = p - seg.P
    x, y, z = jnp.dot(d, seg.bend), jnp.dot(d, seg.normal), jnp.dot(d, seg.axis)
    X = L - x * theta
    # At the circle's centre (X = z theta = 0) every arc point is equally far: floor
    # the root's argument so that its derivative stays finite there.
    den = jnp.sqrt(jnp.maximum(X * X + (z * theta) ** 2, jnp.finfo(X.dtype).tiny)) + L
    radial = (theta * (x * x + z * z) - 2.0 * x * L) / jnp.where(den > 0, den, 1.0)
    A = z >= 0.0
    B = z * seg.cos_theta <= X * seg.sin_ratio
    abs_theta = jnp.abs(theta)
    on_arc = jnp.where(abs_theta <= jnp.pi, A & B, A | B) | (abs_theta >= 2.0 * jnp.pi)
    e = p - seg.tip
    ends = jnp.minimum(jnp.dot(d, d), jnp.dot(e, e))
    return jnp.where(on_arc, y * y + radial * radial, ends)


def reduced_newton_step(seg: Segment, curve, state):
    """One iteration of :func:`reduced_newton` for one pair: state (u, s, f, radius)
    -> the next state."""
    u, s, f, radius = state
    dtype = u.dtype
    lo, hi = curve.u_range[0], curve.u_range[1]
    width = hi - lo
    t = pair_terms(seg, curve, s, u)
    gu, a, b, c = t.gu, t.a, t.b, t.c
    interior = (s > 0.0) & (s < 1.0) & (a > 0.0)
    curv = jnp.where(interior, c - b * b / jnp.where(interior, a, 1.0), c)
    floor = curvature_floor(jnp.abs(c) + jnp.dot(t.C1, t.C1) + jnp.finfo(dtype).tiny, dtype)
    step = jnp.where(curv > floor, -gu / jnp.where(curv > floor, curv, 1.0), -jnp.sign(gu) * width)
    u_t, full = trust_region_step_1d(u, step, radius, width, lo, hi)
    s_t, d2_t = project_to_arc(seg, curve.point(u_t))
    better = d2_t < f
    radius = trust_region_radius(better, ~full, radius)
    return (jnp.where(better, u_t, u), jnp.where(better, s_t, s), jnp.where(better, d2_t, f), radius)


def reduced_newton(seg: Segment, curve, u0, s0, f0, iterations: int):
    """Trust-region Newton on g(u) = min_s D_i(s, u)^2 / 2 from u0 (s0 = s*(u0)).

    Gradient by the envelope theorem, ``g' = -r . F_o'(u)`` with ``r = F_Ri(s*)
    - F_o(u)`` (paper eq. 14 at the optimal s). Curvature: for an interior s*
    the Schur complement of the 2x2 Hessian of eqs. 13-14,
    ``c - b^2 / a``; for s* at an end (paper eqs. 17-18) ``c`` itself. A
    non-positive curvature gives a gradient step of the trust radius. A step is
    accepted only if it lowers g (the radius doubles if the step had been cut
    to it); a rejected step shrinks the radius fourfold. Every iterate lies in
    [u_min, u_max].

    u0, s0, f0 may carry leading axes (several starts on the same pair): they
    are vmapped INSIDE the loop body, which gives what vmapping this function
    gives without vmap's second tracing of the loop (tracing time is most of a
    rollout's compile time).
    """
    step = partial(reduced_newton_step, seg, curve)
    for _ in range(jnp.ndim(u0)):
        step = jax.vmap(step)
    return reduced_newton_loop(step, u0, s0, f0, iterations)


def reduced_newton_loop(step, u0, s0, f0, iterations: int):
    """The loop of :func:`reduced_newton`: ``iterations`` calls of ``step``, a
    :func:`reduced_newton_step` vmapped to the shape of u0 (one pair per element;
    the warm start's polish maps it over every (curve, segment) pair), from the
    initial trust radius 0.05 in u. Returns (u, s, f)."""
    radius0 = jnp.full(jnp.shape(u0), 0.05, u0.dtype)
    u, s, f, _ = jax.lax.fori_loop(0, iterations, lambda _, state: step(state), (u0, s0, f0, radius0))
    return u, s, f


def _curve_newton(curve, p, u0, iterations: int, radius0: float):
    """Safeguarded 1-D Newton on |p - F_o(u)|^2 / 2 over u in the curve's range
    from u0 (the point-to-curve half of paper eq. 14), with the trust region of
    :func:`reduced_newton`. Returns (u, |p - F_o(u)|^2)."""
    lo, hi = curve.u_range[0], curve.u_range[1]
    width = hi - lo
    dtype = u0.dtype

    def body(_, state):
        u, fu, radius = state
        r = curve.point(u) - p
        C1, C2 = curve.derivative(u), curve.second_derivative(u)
        g = jnp.dot(r, C1)
        h = jnp.dot(C1, C1) + jnp.dot(r, C2)
        ok = h > curvature_floor(jnp.dot(C1, C1) + jnp.finfo(dtype).tiny, dtype)
        step = jnp.where(ok, -g / jnp.where(ok, h, 1.0), -jnp.sign(g) * width)
        u_t, full = trust_region_step_1d(u, step, radius, width, lo, hi)
        r_t = p - curve.point(u_t)
        f_t = jnp.dot(r_t, r_t)
        better = f_t < fu
        radius = trust_region_radius(better, ~full, radius)
        return jnp.where(better, u_t, u), jnp.where(better, f_t, fu), radius

    r0 = p - curve.point(u0)
    u, fu, _ = jax.lax.fori_loop(0, iterations, body, (u0, jnp.dot(r0, r0), jnp.asarray(radius0, dtype)))
    return u, fu


def solve_pair_reduced(seg: Segment, curve, u_grid, C_grid, options):
    """All three cases for one segment and one curve via the reduced problem.

    ``min_{s, u} D^2 = min_u g(u)`` with ``g(u) = min_s D^2(s, u)`` exact in
    closed form (:func:`project_to_arc`), which already contains the
    s-boundary cases (paper eqs. 17-18: s* = 0 or 1) and, at u = u_min/u_max,
    the u-boundary cases and the endpoint pairs (eqs. 15-16, case 3).

    Starts for Newton in u (:func:`reduced_newton`, the stationarity equation
    dD^2/du = 0 at s*(u), eq. 14): the ``starts`` smallest local minima of g
    sampled on ``u_grid`` (both ends included), and the ``starts`` smallest
    local minima of the arm-side profile — for each of ``grid_s`` points along
    the segment, its nearest curve point (best sample, polished by
    ``projection_iterations`` 1-D Newton steps). The profile finds a basin of
    g narrower than the u-samples' spacing (a long, fast curve passing close
    to the arm). The best sample is a candidate too, so the answer is never
    worse than the grid. ``options``: a :class:`~softplan_jax.geometry._closest.SolverOptions`.
    Returns (s, u, D^2, converged).
    """
    dtype = seg.L.dtype
    k = options.starts
    g_grid = jax.vmap(lambda c: arc_distance2(seg, c))(C_grid)
    # Arm-side profile.
    s_arm = jnp.linspace(0.0, 1.0, options.grid_s, dtype=dtype)
    A = jax.vmap(seg.point)(s_arm)
    near = jnp.argmin(jnp.sum((A[:, None, :] - C_grid[None, :, :]) ** 2, axis=-1), axis=1)
    radius0 = 2.0 / options.grid_u  # about two sample spacings
    u_prof, f_prof = jax.vmap(lambda p, u0: _curve_newton(curve, p, u0, options.projection_iterations, radius0))(
        A, u_grid[near]
    )
    u_seed = u_prof[local_minima_1d(f_prof, k)]
    s_seed, g_seed = jax.vmap(lambda u: project_to_arc(seg, curve.point(u)))(u_seed)
    # The grid's seeds and best sample (their minimisers s* in closed form only here).
    kg = local_minima_1d(g_grid, k)
    kg = jnp.concatenate([kg, jnp.argmin(g_grid)[None].astype(kg.dtype)])
    s_kg, f_kg = jax.vmap(lambda c: project_to_arc(seg, c))(C_grid[kg])
    u0 = jnp.concatenate([u_grid[kg[:k]], u_seed])
    s0 = jnp.concatenate([s_kg[:k], s_seed])
    f0 = jnp.concatenate([f_kg[:k], g_seed])
    u_n, s_n, f_n = reduced_newton(seg, curve, u0, s0, f0, options.iterations)
    u_c = jnp.concatenate([u_n, u_grid[kg[k:]]])
    s_c = jnp.concatenate([s_n, s_kg[k:]])
    f_c = jnp.concatenate([f_n, f_kg[k:]])
    best = jnp.argmin(f_c)
    x = jnp.stack([s_c[best], u_c[best]])
    return x[0], x[1], f_c[best], first_order_converged(seg, curve, x)


def first_order_converged(seg: Segment, curve, x):
    """Projected-gradient test of the first-order conditions (paper eqs. 13-18)
    at x = (s, u): () bool, the solver's ``converged``."""
    s, u = x[0], x[1]
    dtype = x.dtype
    t = pair_terms(seg, curve, s, u)
    A1, C1, gs, gu = t.A1, t.C1, t.gs, t.gu
    # A bound-constrained coordinate is stationary if the gradient pushes outward.
    gs = jnp.where((s <= 0.0) & (gs > 0), 0.0, jnp.where((s >= 1.0) & (gs < 0), 0.0, gs))
    u_lo, u_hi = curve.u_range[0], curve.u_range[1]
    gu = jnp.where((u <= u_lo) & (gu > 0), 0.0, jnp.where((u >= u_hi) & (gu < 0), 0.0, gu))
    scale = 1.0 + safe_norm(seg.point(s)) + safe_norm(curve.point(u))
    tol = solver_tolerance(dtype) * scale
    return (jnp.abs(gs) <= tol * (safe_norm(A1) + 1.0)) & (jnp.abs(gu) <= tol * (safe_norm(C1) + 1.0))
