"""The Scenario pytree and its constructors (paper section 2: the arm of section 2.1, the
obstacles of section 2.3, the goal of eq. 9): obstacles in three padded groups so that scenes
of one padded shape share one compilation (``curves``: polynomial curves stacked to
``(m_c, 3, K)`` with ``curve_mask``; ``points``: point sets padded to ``(m_p, N_max, 3)``
with ``point_mask``; ``parametric``: a tuple of :class:`ParametricCurve`, each function
compiled separately), whose layout :mod:`softplan_jax.geometry._obstacles` owns;
:func:`make_scenario` builds one scene, :func:`stack_scenarios` a batch."""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._validation import (
    as_float_array,
    check_configuration,
    check_finite,
    check_points,
    check_scale,
    host_array,
    is_concrete,
)
from ..geometry._curves import ParametricCurve, PolynomialCurve, check_curve_scale, stack_curves
from ..geometry._obstacles import (  # obstacle_count re-exported: the layout belongs to obstacles
    obstacle_count,
    point_obstacle_distances,
)

__all__ = [
    "Scenario",
    "default_start",
    "make_scenario",
    "stack_scenarios",
    "obstacle_count",
    "scenario_warnings",
    "goal_obstacle_hits",
    "unreachable_reason",
    "check_scenario",
]


class Scenario(NamedTuple):
    """A planning problem (a pytree; every leaf an array except the static
    functions of ``parametric``).

    Attributes:
      q0: (n, 3) start configuration.
      goal: (3,) goal position of the tip.
      curves: PolynomialCurve with coeffs (m_c, 3, K), u_range (m_c, 2), radius (m_c,).
      curve_mask: (m_c,) bool, False for padding slots.
      points: (m_p, N_max, 3) point-set obstacles.
      point_mask: (m_p, N_max) bool, False for padding points.
      point_radius: (m_p,) radius of each point obstacle's points.
      parametric: tuple of ParametricCurve obstacles.
      arm_radius: () radius of the arm (clearance is measured from its surface).
      L_min: (n,) lower actuator limit on each L_i.
      L_max: (n,) upper actuator limit on each L_i (inf for none).
    """

    q0: jax.Array
    goal: jax.Array
    curves: PolynomialCurve
    curve_mask: jax.Array
    points: jax.Array
    point_mask: jax.Array
    point_radius: jax.Array
    parametric: tuple
    arm_radius: jax.Array
    L_min: jax.Array
    L_max: jax.Array

    @property
    def n_segments(self) -> int:
        return self.q0.shape[-2]


def default_start(n_segments: int = 3, length: float = 1.0, dtype=None):
    """The documented default start pose: a straight, vertical arm.

    Every segment has length ``length`` and theta = 0; the bending planes phi
    are 0, 2*pi/3, 2*pi/3, ... so that, the paper's ``R_i = Rz(phi) Ry(theta)``
    composing, consecutive segments bend in planes 120 degrees apart and the
    three lateral directions are all reachable from the straight pose.
    """
    if int(n_segments) < 1:
        raise ValueError(f"n_segments must be >= 1, got {n_segments}")
    n = int(n_segments)
    phi = np.full(n, 2 * math.pi / 3)
    phi[0] = 0.0
    q = np.stack([np.full(n, float(length)), np.zeros(n), phi], axis=1)
    return jnp.asarray(q, dtype=dtype or jnp.result_type(float))


def _length_limits(q0, L_min, L_max) -> tuple:
    """``(L_min, L_max)`` (n,) NumPy arrays of q0's dtype (None: 1e-3 and inf), checked: 0 < L_min
    < L_max, and q0's lengths within them. ValueError otherwise."""
    n, dtype = q0.shape[0], q0.dtype
    L_min = np.broadcast_to(np.asarray(1e-3 if L_min is None else L_min, dtype), (n,))
    L_max = np.broadcast_to(np.asarray(np.inf if L_max is None else L_max, dtype), (n,))
    if np.any(L_min <= 0) or np.any(L_max <= L_min) or np.any(np.isnan(L_max)):
        raise ValueError(f"need 0 < L_min < L_max; got L_min = {L_min.tolist()}, L_max = {L_max.tolist()}")
    lengths = np.asarray(q0)[:, 0]
    if np.any(lengths < L_min) or np.any(lengths > L_max):
        raise ValueError(f"start lengths {lengths.tolist()} lie outside [L_min, L_max]")
    return L_min, L_max


