"""Warm-started, certified closest points for the planner's steps.

From one planner step to the next the arm moves a little, so each
(segment, curve) pair's closest point moves a little too. This module carries
each pair's curve parameter u* from step to step, polishes it with a few
Newton iterations (:func:`~softplan_jax.geometry.closest.reduced_newton`), then
CERTIFIES with a cheap lower bound that the result is the global minimum over
the whole curve; only the pairs whose certificate fails are solved again by
the full solver (:func:`~softplan_jax.geometry.closest.solve_pair_reduced`, with the
same options: a fallback gives exactly the full solver's answer).

The reduced problem. For segment i the squared distance of a point p to the
arc, ``d_i(p)^2 = min_s |F_Ri(s) - p|^2``, is exact in closed form
(:func:`~softplan_jax.geometry.closest.project_to_arc`), so the pair's minimum is
``min_u d_i(F_o(u))`` over the curve's range: a 1-D problem in u.

The lower bound on a piece [a, b] of the curve. Let
``x(t) = (1 - t) F_o(a) + t F_o(b)`` be the chord and ``l = |F_o(b) - F_o(a)|``.
For ANY set A, ``d_A(x)^2 - |x|^2 = min_{y in A} (|y|^2 - 2 y.x)`` is concave in
x (a minimum of affine functions), so it lies above its chords; with
``|x(t)|^2 = (1 - t)|x0|^2 + t|x1|^2 - t (1 - t) l^2`` this gives::

    d_A(x(t))^2 >= (1 - t) d_A(x0)^2 + t d_A(x1)^2 - t (1 - t) l^2

(exact when A is a single point; second order in l, where the Lipschitz bound
``d_A(centre) - radius`` is first order, too weak for far obstacles). The
curve leaves its chord by at most ``e = (b - a)^2 / 8 max |F_o''|`` on the
piece (the linear interpolation error) and ``d_A`` is 1-Lipschitz, so every u
in the piece has ``d_i(F_o(u)) >= sqrt(min_t [rhs]) - e``; the minimum over t
of the quadratic is in closed form. ``max |F_o''|``: for a
:class:`~softplan_jax.geometry.curves.PolynomialCurve` a rigorous bound (the Taylor
expansion of F_o'' at the piece's centre, term by term; exact for degree
<= 2); for a :class:`~softplan_jax.geometry.curves.ParametricCurve` the largest of
``PARAMETRIC_SAMPLES`` samples over the range times ``PARAMETRIC_SAFETY`` (2),
computed once per scenario: NOT a proof, a curve whose second derivative
peaks sharply between samples can defeat it.

The pieces: a geometric grid around each polished u_i. Outside the trusted
window (below), each side of u_i is cut at ``NODES`` points
``u_i +- w (R / w)^(k / (NODES - 1))``, k = 0 .. NODES - 1, from the window's
edge (w: its half-width) to the end of the range (R: the distance to it), so a
piece is a fixed fraction of its distance from u_i. Then near a minimum where
the distance grows like ``sin(alpha) |u - u_i|`` (alpha: the angle between arm
and curve) every piece passes once ``tan(alpha)`` exceeds a fixed fraction
(scale free), where evenly spaced cells fail near the window whenever the
curve runs nearly parallel to the arm. Cost: ``2 NODES`` point-to-arc
distances per pair and step, in square roots and divisions only
(:func:`~softplan_jax.geometry.closest.arc_distance2`: the certificate needs the
values, not the minimisers; measured in ``benchmarks/kernel.py`` (git history, b850131): 18.6 ->
7.5 µs of the tree's step with project_to_arc's trigonometry gone), pair
fallbacks 0.4-0.6 % with 8 nodes per side against 3 % with 16 even cells
(``benchmarks/warm_start.py``).

The certificate (per obstacle). Each segment i's polished pair gives an
achievable distance D_i; ``D_w = min_i D_i``. The WINDOW of half-width
``w = WINDOW (u_max - u_min) / (grid_u - 1)`` around u_i (1.5 mean spacings of
the full solver's u-grid wide) is trusted to hold no value below D_i when the
polish converged (the first-order test
:func:`~softplan_jax.geometry.closest.first_order_converged`): THE ASSUMPTION, the one
the full solver makes inside a cell of its u-grid, that no second, lower
basin hides within about a grid spacing of a local minimum. Every piece
outside the window must have a lower bound >= D_w minus a rounding tolerance
(``TOLERANCE`` eps (1 + the curve's size)). Segment i is certified when its
polish converged and all its pieces pass; then its true minimum is
>= min(D_i, D_w), so the obstacle's minimum over segments is D_w. A failed
segment gets the full solve (keeping the smaller of the full and the polished
D^2, both achievable); a segment certified against D_w stays certified when a
fallback lowers D_w, so one pass is enough.

Fallback cost. The failed pairs are solved one by one in a
``lax.while_loop`` (flattened over the curves of a stack). Under ``vmap`` a
batching rule (``jax.custom_batching.custom_vmap``) folds the batch axis into
that loop: it solves the failed pairs of ALL members, ``chunk`` side by side
per iteration, so a batch pays for its failures only, where plain ``vmap``
would run the loop as long as the member with the most failures and solve a
pair for every member in each iteration. At the first step of a rollout (no
warm state) every pair fails and takes the full solve. The chunk is
``max(FALLBACK_CHUNK, ceil(pairs / trips))`` (pairs: the batch's curve-segment
pairs), so the loop's trips per step stay bounded (at most ``trips``) however
wide the batch: with a fixed chunk of 8 they grew with the width (measured on
random_scenarios(0, 1024), 200 steps: 0.28 failed pairs per scene-step, so a
mean of 21 trips per step at 1,024 scenes side by side and 84 at 4,096; every
trip is a serial round of small kernels on a GPU). ``trips`` is
``FALLBACK_TRIPS`` (64) on an accelerator and ``CPU_FALLBACK_TRIPS`` (192) in a
program traced for a CPU (:func:`fallback_trips`), where a trip costs little
beyond its pairs' solves, so a smaller chunk solves fewer pairs that did not
fail (``benchmarks/fallback_chunk.py``). At 64 lanes and 8 slots (1,536 pairs)
the chunk is 8 on a CPU (24 on an accelerator); at 256 lanes, 32 (96).

Derivatives. Everything here runs without derivatives (stop_gradient); the
winning pair goes through :func:`~softplan_jax.geometry.closest.closest_from_pairs`,
the tail of :func:`~softplan_jax.geometry.closest.curve_closest`, so the derivatives
w.r.t. q (implicit function theorem, envelope theorem) are the full solver's.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base.numerics import evaluate_where
from .closest import SolverOptions, closest_from_pairs
from .closest_newton import (
    Segment,
    arc_distance2,
    first_order_converged,
    project_to_arc,
    reduced_newton_loop,
    reduced_newton_step,
    solve_pair_reduced,
    u_samples,
)
from .curves import PolynomialCurve
from .kinematics import segment_frames

__all__ = ["CurveData", "curve_data", "warm_curves"]

# Cut points of the lower bound per side of u* (window edge and range end included).
NODES = 8
# Newton iterations polishing the previous step's u* (the full solver: 4 starts x 8).
# Measured (benchmarks/kernel.py at b850131, benchmarks/warm_start.py, 200 random scenes): 4, 3, 2
# iterations give pair fallback rates 0.53 %, 0.63 %, 1.5 % and batched steps of
# 30, 27, 25 us. 3: with 2, a start off by 0.01 of the curve's range (about one large
# planner step) often needs the fallback (tests/test_warm_start.py: 11 of 48 cases
# certified, against 20+ with 3), and the tree needed 52 pair fallbacks in 54 steps.
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
# the loop stay bounded as the batch widens (module docstring, "Fallback cost"): FALLBACK_TRIPS
# on an accelerator, CPU_FALLBACK_TRIPS on a CPU (benchmarks/fallback_chunk.py).
FALLBACK_CHUNK = 8
FALLBACK_TRIPS = 64
CPU_FALLBACK_TRIPS = 192


class CurveData(NamedTuple):
    """What the warm start precomputes for ONE curve, once per scenario
    (vmap :func:`curve_data` over a stack; every field then gains a leading axis).

    Attributes:
      curvature: () a bound on |F_o''| over the whole range (rigorous for a
        PolynomialCurve, sampled with a safety factor for a ParametricCurve).
      u_grid: (grid_u,) the full solver's u-samples (:func:`~softplan_jax.geometry.closest.u_samples`).
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


