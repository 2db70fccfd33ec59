"""Closest points between the arm and curve obstacles (paper §2.3): the entry points, the result
type and the solver options. For segment i and a curve F_o, ``D_i(s, u)^2 = |F_Ri(s) - F_o(u)|^2``
is minimised over the box ``[0, 1] x [u_min, u_max]`` in the paper's three cases (interior
stationary points, eqs. 13-14; the four boundary problems, eqs. 15-18; the four endpoint pairs),
then over segments, by the reduced solver (:class:`SolverOptions`, the default;
:mod:`softplan_jax.geometry._closest_newton`) or the paper's 2-D solver
(:mod:`softplan_jax.geometry._closest_grid`). The solve runs on ``stop_gradient(q)``: the distance
is differentiated by the envelope theorem (``(s*, u*)`` held fixed), and ``s``, ``u`` and the
points by the implicit function theorem over the free coordinates f (those strictly inside the
box), ``d(s*, u*)/dq = -H_ff^{-1} dg_f/dq``. Point obstacles: :mod:`softplan_jax.geometry._point_sets`."""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import psd_shift, safe_norm
from ..base._validation import check_configuration
from ._closest_newton import Segment, pair_terms, solve_pair_reduced, u_samples
from ._curves import ParametricCurve, PolynomialCurve
from ._kinematics import segment_frames

__all__ = [
    "ClosestPoint",
    "SolverOptions",
    "DEFAULT_OPTIONS",
    "closest_point",
    "curve_closest",
    "closest_from_pairs",
]


class ClosestPoint(NamedTuple):
    """The closest pair between the arm and one obstacle.

    Attributes:
      distance: () distance between the arm backbone and the obstacle centre
        line (radii not subtracted).
      segment: () int, 0-based index of the arm segment holding ``arm_point``.
      s: () fraction along that segment.
      u: () curve parameter of ``obstacle_point`` (N-point method: the index of
        the nearest obstacle point).
      arm_point: (3,) ``F_Ri(s)``.
      obstacle_point: (3,) ``F_o(u)``.
      converged: () bool, the winning Newton solve met its tolerance (always
        True for endpoint pairs and for the N-point method).
    """

    distance: jax.Array
    segment: jax.Array
    s: jax.Array
    u: jax.Array
    arm_point: jax.Array
    obstacle_point: jax.Array
    converged: jax.Array


class SolverOptions(NamedTuple):
    """Static settings of the default closest-point solver (hashable; jit-static).

    The minimum over the arc is taken in closed form (a PCC segment is a
    circular arc) and Newton runs on the curve parameter u alone, from the
    smallest local minima of two sampled distance profiles; it covers the
    paper's three cases (see the module docstring). The paper's own 2-D Newton
    on both stationarity equations is :class:`GridSolverOptions`
    (``softplan_jax.geometry._closest_grid``); either goes wherever a solver is taken
    (``closest_point(..., options)``, ``plan(..., solver=...)``).

    Attributes:
      grid_s: points of the arm-side distance profile along each segment (s).
      grid_u: samples of the curve (u), ends included.
      projection_iterations: 1-D Newton steps that polish the distance profiles.
      starts: Newton starts in u from each of the two seed sources (so 2 x starts in all).
      iterations: Newton iterations in u per start.
    """

    grid_s: int = 10
    grid_u: int = 32
    projection_iterations: int = 4
    starts: int = 2
    iterations: int = 8

    def pair_solver(self, curve):
        """``seg -> (s, u, D^2, converged)`` for one curve (derivatives w.r.t. q not propagated)."""
        # The curve's u-samples and points do not depend on the segment: computed once.
        u_grid = u_samples(curve, self.grid_u)
        C_grid = jax.vmap(curve.point)(u_grid)
        return lambda seg: solve_pair_reduced(seg, curve, u_grid, C_grid, self)


DEFAULT_OPTIONS = SolverOptions()


