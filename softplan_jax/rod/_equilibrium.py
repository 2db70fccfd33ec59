"""The static equilibrium of the loaded arm: a Kirchhoff rod (inextensible, unshearable) per
segment, whose intrinsic curvature is the PCC curvature of q, under its weight and a tip load,
base clamped at the origin with the paper's base frame (section 2.1), free tip.

The equations (Antman 2005, ch. 8; Rucker & Webster 2011, eqs. 1-6; Till, Aloi & Rucker 2019),
in arc length s, world frame, gravity along -z:

* ``p' = R e3``, ``R' = R [u]x`` (inextensible, unshearable);
* ``R^T m = K (u - u*_i)``, ``K = diag(EI, EI, GJ)`` (linear elastic; the actuators' uniform
  moment ``EI u*_i`` per segment);
* ``n' + f = 0`` with ``f = -w e_z`` and ``n(L) = F``: the internal force in closed form,
  ``n(s) = F - e_z * (weight of the rod beyond s)``;
* ``m' + p' x n = 0`` with ``m(L) = 0`` (free tip).

Only the moment needs a solve: shooting on the base moment ``m(0)`` (3 unknowns), Newton with
backtracking on the tip moment, differentiated implicitly by ``jax.lax.custom_root`` (the
implicit-function theorem: one 3 x 3 solve per tangent, never the Newton iterations). The
integrator is the Runge-Kutta-Munthe-Kaas method of order 4 on SE(3) x R^3 (Munthe-Kaas 1999):
each step is a rigid-body exponential, so a piece of constant curvature (no load: m = 0) is
integrated exactly and the unloaded rod is the PCC shape to rounding.

The material frame is the PCC arc's rotation-minimising frame (no twist along the unloaded
backbone), so the intrinsic curvature of segment i is ``(theta_i / L_i) (-sin Phi_i, cos Phi_i, 0)``
with ``Phi_i = phi_1 + ... + phi_i`` (the paper's frames turn by phi_i at each segment's base).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import solve_small
from ..base._validation import check_configuration, check_int, is_concrete
from ._lie import se3_bracket, se3_exp
from ._model import RodModel, per_segment, segment_material

__all__ = [
    "LoadedShape",
    "DEFAULT_STEPS",
    "intrinsic_curvature",
    "solve_equilibrium",
    "loaded_backbone",
    "loaded_points",
    "loaded_points_jacobian",
]

# Integration steps per segment (order 4: the unloaded rod is exact; see docs/loaded-arm.md
# for the error against finer solutions).
DEFAULT_STEPS = 16
# Newton iterations at most (all load stages together), per load stage, halvings of a step in
# the backtracking line search, and the smallest load step of the continuation.
MAX_NEWTON = 60
STAGE_NEWTON = 12
MAX_HALVINGS = 12
MIN_LOAD_STEP = 1.0 / 64


class LoadedShape(NamedTuple):
    """The loaded rod at its integration nodes: node j of segment i is at fraction j / steps
    (a segment's last node is the next one's first).

    Fields:
      positions: (n, steps + 1, 3) backbone points.
      rotations: (n, steps + 1, 3, 3) material frames (column 3: the tangent).
      moments: (n, steps + 1, 3) internal moment m (world frame, N m).
      base_moment: (3,) the solved m(0).
      converged: () bool, the tip moment within tolerance.
      residual: () |m(L)| relative to the load's largest moment ``L (|F| + W)``.
      iterations: () Newton iterations taken.
    """

    positions: jax.Array
    rotations: jax.Array
    moments: jax.Array
    base_moment: jax.Array
    converged: jax.Array
    residual: jax.Array
    iterations: jax.Array


class _Steps(NamedTuple):
    """Per integration step (leading axis n * steps): body curvature u* (3,), compliance
    K^-1 diagonal (3,), length h, the weight beyond the step's start W0, weight per length w."""

    u_star: jax.Array
    compliance: jax.Array
    h: jax.Array
    W0: jax.Array
    w: jax.Array


def intrinsic_curvature(q):
    """Body-frame intrinsic curvature (n, 3) of each segment: the PCC arc of q in the
    rotation-minimising material frame, ``(theta_i / L_i) (-sin Phi_i, cos Phi_i, 0)``,
    ``Phi_i = phi_1 + ... + phi_i`` (paper section 2.1: R_i = Rz(phi_i) Ry(theta_i))."""
    q = check_configuration(q)
    kappa = q[:, 1] / q[:, 0]
    Phi = jnp.cumsum(q[:, 2])
    return jnp.stack([-kappa * jnp.sin(Phi), kappa * jnp.cos(Phi), jnp.zeros_like(kappa)], axis=-1)