class _Pairs(NamedTuple):
    """Every (curve, segment) pair's solution: arrays (m, n) (or (n,) for one curve)."""

    s: jax.Array
    u: jax.Array
    d2: jax.Array
    converged: jax.Array


def _per_pair(fn):
    """``fn(curve, seg, *args)`` over every (curve, segment) pair: curves (m,) outer,
    segments (n,) inner, args with leading axes (m, n)."""
    return jax.vmap(jax.vmap(fn, in_axes=(None, 0, 0)), in_axes=(0, None, 0))


def _polish_and_certify(segs: Segment, curves, data: CurveData, u_prev, solver: SolverOptions):
    """Polish every (curve, segment) pair from u_prev and certify it.

    Args:
      segs: Segment with a leading axis n (without derivatives).
      curves: a curve stack (leading axis m); data: their CurveData (m,);
        u_prev: (m, n) the previous step's u*.
      solver: SolverOptions (static): its grid_u sets the window.

    Returns:
      (_Pairs with arrays (m, n), certified (m, n) bool).
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
    return _Pairs(s_w, u_w, d2_w, conv), certified


def _fallback(segs: Segment, curves, data: CurveData, pairs: _Pairs, fail, solver: SolverOptions) -> _Pairs:
    """The full solve of every failed pair (fail (m, n)); each failed pair keeps the
    smaller of its full and polished D^2. Under ``vmap`` the failures of the whole
    batch are solved together (see :func:`_fallback_fn`)."""
    return _fallback_fn(solver)(segs, curves, data, pairs, fail)


@functools.cache
def _fallback_fn(solver: SolverOptions):
    """:func:`_solve_failed` for one SolverOptions, with a batching rule.

    Plain ``vmap`` would turn the while loop over failed pairs into one that
    runs until the batch member with the most failures is done, every
    iteration solving a pair for EVERY member: a batch of B paid B full pair
    solves per failure of its worst member (measured: 8 of 44 µs per
    scenario-step, batch of 64). The rule instead folds the batch axis into
    the array and solves only the failed pairs of all members, a chunk at a time
    (:func:`_solve_failed`; ``benchmarks/kernel.py`` at b850131, batch of 64 and
    a chunk of 8: 39 -> 31 µs per scenario-step). Nested ``vmap`` folds one axis per level. custom_vmap has
    no reverse-mode rule; none is needed, as every input is stop_gradient-ed
    (the JVP of a rollout sees only symbolic-zero tangents here).
    """

    @jax.custom_batching.custom_vmap
    def fallback(segs, curves, data, pairs, fail):
        return _solve_failed(segs, curves, data, pairs, fail, solver)

    @fallback.def_vmap
    def _rule(axis_size, in_batched, *args):
        def lift(x, batched):
            return x if batched else jnp.broadcast_to(x, (axis_size, *jnp.shape(x)))

        args = [jax.tree_util.tree_map(lift, a, b) for a, b in zip(args, in_batched, strict=True)]
        out = fallback(*args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return fallback


def fallback_trips(platform: str | None = None) -> int:
    """The bound on the fallback loop's trips per step (module docstring, "Fallback
    cost"): :data:`CPU_FALLBACK_TRIPS` for ``platform`` "cpu", else :data:`FALLBACK_TRIPS`
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