def _implicit(seg: Segment, curve, s, u):
    """(s, u) whose value is the solver's and whose derivative w.r.t. q is the
    implicit-function derivative over the free coordinates."""
    s, u = jax.lax.stop_gradient(s), jax.lax.stop_gradient(u)
    t = pair_terms(seg, curve, s, u)
    g = jnp.stack([t.gs, t.gu])
    a, b, c = t.a, t.b, t.c
    dtype = s.dtype
    mu = psd_shift(a, b, c, dtype)
    a, c = a + mu, c + mu
    free_s = (s > 0.0) & (s < 1.0)
    free_u = (u > curve.u_range[0]) & (u < curve.u_range[1])
    both = free_s & free_u
    det = a * c - b * b
    ds_both = (c * g[0] - b * g[1]) / det
    du_both = (a * g[1] - b * g[0]) / det
    ds = jnp.where(both, ds_both, jnp.where(free_s, g[0] / a, 0.0))
    du = jnp.where(both, du_both, jnp.where(free_u, g[1] / c, 0.0))
    # Value unchanged; derivative -H_ff^{-1} dg_f (g = 0 at the solution).
    return s - (ds - jax.lax.stop_gradient(ds)), u - (du - jax.lax.stop_gradient(du))


def curve_closest(q, curve, options: SolverOptions) -> ClosestPoint:
    """Exact closest pair between the arm and ONE curve (paper §2.3): the
    traceable core of :func:`closest_point`, without input validation.

    Args:
      q: (n, 3) configuration.
      curve: one PolynomialCurve or ParametricCurve (vmap for stacks).
      options: SolverOptions or GridSolverOptions (static).

    Returns:
      ClosestPoint (``segment`` int32, ``u`` of q's dtype).
    """
    curve = curve.astype(q.dtype)
    segs = Segment.from_frame(q, *segment_frames(q))
    segs_nograd = jax.tree_util.tree_map(jax.lax.stop_gradient, segs)
    curve_nograd = jax.tree_util.tree_map(jax.lax.stop_gradient, curve)
    solve = options.pair_solver(curve_nograd)  # SolverOptions or closest_grid.GridSolverOptions
    s_all, u_all, d2_all, conv_all = jax.vmap(solve)(segs_nograd)
    return closest_from_pairs(segs, curve, s_all, u_all, d2_all, conv_all)


def closest_from_pairs(segs: Segment, curve, s_all, u_all, d2_all, conv_all) -> ClosestPoint:
    """The closest pair from every segment's solution for one curve: the
    segment with the smallest D^2, with the derivatives of the module
    docstring (implicit function theorem for s, u and the points, envelope
    theorem for the distance). Shared by :func:`curve_closest` and the warm
    start (:mod:`softplan_jax.geometry._warm_start`), so both differentiate alike.

    Args:
      segs: Segment with a leading axis n (NOT stop_gradient-ed: the
        derivatives w.r.t. q flow through it).
      curve: one curve, of q's dtype.
      s_all, u_all, d2_all, conv_all: (n,) each segment's solution (s, u, D^2,
        converged), computed without derivatives.

    Returns:
      ClosestPoint (``segment`` int32).
    """
    i = jnp.argmin(d2_all)
    seg = jax.tree_util.tree_map(lambda x: x[i], segs)
    s, u = _implicit(seg, curve, s_all[i], u_all[i])
    arm_point = seg.point(s)
    obstacle_point = curve.point(u)
    # Envelope theorem: (s*, u*) held fixed for the distance.
    distance = safe_norm(
        seg.point(jax.lax.stop_gradient(s)) - curve.point(jax.lax.stop_gradient(u))
    )
    return ClosestPoint(distance, i.astype(jnp.int32), s, u, arm_point, obstacle_point, conv_all[i])


@partial(package_jit, static_argnames="options")
def _closest_point_jit(q, curve, options):
    if isinstance(curve, PolynomialCurve) and curve.coeffs.ndim == 3:
        return jax.vmap(lambda c: curve_closest(q, c, options))(curve)
    return curve_closest(q, curve, options)


def closest_point(q, curve, options: SolverOptions = DEFAULT_OPTIONS) -> ClosestPoint:
    """Exact closest point between the arm and a curve obstacle (paper §2.3).

    Args:
      q: (n, 3) configuration.
      curve: a :class:`PolynomialCurve` or :class:`ParametricCurve`. A stacked
        PolynomialCurve (coeffs (m, 3, K)) gives batched results with leading
        axis m (padding slots are solved too; mask them yourself).
      options: :class:`SolverOptions` (static).

    Returns:
      :class:`ClosestPoint` (fields with a leading m axis for a stacked curve).
      Differentiable in q: see the module docstring (envelope theorem for the
      distance, implicit function theorem for s, u and the points).
    """
    q = check_configuration(q)
    if not isinstance(curve, (PolynomialCurve, ParametricCurve)):
        raise ValueError(
            f"curve must be a PolynomialCurve or ParametricCurve, got {type(curve).__name__}; "
            "use closest_point_to_points for point sets"
        )
    return _closest_point_jit(q, curve, options)