def step_data(q, model: RodModel, steps: int) -> tuple[_Steps, jax.Array]:
    """The per-step data and the tip load F (3,)."""
    n = q.shape[0]
    EI, GJ, w, F = segment_material(model, n, q.dtype)
    L = q[:, 0]
    seg_weight = w * L
    beyond = jnp.cumsum(seg_weight[::-1])[::-1] - seg_weight  # weight of the segments after i
    j = jnp.arange(steps, dtype=q.dtype) / steps
    W0 = beyond[:, None] + seg_weight[:, None] * (1.0 - j[None, :])  # (n, steps)
    comp = jnp.stack([1.0 / EI, 1.0 / EI, 1.0 / GJ], axis=-1)
    rep = lambda x: jnp.repeat(x, steps, axis=0)
    data = _Steps(rep(intrinsic_curvature(q)), rep(comp), rep(L / steps), W0.reshape(-1), rep(w))
    return data, F


def _rkmk4(R, p, m, d: _Steps, F, h):
    """One step of length h (<= d.h) of the RKMK4 method from (R, p, m): body twist
    ``V = (u, e3)``, ``u = u* + K^-1 R^T m``, ``m' = -(R e3) x n`` (module docstring). The local
    coordinates of ``g = g_k exp(xi)`` obey ``xi' = dexp^-1_(-xi)(V) = V + [xi, V]/2 +
    [xi, [xi, V]]/12 + O(h^4)`` (body velocity ``g^-1 g' = V``; Munthe-Kaas 1999; Iserles et al.
    2000, sec. 4)."""
    e3 = jnp.array([0.0, 0.0, 1.0], R.dtype)

    def field(sig, xi, m_):
        dR, dp = se3_exp(xi)
        Rs = R @ dR
        u = d.u_star + d.compliance * (Rs.T @ m_)
        V = jnp.concatenate([u, e3])
        ad = se3_bracket(xi, V)
        dxi = V + 0.5 * ad + se3_bracket(xi, ad) / 12.0
        n = F - (d.W0 - d.w * sig) * e3
        return dxi, -jnp.cross(Rs[:, 2], n)

    z = jnp.zeros(6, R.dtype)
    k1 = field(0.0, z, m)
    k2 = field(0.5 * h, 0.5 * h * k1[0], m + 0.5 * h * k1[1])
    k3 = field(0.5 * h, 0.5 * h * k2[0], m + 0.5 * h * k2[1])
    k4 = field(h, h * k3[0], m + h * k3[1])
    xi = h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
    m_next = m + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
    dR, dp = se3_exp(xi)
    return R @ dR, p + R @ dp, m_next


def integrate(m0, data: _Steps, F):
    """Nodes (R (S+1, 3, 3), p (S+1, 3), m (S+1, 3)) from the base (R = I, p = 0, m = m0)."""
    dtype = m0.dtype
    start = (jnp.eye(3, dtype=dtype), jnp.zeros(3, dtype), m0)

    def body(state, d):
        nxt = _rkmk4(*state, d, F, d.h)
        return nxt, nxt

    _, (Rs, ps, ms) = jax.lax.scan(body, start, data)
    cat = lambda a, b: jnp.concatenate([a[None], b])
    return cat(start[0], Rs), cat(start[1], ps), cat(start[2], ms)


def _moments(m0, data: _Steps, F):
    """The internal moment (S+1, 3) at every node for the base moment m0."""
    return integrate(m0, data, F)[2]


def _tip_moment(m0, data: _Steps, F):
    """The shooting residual m(L) (3,) for the base moment m0."""
    dtype = m0.dtype

    def body(state, d):
        return _rkmk4(*state, d, F, d.h), None

    (_, _, m_tip), _ = jax.lax.scan(body, (jnp.eye(3, dtype=dtype), jnp.zeros(3, dtype), m0), data)
    return m_tip