def _solve_failed(segs: Segment, curves, data: CurveData, pairs: _Pairs, fail, solver: SolverOptions) -> _Pairs:
    """The loop of :func:`_fallback` over any leading axes ``lead`` (``fail``:
    lead + (m, n); segs: lead + (n,); curves, data: lead + (m,)): the failed
    pairs go through :func:`~softplan_jax.base.numerics.evaluate_where`, ``chunk``
    at a time (1 without leading axes, else :func:`fallback_chunk`), and each keeps the
    better of its full and polished answers."""
    m, n = fail.shape[-2:]
    lead = fail.shape[:-2]
    batch = math.prod(lead)
    total = batch * m * n
    chunk = fallback_chunk(total) if lead else min(1, total)

    def flat(tree):  # lead axes -> one axis of size batch
        return jax.tree_util.tree_map(lambda x: x.reshape((batch, *x.shape[len(lead) :])), tree)

    segs_f, curves_f, data_f = flat(segs), flat(curves), flat(data)
    pairs_f = _Pairs(*(x.reshape(total) for x in pairs))
    todo = fail.reshape(total)

    def solve(idx):
        b, k, i = idx // (m * n), (idx // n) % m, idx % n
        curve = jax.tree_util.tree_map(lambda x: x[b, k], curves_f)
        c = jax.tree_util.tree_map(lambda x: x[b, k], data_f)
        seg = jax.tree_util.tree_map(lambda x: x[b, i], segs_f)
        return _Pairs(*solve_pair_reduced(seg, curve, c.u_grid, c.C_grid, solver))

    new = evaluate_where(todo, solve, chunk, pairs_f)
    keep = todo & (new.d2 <= pairs_f.d2)
    return _Pairs(*(jnp.where(keep, a, b).reshape(fail.shape) for a, b in zip(new, pairs_f, strict=True)))


def warm_curves(q, curves, data: CurveData, u_prev, fresh, active, solver: SolverOptions):
    """Closest pairs between the arm and a STACK of curves, warm-started and certified.

    Args:
      q: (n, 3) configuration (derivatives w.r.t. q as in
        :func:`~softplan_jax.geometry.closest.curve_closest`).
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
    pairs, certified = _polish_and_certify(segs_ng, curves_ng, data, u_prev, solver)
    fail = (fresh | ~certified) & active[:, None]
    pairs = _fallback(segs_ng, curves_ng, data, pairs, fail, solver)
    cps = jax.vmap(lambda c, s, u, d2, conv: closest_from_pairs(segs, c, s, u, d2, conv))(
        curves, pairs.s, pairs.u, pairs.d2, pairs.converged
    )
    return cps, pairs.u, jnp.sum(fail).astype(jnp.int32)