def make_scenario(
    goal,
    obstacles,
    q0=None,
    *,
    arm_radius=0.0,
    L_min=None,
    L_max=None,
    curve_slots: int | None = None,
    point_slots: int | None = None,
    max_points: int | None = None,
    degree: int | None = None,
) -> Scenario:
    """Build a :class:`Scenario`.

    Args:
      goal: (3,) goal of the tip.
      obstacles: a list of PolynomialCurve, ParametricCurve or (N, 3) point arrays.
      q0: (n, 3) start; None = :func:`default_start` (3 segments of length 1).
      arm_radius: radius of the arm, >= 0.
      L_min, L_max: scalars or (n,) actuator limits on L_i; None = (1e-3, inf).
      curve_slots, point_slots, max_points, degree: pad the obstacle groups
        to these sizes (to share one compiled shape across scenes); default
        the sizes of this scene (a group with no obstacle has zero slots).

    Returns:
      Scenario.
    """
    q0 = default_start() if q0 is None else check_configuration(q0)
    dtype = q0.dtype
    goal = as_float_array(goal, "goal")
    if goal.shape != (3,):
        raise ValueError(f"goal must have shape (3,); got {goal.shape}")
    check_finite(goal, "goal")
    check_scale(goal, "goal", dtype)
    if not isinstance(obstacles, (list, tuple)):
        raise ValueError(f"obstacles must be a list; got {type(obstacles).__name__}")
    polys, params, point_sets, point_radii = [], [], [], []
    for k, ob in enumerate(obstacles):
        if isinstance(ob, PolynomialCurve):
            if ob.coeffs.ndim != 2:
                raise ValueError(f"obstacles[{k}] is a stacked PolynomialCurve; pass single curves")
            check_curve_scale(ob.coeffs, ob.u_range, ob.radius, dtype, f"obstacles[{k}]")
            polys.append(ob)
        elif isinstance(ob, ParametricCurve):
            params.append(ob.astype(dtype))
        else:
            try:
                pts = check_points(ob, f"obstacles[{k}]")
            except ValueError as err:
                raise ValueError(
                    f"{err} (each obstacle must be a PolynomialCurve, a ParametricCurve or an "
                    "(N, 3) point array)"
                ) from None
            check_scale(pts, f"obstacles[{k}]", dtype)
            point_sets.append(np.asarray(pts))
            point_radii.append(0.0)
    curves, curve_mask = stack_curves(polys, size=max(curve_slots or 0, len(polys)), degree=degree)
    if curve_slots is not None and curve_slots < len(polys):
        raise ValueError(f"curve_slots = {curve_slots} < number of polynomial curves {len(polys)}")
    n_p = max(point_slots or 0, len(point_sets))
    if point_slots is not None and point_slots < len(point_sets):
        raise ValueError(f"point_slots = {point_slots} < number of point obstacles {len(point_sets)}")
    n_max = max([max_points or 0, 1] + [p.shape[0] for p in point_sets])
    if max_points is not None and max_points < max([0] + [p.shape[0] for p in point_sets]):
        raise ValueError(f"max_points = {max_points} is smaller than the largest point set")
    points = np.zeros((n_p, n_max, 3))
    point_mask = np.zeros((n_p, n_max), bool)
    for k, p in enumerate(point_sets):
        points[k, : p.shape[0]] = p
        point_mask[k, : p.shape[0]] = True
    L_min, L_max = _length_limits(q0, L_min, L_max)
    arm_radius = as_float_array(arm_radius, "arm_radius")
    if arm_radius.shape != () or not bool(np.isfinite(np.asarray(arm_radius))) or float(arm_radius) < 0:
        raise ValueError(f"arm_radius must be a finite scalar >= 0; got {arm_radius}")
    check_scale(arm_radius, "arm_radius", dtype, "values")
    check_scale(np.where(np.isinf(L_max), 0.0, L_max), "L_max", dtype, "lengths")
    # NumPy, then one transfer per array (host_array): eager jnp operations would each compile.
    scenario = Scenario(
        q0=q0,
        goal=host_array(goal, dtype),
        curves=curves.astype(dtype),
        curve_mask=curve_mask,
        points=host_array(points, dtype),
        point_mask=host_array(point_mask),
        point_radius=host_array(np.pad(point_radii, (0, n_p - len(point_radii))), dtype),
        parametric=tuple(params),
        arm_radius=host_array(arm_radius, dtype),
        L_min=host_array(L_min),
        L_max=host_array(L_max),
    )
    for msg in scenario_warnings(scenario):
        warnings.warn(msg, UserWarning, stacklevel=2)
    return scenario


