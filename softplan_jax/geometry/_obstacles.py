"""A scene's obstacles as one padded layout: stacked polynomial curves, stacked point sets and
parametric curves, in that order, give every per-obstacle array of the library one leading axis
of ``m = m_c + m_p + m_par`` slots. This module is the only one that knows that order: it gives
the closest points of a whole scene (exact, paper §2.3: :func:`true_closest`; as the planner
models the obstacles, the N points of paper §3 for ``method="points"``: :func:`model_closest`),
per-slot radii, masks and clearances, samples to draw, and maps a per-obstacle or per-group
function over the slots (:func:`map_obstacles`, :func:`map_obstacle_groups`). Docs: "How the
planner works inside"."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._closest import ClosestPoint, SolverOptions, curve_closest
from ._curves import curve_points
from ._kinematics import motion_bound
from ._near_pairs import near_curves
from ._point_curve import point_curve_distance, point_curve_lower_bounds
from ._point_sets import point_set_closest, points_closest
from ._warm_start import curve_data, warm_curves

__all__ = [
    "obstacle_count",
    "map_obstacles",
    "map_obstacle_groups",
    "radius_and_mask",
    "clearance_of",
    "empty_closest",
    "placeholder_closest",
    "true_closest",
    "model_closest",
    "warm_cells",
    "warm_state",
    "near_state",
    "near_closest",
    "warm_closest",
    "obstacle_samples",
    "point_obstacle_distances",
    "obstacle_labels",
]


def obstacle_count(scenario) -> int:
    """Number of obstacle slots m (padding included): curves + point sets + parametric."""
    return scenario.curves.coeffs.shape[-3] + scenario.points.shape[-3] + len(scenario.parametric)


def map_obstacles(scenario, on_curve, on_points, slot_args=(), empty=None):
    """Apply a per-obstacle function to every slot of a scene, in slot order.

    Args:
      scenario: one Scenario (not batched).
      on_curve: ``on_curve(curve, *args) -> pytree``, for a polynomial curve
        (vmapped over the stacked curves) and for each parametric curve.
      on_points: ``on_points(points (N, 3), mask (N,), *args) -> pytree``, for
        a point set (vmapped over the stacked point sets).
      slot_args: a tuple of pytrees with a leading axis m (one entry per
        slot), passed to the functions entry by entry.
      empty: what to return for a scene without obstacle slots.

    Returns:
      The functions' results stacked along a leading axis m.
    """
    parts = []
    for kind, group, rows in _slot_groups(scenario, slot_args):
        if kind == "curves":
            parts.append(jax.vmap(on_curve)(group, *rows))
        elif kind == "points":
            parts.append(jax.vmap(on_points)(*group, *rows))
        else:  # one parametric curve: called directly (a Python function, not vmapped)
            out = on_curve(group, *jax.tree_util.tree_map(lambda x: x[0], rows))
            parts.append(jax.tree_util.tree_map(lambda x: x[None], out))
    return _concatenate(parts, empty)


def map_obstacle_groups(scenario, on_curves, on_point_sets, slot_args=(), empty=None):
    """Apply a per-GROUP function to the slots of a scene, group by group in slot order.

    Like :func:`map_obstacles`, but each function gets a whole group of slots
    of one kind (no vmap; for work that is not the same for every slot, e.g.
    a loop over some of them): the stacked polynomial curves, the stacked
    point sets, then each parametric curve as a group of one.

    Args:
      scenario: one Scenario (not batched).
      on_curves: ``on_curves(curves, *args) -> pytree`` with leading axis g:
        ``curves`` a curve stack with leading axis g (the polynomial stack, or
        a parametric curve with an axis 1 added to its array leaves, so that
        ``tree_map(lambda x: x[k], curves)`` is one curve either way).
      on_point_sets: ``on_point_sets(points (g, N, 3), mask (g, N), *args) -> pytree``.
      slot_args: a tuple of pytrees with a leading axis m, passed to the
        functions as their group's rows (leading axis g).
      empty: what to return for a scene without obstacle slots.

    Returns:
      The functions' results concatenated along the leading axis (m).
    """
    parts = []
    for kind, group, rows in _slot_groups(scenario, slot_args):
        if kind == "curves":
            parts.append(on_curves(group, *rows))
        elif kind == "points":
            parts.append(on_point_sets(*group, *rows))
        else:  # a parametric curve as a group of one
            parts.append(on_curves(jax.tree_util.tree_map(lambda x: x[None], group), *rows))
    return _concatenate(parts, empty)


def _slot_groups(scenario, slot_args):
    """The obstacle layout, in slot order: ``(kind, group, rows)`` for the stacked
    polynomial curves (``"curves"``), the stacked point sets (``"points"``, group =
    (points, mask)) and each parametric curve (``"parametric"``), where ``rows`` are the
    group's rows (leading axis) of every pytree in ``slot_args``. Empty groups are skipped."""
    m_c = scenario.curves.coeffs.shape[0]
    m_p = scenario.points.shape[0]

    def rows(a, b):
        return jax.tree_util.tree_map(lambda x: x[a:b], tuple(slot_args))

    if m_c:
        yield "curves", scenario.curves, rows(0, m_c)
    if m_p:
        yield "points", (scenario.points, scenario.point_mask), rows(m_c, m_c + m_p)
    for k, pc in enumerate(scenario.parametric):
        j = m_c + m_p + k
        yield "parametric", pc, rows(j, j + 1)


