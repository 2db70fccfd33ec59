"""Scenarios: the arm's start, the goal and the obstacles, as one pytree.

Obstacles come in three padded groups so that scenes of one padded shape share
one compilation:

* ``curves`` — polynomial curves stacked to ``(m_c, 3, K)`` with ``curve_mask``;
* ``points`` — point-set obstacles padded to ``(m_p, N_max, 3)`` with
  ``point_mask`` ``(m_p, N_max)`` (a slot with no real point is padding);
* ``parametric`` — a tuple of :class:`ParametricCurve` (their functions are
  static, so each distinct function compiles separately).

:func:`paper_scenario` gives the paper's three simulations (Tables 2–4);
:func:`load_scenario` / :func:`save_scenario` read and write the JSON format
documented in the README.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .curves import ParametricCurve, PolynomialCurve, line_segment, stack_curves
from .validation import as_float_array, check_configuration, check_finite, check_points

__all__ = [
    "Scenario",
    "default_start",
    "make_scenario",
    "paper_scenario",
    "PAPER_SCENARIOS",
    "PAPER_RESULTS",
    "load_scenario",
    "save_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    "obstacle_count",
    "scenario_warnings",
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


def obstacle_count(scenario: Scenario) -> int:
    """Number of obstacle slots (padding included): curves + point sets + parametric."""
    return scenario.curves.coeffs.shape[-3] + scenario.points.shape[-3] + len(scenario.parametric)


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
    if not isinstance(obstacles, (list, tuple)):
        raise ValueError(f"obstacles must be a list; got {type(obstacles).__name__}")
    polys, params, point_sets, point_radii = [], [], [], []
    for k, ob in enumerate(obstacles):
        if isinstance(ob, PolynomialCurve):
            if ob.coeffs.ndim != 2:
                raise ValueError(f"obstacles[{k}] is a stacked PolynomialCurve; pass single curves")
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
    n = q0.shape[0]
    L_min = jnp.broadcast_to(jnp.asarray(1e-3 if L_min is None else L_min, dtype), (n,))
    L_max = jnp.broadcast_to(jnp.asarray(jnp.inf if L_max is None else L_max, dtype), (n,))
    if bool(jnp.any(L_min <= 0)) or bool(jnp.any(L_max <= L_min)) or bool(jnp.any(jnp.isnan(L_max))):
        raise ValueError(f"need 0 < L_min < L_max; got L_min = {L_min.tolist()}, L_max = {L_max.tolist()}")
    if bool(jnp.any(q0[:, 0] < L_min)) or bool(jnp.any(q0[:, 0] > L_max)):
        raise ValueError(f"start lengths {q0[:, 0].tolist()} lie outside [L_min, L_max]")
    arm_radius = as_float_array(arm_radius, "arm_radius")
    if arm_radius.shape != () or not bool(jnp.isfinite(arm_radius)) or float(arm_radius) < 0:
        raise ValueError(f"arm_radius must be a finite scalar >= 0; got {arm_radius}")
    scenario = Scenario(
        q0=q0,
        goal=goal.astype(dtype),
        curves=curves.astype(dtype),
        curve_mask=curve_mask,
        points=jnp.asarray(points, dtype),
        point_mask=jnp.asarray(point_mask),
        point_radius=jnp.asarray(np.pad(point_radii, (0, n_p - len(point_radii))), dtype),
        parametric=tuple(params),
        arm_radius=arm_radius.astype(dtype),
        L_min=L_min,
        L_max=L_max,
    )
    for msg in scenario_warnings(scenario):
        warnings.warn(msg, UserWarning, stacklevel=2)
    return scenario


# Curve samples of the goal check in scenario_warnings (a warning, not a proof: a
# goal within the sample spacing of a curve counts as on it).
_GOAL_CHECK_SAMPLES = 2049


def scenario_warnings(scenario: Scenario) -> list[str]:
    """Sanity checks of one (unbatched) scenario that are not errors: the goal
    on or inside an obstacle (its radius plus the arm's), or farther from the
    base than the arm reaches with every length at its limit L_max.

    Returns the messages (empty when all is well); :func:`make_scenario` and
    :func:`load_scenario` issue them as ``UserWarning`` and the CLI prints them.
    """
    from .curves import curve_points

    out = []
    goal = np.asarray(scenario.goal, np.float64)
    arm_r = float(scenario.arm_radius)
    # Distance sampled on the curves minus half the sample spacing: never larger than the true one.
    hits = []
    m_c = scenario.curves.coeffs.shape[0]
    curves = [(k, jax.tree_util.tree_map(lambda x, k=k: x[k], scenario.curves)) for k in range(m_c)
              if bool(scenario.curve_mask[k])]
    curves += [(m_c + scenario.points.shape[0] + k, pc) for k, pc in enumerate(scenario.parametric)]
    for k, c in curves:
        pts = np.asarray(curve_points(c, _GOAL_CHECK_SAMPLES), np.float64)
        spacing = float(np.max(np.linalg.norm(np.diff(pts, axis=0), axis=-1)))
        d = float(np.min(np.linalg.norm(pts - goal, axis=-1))) - 0.5 * spacing
        if d <= float(c.radius) + arm_r:
            hits.append(k)
    for k in range(scenario.points.shape[0]):
        pts = np.asarray(scenario.points[k], np.float64)[np.asarray(scenario.point_mask[k])]
        if pts.size and np.min(np.linalg.norm(pts - goal, axis=-1)) <= float(scenario.point_radius[k]) + arm_r:
            hits.append(m_c + k)
    if hits:
        out.append(f"the goal {goal.tolist()} lies on or inside obstacle(s) {hits} (within the obstacle's "
                   "radius plus the arm's): it cannot be reached without contact")
    reach = float(np.sum(np.asarray(scenario.L_max, np.float64)))
    if np.isfinite(reach) and np.linalg.norm(goal) > reach:
        out.append(f"the goal is {np.linalg.norm(goal):.4g} from the arm's base, farther than the arm reaches "
                   f"with every length at L_max ({reach:.4g}): it cannot be reached")
    return out


# ----------------------------------------------------------------------------
# The paper's scenarios (Tables 2-4).


def _poly(x, y, z, u_range):
    """PolynomialCurve from per-axis coefficient lists (lowest degree first)."""
    K = max(len(x), len(y), len(z))
    coeffs = np.zeros((3, K))
    for row, c in enumerate((x, y, z)):
        coeffs[row, : len(c)] = c
    return PolynomialCurve(coeffs, u_range)


PAPER_SCENARIOS = {
    # Table 2: X = 1, Y = u, Z = 0.5 - u, -2 < u < 2.
    "sim1": dict(goal=[1.1, -0.8, 0.9], curves=[([1.0], [0.0, 1.0], [0.5, -1.0], (-2.0, 2.0))]),
    # Table 3: X = 0.5, Y = u, Z = 5u^2, -2 < u < 2.
    "sim2": dict(goal=[1.0, 1.0, 1.0], curves=[([0.5], [0.0, 1.0], [0.0, 0.0, 5.0], (-2.0, 2.0))]),
    # Table 4, the four legible branches, plus the trunk X = 1, Y = 1, Z = u,
    # u in [0, 3]: the table is garbled after its fourth row (DESIGN.md).
    "tree": dict(
        goal=[1.0, 0.7, 1.45],
        curves=[
            ([1.0, -0.2], [1.0, -1.0], [2.0, 0.0, -1.0], (0.0, 1.0)),
            ([1.0, -0.5], [1.0, 1.0, -1.0], [1.7, 0.3], (0.0, 1.5)),
            ([1.0, 1.0, -1.0], [1.0, -1.0], [2.0, -0.1], (0.0, 1.5)),
            ([1.0], [1.0, -1.0], [1.5, 0.1], (0.0, 1.5)),
            ([1.0], [1.0], [0.0, 1.0], (0.0, 3.0)),
        ],
    ),
}

# The paper's reported results: (iterations to reach goal, average computation
# time in seconds) per obstacle model, Tables 2-4 ("curve" = proposed method).
PAPER_RESULTS = {
    "sim1": {"curve": (60, 0.2914), 1: (24, 0.0053), 10: (24, 0.0690), 50: (24, 0.4254), 100: (66, 1.6679)},
    "sim2": {"curve": (30, 0.2971), 1: (23, 0.0044), 10: (23, 0.0599), 50: (24, 0.2720), 100: (23, 0.5794)},
    # Table 4's numbers are not legible in the source; the text says the curve
    # method is "comparable to the 10-point method" and much faster than 50.
    "tree": {},
}


def paper_scenario(name: str, *, dtype=None, **kwargs) -> Scenario:
    """One of the paper's scenarios: "sim1" (Table 2), "sim2" (Table 3), "tree" (Table 4).

    Three segments of static length 1 (paper Table 1), starting from
    :func:`default_start`. The tree uses the four legible branches of Table 4
    plus the trunk X = 1, Y = 1, Z = u, u in [0, 3] (the table is garbled
    after its fourth row). Extra keyword arguments go to :func:`make_scenario`
    (padding, radii, limits).
    """
    if name not in PAPER_SCENARIOS:
        raise ValueError(f"unknown paper scenario {name!r}; choose one of {sorted(PAPER_SCENARIOS)}")
    spec = PAPER_SCENARIOS[name]
    curves = [_poly(x, y, z, ur) for x, y, z, ur in spec["curves"]]
    q0 = kwargs.pop("q0", None)
    q0 = default_start(dtype=dtype) if q0 is None else q0
    return make_scenario(jnp.asarray(spec["goal"], q0.dtype), curves, q0, **kwargs)


# ----------------------------------------------------------------------------
# JSON scenario files.

# "metadata": any JSON object (e.g. fit residuals from `softplan fit`); kept out of the Scenario.
_TOP_KEYS = {"format", "arm", "goal", "obstacles", "name", "description", "metadata"}
_ARM_KEYS = {"segments", "start", "radius", "length_limits"}
_FORMAT = "softplan-scenario/1"


def _err(path: str, msg: str) -> ValueError:
    return ValueError(f"scenario field {path}: {msg}")


def _only_numbers(value) -> bool:
    if isinstance(value, bool) or isinstance(value, str) or value is None:
        return False
    if isinstance(value, (list, tuple)):
        return all(_only_numbers(v) for v in value)
    return isinstance(value, (int, float))


def _num_array(value, path: str, shape=None):
    if not _only_numbers(value):
        raise _err(path, f"must be numbers (JSON numbers, not strings or booleans), got {value!r}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise _err(path, f"must be numbers, got {value!r}") from None
    if shape is not None and (
        arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape, shape, strict=True))
    ):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise _err(path, f"must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise _err(path, f"must be finite, got {value!r}")
    return arr


def scenario_from_dict(data: dict, dtype=None) -> Scenario:
    """Build a Scenario from the JSON structure (see the README); every
    malformed field raises a ValueError naming the field."""
    if not isinstance(data, dict):
        raise _err("(top)", f"must be a JSON object, got {type(data).__name__}")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise _err(key, f"must be a string, got {data[key]!r}")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise _err(sorted(unknown)[0], f"unknown key (allowed: {sorted(_TOP_KEYS)})")
    if data.get("format", _FORMAT) != _FORMAT:
        raise _err("format", f"must be {_FORMAT!r}, got {data.get('format')!r}")
    if not isinstance(data.get("metadata", {}), dict):
        raise _err("metadata", f"must be a JSON object, got {data['metadata']!r}")
    if "goal" not in data:
        raise _err("goal", "is missing")
    goal = _num_array(data["goal"], "goal", (3,))
    arm = data.get("arm", {})
    if not isinstance(arm, dict):
        raise _err("arm", "must be an object")
    unknown = set(arm) - _ARM_KEYS
    if unknown:
        raise _err(f"arm.{sorted(unknown)[0]}", f"unknown key (allowed: {sorted(_ARM_KEYS)})")
    n = arm.get("segments", 3)
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise _err("arm.segments", f"must be an integer >= 1, got {n!r}")
    if "start" in arm:
        q0 = _num_array(arm["start"], "arm.start", (n, 3))
        if np.any(q0[:, 0] <= 0):
            raise _err("arm.start", f"segment lengths (first column) must be > 0, got {q0[:, 0].tolist()}")
    else:
        q0 = np.asarray(default_start(n))
    radius = _num_array(arm.get("radius", 0.0), "arm.radius", ())
    if radius < 0:
        raise _err("arm.radius", f"must be >= 0, got {float(radius)}")
    L_min, L_max = 1e-3, math.inf
    if "length_limits" in arm:
        lim = arm["length_limits"]
        if not isinstance(lim, (list, tuple)) or len(lim) != 2:
            raise _err("arm.length_limits", f"must be [L_min, L_max], got {lim!r}")
        L_min = float(_num_array(lim[0], "arm.length_limits[0]", ()))
        L_max = math.inf if lim[1] is None else float(_num_array(lim[1], "arm.length_limits[1]", ()))
        if not 0 < L_min < L_max:
            raise _err("arm.length_limits", f"need 0 < L_min < L_max, got {lim!r}")
        if np.any(q0[:, 0] < L_min) or np.any(q0[:, 0] > L_max):
            raise _err("arm.length_limits", f"the start lengths {q0[:, 0].tolist()} lie outside {lim!r}")
    obstacles_json = data.get("obstacles", [])
    if not isinstance(obstacles_json, list):
        raise _err("obstacles", "must be a list")
    obstacles = []
    for k, ob in enumerate(obstacles_json):
        path = f"obstacles[{k}]"
        if not isinstance(ob, dict) or "type" not in ob:
            raise _err(path, "must be an object with a 'type'")
        kind = ob["type"]
        allowed = {
            "polynomial": {"type", "coeffs", "u_range", "radius", "name", "metadata"},
            "line_segment": {"type", "start", "end", "radius", "name", "metadata"},
            "points": {"type", "points", "radius", "name", "metadata"},
        }
        if kind not in allowed:
            raise _err(f"{path}.type", f"unknown obstacle type {kind!r}; choose one of {sorted(allowed)}")
        extra = set(ob) - allowed[kind]
        if extra:
            raise _err(f"{path}.{sorted(extra)[0]}", f"unknown key for a {kind} obstacle")
        if not isinstance(ob.get("metadata", {}), dict):
            raise _err(f"{path}.metadata", f"must be a JSON object, got {ob['metadata']!r}")
        r = _num_array(ob.get("radius", 0.0), f"{path}.radius", ())
        if r < 0:
            raise _err(f"{path}.radius", f"must be >= 0, got {float(r)}")
        if kind == "polynomial":
            for key in ("coeffs", "u_range"):
                if key not in ob:
                    raise _err(f"{path}.{key}", "is missing")
            coeffs = _num_array(ob["coeffs"], f"{path}.coeffs", (3, None))
            if coeffs.shape[1] < 1:
                raise _err(f"{path}.coeffs", "needs at least one coefficient per axis")
            u_range = _num_array(ob["u_range"], f"{path}.u_range", (2,))
            if not u_range[0] < u_range[1]:
                raise _err(f"{path}.u_range", f"must satisfy u_min < u_max, got {u_range.tolist()}")
            obstacles.append(PolynomialCurve(coeffs, u_range, float(r)))
        elif kind == "line_segment":
            for key in ("start", "end"):
                if key not in ob:
                    raise _err(f"{path}.{key}", "is missing")
            a = _num_array(ob["start"], f"{path}.start", (3,))
            b = _num_array(ob["end"], f"{path}.end", (3,))
            obstacles.append(line_segment(a, b, float(r)))
        else:
            if "points" not in ob:
                raise _err(f"{path}.points", "is missing")
            pts = _num_array(ob["points"], f"{path}.points", (None, 3))
            if pts.shape[0] == 0:
                raise _err(f"{path}.points", "is empty")
            obstacles.append((pts, float(r)))
    # Point radii are per obstacle: build, then set them.
    plain = [o[0] if isinstance(o, tuple) else o for o in obstacles]
    q0 = jnp.asarray(q0, dtype or jnp.result_type(float))
    scen = make_scenario(jnp.asarray(goal, q0.dtype), plain, q0, arm_radius=float(radius), L_min=L_min, L_max=L_max)
    radii = [o[1] for o in obstacles if isinstance(o, tuple)]
    if radii:
        pr = np.zeros(scen.point_radius.shape)
        pr[: len(radii)] = radii
        scen = scen._replace(point_radius=jnp.asarray(pr, q0.dtype))
    return scen


def scenario_to_dict(scenario: Scenario, name: str | None = None) -> dict:
    """The JSON structure of a Scenario (padding dropped). ParametricCurves
    cannot be written: their functions are arbitrary code."""
    if scenario.parametric:
        raise ValueError(
            "a scenario with ParametricCurve obstacles cannot be saved to JSON; "
            "fit a PolynomialCurve to it (fit_polynomial_curve) first"
        )
    if scenario.q0.ndim != 2:
        raise ValueError("save one scenario at a time (this one is batched)")
    q0 = np.asarray(scenario.q0)
    obstacles = []
    coeffs = np.asarray(scenario.curves.coeffs)
    for k in np.nonzero(np.asarray(scenario.curve_mask))[0]:
        obstacles.append(
            {
                "type": "polynomial",
                "coeffs": coeffs[k].tolist(),
                "u_range": np.asarray(scenario.curves.u_range[k]).tolist(),
                "radius": float(scenario.curves.radius[k]),
            }
        )
    pm = np.asarray(scenario.point_mask)
    for k in range(pm.shape[0]):
        if pm[k].any():
            obstacles.append(
                {
                    "type": "points",
                    "points": np.asarray(scenario.points[k])[pm[k]].tolist(),
                    "radius": float(scenario.point_radius[k]),
                }
            )
    L_max = float(scenario.L_max.max())
    out = {
        "format": _FORMAT,
        "arm": {
            "segments": int(q0.shape[0]),
            "start": q0.tolist(),
            "radius": float(scenario.arm_radius),
            "length_limits": [float(scenario.L_min.min()), None if math.isinf(L_max) else L_max],
        },
        "goal": np.asarray(scenario.goal).tolist(),
        "obstacles": obstacles,
    }
    if name:
        out = {"name": name, **out}
    return out


def load_scenario(path, dtype=None) -> Scenario:
    """Read a scenario JSON file (format ``softplan-scenario/1``, see the README)."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise ValueError(f"scenario file not found: {path}") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"scenario file {path} is not valid JSON: {err}") from None
    except UnicodeDecodeError as err:
        raise ValueError(f"scenario file {path} is not UTF-8 text: {err}") from None
    except OSError as err:
        raise ValueError(f"cannot read scenario file {path}: {err.strerror or err}") from None
    try:
        return scenario_from_dict(data, dtype=dtype)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def save_scenario(scenario: Scenario, path, name: str | None = None, overwrite: bool = False) -> None:
    """Write a scenario as JSON. Refuses to replace an existing file unless
    ``overwrite=True``; the file is written whole (via a temporary file) or not at all."""
    write_json_file(path, scenario_to_dict(scenario, name), overwrite)


def write_json_file(path, data: dict, overwrite: bool = False) -> None:
    """Write ``data`` as an indented JSON file, whole (via a temporary file in the
    same directory, then a rename) or not at all; an existing file is replaced
    only with ``overwrite=True`` (ValueError otherwise)."""
    path = os.fspath(path)
    if os.path.exists(path) and not overwrite:
        raise ValueError(f"{path} exists; pass overwrite=True to replace it")
    text = json.dumps(data, indent=2)
    fd, tmp = tempfile.mkstemp(prefix=".softplan-", suffix=".json", dir=os.path.dirname(os.path.abspath(path)))
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


# ----------------------------------------------------------------------------
# Random scenario suites (benchmarks/batch_sweep.py).

import functools  # noqa: E402


def _seed_sequence(key_or_seed) -> np.random.SeedSequence:
    """A NumPy SeedSequence from an int seed or a JAX PRNG key (raw or typed)."""
    if isinstance(key_or_seed, (int, np.integer)) and not isinstance(key_or_seed, bool):
        if int(key_or_seed) < 0:
            raise ValueError(f"seed must be >= 0, got {key_or_seed}")
        return np.random.SeedSequence(int(key_or_seed))
    try:
        key = key_or_seed
        if jnp.issubdtype(jnp.asarray(key).dtype, jax.dtypes.prng_key):
            key = jax.random.key_data(key)
        words = np.asarray(key)
    except (TypeError, ValueError):
        words = None
    if words is None or words.dtype.kind not in "ui" or words.size == 0:
        raise ValueError(f"key_or_seed must be an int seed or a JAX PRNG key, got {key_or_seed!r}")
    return np.random.SeedSequence([int(w) for w in words.astype(np.uint64).ravel()])


@functools.cache
def _batched_tips():
    """jit(vmap(tip position)), built once (a new jit per call would recompile)."""
    from .kinematics import tip_position

    return jax.jit(jax.vmap(tip_position))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_perpendicular(rng, e):
    """Unit vectors (..., 3) perpendicular to the unit vectors e (..., 3), uniform in angle."""
    helper = np.where(np.abs(e[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    b1 = _unit(np.cross(e, helper))
    b2 = np.cross(e, b1)
    ang = rng.uniform(0.0, 2.0 * np.pi, e.shape[:-1])[..., None]
    return np.cos(ang) * b1 + np.sin(ang) * b2


def _sampled_min_distance(curve_pts, cloud, chunk: int = 1024):
    """min over samples of |curve point - cloud point|: curve_pts (M, S, 3), cloud (A, 3) -> (M,)."""
    out = np.empty(curve_pts.shape[0])
    c2 = np.sum(cloud * cloud, axis=-1)
    for a in range(0, curve_pts.shape[0], chunk):
        p = curve_pts[a : a + chunk]
        cross = (p.reshape(-1, 3) @ cloud.T).reshape(*p.shape[:2], -1)
        d2 = np.sum(p * p, axis=-1)[..., None] + c2 - 2.0 * cross
        out[a : a + chunk] = np.sqrt(np.maximum(np.min(d2, axis=(1, 2)), 0.0))
    return out


def _quadratic_points(coeffs, n_samples: int):
    """(M, n_samples, 3) points of quadratics coeffs (M, 3, 3) at u evenly spaced in [0, 1], and the
    largest arc length between consecutive samples (M,) (the speed |k1 + 2 k2 u| is convex in u,
    so its maximum is at an end)."""
    u = np.linspace(0.0, 1.0, n_samples)
    k0, k1, k2 = coeffs[:, None, :, 0], coeffs[:, None, :, 1], coeffs[:, None, :, 2]
    pts = k0 + u[None, :, None] * k1 + (u**2)[None, :, None] * k2
    speed = np.maximum(np.linalg.norm(coeffs[..., 1], axis=-1),
                       np.linalg.norm(coeffs[..., 1] + 2.0 * coeffs[..., 2], axis=-1))
    return pts, speed / (n_samples - 1)


def _clear_of(coeffs, arm_fine, h_fine, arm_coarse, h_coarse, goal, start_clearance, goal_clearance):
    """Whether each quadratic curve (M, 3, 3) is certainly at least start_clearance from the arm
    and goal_clearance from its goal (M, 3). Sampled distances minus the sampling error bound
    (half the sample spacing on each side), coarse first, fine only where the coarse answer is
    undecided; conservative: a curve within the error bound of a threshold is rejected."""
    pts_c, hc_c = _quadratic_points(coeffs, 16)
    d = _sampled_min_distance(pts_c, arm_coarse)
    sure = d - 0.5 * (hc_c + h_coarse) >= start_clearance
    undecided = np.nonzero(~sure & (d >= start_clearance))[0]
    if undecided.size:
        pts_f, hc_f = _quadratic_points(coeffs[undecided], 64)
        d_f = _sampled_min_distance(pts_f, arm_fine)
        sure[undecided] = d_f - 0.5 * (hc_f + h_fine) >= start_clearance
    pts_g, hc_g = _quadratic_points(coeffs, 64)
    d_goal = np.min(np.linalg.norm(pts_g - goal[:, None, :], axis=-1), axis=1)
    return sure & (d_goal - 0.5 * hc_g >= goal_clearance)


def random_scenarios(
    key_or_seed,
    n: int,
    *,
    obstacles=(1, 8),
    degrees=(1, 2),
    curve_slots: int = 8,
    degree: int = 2,
    theta_max: float = 1.6,
    length: float = 1.0,
    q0=None,
    min_goal_distance: float = 0.5,
    path_fraction=(0.3, 0.7),
    path_offset: float = 0.1,
    curve_length=(0.6, 1.6),
    bend: float = 0.5,
    start_clearance: float = 0.15,
    goal_clearance: float = 0.15,
    max_rounds: int = 200,
    dtype=None,
) -> Scenario:
    """A seeded suite of ``n`` random scenarios, padded to one shape and stacked.

    The generator (host side, NumPy, deterministic for a given seed/key and
    arguments):

    * **Start**: ``q0`` (default :func:`default_start`: the straight vertical
      arm, tip at (0, 0, 3)), the same for every scenario.
    * **Goal** (reachable by construction): the tip of a random configuration
      with every ``L_i = length``, ``theta_i ~ U[0, theta_max]``,
      ``phi_i ~ U[-pi, pi]``; redrawn until it lies at least
      ``min_goal_distance`` from the start tip.
    * **Obstacles**: ``k ~ U{obstacles[0] .. obstacles[1]}`` polynomial curves,
      each of degree ``d ~ U{degrees}``, u in [0, 1], placed to BLOCK the direct
      path: with ``p0`` the start tip, ``g`` the goal and ``e`` the unit vector
      from ``p0`` to ``g``, the curve's midpoint ``c`` lies on the straight
      segment ``p0 -> g`` at a fraction ``t ~ U[path_fraction]``, moved
      sideways (perpendicular to ``e``) by a uniform offset in a disc of
      radius ``path_offset``; the curve runs through ``c`` along a random
      direction ``a`` perpendicular to ``e`` (so it crosses the path), with
      length ``l ~ U[curve_length]``; a degree-2 curve also bends by
      ``beta ~ U[-bend, bend]`` towards a random direction ``b`` perpendicular
      to ``a``::

          F(u) = c + l (u - 1/2) a + beta l (u - 1/2)^2 b,   u in [0, 1].

      An obstacle is redrawn (new t, offset, direction, length, bend) until it
      is certainly at least ``start_clearance`` from the start arm and
      ``goal_clearance`` from the goal: sampled distances (curve at up to 64
      points, arm at 40 points per segment) minus the sampling error bound
      (half the sample spacing on each side) must clear the thresholds, so the
      exact clearances are never smaller. If one obstacle finds no place in
      ``max_rounds`` draws (the goal leaves no room, e.g. a path hugging the
      arm), that scenario's goal and obstacles are drawn anew. Obstacles may
      cross each other.
    * Radii are 0 (arm and obstacles), length limits the defaults of
      :func:`make_scenario`.

    Args:
      key_or_seed: an int seed or a JAX PRNG key.
      n: number of scenarios.
      obstacles: (min, max) obstacle count, 1 <= min <= max <= curve_slots.
      degrees: the curve degrees to draw from (each 1 or 2, <= ``degree``).
      curve_slots, degree: the padded shape (every scenario has the same).
      theta_max, length: the goal configurations' bending range and segment length.
      q0: (n_seg, 3) start, or None for :func:`default_start`.
      min_goal_distance, path_fraction, path_offset, curve_length, bend,
      start_clearance, goal_clearance: see above.
      max_rounds: redraw rounds before giving up (ValueError: the constraints
        are too tight).
      dtype: float dtype of the result; default JAX's default float.

    Returns:
      A batched :class:`Scenario` (leading axis n): q0 (n, n_seg, 3), goal
      (n, 3), curves.coeffs (n, curve_slots, 3, degree + 1), curve_mask
      (n, curve_slots), no point sets; each entry equals ``make_scenario(goal,
      curves, q0, curve_slots=curve_slots, degree=degree)``.
    """
    from .kinematics import backbone_points

    _backbone_points_jit = jax.jit(backbone_points, static_argnums=1)

    n = int(n)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    lo, hi = (int(v) for v in obstacles)
    if not 1 <= lo <= hi <= int(curve_slots):
        raise ValueError(
            f"need 1 <= obstacles[0] <= obstacles[1] <= curve_slots; "
            f"got {obstacles}, curve_slots {curve_slots}"
        )
    degrees = [int(d) for d in degrees]
    if not degrees or any(d not in (1, 2) or d > int(degree) for d in degrees):
        raise ValueError(
            f"degrees must be a non-empty list of 1 and/or 2, each <= degree = {degree}; got {degrees}"
        )
    if not 0.0 <= path_fraction[0] <= path_fraction[1] <= 1.0:
        raise ValueError(f"path_fraction must satisfy 0 <= a <= b <= 1, got {path_fraction}")
    if not 0.0 < curve_length[0] <= curve_length[1]:
        raise ValueError(f"curve_length must satisfy 0 < a <= b, got {curve_length}")
    for name, v in (("theta_max", theta_max), ("length", length)):
        if not v > 0:
            raise ValueError(f"{name} must be > 0, got {v}")
    for name, v in (("path_offset", path_offset), ("bend", bend), ("min_goal_distance", min_goal_distance),
                    ("start_clearance", start_clearance), ("goal_clearance", goal_clearance)):
        if not v >= 0:
            raise ValueError(f"{name} must be >= 0, got {v}")
    dtype = dtype or jnp.result_type(float)
    q0 = check_configuration(default_start() if q0 is None else q0)
    q0_np = np.asarray(q0, np.float64)
    n_seg = q0_np.shape[0]
    rng = np.random.default_rng(_seed_sequence(key_or_seed))
    tips = _batched_tips()
    q0_j = jnp.asarray(q0_np, q0.dtype)
    p0 = np.asarray(tips(q0_j[None]), np.float64)[0]
    arm_fine = np.concatenate([np.zeros((1, 3)), np.asarray(_backbone_points_jit(q0_j, 40), np.float64)])
    arm_coarse = np.concatenate([np.zeros((1, 3)), np.asarray(_backbone_points_jit(q0_j, 8), np.float64)])
    h_fine, h_coarse = q0_np[:, 0].max() / 40, q0_np[:, 0].max() / 8

    def draw_goals(idx):
        """Goals for scenarios idx: tips of random configurations, at least
        min_goal_distance from the start tip."""
        todo = np.asarray(idx)
        for _ in range(max_rounds):
            # Always n candidates (one compiled shape); the accepted ones fill todo in order.
            qs = np.stack(
                [np.full((n, n_seg), float(length)), rng.uniform(0.0, theta_max, (n, n_seg)),
                 rng.uniform(-np.pi, np.pi, (n, n_seg))], axis=-1)
            g = np.asarray(tips(jnp.asarray(qs)), np.float64)
            g = g[np.linalg.norm(g - p0, axis=-1) >= min_goal_distance]
            take = min(todo.size, g.shape[0])
            goal[todo[:take]] = g[:take]
            todo = todo[take:]
            if todo.size == 0:
                return
        raise ValueError(f"no goal at least {min_goal_distance} from the start tip after {max_rounds} rounds")

    goal = np.zeros((n, 3))
    draw_goals(np.arange(n))
    counts = rng.integers(lo, hi + 1, n)
    real = np.arange(curve_slots)[None, :] < counts[:, None]  # (n, slots)
    deg = rng.choice(degrees, (n, curve_slots))
    coeffs = np.zeros((n, curve_slots, 3, int(degree) + 1))
    todo_i, todo_j = np.nonzero(real)
    tries = np.zeros(todo_i.size, int)
    redrawn = 0
    for _ in range(20 * max_rounds):
        # An obstacle that found no place in max_rounds draws: the goal leaves no room
        # (e.g. a path hugging the arm); draw a new goal and all obstacles of that scenario.
        stuck = np.unique(todo_i[tries >= max_rounds])
        if stuck.size:
            redrawn += stuck.size
            draw_goals(stuck)
            coeffs[stuck] = 0.0
            keep = ~np.isin(todo_i, stuck)
            si, sj = np.nonzero(real[stuck])
            todo_i = np.concatenate([todo_i[keep], stuck[si]])
            todo_j = np.concatenate([todo_j[keep], sj])
            tries = np.concatenate([tries[keep], np.zeros(si.size, int)])
        m = todo_i.size
        gi = goal[todo_i]
        ei = _unit(gi - p0)
        t = rng.uniform(path_fraction[0], path_fraction[1], m)
        r = path_offset * np.sqrt(rng.uniform(0.0, 1.0, m))
        c = p0 + t[:, None] * (gi - p0) + r[:, None] * _random_perpendicular(rng, ei)
        a = _random_perpendicular(rng, ei)
        b = _random_perpendicular(rng, a)
        ell = rng.uniform(curve_length[0], curve_length[1], m)
        beta = np.where(deg[todo_i, todo_j] == 2, rng.uniform(-bend, bend, m), 0.0)
        # F(u) = c + l (u - 1/2) a + beta l (u - 1/2)^2 b in the power basis.
        k0 = c - 0.5 * ell[:, None] * a + 0.25 * (beta * ell)[:, None] * b
        k1 = ell[:, None] * a - (beta * ell)[:, None] * b
        k2 = (beta * ell)[:, None] * b
        cand = np.stack([k0, k1, k2], axis=-1)  # (m, 3, 3)
        ok = _clear_of(cand, arm_fine, h_fine, arm_coarse, h_coarse, gi, start_clearance, goal_clearance)
        coeffs[todo_i[ok], todo_j[ok], :, :3] = cand[ok]
        todo_i, todo_j, tries = todo_i[~ok], todo_j[~ok], tries[~ok] + 1
        if todo_i.size == 0:
            break
    else:
        raise ValueError(
            f"{todo_i.size} obstacles could not be placed; loosen start_clearance, goal_clearance, "
            "path_offset or min_goal_distance"
        )

    # Host arrays converted once (no per-op compilation), laid out as make_scenario does.
    np_dtype = np.dtype(dtype)

    def put(x):
        return jnp.asarray(np.asarray(x, np_dtype))

    curves = PolynomialCurve.tree_unflatten(
        None,
        [put(coeffs), put(np.tile([0.0, 1.0], (n, curve_slots, 1))), put(np.zeros((n, curve_slots)))],
    )
    return Scenario(
        q0=put(np.broadcast_to(q0_np, (n, n_seg, 3))),
        goal=put(goal),
        curves=curves,
        curve_mask=jnp.asarray(real),
        points=put(np.zeros((n, 0, 1, 3))),
        point_mask=jnp.asarray(np.zeros((n, 0, 1), bool)),
        point_radius=put(np.zeros((n, 0))),
        parametric=(),
        arm_radius=put(np.zeros(n)),
        L_min=put(np.full((n, n_seg), 1e-3)),
        L_max=put(np.full((n, n_seg), np.inf)),
    )


__all__.append("random_scenarios")