def _tolerance(dtype) -> float:
    """Tip moment accepted as zero, relative to the load's largest moment."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 2e-4


def _newton(f, m0, tol, max_iterations):
    """Newton's method with backtracking on |f| from m0 until ``|f| <= tol``:
    ``(m, |f|, iterations)``."""

    def with_value(m):
        r = f(m)
        return r, r

    def cond(st):
        m, r, it = st
        return (jnp.linalg.norm(r) > tol) & (it < max_iterations) & jnp.all(jnp.isfinite(r))

    def body(st):
        m, r, it = st
        J, r = jax.jacfwd(with_value, has_aux=True)(m)
        step = -solve_small(J, r)
        step = jnp.where(jnp.all(jnp.isfinite(step)), step, 0.0)
        norm0 = jnp.linalg.norm(r)

        def ls_cond(ls):
            alpha, r_new, k = ls
            bad = ~(jnp.linalg.norm(r_new) < (1.0 - 1e-4 * alpha) * norm0)
            return bad & (k < MAX_HALVINGS)

        def ls_body(ls):
            alpha, _, k = ls
            alpha = 0.5 * alpha
            return alpha, f(m + alpha * step), k + 1

        one = jnp.ones((), m.dtype)
        alpha, r_new, _ = jax.lax.while_loop(ls_cond, ls_body, (one, f(m + step), 0))
        return m + alpha * step, r_new, it + 1

    m, r, it = jax.lax.while_loop(cond, body, (m0, f(m0), 0))
    return m, jnp.linalg.norm(r), it


def _vee(A):
    """The vector (..., 3) of the skew part of A (..., 3, 3)."""
    return 0.5 * jnp.stack([A[..., 2, 1] - A[..., 1, 2], A[..., 0, 2] - A[..., 2, 0], A[..., 1, 0] - A[..., 0, 1]], -1)


def _stable(m0, data: _Steps, F):
    """Stability of the equilibrium (the second variation of the energy positive definite), by
    the Jacobi fields of the clamped base: ``Theta(s) = d theta(s)/d m0`` (world rotation
    variation) and ``M(s) = d m(s)/d m0``. With ``M~ = M + [m]x Theta / 2`` the matrix
    ``S(s) = Theta^T M~`` is symmetric (the rod's equations are Hamiltonian), ``S ~ s K^-1`` near
    the base, and the equilibrium is stable where S stays positive definite on (0, L]: the
    Riccati matrix ``M~ Theta^-1`` is then defined and positive definite up to the free end
    (Legendre-Jacobi theory; Till & Rucker 2017; Kumar & Healey 2010). Checked at every node
    (Sylvester's leading minors). Returns ``(stable, smallest leading minor ratio)``."""
    m0 = jax.lax.stop_gradient(m0)
    JR, _, JM = jax.jacfwd(integrate)(m0, data, F)  # (S+1, 3, 3, 3), (S+1, 3, 3)
    Rs, _, ms = integrate(m0, data, F)
    Theta = _vee(jnp.einsum("kabj,kcb->kjac", JR, Rs))  # (S+1, 3 tangents, 3): d theta / d m0_j
    Theta = jnp.swapaxes(Theta, -1, -2)  # (S+1, 3, 3): column j = d theta / d m0_j
    M_t = JM + 0.5 * jnp.cross(ms[:, :, None], Theta, axisa=1, axisb=1, axisc=1)
    S = jnp.einsum("kai,kaj->kij", Theta, M_t)[1:]
    S = 0.5 * (S + jnp.swapaxes(S, -1, -2))
    d1 = S[:, 0, 0]
    d2 = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    d3 = jnp.linalg.det(S)
    ok = (d1 > 0) & (d2 > 0) & (d3 > 0)
    return jnp.all(ok), jnp.min(d3 / (d1 * d1 * d1 + jnp.finfo(S.dtype).tiny))


def _continuation(data: _Steps, F, m_init, scale):
    """The stable equilibrium at full load, reached by load continuation: Newton at load
    fraction lam = min(1, lam_done + dlam) from the last accepted moment, dlam doubled on
    success (a solved, stable stage) and halved on failure; the first attempt is the full load.
    Returns ``(m0, (relative residual, Newton iterations))``; the residual is +inf where the full
    load was not reached."""
    tol = _tolerance(m_init.dtype)
    dtype = m_init.dtype

    def at(lam):
        scaled = data._replace(W0=lam * data.W0, w=lam * data.w)
        return scaled, lam * F

    def cond(st):
        lam_done, m, dlam, it, _ = st
        return (lam_done < 1.0) & (dlam >= MIN_LOAD_STEP) & (it < MAX_NEWTON)

    def body(st):
        lam_done, m, dlam, it, res_done = st
        lam = jnp.minimum(1.0, lam_done + dlam)
        d, F_lam = at(lam)
        m_new, res, k = _newton(lambda x: _tip_moment(x, d, F_lam), m, tol * scale * lam, STAGE_NEWTON)
        good = (res <= tol * scale * lam) & _stable(m_new, d, F_lam)[0]
        return (jnp.where(good, lam, lam_done), jnp.where(good, m_new, m),
                jnp.where(good, 2.0 * dlam, 0.5 * dlam), it + k, jnp.where(good, res, res_done))

    one = jnp.ones((), dtype)
    inf = jnp.full((), jnp.inf, dtype)
    lam_done, m, _, it, res = jax.lax.while_loop(cond, body, (jnp.zeros((), dtype), m_init, one, 0, inf))
    # |m(L)| at the accepted full-load stage (Newton's own last residual), relative to the load's moment.
    return m, (jnp.where(lam_done >= 1.0, res / scale, jnp.inf), it.astype(dtype))


def solve_shape(q, model: RodModel, steps: int) -> LoadedShape:
    """:func:`solve_equilibrium` on checked input, traced as it is (no jit of its own)."""
    n = q.shape[0]
    data, F = step_data(q, model, steps)
    L_tot = jnp.sum(q[:, 0])
    scale = L_tot * (jnp.linalg.norm(F) + data.W0[0]) + jnp.finfo(q.dtype).tiny
    scale = jax.lax.stop_gradient(scale)

    def residual(m0):
        return _tip_moment(m0, data, F)

    def tangent_solve(g, y):  # jnp.linalg.solve: linear in y, so reverse mode can transpose it
        return jnp.linalg.solve(jax.jacfwd(g)(y), y)

    nograd = jax.lax.stop_gradient
    m0, (res, it) = jax.lax.custom_root(
        residual, jnp.zeros(3, q.dtype),
        lambda f, x0: _continuation(nograd(data), nograd(F), x0, scale), tangent_solve, has_aux=True)
    Rs, ps, ms = integrate(m0, data, F)
    # The continuation accepts only stable stages, so a finite residual at full load is a stable
    # equilibrium (the residual is +inf where the full load was not reached).
    converged = (res <= _tolerance(q.dtype)) & jnp.all(jnp.isfinite(ps))

    return segment_nodes(Rs, ps, ms, m0, converged, res, it.astype(jnp.int32), n, steps)


def segment_nodes(Rs, ps, ms, m0, converged, residual, iterations, n: int, steps: int) -> LoadedShape:
    """The :class:`LoadedShape` of an integration's nodes (S + 1, ...): each segment's
    ``steps + 1`` nodes (a segment's last node repeated as the next one's first)."""
    idx = jnp.arange(n)[:, None] * steps + jnp.arange(steps + 1)[None, :]
    return LoadedShape(ps[idx], Rs[idx], ms[idx], m0, converged, residual, iterations)


# Called on concrete arrays, the solve runs as one compiled program per shape (jit at the entry
# point); inside a trace it is traced as it is.
_solve_jit = package_jit(solve_shape, None, static_argnames=("steps",))


def _solve_entry(q, model, steps):
    if is_concrete(q) and model_is_concrete(model):
        return _solve_jit(q, per_segment(model, q.shape[0], q.dtype), steps)
    return (_solve_jit if is_concrete(q) else solve_shape)(q, model, steps)


def model_is_concrete(model) -> bool:
    """Every leaf of the model concrete (no tracer): the entry points may then jit."""
    return all(is_concrete(x) for x in jax.tree_util.tree_leaves(model))


def check_inputs(q, model, steps):
    """``(q, steps)`` checked: q a configuration, steps an int >= 1, model a RodModel whose
    per-segment fields fit q. ValueError otherwise."""
    q = check_configuration(q)
    steps = check_int(steps, "steps", 1)
    if not isinstance(model, RodModel):
        raise ValueError(f"model must be a softplan_jax.RodModel, got {type(model).__name__}")
    segment_material(model, q.shape[0], q.dtype)  # per-segment shapes against q
    return q, steps


def solve_equilibrium(q, model: RodModel, steps: int = DEFAULT_STEPS) -> LoadedShape:
    """The loaded arm's static equilibrium at configuration q (module docstring: the rod
    equations, shooting on m(0), implicit derivatives).

    Plain and traceable (jit, vmap over q and the model's leaves, grad/jacfwd through the
    implicit solve). Check ``converged``: a solve that did not converge is reported there,
    its shape is not the equilibrium.

    Args:
      q: (n, 3) configuration, rows [L_i, theta_i, phi_i].
      model: :class:`RodModel`.
      steps: integration steps per segment (static).

    Returns:
      :class:`LoadedShape`.
    """
    q, steps = check_inputs(q, model, steps)
    return _solve_entry(q, model, steps)


def point_on(shape: LoadedShape, q, model, steps: int, i, frac):
    """The point at fraction ``frac`` of segment i: a partial RKMK4 step from the node below."""
    data, F = step_data(q, model, steps)
    x = frac * steps
    j = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, steps - 1)
    i = jnp.asarray(i).astype(jnp.int32)
    h = (x - j.astype(x.dtype)) * q[i, 0] / steps
    d = jax.tree_util.tree_map(lambda a: a[i * steps + j], data)
    _, p, _ = _rkmk4(shape.rotations[i, j], shape.positions[i, j], shape.moments[i, j], d, F, h)
    return p


def unconverged_error(residual, iterations, model: RodModel):
    return ValueError(
        f"the loaded arm's equilibrium did not converge to a stable shape (relative tip moment {float(residual):.3g}"
        f" after {int(iterations)} Newton iterations): the rod cannot carry RodModel.weight_per_length="
        f"{model.weight_per_length!r} with tip_load={model.tip_load!r} at RodModel.bending_stiffness="
        f"{model.bending_stiffness!r} in this configuration (it buckles or folds); stiffen the rod or lighten the load")


def _points(q, model, segments, fractions, steps: int):
    shape = solve_shape(q, model, steps)
    pts = jax.vmap(lambda i, f: point_on(shape, q, model, steps, i, f))(segments, fractions)
    return jnp.where(shape.converged, pts, jnp.nan), shape.converged, shape.residual, shape.iterations


_points_jit = package_jit(_points, None, static_argnames=("steps",))


def loaded_points(q, model: RodModel, segments, fractions, steps: int = DEFAULT_STEPS):
    """Points (m, 3) of the loaded backbone at ``fractions`` (m,) of ``segments`` (m,) (int).

    Differentiable in q and the model through the implicit solve; NaN where the solve did not
    converge (a traced call), a ValueError for a concrete one.
    """
    q, steps = check_inputs(q, model, steps)
    fractions = jnp.asarray(fractions, q.dtype)
    segments = jnp.asarray(segments).astype(jnp.int32)
    if fractions.ndim != 1 or segments.shape != fractions.shape:
        raise ValueError(f"segments and fractions must be (m,) arrays of one length; got {segments.shape} and "
                         f"{fractions.shape}")
    concrete = is_concrete(q) and is_concrete(fractions) and is_concrete(segments) and model_is_concrete(model)
    if concrete:
        model = per_segment(model, q.shape[0], q.dtype)
    pts, converged, res, it = (_points_jit if concrete else _points)(q, model, segments, fractions, steps)
    if is_concrete(converged) and not bool(converged):
        raise unconverged_error(res, it, model)
    return pts


def _points_jacobian(q, model, segments, fractions, steps: int):
    jac = jax.jacfwd(lambda q_: _points(q_, model, segments, fractions, steps)[0])(q)
    return jac.reshape(jac.shape[0], 3, 3 * q.shape[0])


_points_jacobian_jit = package_jit(_points_jacobian, None, static_argnames=("steps",))


def loaded_points_jacobian(q, model: RodModel, segments, fractions, steps: int = DEFAULT_STEPS):
    """``d point / d q`` (m, 3, 3n) of the loaded backbone's points (:func:`loaded_points`),
    through the equilibrium (implicit differentiation of the shooting solve), q flattened
    row-major as in :func:`~softplan_jax.geometry._kinematics.point_jacobian`. NaN where the
    solve did not converge."""
    q, steps = check_inputs(q, model, steps)
    fractions = jnp.asarray(fractions, q.dtype)
    segments = jnp.asarray(segments).astype(jnp.int32)
    concrete = is_concrete(q) and is_concrete(fractions) and model_is_concrete(model)
    if concrete:
        model = per_segment(model, q.shape[0], q.dtype)
    return (_points_jacobian_jit if concrete else _points_jacobian)(q, model, segments, fractions, steps)


def loaded_backbone(q, model: RodModel, n: int, steps: int = DEFAULT_STEPS):
    """The loaded arm's backbone: ``n`` evenly spaced fractions of each segment, 0 and 1
    included (the ``s`` of :func:`~softplan_jax.geometry._kinematics.segment_point`).

    With no load (zero weight and tip load) this is the PCC shape of q (paper section 2.1).

    Args:
      q: (segments, 3) configuration.
      model: :class:`RodModel`.
      n: points per segment, >= 2.
      steps: integration steps per segment (static).

    Returns:
      (segments, n, 3) points; NaN where a traced solve did not converge.

    Raises:
      ValueError: bad q, model or n; for concrete input, a load the solve cannot carry.
    """
    n = check_int(n, "n", 2)
    q, steps = check_inputs(q, model, steps)
    segs = q.shape[0]
    fr = jnp.linspace(0.0, 1.0, n, dtype=q.dtype)
    seg = jnp.repeat(jnp.arange(segs), n)
    return loaded_points(q, model, seg, jnp.tile(fr, segs), steps).reshape(segs, n, 3)