def _concatenate(parts, empty):
    """The groups' results joined along the slot axis (``empty`` for a scene without slots)."""
    if not parts:
        return empty
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)


def radius_and_mask(scenario, xp=jnp):
    """Obstacle radius (m,) and mask (m,) bool (False: a padding slot) of every slot, as
    arrays of ``xp`` (``numpy`` on the host)."""
    radius = xp.concatenate(
        [
            scenario.curves.radius,
            scenario.point_radius,
            xp.stack([pc.radius for pc in scenario.parametric])
            if scenario.parametric
            else xp.zeros((0,), scenario.q0.dtype),
        ]
    )
    mask = xp.concatenate(
        [
            scenario.curve_mask,
            xp.any(xp.asarray(scenario.point_mask), axis=-1),  # np.any would call jax's any
            xp.ones((len(scenario.parametric),), bool),
        ]
    )
    return radius, mask


def clearance_of(pairs: ClosestPoint, scenario):
    """(m,) the clearance of closest pairs (leading axis m): distance minus the arm's radius
    minus the obstacle's (docs: Conventions, "Clearance and collision"), +inf for padding slots."""
    radius, mask = radius_and_mask(scenario)
    return jnp.where(mask, pairs.distance - scenario.arm_radius - radius, jnp.inf)


def empty_closest(dtype) -> ClosestPoint:
    """A ClosestPoint with zero obstacles (a scene without obstacles)."""
    z = jnp.zeros((0,), dtype)
    return ClosestPoint(z, jnp.zeros((0,), jnp.int32), z, z, jnp.zeros((0, 3), dtype), jnp.zeros((0, 3), dtype),
                        jnp.zeros((0,), bool))


def placeholder_closest(q, scenario) -> ClosestPoint:
    """Zeros of the shape of :func:`true_closest` (where no exact pair is needed)."""
    m = obstacle_count(scenario)
    z = jnp.zeros((m,), q.dtype)
    return ClosestPoint(z, jnp.zeros((m,), jnp.int32), z, z, jnp.zeros((m, 3), q.dtype),
                        jnp.zeros((m, 3), q.dtype), jnp.ones((m,), bool))