def goal_obstacle_hits(scenario: Scenario) -> list[tuple[int, float, bool]]:
    """The obstacles whose surface the goal lies on or inside, for one (unbatched) scene:
    ``(slot, clearance, exact)`` for every real obstacle with ``clearance = distance -
    radius - arm_radius <= 0``, the tip's clearance if it were on the goal. The distance is
    exact for polynomial curves and point sets
    (:func:`~softplan_jax.geometry._obstacles.point_obstacle_distances`; the reachability
    proof ``goal_in_obstacle`` uses the same), a bound from below for parametric curves
    (``exact`` False)."""
    goal = np.asarray(scenario.goal, np.float64)
    arm_r = float(scenario.arm_radius)
    hits = []
    # beyond=arm_r: a curve proven farther than radius + arm_r needs no exact distance (no hit).
    for o in point_obstacle_distances(scenario, goal, beyond=arm_r):
        clearance = o["distance"] - o["radius"] - arm_r
        if clearance <= 0:
            hits.append((o["slot"], clearance, o["exact"]))
    return hits


def unreachable_reason(scenario: Scenario) -> str:
    """A proof that no configuration puts the tip on the goal without contact, for one
    (unbatched) scene, on the host: "beyond_reach" (every point of a PCC arm lies within its
    backbone length ``sum_i L_i`` of the base, each segment's chord being at most its arc, so
    a goal farther than ``sum_i L_max_i`` is out of reach), "goal_in_obstacle" (the goal within
    an obstacle's radius plus the arm's of its centre line: exact distances,
    :func:`goal_obstacle_hits`; parametric curves prove nothing), or "" (no proof)."""
    goal = np.asarray(scenario.goal, np.float64)
    L_max = np.asarray(scenario.L_max, np.float64)
    if np.all(np.isfinite(L_max)) and np.linalg.norm(goal) > np.sum(L_max):
        return "beyond_reach"
    if any(exact for _, _, exact in goal_obstacle_hits(scenario)):
        return "goal_in_obstacle"
    return ""


def scenario_warnings(scenario: Scenario) -> list[str]:
    """Sanity checks of one (unbatched) scenario that are not errors: the goal
    on or inside an obstacle (its radius plus the arm's; :func:`goal_obstacle_hits`,
    exact distances), or farther from the base than the arm reaches with every
    length at its limit L_max.

    Returns the messages (empty when all is well); :func:`make_scenario` and
    :func:`load_scenario` issue them as ``UserWarning`` and the CLI prints them.
    """
    out = []
    goal = np.asarray(scenario.goal, np.float64)
    hits = goal_obstacle_hits(scenario)
    if hits:
        slots = [slot for slot, _, _ in hits]
        clear = ", ".join(f"{c:.3g}" + ("" if exact else " (sampled)") for _, c, exact in hits)
        out.append(f"the goal {goal.tolist()} lies on or inside obstacle(s) {slots} (within the obstacle's "
                   f"radius plus the arm's: the tip's clearance there {clear}): it cannot be reached without contact")
    reach = float(np.sum(np.asarray(scenario.L_max, np.float64)))
    if np.isfinite(reach) and np.linalg.norm(goal) > reach:
        out.append(f"the goal is {np.linalg.norm(goal):.4g} from the arm's base, farther than the arm reaches "
                   f"with every length at L_max ({reach:.4g}): it cannot be reached")
    return out



