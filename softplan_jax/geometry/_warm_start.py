"""Warm-started, certified closest points for the planner's steps (paper §2.3). Each (segment,
curve) pair's curve parameter u* is carried from step to step, polished by a few Newton
iterations of the reduced problem ``min_u d_i(F_o(u))`` (``d_i`` the exact distance to the arc;
:func:`~softplan_jax.geometry._closest_newton.reduced_newton`), and certified the global minimum by
a lower bound on geometric pieces of the curve around it: for any set A, ``d_A(x)^2 - |x|^2`` is
concave, so along a chord ``d_A(x(t))^2 >= (1 - t) d_A(x0)^2 + t d_A(x1)^2 - t (1 - t) l^2``, less
the curve's distance from its chord, ``(b - a)^2 / 8 max |F_o''|``. Only the pairs whose
certificate fails take the full solve
(:func:`~softplan_jax.geometry._closest_newton.solve_pair_reduced`, the same options), a batch's
failures solved side by side by a ``custom_vmap`` rule; the derivatives are the full solver's
(:func:`~softplan_jax.geometry._closest.closest_from_pairs`). The bound, the window it trusts, the
fallback's cost and how the constants were chosen: docs, "How the planner works inside"."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._numerics import batch_folded, evaluate_where
from ._closest import SolverOptions, closest_from_pairs
from ._closest_newton import (
    Segment,
    arc_distance2,
    first_order_converged,
    project_to_arc,
    reduced_newton_loop,
    reduced_newton_step,
    solve_pair_reduced,
    u_samples,
)
from ._curves import PolynomialCurve
from ._kinematics import segment_frames

__all__ = ["CurveData", "curve_data", "warm_curves"]

# Cut points of the lower bound per side of u* (window edge and range end included).
NODES = 8
# Newton iterations polishing the previous step's u* (the full solver: 4 starts x 8); fewer
# fallbacks than 2, cheaper than 4 (docs: "How the planner works inside").
POLISH_ITERATIONS = 3
# Half-width of the trusted window around a polished u*, in mean spacings of the full
# solver's u-grid (u_max - u_min) / (grid_u - 1): the window is 1.5 spacings wide.
WINDOW = 0.75
# Rounding tolerance of the certificate: TOLERANCE * eps * (1 + the curve's size).
TOLERANCE = 64.0
# ParametricCurve: max |F_o''| from samples over the range, times this factor.
PARAMETRIC_SAFETY = 2.0
PARAMETRIC_SAMPLES = 257
# Failed pairs solved side by side per iteration of the fallback loop under vmap: at least
# FALLBACK_CHUNK, and at least 1 / trips of the batch's pairs, so that a step's trips through
# the loop stay bounded as the batch widens: FALLBACK_TRIPS on an accelerator,
# CPU_FALLBACK_TRIPS on a CPU (docs: "How the planner works inside", "The fallback's cost").
FALLBACK_CHUNK = 8
FALLBACK_TRIPS = 64
CPU_FALLBACK_TRIPS = 192


class CurveData(NamedTuple):
    """What the warm start precomputes for ONE curve, once per scenario
    (vmap :func:`curve_data` over a stack; every field then gains a leading axis).

    Attributes:
      curvature: () a bound on |F_o''| over the whole range (rigorous for a
        PolynomialCurve, sampled with a safety factor for a ParametricCurve).
      u_grid: (grid_u,) the full solver's u-samples (:func:`~softplan_jax.geometry._closest.u_samples`).
      C_grid: (grid_u, 3) F_o at them (for the fallback).
      size: () 1 + max |F_o| over u_grid (the scale of the rounding tolerance).
    """

    curvature: jax.Array
    u_grid: jax.Array
    C_grid: jax.Array
    size: jax.Array


def curve_data(curve, solver: SolverOptions) -> CurveData:
    """The warm start's per-curve data for ONE curve (computed once per scenario).

    Args:
      curve: one PolynomialCurve or ParametricCurve.
      solver: the full solver's SolverOptions (static): its grid, for the fallback.

    Returns:
      :class:`CurveData`.
    """
    curve = jax.tree_util.tree_map(jax.lax.stop_gradient, curve)
    lo, hi = curve.u_range[0], curve.u_range[1]
    if isinstance(curve, PolynomialCurve):
        curvature = curve.second_derivative_bound(lo, hi)
    else:
        u = jnp.linspace(0.0, 1.0, PARAMETRIC_SAMPLES, dtype=lo.dtype) * (hi - lo) + lo
        acc = jax.vmap(curve.second_derivative)(u)
        curvature = PARAMETRIC_SAFETY * jnp.max(jnp.sqrt(jnp.sum(acc * acc, axis=-1)))
    u_grid = u_samples(curve, solver.grid_u)
    C_grid = jax.vmap(curve.point)(u_grid)
    size = 1.0 + jnp.max(jnp.sqrt(jnp.sum(C_grid * C_grid, axis=-1)))
    return CurveData(curvature, u_grid, C_grid, size)


def _chord_bound(g0, g1, l2):
    """min over t in [0, 1] of (1 - t) g0 + t g1 - t (1 - t) l2 (see the module docstring)."""
    pos = l2 > 0
    t = jnp.clip((l2 + g0 - g1) / (2.0 * jnp.where(pos, l2, 1.0)), 0.0, 1.0)
    return jnp.where(pos, g0 + t * (g1 - g0 - l2) + t * t * l2, jnp.minimum(g0, g1))


def _piece_bounds(seg: Segment, curve, data: CurveData, u_i, half):
    """Lower bounds on d_i(F_o(u)) over the pieces of the geometric grid on both sides
    of u_i (row 0: u > u_i + half, row 1: u < u_i - half). Returns (bounds
    (2, NODES - 1), whether each side reaches outside the window (2,) bool, the cut
    points (2, NODES), from the window's edge outwards)."""
    lo, hi = curve.u_range[0], curve.u_range[1]
    dtype = u_i.dtype
    sign = jnp.array([1.0, -1.0], dtype)
    end = jnp.stack([hi, lo])
    extent = sign * (end - u_i)
    outside = extent > half
    ratio = jnp.where(outside, extent / half, 1.0)
    # ratio^(k / (NODES - 1)) by repeated multiplication: one exp and one log per side.
    step = jnp.exp(jnp.log(ratio) / (NODES - 1))
    powers = [jnp.ones_like(step)]
    for _ in range(NODES - 1):
        powers.append(powers[-1] * step)
    t = jnp.clip(u_i + sign[:, None] * half * jnp.stack(powers, axis=1), lo, hi)
    t = t.at[:, -1].set(end)  # the last piece ends exactly at the range's end
    P = jax.vmap(curve.point)(t.reshape(-1)).reshape(2, NODES, 3)
    g = jax.vmap(lambda p: arc_distance2(seg, p))(P.reshape(-1, 3)).reshape(2, NODES)
    q = _chord_bound(g[:, :-1], g[:, 1:], jnp.sum((P[:, 1:] - P[:, :-1]) ** 2, axis=-1))
    a, b = jnp.minimum(t[:, :-1], t[:, 1:]), jnp.maximum(t[:, :-1], t[:, 1:])
    kappa = data.curvature
    if isinstance(curve, PolynomialCurve):
        local = jax.vmap(curve.second_derivative_bound)(a.reshape(-1), b.reshape(-1))
        kappa = jnp.minimum(kappa, local.reshape(a.shape))
    return jnp.sqrt(jnp.maximum(q, 0.0)) - 0.125 * kappa * (b - a) ** 2, outside, t


class Pairs(NamedTuple):
    """Every (curve, segment) pair's solution: arrays (m, n) (or (n,) for one curve)."""

    s: jax.Array
    u: jax.Array
    d2: jax.Array
    converged: jax.Array


def _per_pair(fn):
    """``fn(curve, seg, *args)`` over every (curve, segment) pair: curves (m,) outer,
    segments (n,) inner, args with leading axes (m, n)."""
    return jax.vmap(jax.vmap(fn, in_axes=(None, 0, 0)), in_axes=(0, None, 0))


def polish_and_certify(segs: Segment, curves, data: CurveData, u_prev, solver: SolverOptions):
    """Polish every (curve, segment) pair from u_prev and certify it.

    Args:
      segs: Segment with a leading axis n (without derivatives).
      curves: a curve stack (leading axis m); data: their CurveData (m,);
        u_prev: (m, n) the previous step's u*.
      solver: SolverOptions (static): its grid_u sets the window.

    Returns:
      (Pairs with arrays (m, n), certified (m, n) bool).
    """
    dtype = u_prev.dtype
    u_prev = jnp.clip(u_prev, curves.u_range[:, :1], curves.u_range[:, 1:])

    def start(curve, seg, u0):
        return project_to_arc(seg, curve.point(u0))

    # reduced_newton's loop, every pair vmapped inside the loop body.
    step = _per_pair(lambda curve, seg, state: reduced_newton_step(seg, curve, state))
    s0, f0 = _per_pair(start)(curves, segs, u_prev)
    u_w, s_w, d2_w = reduced_newton_loop(lambda state: step(curves, segs, state), u_prev, s0, f0, POLISH_ITERATIONS)
    conv = _per_pair(lambda curve, seg, x: first_order_converged(seg, curve, x))(
        curves, segs, jnp.stack([s_w, u_w], axis=-1)
    )

    def certify(curve, data, d2, u):
        floor = jnp.sqrt(jnp.min(d2)) - TOLERANCE * jnp.finfo(dtype).eps * data.size
        half = WINDOW * (curve.u_range[1] - curve.u_range[0]) / (solver.grid_u - 1)

        def one(seg, u_i):
            bounds, outside, _ = _piece_bounds(seg, curve, data, u_i, half)
            return jnp.all(~outside[:, None] | (bounds >= floor))

        return jax.vmap(one)(segs, u)

    certified = jax.vmap(certify)(curves, data, d2_w, u_w) & conv
    return Pairs(s_w, u_w, d2_w, conv), certified


def fallback(segs: Segment, curves, data: CurveData, pairs: Pairs, fail, solver: SolverOptions) -> Pairs:
    """The full solve of every failed pair (fail (m, n)); each failed pair keeps the
    smaller of its full and polished D^2. Under ``vmap`` the failures of the whole
    batch are solved together (see :func:`_fallback_fn`)."""
    return _fallback_fn(solver)(segs, curves, data, pairs, fail)


@functools.cache
def _fallback_fn(solver: SolverOptions):
    """:func:`_solve_failed` for one SolverOptions, with a batching rule.

    Plain ``vmap`` would turn the while loop over failed pairs into one that
    runs until the batch member with the most failures is done, every
    iteration solving a pair for EVERY member: a batch of B would pay B full pair
    solves per failure of its worst member. The rule instead folds the batch axis into
    the array and solves only the failed pairs of all members, a chunk at a time
    (:func:`_solve_failed`, :func:`~softplan_jax.base._numerics.batch_folded`; docs: "How the
    planner works inside"). custom_vmap has no reverse-mode rule; none is needed, as every input
    is stop_gradient-ed (the JVP of a rollout sees only symbolic-zero tangents here).
    """
    return batch_folded(lambda segs, curves, data, pairs, fail: _solve_failed(segs, curves, data, pairs, fail, solver))


def fallback_trips(platform: str | None = None) -> int:
    """The bound on the fallback loop's trips per step (docs: "How the planner works
    inside"): :data:`CPU_FALLBACK_TRIPS` for ``platform`` "cpu", else :data:`FALLBACK_TRIPS`
    (None: ``jax.default_backend()``, the platform a program traced now runs on unless
    placed elsewhere). Either bound solves the same pairs; only the cost differs."""
    platform = jax.default_backend() if platform is None else platform
    return CPU_FALLBACK_TRIPS if platform == "cpu" else FALLBACK_TRIPS


def fallback_chunk(pairs: int, trips: int | None = None) -> int:
    """Failed pairs the batched fallback loop solves side by side, for a batch of ``pairs``
    (curve, segment) pairs: ``min(max(FALLBACK_CHUNK, ceil(pairs / trips)), pairs)``
    (``trips``: None, :func:`fallback_trips` of this platform)."""
    trips = fallback_trips() if trips is None else trips
    return min(max(FALLBACK_CHUNK, -(-pairs // trips)), pairs)


def pair_picker(segs: Segment, curves, data: CurveData, shape):
    """The (curve, segment) pairs of ``shape`` = lead + (m, n) (any leading axes ``lead``; segs:
    lead + (n,); curves, data: lead + (m,)) by one flat index, lead axes first, then the curve,
    then the segment: ``pick(idx) -> (seg, curve, data)`` of that pair (no leading axes)."""
    m, n = shape[-2:]
    lead = shape[:-2]
    batch = math.prod(lead)

    def flat(tree):  # lead axes -> one axis of size batch
        return jax.tree_util.tree_map(lambda x: x.reshape((batch, *x.shape[len(lead) :])), tree)

    segs_f, curves_f, data_f = flat(segs), flat(curves), flat(data)

    def pick(idx):
        b, k, i = idx // (m * n), (idx // n) % m, idx % n
        curve = jax.tree_util.tree_map(lambda x: x[b, k], curves_f)
        c = jax.tree_util.tree_map(lambda x: x[b, k], data_f)
        seg = jax.tree_util.tree_map(lambda x: x[b, i], segs_f)
        return seg, curve, c

    return pick


def _solve_failed(segs: Segment, curves, data: CurveData, pairs: Pairs, fail, solver: SolverOptions) -> Pairs:
    """The loop of :func:`fallback` over any leading axes ``lead`` (``fail``:
    lead + (m, n); segs: lead + (n,); curves, data: lead + (m,)): the failed
    pairs go through :func:`~softplan_jax.base._numerics.evaluate_where`, ``chunk``
    at a time (1 without leading axes, else :func:`fallback_chunk`), and each keeps the
    better of its full and polished answers."""
    total = fail.size
    chunk = fallback_chunk(total) if fail.ndim > 2 else min(1, total)
    pick = pair_picker(segs, curves, data, fail.shape)
    pairs_f = Pairs(*(x.reshape(total) for x in pairs))
    todo = fail.reshape(total)

    def solve(idx):
        seg, curve, c = pick(idx)
        return Pairs(*solve_pair_reduced(seg, curve, c.u_grid, c.C_grid, solver))

    new = evaluate_where(todo, solve, chunk, pairs_f)
    keep = todo & (new.d2 <= pairs_f.d2)
    return Pairs(*(jnp.where(keep, a, b).reshape(fail.shape) for a, b in zip(new, pairs_f, strict=True)))


def warm_curves(q, curves, data: CurveData, u_prev, fresh, active, solver: SolverOptions):
    """Closest pairs between the arm and a STACK of curves, warm-started and certified.

    Args:
      q: (n, 3) configuration (derivatives w.r.t. q as in
        :func:`~softplan_jax.geometry._closest.curve_closest`).
      curves: a curve stack with leading axis m (a stacked PolynomialCurve, or
        one curve with a leading axis 1 added to its array leaves).
      data: CurveData with leading axis m (:func:`curve_data`, vmapped).
      u_prev: (m, n) each pair's u* at the previous step.
      fresh: () bool, no warm state (the first step): every pair takes the full solve.
      active: (m,) bool, False for padding slots (never full-solved; their
        values are meaningless but finite).
      solver: SolverOptions (static).

    Returns:
      ``(ClosestPoint with leading axis m, u (m, n) for the next step,
      fallbacks () int32: pairs that took the full solve)``.
    """
    curves = curves.astype(q.dtype)
    segs = Segment.from_frame(q, *segment_frames(q))
    segs_ng = jax.tree_util.tree_map(jax.lax.stop_gradient, segs)
    curves_ng = jax.tree_util.tree_map(jax.lax.stop_gradient, curves)
    data = jax.tree_util.tree_map(jax.lax.stop_gradient, data)
    u_prev = jax.lax.stop_gradient(u_prev)
    pairs, certified = polish_and_certify(segs_ng, curves_ng, data, u_prev, solver)
    fail = (fresh | ~certified) & active[:, None]
    pairs = fallback(segs_ng, curves_ng, data, pairs, fail, solver)
    cps = jax.vmap(lambda c, s, u, d2, conv: closest_from_pairs(segs, c, s, u, d2, conv))(
        curves, pairs.s, pairs.u, pairs.d2, pairs.converged
    )
    return cps, pairs.u, jnp.sum(fail).astype(jnp.int32)
