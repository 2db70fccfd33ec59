"""The loaded shape for the closest-point kernel: a chain of short constant-curvature pieces in
the paper's convention (section 2.1), itself a PCC configuration, with a proven bound on the
gap between the pieces and the equilibrium curve (docs/loaded-arm.md, "The gap").

Each segment is cut into p pieces of equal arc length h; piece k is the circular arc that starts
with the chain's tangent and ends with the equilibrium's tangent at the piece's end, so the
chain and the rod share their tangents at every piece boundary and their positions drift apart
only by what each piece's arc misses of the rod's turning inside it. With ``omega = t x t'``
the rod's bending angular velocity (world frame) and ``M >= |omega'|`` on the piece, the chain's
tangent stays within ``min(M sigma^2 / 2 + (sigma / h) c, M (h - sigma)^2 / 2 + (1 - sigma / h) c)``
of the rod's, ``c = lambda(R) 2 asin(M h^2 / 4)``, ``lambda(R) = R / sin R`` (the Lipschitz
constant of the sphere's logarithm on a cap of radius R < pi/2), so over the piece the positions
drift by at most ``Delta = M h^3 / 24 + c h / 4``. The gap is ``sum_k Delta_k``: no point of the
chain is farther than that from the rod's point at the same arc length. ``M`` is bounded from the
equilibrium: ``omega' = R (u x u_perp + u_perp')`` with ``u = u* + K^-1 R^T m`` and
``m' = -t x n``, so ``|omega'| <= (m/GJ)(|u*| + m/EI) + (|n| + |u*| m + |1/GJ - 1/EI| m^2 / 2)/EI``
with the bounds of |m| and |n| on the piece.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import safe_norm
from ..base._validation import check_int, is_concrete
from ._equilibrium import DEFAULT_STEPS, LoadedShape, check_inputs, model_is_concrete, solve_shape, unconverged_error
from ._model import RodModel, per_segment, segment_material

__all__ = ["loaded_pieces", "pieces_from_shape", "piece_location", "pieces_steps"]


def pieces_steps(pieces_per_segment: int, steps: int | None = None) -> int:
    """Integration steps per segment for ``pieces_per_segment`` pieces: a multiple of it (at least
    :data:`~softplan_jax.rod._equilibrium.DEFAULT_STEPS` when ``steps`` is None)."""
    p = check_int(pieces_per_segment, "pieces_per_segment", 1)
    if steps is None:
        return p * -(-DEFAULT_STEPS // p)
    steps = check_int(steps, "steps", 1)
    if steps % p:
        raise ValueError(f"steps ({steps}) must be a multiple of pieces_per_segment ({p})")
    return steps


def piece_location(piece, s, pieces_per_segment: int):
    """The segment and the fraction of it (both like ``piece``) of fraction ``s`` of ``piece``
    in the chain of :func:`loaded_pieces`: ``segment = piece // p``,
    ``fraction = (piece % p + s) / p``."""
    p = check_int(pieces_per_segment, "pieces_per_segment", 1)
    piece = jnp.asarray(piece)
    return piece // p, ((piece % p).astype(jnp.result_type(s)) + s) / p


def _chain_angles(tangents):
    """The paper's [theta_k, phi_k] (K, 2) of the arcs joining consecutive unit tangents
    (K + 1, 3), starting from the base frame F_0 = I: ``b = F_k^T t_{k+1}``, ``theta_k =
    atan2(|b_xy|, b_z)``, ``phi_k = atan2(b_y, b_x)``, ``F_{k+1} = F_k Rz(phi_k) Ry(theta_k)``
    (paper section 2.1). A straight piece gets phi = 0 (double-where: finite derivatives)."""
    dtype = tangents.dtype

    def step(F, t_next):
        b = F.T @ t_next
        r = safe_norm(b[:2])
        straight = r == 0
        theta = jnp.arctan2(r, b[2])
        phi = jnp.arctan2(jnp.where(straight, 0.0, b[1]), jnp.where(straight, 1.0, b[0]))
        ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
        zero = jnp.zeros_like(ct)
        R = jnp.stack([jnp.stack([cp * ct, -sp, cp * st]), jnp.stack([sp * ct, cp, sp * st]),
                       jnp.stack([-st, zero, ct])])  # Rz(phi) Ry(theta), paper section 2.1
        return F @ R, jnp.stack([theta, phi])

    _, angles = jax.lax.scan(step, jnp.eye(3, dtype=dtype), tangents[1:])
    return angles


def _piece_gaps(shape: LoadedShape, q, model: RodModel, p: int, angles):
    """Each piece's drift bound Delta_k (n p,) (module docstring), from the equilibrium's nodes."""
    n, nodes = shape.moments.shape[:2]
    steps = nodes - 1
    r = steps // p
    dtype = q.dtype
    EI, GJ, w, F = segment_material(model, n, dtype)
    L = q[:, 0]
    h = jnp.repeat(L / p, p)  # (n p,) piece lengths
    hf = jnp.repeat(L / steps, p)  # the integration step inside each piece
    # |n| at the piece ends: n(s) = F - W(s) e_z, W the weight beyond s (convex in s: max at ends).
    seg_weight = w * L
    beyond = jnp.cumsum(seg_weight[::-1])[::-1] - seg_weight
    j = jnp.arange(p + 1, dtype=dtype) / p
    W_ends = beyond[:, None] + seg_weight[:, None] * (1.0 - j[None, :])  # (n, p + 1)
    n_ends = jnp.linalg.norm(F[None, None, :] - W_ends[..., None] * jnp.array([0.0, 0.0, 1.0], dtype), axis=-1)
    n_bar = jnp.maximum(n_ends[:, :-1], n_ends[:, 1:]).reshape(-1)
    # |m| on the piece: the largest node value plus n_bar * hf / 2 (|m'| <= |n|).
    m_nodes = jnp.linalg.norm(shape.moments, axis=-1)  # (n, steps + 1)
    idx = jnp.arange(p)[:, None] * r + jnp.arange(r + 1)[None, :]  # (p, r + 1)
    m_bar = jnp.max(m_nodes[:, idx], axis=-1).reshape(-1) + 0.5 * n_bar * hf
    EI_k, GJ_k = jnp.repeat(EI, p), jnp.repeat(GJ, p)
    kappa = jnp.repeat(jnp.abs(q[:, 1]) / L, p)  # |u*| of the piece's segment
    M = (m_bar / GJ_k) * (kappa + m_bar / EI_k) + (
        n_bar + kappa * m_bar + jnp.abs(1.0 / GJ_k - 1.0 / EI_k) * 0.5 * m_bar * m_bar) / EI_k
    eps = 0.5 * M * h * h
    R = jnp.maximum(jnp.abs(angles[:, 0]), h * (kappa + m_bar / EI_k))
    lam = jnp.where(R < 0.5 * jnp.pi, R / jnp.sin(jnp.where(R > 0, R, 1.0)), jnp.inf)
    lam = jnp.where(R > 0, lam, 1.0)
    c = lam * 2.0 * jnp.arcsin(jnp.minimum(0.5 * eps, 1.0))
    return M * h**3 / 24.0 + 0.25 * c * h


def pieces_from_shape(shape: LoadedShape, q, model: RodModel, pieces_per_segment: int):
    """:func:`loaded_pieces` from a solved :class:`~softplan_jax.rod._equilibrium.LoadedShape`
    (its steps a multiple of ``pieces_per_segment``): ``(Q (n p, 3), gap ())``."""
    p = check_int(pieces_per_segment, "pieces_per_segment", 1)
    n, nodes = shape.rotations.shape[:2]
    steps = nodes - 1
    if steps % p:
        raise ValueError(f"the shape's {steps} steps per segment are not a multiple of pieces_per_segment ({p})")
    r = steps // p
    # Tangents at the piece boundaries, base first: segment i's nodes 0, r, 2r, ... (its last
    # node is the next segment's first), then the tip.
    t = shape.rotations[..., 2]  # (n, steps + 1, 3)
    ends = jnp.concatenate([t[:, :-1:r].reshape(-1, 3), t[-1, -1:]], axis=0)  # (n p + 1, 3)
    angles = _chain_angles(ends)
    Q = jnp.concatenate([jnp.repeat(q[:, :1] / p, p, axis=0), angles], axis=1)
    gap = jnp.sum(_piece_gaps(shape, q, model, p, angles))
    ok = shape.converged & jnp.all(jnp.isfinite(Q))
    return jnp.where(ok, Q, jnp.nan), jnp.where(ok, gap, jnp.nan)


def loaded_pieces(q, model: RodModel, pieces_per_segment: int, steps: int | None = None):
    """The loaded backbone as ``n p`` constant-curvature pieces, a PCC configuration in the
    paper's convention that :func:`~softplan_jax.closest_point` takes as it is, and the proven
    gap: no point of the pieces is farther than ``gap`` from the equilibrium's point at the same
    arc length (module docstring), so a clearance measured on the pieces, less ``gap``, is a
    lower bound of the loaded arm's.

    Piece ``k`` is fraction ``[k % p, k % p + 1] / p`` of segment ``k // p``
    (:func:`piece_location`). Differentiable in q and the model (through the implicit solve);
    at an exactly straight piece the paper's phi is singular and its derivative is taken as 0.

    Args:
      q: (n, 3) configuration.
      model: :class:`~softplan_jax.rod._model.RodModel`.
      pieces_per_segment: p >= 1 (static).
      steps: integration steps per segment, a multiple of p (None: :func:`pieces_steps`).

    Returns:
      ``(Q (n p, 3), gap ())``; NaN where a traced solve did not converge; ``gap`` is +inf
      where a piece turns by pi/2 or more (use more pieces).

    Raises:
      ValueError: bad input; for concrete input, a load the solve cannot carry.
    """
    p = check_int(pieces_per_segment, "pieces_per_segment", 1)
    steps = pieces_steps(p, steps)
    q, steps = check_inputs(q, model, steps)
    concrete = is_concrete(q) and model_is_concrete(model)
    if concrete:  # one program whether the model's fields are scalars or per segment
        model = per_segment(model, q.shape[0], q.dtype)
    Q, gap, converged, res, it = (_pieces_jit if concrete else _pieces)(q, model, p, steps)
    if is_concrete(converged) and not bool(converged):
        raise unconverged_error(res, it, model)
    return Q, gap


def _pieces(q, model, p: int, steps: int):
    shape = solve_shape(q, model, steps)
    return (*pieces_from_shape(shape, q, model, p), shape.converged, shape.residual, shape.iterations)


_pieces_jit = package_jit(_pieces, None, static_argnames=("p", "steps"))
