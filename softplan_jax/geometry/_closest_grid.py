"""The paper's 2-D closest-point solver (paper §2.3, eqs. 13-18), picked with
:class:`GridSolverOptions` wherever a solver is taken: Newton on both stationarity equations from
the local minima of ``D^2`` on a ``grid_s x grid_u`` grid of the (s, u) box and of two distance
profiles (case 1), from each edge's local minima (case 2, one coordinate free) and the four
endpoint pairs (case 3), with the shared kernel
(:func:`~softplan_jax.geometry._closest_newton.pair_terms`) and trust region
(:func:`~softplan_jax.geometry._closest_newton.trust_region_radius`), the Hessian shifted where it
is not positive definite and a coordinate on a bound held where its gradient points outward
(projected Newton). Kept as the paper's formulation and as a cross-check of the default solver
(:mod:`softplan_jax.geometry._closest_newton`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._numerics import psd_shift
from ._closest_newton import (
    Segment,
    first_order_converged,
    local_minima_1d,
    pair_terms,
    trust_region_radius,
    u_samples,
)

__all__ = ["GridSolverOptions", "solve_pair_grid"]


class GridSolverOptions(NamedTuple):
    """Static settings of the paper's 2-D solver (hashable; jit-static): pass it
    where a :class:`~softplan_jax.geometry._closest.SolverOptions` goes.

    Attributes:
      grid_s: grid points along each segment (s), ends included.
      grid_u: grid points along the curve (u), ends included.
      starts: interior (case 1) Newton starts taken from each of the grid's
        local minima and the two distance profiles (so 3 x starts in all).
      edge_starts: Newton starts per boundary problem (case 2).
      iterations: Newton iterations per start.
      projection_iterations: 1-D Newton steps that polish the distance profiles.
    """

    grid_s: int = 10
    grid_u: int = 32
    starts: int = 3
    edge_starts: int = 2
    iterations: int = 12
    projection_iterations: int = 4

    def pair_solver(self, curve):
        """``seg -> (s, u, D^2, converged)`` for one curve (derivatives w.r.t. q not propagated)."""
        return lambda seg: solve_pair_grid(seg, curve, self)


def _newton_step(seg: Segment, curve, x, free):
    """One safeguarded Newton step on f(s, u) = |F_Ri(s) - F_o(u)|^2 / 2.

    ``free`` (2,) bool says which of (s, u) may move: both for case 1 (paper
    eqs. 13-14), one for the boundary problems of case 2 (eqs. 15-18). A
    coordinate on a bound with its gradient pointing outward is also held.
    Returns the Newton step (zero in held coordinates).
    """
    dtype = x.dtype
    t = pair_terms(seg, curve, x[0], x[1])
    # Stationarity equations g = 0 (eqs. 13-14) and their Jacobian [[a, b], [b, c]].
    g = jnp.stack([t.gs, t.gu])
    # Active set: a coordinate on a bound whose gradient points out of the box
    # is held there, and Newton runs in the others (projected Newton).
    lo = jnp.stack([jnp.zeros((), dtype), curve.u_range[0]])
    hi = jnp.stack([jnp.ones((), dtype), curve.u_range[1]])
    held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))
    free = free & ~held
    g = jnp.where(free, g, 0.0)
    a = jnp.where(free[0], t.a, 1.0)
    c = jnp.where(free[1], t.c, 1.0)
    b = jnp.where(free[0] & free[1], t.b, 0.0)
    mu = psd_shift(a, b, c, dtype)
    a, c = a + mu, c + mu
    det = a * c - b * b
    return -jnp.stack([c * g[0] - b * g[1], a * g[1] - b * g[0]]) / det


def _newton(seg: Segment, curve, x0, free, iterations: int):
    """Box-constrained trust-region Newton from x0 = (s, u) over the free coordinates.

    The Newton step is capped to a trust radius (a fraction of the box); the
    best of the step lengths 1, 1/2, 1/4 is taken if it lowers f, and the
    radius then grows (full step) or stays; otherwise the point stays and the
    radius shrinks fourfold. f never increases and every iterate lies in the box.
    """
    dtype = x0.dtype
    lo = jnp.stack([jnp.zeros((), dtype), curve.u_range[0]])
    hi = jnp.stack([jnp.ones((), dtype), curve.u_range[1]])
    width = hi - lo
    ts = jnp.array([1.0, 0.5, 0.25], dtype)

    def f(x):
        r = seg.point(x[0]) - curve.point(x[1])
        return jnp.dot(r, r)

    def body(_, state):
        x, radius, fx = state
        step = _newton_step(seg, curve, x, free)
        size = jnp.max(jnp.abs(step) / width)
        step = step * jnp.minimum(1.0, radius / jnp.maximum(size, jnp.finfo(dtype).tiny))
        cands = jnp.clip(x[None, :] + ts[:, None] * step[None, :], lo, hi)
        fc = jax.vmap(f)(cands)
        k = jnp.argmin(fc)
        better = fc[k] < fx
        radius = trust_region_radius(better, k == 0, radius)
        return jnp.where(better, cands[k], x), radius, jnp.where(better, fc[k], fx)

    x0 = jnp.clip(x0, lo, hi)
    init = (x0, jnp.asarray(0.25, dtype), f(x0))
    return jax.lax.fori_loop(0, iterations, body, init)[0]


def _local_minima_2d(vals, k: int):
    """Flat indices of the k smallest 8-neighbour local minima of a 2-D grid."""
    padded = jnp.pad(vals, 1, constant_values=jnp.inf)
    n0, n1 = vals.shape
    is_min = jnp.ones(vals.shape, bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            neighbour = padded[1 + di : 1 + di + n0, 1 + dj : 1 + dj + n1]
            is_min &= vals <= neighbour
    score = jnp.where(is_min, vals, jnp.inf).reshape(-1)
    return jax.lax.top_k(-score, k)[1]


def solve_pair_grid(seg: Segment, curve, options: GridSolverOptions):
    """All three cases of paper §2.3 for one segment and one curve (no
    derivatives w.r.t. q), by 2-D Newton from an (s, u) grid
    (:class:`GridSolverOptions`; see the module docstring).

    Returns (s, u, D^2, converged) of the best candidate.
    """
    dtype = seg.L.dtype
    u_lo, u_hi = curve.u_range[0], curve.u_range[1]
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)
    n_s, n_u, ke = options.grid_s, options.grid_u, options.edge_starts
    s_grid = jnp.linspace(0.0, 1.0, n_s, dtype=dtype)  # uniform in arc length
    u_grid = u_samples(curve, n_u)
    A = jax.vmap(seg.point)(s_grid)  # (n_s, 3)
    C = jax.vmap(curve.point)(u_grid)  # (n_u, 3)
    grid = jnp.sum((A[:, None, :] - C[None, :, :]) ** 2, axis=-1)  # (n_s, n_u)

    # Case 1 starts. The grid's 2-D local minima, plus the local minima of two
    # distance profiles: for each arm sample s_i the distance to the curve
    # (u from the best grid column, polished by a few 1-D Newton steps), and
    # for each curve sample u_j the distance to the segment (likewise). A
    # profile resolves a basin that falls between grid columns where the
    # curve moves fast, which the raw grid misses.
    k, proj = options.starts, options.projection_iterations
    flat = _local_minima_2d(grid, k)
    x_grid = jnp.stack([s_grid[flat // n_u], u_grid[flat % n_u]], axis=-1)
    along_u, along_s = jnp.array([False, True]), jnp.array([True, False])
    x_rows = jnp.stack([s_grid, u_grid[jnp.argmin(grid, axis=1)]], axis=-1)
    x_rows = jax.vmap(lambda x: _newton(seg, curve, x, along_u, proj))(x_rows)
    x_cols = jnp.stack([s_grid[jnp.argmin(grid, axis=0)], u_grid], axis=-1)
    x_cols = jax.vmap(lambda x: _newton(seg, curve, x, along_s, proj))(x_cols)
    f_of = jax.vmap(lambda x: jnp.sum((seg.point(x[0]) - curve.point(x[1])) ** 2))
    x_int = jnp.concatenate(
        [
            x_grid,
            x_rows[local_minima_1d(f_of(x_rows), k)],
            x_cols[local_minima_1d(f_of(x_cols), k)],
        ]
    )
    # Case 2 starts: each edge's 1-D local minima, one coordinate free.
    # u = u_min / u_max: solve dD^2/ds = 0 for s (eqs. 15-16);
    # s = 0 / 1: solve dD^2/du = 0 for u (eqs. 17-18).
    s_lo = s_grid[local_minima_1d(grid[:, 0], ke)]
    s_hi = s_grid[local_minima_1d(grid[:, -1], ke)]
    u_0 = u_grid[local_minima_1d(grid[0, :], ke)]
    u_1 = u_grid[local_minima_1d(grid[-1, :], ke)]
    full = lambda v: jnp.full((ke,), v, dtype)  # noqa: E731
    x_edge = jnp.concatenate(
        [
            jnp.stack([s_lo, full(u_lo)], -1),
            jnp.stack([s_hi, full(u_hi)], -1),
            jnp.stack([full(0.0), u_0], -1),
            jnp.stack([full(1.0), u_1], -1),
        ]
    )
    free = jnp.concatenate(
        [
            jnp.ones((3 * k, 2), bool),
            jnp.tile(jnp.array([[True, False]]), (2 * ke, 1)),
            jnp.tile(jnp.array([[False, True]]), (2 * ke, 1)),
        ]
    )
    x_newton = jax.vmap(lambda x, m: _newton(seg, curve, x, m, options.iterations))(
        jnp.concatenate([x_int, x_edge]), free
    )
    # Case 3: the four endpoint pairs.
    x_corner = jnp.stack(
        [jnp.stack([zero, u_lo]), jnp.stack([zero, u_hi]), jnp.stack([one, u_lo]), jnp.stack([one, u_hi])]
    )
    cands = jnp.concatenate([x_newton, x_corner])
    d2 = jax.vmap(lambda x: jnp.sum((seg.point(x[0]) - curve.point(x[1])) ** 2))(cands)
    best = jnp.argmin(d2)
    x = cands[best]
    return x[0], x[1], d2[best], first_order_converged(seg, curve, x)