def check_scenario(scenario, batched: bool | None = None) -> Scenario:
    """The planners' check of a Scenario built or edited by hand (``_replace``): every field
    an array of the shape and dtype the layout needs (the shapes of :class:`Scenario`'s
    attributes, one leading batch axis when ``batched``; None: either), the goal, the start
    and the limits finite. A ValueError names the first wrong field; returns the scenario."""
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario (see make_scenario), got {type(scenario).__name__}")
    if not isinstance(scenario.curves, PolynomialCurve):
        raise ValueError(f"scenario.curves must be a stacked PolynomialCurve, got {type(scenario.curves).__name__}")
    if not isinstance(scenario.parametric, tuple) or not all(isinstance(p, ParametricCurve)
                                                             for p in scenario.parametric):
        raise ValueError("scenario.parametric must be a tuple of ParametricCurve")
    q0 = getattr(scenario.q0, "shape", None)
    if q0 is None or len(q0) not in (2, 3) or q0[-1] != 3:
        raise ValueError(f"scenario.q0 must be an array of shape (n, 3) (a batch: (B, n, 3)), got {q0}")
    if not jnp.issubdtype(scenario.q0.dtype, jnp.floating):
        raise ValueError(f"scenario.q0 must be a floating array, got dtype {scenario.q0.dtype}")
    lead = q0[:-2]
    if batched is not None and bool(lead) != batched:
        raise ValueError(f"scenario.q0 has shape {q0}: expected {'a batch (B, n, 3)' if batched else '(n, 3)'}")
    n = q0[-2]
    m_c = scenario.curves.coeffs.shape[len(lead)] if scenario.curves.coeffs.ndim == len(lead) + 3 else None
    pts = getattr(scenario.points, "shape", ())
    m_p, n_max = (pts[len(lead)], pts[len(lead) + 1]) if len(pts) == len(lead) + 3 else (None, None)
    want = {
        "goal": (3,), "curves.coeffs": (m_c, 3, None), "curves.u_range": (m_c, 2), "curves.radius": (m_c,),
        "curve_mask": (m_c,), "points": (m_p, n_max, 3), "point_mask": (m_p, n_max), "point_radius": (m_p,),
        "arm_radius": (), "L_min": (n,), "L_max": (n,),
    }
    for name, shape in want.items():
        x = scenario
        for part in name.split("."):
            x = getattr(x, part)
        got = tuple(getattr(x, "shape", ()))
        full = lead + shape
        if not hasattr(x, "dtype") or len(got) != len(full) or any(
                w is not None and g != w for g, w in zip(got, full, strict=True)):
            dims = ["B" if k < len(lead) else "K" if w is None else str(w) for k, w in enumerate(full)]
            text = "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"
            raise ValueError(f"scenario.{name} must have shape {text} for a start q0 of shape {q0}, got "
                             f"{got if hasattr(x, 'dtype') else type(x).__name__} (rebuild it with make_scenario)")
        mask = name in ("curve_mask", "point_mask")
        if mask != (x.dtype == bool) or (not mask and x.dtype != scenario.q0.dtype):
            want_dtype = "bool" if mask else f"{scenario.q0.dtype} (the dtype of the start q0)"
            raise ValueError(f"scenario.{name} must be an array of dtype {want_dtype}, got {x.dtype}")
    for name in ("q0", "goal", "L_min"):
        check_finite(getattr(scenario, name), f"scenario.{name}")
    dtype = scenario.q0.dtype
    for name in ("goal", "points", "point_radius", "arm_radius"):
        check_scale(getattr(scenario, name), f"scenario.{name}", dtype, "values")
    if is_concrete(scenario.q0):  # a NumPy view: no slice dispatched to the device
        check_scale(np.asarray(scenario.q0)[..., 0], "scenario.q0", dtype, "segment lengths")
    check_curve_scale(scenario.curves.coeffs, scenario.curves.u_range, scenario.curves.radius, dtype,
                      "scenario.curves")
    return scenario


def stack_scenarios(scenarios) -> Scenario:
    """Stack scenarios of one padded shape into a batch (leading axis)."""
    scenarios = list(scenarios)
    if not scenarios:
        raise ValueError("stack_scenarios needs at least one scenario")
    ref = jax.tree_util.tree_structure(scenarios[0])
    shapes0 = [x.shape for x in jax.tree_util.tree_leaves(scenarios[0])]
    for k, sc in enumerate(scenarios):
        if jax.tree_util.tree_structure(sc) != ref or [x.shape for x in jax.tree_util.tree_leaves(sc)] != shapes0:
            raise ValueError(
                f"scenario {k} has a different padded shape or obstacle functions than scenario 0; "
                "build them with the same curve_slots/point_slots/max_points/degree"
            )

    def stack(*xs):
        if any(isinstance(x, jax.core.Tracer) for x in xs):
            return jnp.stack(xs)
        # Concrete leaves: stacked on the host and transferred once (one device_put per
        # leaf instead of one per scene); the values and dtypes are those of jnp.stack.
        return jnp.asarray(np.stack([np.asarray(x) for x in xs]), dtype=jnp.result_type(*xs))

    return jax.tree_util.tree_map(stack, *scenarios)