def true_closest(q, scenario, solver: SolverOptions) -> ClosestPoint:
    """Exact closest pairs between the arm and every obstacle slot of a scene.

    Curves by the solver of paper §2.3; point sets by the exact closest point
    of the backbone to each point. Padding slots are solved too (their values
    are meaningless; mask them with :func:`radius_and_mask`).

    Args:
      q: (n, 3) configuration.
      scenario: one Scenario.
      solver: SolverOptions (static).

    Returns:
      ClosestPoint whose fields have a leading axis m.
    """
    return map_obstacles(
        scenario,
        lambda c: curve_closest(q, c, solver),
        lambda p, m: point_set_closest(q, p, m),
        empty=empty_closest(q.dtype),
    )


def _curve_groups(scenario):
    """The curve slots as stacks: the polynomial stack (if any), then each
    parametric curve as a stack of one (a leading axis 1 on its array leaves)."""
    groups = []
    if scenario.curves.coeffs.shape[0]:
        groups.append((scenario.curves, scenario.curve_mask))
    for pc in scenario.parametric:
        groups.append((jax.tree_util.tree_map(lambda x: x[None], pc), jnp.ones((1,), bool)))
    return groups


def warm_cells(scenario, solver: SolverOptions):
    """The warm start's per-curve data (:func:`~softplan_jax.geometry._warm_start.curve_data`)
    of every curve slot, one entry per curve stack (polynomial stack, then each
    parametric curve); computed once per scenario, outside the scan."""
    dtype = scenario.q0.dtype
    return tuple(
        jax.vmap(lambda c: curve_data(c, solver))(curves.astype(dtype)) for curves, _ in _curve_groups(scenario)
    )


def warm_state(scenario, rows=None):
    """The warm start's state before the first step: u* = 0 (m_g, n) per curve stack, n the
    arm's segments or ``rows`` (unused: the first step solves every pair in full)."""
    n = scenario.q0.shape[0] if rows is None else rows
    return tuple(
        jnp.zeros((curves.u_range.shape[0], n), scenario.q0.dtype) for curves, _ in _curve_groups(scenario)
    )


def warm_closest(q, scenario, solver: SolverOptions, cells, state, fresh):
    """:func:`true_closest` with the warm start of :mod:`softplan_jax.geometry._warm_start`
    (same results, certified; derivatives the same).

    Args:
      q: (n, 3) configuration.
      scenario: one Scenario.
      solver: SolverOptions (static).
      cells: :func:`warm_cells` of the scenario.
      state: the previous step's state (:func:`warm_state` before the first step).
      fresh: () bool, no warm state yet: every curve pair takes the full solve.

    Returns:
      ``(ClosestPoint with a leading axis m, the next state, fallbacks () int32:
      curve-segment pairs that took the full solve)``.
    """
    outs = [
        warm_curves(q, curves, c, u, fresh, active, solver)
        for (curves, active), c, u in zip(_curve_groups(scenario), cells, state, strict=True)
    ]
    closest, fallbacks = _with_point_sets(q, scenario, outs)
    return closest, tuple(o[1] for o in outs), fallbacks


def near_state(scenario, rows=None):
    """The state of :func:`near_closest` before the first step: ``(groups, q_prev)``, per curve
    stack every pair's u* and distance bound, zeros (m_g, n), and the previous configuration,
    zeros (n, 3); n the arm's segments or ``rows`` (unused: the first step solves every pair)."""
    n = scenario.q0.shape[0] if rows is None else rows
    dtype = scenario.q0.dtype
    groups = tuple((jnp.zeros((c.u_range.shape[0], n), dtype),) * 2 for c, _ in _curve_groups(scenario))
    return groups, jnp.zeros((n, 3), dtype)


def near_closest(q, scenario, solver: SolverOptions, cells, state, fresh, reach, travel=None):
    """:func:`warm_closest` solving only the curve pairs whose distance bound is below ``reach``
    (:func:`~softplan_jax.geometry._near_pairs.near_curves`; the others report their bound).

    Args:
      q, scenario, solver, cells, fresh: as :func:`warm_closest`.
      state: the previous step's state (:func:`near_state` before the first step).
      reach: () a distance, centre line to centre line.
      travel: (m,) how far each obstacle slot can have moved since the previous step (None:
        a static scene).

    Returns:
      ``(ClosestPoint with a leading axis m, the next state, fallbacks () int32)``.
    """
    groups, q_prev = state
    bound = motion_bound(q_prev, q)
    travels = [None] * len(groups) if travel is None else _group_slices(scenario, travel)
    outs = [
        near_curves(q, curves, c, g, bound, fresh, active, reach, solver, tr)
        for (curves, active), c, g, tr in zip(_curve_groups(scenario), cells, groups, travels, strict=True)
    ]
    closest, fallbacks = _with_point_sets(q, scenario, outs)
    return closest, (tuple(o[1] for o in outs), jax.lax.stop_gradient(q)), fallbacks


def _group_slices(scenario, x):
    """A per-slot array (m, ...) cut into :func:`_curve_groups`' stacks: the polynomial stack's
    slots, then each parametric curve's slot (the point sets' slots between them left out)."""
    m_c, m_p = scenario.curves.coeffs.shape[0], scenario.points.shape[0]
    parts = [x[:m_c]] if m_c else []
    return parts + [x[m_c + m_p + k : m_c + m_p + k + 1] for k in range(len(scenario.parametric))]


def _with_point_sets(q, scenario, outs):
    """``(ClosestPoint of every slot, fallbacks)`` from the curve stacks' ``(closest, state,
    fallbacks)``: the point sets' exact closest points inserted in their slots."""
    parts = [o[0] for o in outs]
    m_c, m_p = scenario.curves.coeffs.shape[0], scenario.points.shape[0]
    if m_p:
        pts = jax.vmap(lambda p, m: point_set_closest(q, p, m))(scenario.points, scenario.point_mask)
        parts.insert(1 if m_c else 0, pts)
    fallbacks = sum((o[2] for o in outs), jnp.zeros((), jnp.int32))
    return _concatenate(parts, empty_closest(q.dtype)), fallbacks


def model_closest(q, scenario, truth: ClosestPoint, method: str, n_points: int,
                  points_per_segment: int) -> ClosestPoint:
    """Closest pairs as the planner models the obstacles (paper eq. 9's V_sj).

    ``method="curve"``: a curve's pair is its exact one, taken from ``truth``
    (:func:`true_closest` at the same q). ``method="points"``: every curve is
    ``n_points`` points evenly spaced in u (:func:`~softplan_jax.geometry._curves.curve_points`).
    Point sets always use the N-point model: the arm sampled at
    ``points_per_segment`` points per segment (paper Table 1), brute force.

    Returns:
      ClosestPoint with a leading axis m.
    """
    k = points_per_segment

    def on_points(p, m, t):
        return points_closest(q, p, m, k)

    if method == "curve":
        def on_curve(c, t):
            return t
    else:
        all_true = jnp.ones((n_points,), bool)

        def on_curve(c, t):
            return points_closest(q, curve_points(c, n_points), all_true, k)

    return map_obstacles(scenario, on_curve, on_points, (truth,), empty=empty_closest(q.dtype))


def obstacle_labels(scenario) -> list[str]:
    """Names of the real (unmasked) obstacles in slot order: "curve 1", "points 1", "parametric 1", ..."""
    n_c = int(np.asarray(scenario.curve_mask).sum())
    n_p = int(np.asarray(scenario.point_mask).any(axis=-1).sum())
    return (
        [f"curve {k + 1}" for k in range(n_c)]
        + [f"points {k + 1}" for k in range(n_p)]
        + [f"parametric {k + 1}" for k in range(len(scenario.parametric))]
    )


def point_obstacle_distances(scenario, p, parametric_samples: int = 2049, beyond: float | None = None) -> list[dict]:
    """The distance from one point p (3,) to every real obstacle (host side, NumPy), in slot
    order: ``dict(kind, distance, radius, slot, exact)``. Polynomial curves: the exact
    point-curve distance (:func:`~softplan_jax.geometry._point_curve.point_curve_distance`);
    point sets: the nearest point; parametric curves: ``parametric_samples`` samples
    less half their largest spacing (never above the true distance, ``exact`` False: a
    function has no closed form). ``beyond`` (a distance), if given: a polynomial curve
    proven farther than its radius plus ``beyond``
    (:func:`~softplan_jax.geometry._point_curve.point_curve_lower_bound`) gets that bound
    instead of the exact distance (``exact`` False), for a caller that only asks which
    obstacles lie within ``beyond`` of their surface."""
    p = np.asarray(p, np.float64)
    out = []
    coeffs = np.asarray(scenario.curves.coeffs, dtype=np.float64)
    u_range = np.asarray(scenario.curves.u_range, dtype=np.float64)
    radius = np.asarray(scenario.curves.radius, dtype=np.float64)
    real = np.nonzero(np.asarray(scenario.curve_mask))[0]
    bounds = None if beyond is None else point_curve_lower_bounds(coeffs[real], u_range[real], p)
    for i, k in enumerate(real):
        d = None if bounds is None else bounds[i]
        exact = d is None or not d > float(radius[k]) + beyond
        if exact:
            d = point_curve_distance(coeffs[k], u_range[k], p)
        out.append(dict(kind="curve", distance=float(d), radius=float(radius[k]), slot=int(k), exact=exact))
    for o in obstacle_samples(scenario, parametric_samples, curves=False):
        if o["kind"] == "points":
            d = float(np.min(np.linalg.norm(o["pts"] - p, axis=-1)))
            out.append(dict(kind="points", distance=d, radius=o["radius"], slot=o["slot"], exact=True))
        elif o["slot"] >= coeffs.shape[0]:  # parametric
            pts = o["pts"]
            d = float(np.min(np.linalg.norm(pts - p, axis=-1)))
            d -= 0.5 * float(np.max(np.linalg.norm(np.diff(pts, axis=0), axis=-1), initial=0.0))
            out.append(dict(kind="parametric", distance=d, radius=o["radius"], slot=o["slot"], exact=False))
    return out


def obstacle_samples(scenario, samples: int, curves: bool = True) -> list[dict]:
    """Every real obstacle, sampled for drawing (host side, NumPy), in slot order
    (``curves`` False: the point sets and parametric curves only).

    Returns:
      A list of ``dict(kind="curve" | "points", pts (N, 3), radius float,
      slot int)``: curves sampled at ``samples`` values of u evenly spaced
      (ends included), point sets as their unmasked points; ``slot`` is the
      obstacle's index in the clearance records (padding slots counted).
    """
    obs = []
    coeffs = np.asarray(scenario.curves.coeffs, dtype=float)
    u_range = np.asarray(scenario.curves.u_range, dtype=float)
    radius = np.asarray(scenario.curves.radius, dtype=float)
    for k in np.nonzero(np.asarray(scenario.curve_mask))[0] if curves else ():
        u = np.linspace(u_range[k, 0], u_range[k, 1], samples)
        pts = np.stack([np.polynomial.polynomial.polyval(u, coeffs[k, a]) for a in range(3)], axis=-1)
        obs.append(dict(kind="curve", pts=pts, radius=float(radius[k]), slot=int(k)))
    points = np.asarray(scenario.points, dtype=float)
    point_mask = np.asarray(scenario.point_mask)
    point_radius = np.asarray(scenario.point_radius, dtype=float)
    for k in range(points.shape[0]):
        if point_mask[k].any():
            obs.append(dict(kind="points", pts=points[k][point_mask[k]], radius=float(point_radius[k]),
                            slot=coeffs.shape[0] + k))
    for k, pc in enumerate(scenario.parametric):
        pts = np.asarray(curve_points(pc, samples), dtype=float)
        obs.append(dict(kind="curve", pts=pts, radius=float(np.asarray(pc.radius)),
                        slot=coeffs.shape[0] + points.shape[0] + k))
    return obs
