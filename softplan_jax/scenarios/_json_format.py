"""Scenario files: the JSON format ``softplan-scenario/1`` (arm, goal, obstacles as polynomial
curves, line segments or point sets; for a moving scene a ``motion`` per curve and a
``goal_path``: the documentation's "Scenario and gains files"), read with every malformed
field named in a ValueError (:func:`load_scenario` refuses a moving scene, whose motion it
would drop; :func:`load_moving_scenario` reads both) and written atomically."""

from __future__ import annotations

import json
import math
import os
import re

import jax.numpy as jnp
import numpy as np

from ..base._files import write_text
from ..base._memory import check_memory
from ..base._validation import check_scale
from ..geometry._curves import PolynomialCurve, line_segment
from ._material_block import material_from_dict
from ._scenario import Scenario, default_start, make_scenario

__all__ = [
    "scenario_from_dict",
    "scenario_to_dict",
    "load_scenario",
    "save_scenario",
    "write_json_file",
    "moving_from_dict",
    "moving_to_dict",
    "load_moving_scenario",
    "save_moving_scenario",
    "is_moving_dict",
]


# "metadata": any JSON object (e.g. fit residuals from `softplan fit`); kept out of the Scenario.
_TOP_KEYS = {"format", "arm", "goal", "obstacles", "name", "description", "metadata", "goal_path"}
_MOTION_KEYS = {"pivot": (3,), "axis": (3,), "amplitude": (), "omega": (), "phase": (), "shift": (3,),
                "velocity": (3,)}
_GOAL_PATH_KEYS = {"times", "points", "attach"}
_ARM_KEYS = {"segments", "start", "radius", "length_limits", "material"}  # material: scenarios/_material_block.py
_FORMAT = "softplan-scenario/1"
# Arrays per segment that planning an arm allocates at once, in units of its q0 row (a bound
# for the memory check of arm.segments, not an exact count).
_SEGMENT_BYTES_FACTOR = 1000


def _err(path: str, msg: str) -> ValueError:
    return ValueError(f"scenario field {path}: {msg}")


def _only_numbers(value) -> bool:
    if isinstance(value, bool) or isinstance(value, str) or value is None:
        return False
    if isinstance(value, (list, tuple)):
        return all(_only_numbers(v) for v in value)
    return isinstance(value, (int, float))


def _make_field(msg: str) -> str:
    """The JSON field of one of make_scenario's messages (they start with its argument's name)."""
    m = re.match(r"(goal|q\b|start lengths|obstacles\[\d+\]|arm_radius|L_min|L_max|need 0 < L_min)", msg)
    if m is None:
        return "(scene)"
    name = m.group(1)
    return {"goal": "goal", "q": "arm.start", "start lengths": "arm.start", "arm_radius": "arm.radius"}.get(
        name, name if name.startswith("obstacles") else "arm.length_limits")


def _short(value, limit: int = 120) -> str:
    """repr of a JSON value for a message, cut to ``limit`` characters (a 400-digit integer, a long list)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _num_array(value, path: str, shape=None):
    if not _only_numbers(value):
        raise _err(path, f"must be numbers (JSON numbers, not strings or booleans), got {_short(value)}")
    try:
        arr = np.asarray(value, dtype=float)
    except OverflowError:  # a JSON integer beyond the range of a float
        raise _err(path, f"must be finite numbers within the range of a float (about 1.8e308), got "
                         f"{_short(value)}") from None
    except (TypeError, ValueError):
        raise _err(path, f"must be numbers, got {_short(value)}") from None
    if shape is not None and (
        arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape, shape, strict=True))
    ):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise _err(path, f"must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise _err(path, f"must be finite, got {_short(value)}")
    return arr


def is_moving_dict(data) -> bool:
    """The JSON structure has a ``goal_path`` or an obstacle ``motion`` (a moving scene)."""
    if not isinstance(data, dict):
        return False
    obs = data.get("obstacles", [])
    return "goal_path" in data or (isinstance(obs, list) and any(isinstance(o, dict) and "motion" in o for o in obs))


def scenario_from_dict(data: dict, dtype=None) -> Scenario:
    """Build a Scenario from the JSON structure (see the documentation's "Scenario and gains files"); every
    malformed field raises a ValueError naming the field. A moving scene
    (``motion``/``goal_path`` fields) is refused: use :func:`moving_from_dict`."""
    if is_moving_dict(data):
        raise _err("goal_path" if "goal_path" in data else "obstacles[].motion",
                   "this scene moves; read it with load_moving_scenario / moving_from_dict "
                   "(`softplan run` plays it)")
    return _parse(data, dtype)[0]


def moving_from_dict(data: dict, dtype=None):
    """Build a :class:`~softplan_jax.scenarios._motion.MovingScenario` from the JSON structure
    (a file without motion gives one where nothing moves); every malformed field
    raises a ValueError naming the field."""
    from ._motion import curve_motion, goal_path, make_moving_scenario

    scen, motions, path = _parse(data, dtype)
    dtype = scen.q0.dtype
    built = {}
    for k, (where, fields) in motions.items():
        try:
            built[k] = curve_motion(**fields, dtype=dtype)
        except ValueError as err:
            raise _err(where, str(err)) from None
    goal = None
    if path is not None:
        top, first = np.asarray(data["goal"], float), np.asarray(path["points"][0], float)
        if not np.allclose(top, first, rtol=1e-9, atol=1e-12):
            raise _err("goal", f"{top.tolist()} disagrees with goal_path.points[0] = {first.tolist()}: a moving "
                       "scene's goal is its goal path's first point (the planner follows goal_path); make the two equal")
        try:
            goal = goal_path(path["times"], path["points"], path["attach"], dtype=dtype)
        except ValueError as err:
            raise _err("goal_path", str(err)) from None
    return make_moving_scenario(scen, built, goal)


def _parse_motion(value, path: str) -> dict:
    if not isinstance(value, dict):
        raise _err(path, f"must be an object, got {_short(value)}")
    extra = set(value) - set(_MOTION_KEYS)
    if extra:
        raise _err(f"{path}.{sorted(extra)[0]}", f"unknown key (allowed: {sorted(_MOTION_KEYS)})")
    fields = {key: _num_array(value[key], f"{path}.{key}", shape) for key, shape in _MOTION_KEYS.items()
              if key in value}
    if "omega" in fields and fields["omega"] < 0:
        raise _err(f"{path}.omega", f"must be >= 0, got {float(fields['omega'])}")
    return fields


def _parse_goal_path(value, curve_index: dict) -> dict:
    if not isinstance(value, dict):
        raise _err("goal_path", f"must be an object, got {_short(value)}")
    extra = set(value) - _GOAL_PATH_KEYS
    if extra:
        raise _err(f"goal_path.{sorted(extra)[0]}", f"unknown key (allowed: {sorted(_GOAL_PATH_KEYS)})")
    for key in ("times", "points"):
        if key not in value:
            raise _err(f"goal_path.{key}", "is missing")
    times = _num_array(value["times"], "goal_path.times", (None,))
    if times.shape[0] < 1:
        raise _err("goal_path.times", "is empty")
    if np.any(np.diff(times) <= 0):
        raise _err("goal_path.times", f"must be strictly increasing, got {times.tolist()}")
    points = _num_array(value["points"], "goal_path.points", (times.shape[0], 3))
    attach = value.get("attach", None)
    if attach is not None:
        if not isinstance(attach, int) or isinstance(attach, bool):
            raise _err("goal_path.attach", f"must be an obstacle index (an integer) or null, got {_short(attach)}")
        if attach not in curve_index:
            raise _err("goal_path.attach", f"obstacle {attach} is not a polynomial curve or line segment of this "
                       f"scene (those are {sorted(curve_index)})")
    return {"times": times, "points": points, "attach": -1 if attach is None else curve_index[attach]}


def _parse(data: dict, dtype=None):
    """(Scenario, {curve index: (field path, motion fields)}, goal path fields or None)."""
    _check_top(data)
    goal = _num_array(data["goal"], "goal", (3,))
    q0, radius, L_min, L_max = _parse_arm(data.get("arm", {}))
    obstacles_json = data.get("obstacles", [])
    if not isinstance(obstacles_json, list):
        raise _err("obstacles", "must be a list")
    obstacles = []
    motions, curve_index = {}, {}
    for k, ob in enumerate(obstacles_json):
        path = f"obstacles[{k}]"
        kind, r = _check_obstacle(ob, path)
        if kind != "points":
            curve_index[k] = len(curve_index)  # polynomial curves keep their order in the scene
            if "motion" in ob:
                motions[curve_index[k]] = (f"{path}.motion", _parse_motion(ob["motion"], f"{path}.motion"))
        obstacles.append(_parse_obstacle(ob, kind, r, path))
    scen = _build(goal, q0, radius, L_min, L_max, obstacles, obstacles_json, dtype)
    path = _parse_goal_path(data["goal_path"], curve_index) if "goal_path" in data else None
    return scen, motions, path


def _check_top(data) -> None:
    """The top level's keys, name, description, format and metadata, and a goal."""
    if not isinstance(data, dict):
        raise _err("(top)", f"must be a JSON object, got {type(data).__name__}")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise _err(key, f"must be a string, got {_short(data[key])}")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise _err(sorted(unknown)[0], f"unknown key (allowed: {sorted(_TOP_KEYS)})")
    if data.get("format", _FORMAT) != _FORMAT:
        raise _err("format", f"must be {_FORMAT!r}, got {_short(data.get('format'))}")
    if not isinstance(data.get("metadata", {}), dict):
        raise _err("metadata", f"must be a JSON object, got {_short(data['metadata'])}")
    if "goal" not in data:
        raise _err("goal", "is missing")


def _parse_arm(arm):
    """``arm``: ``(q0 (n, 3), radius, L_min, L_max)``."""
    if not isinstance(arm, dict):
        raise _err("arm", "must be an object")
    unknown = set(arm) - _ARM_KEYS
    if unknown:
        raise _err(f"arm.{sorted(unknown)[0]}", f"unknown key (allowed: {sorted(_ARM_KEYS)})")
    n = arm.get("segments", 3)
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise _err("arm.segments", f"must be an integer >= 1, got {_short(n)}")
    if "material" in arm:  # the loaded arm's material: checked here, read by scenarios._material
        material_from_dict(arm["material"], n)
    try:
        # The planner's per-step arrays grow with n (Jacobians (3, 3n) per obstacle and step).
        check_memory(8.0 * 3 * n * _SEGMENT_BYTES_FACTOR, "arm.segments", f"an arm of {n} segments",
                     "use an arm of a few segments (the paper's has 3)", on_device=False)
    except ValueError as err:
        raise _err("arm.segments", str(err)) from None
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
            raise _err("arm.length_limits", f"must be [L_min, L_max], got {_short(lim)}")
        L_min = float(_num_array(lim[0], "arm.length_limits[0]", ()))
        L_max = math.inf if lim[1] is None else float(_num_array(lim[1], "arm.length_limits[1]", ()))
        if not 0 < L_min < L_max:
            raise _err("arm.length_limits", f"need 0 < L_min < L_max, got {_short(lim)}")
        if np.any(q0[:, 0] < L_min) or np.any(q0[:, 0] > L_max):
            raise _err("arm.length_limits", f"the start lengths {q0[:, 0].tolist()} lie outside {_short(lim)}")
    return q0, radius, L_min, L_max


# The keys of each obstacle type.
_OBSTACLE_KEYS = {
    "polynomial": {"type", "coeffs", "u_range", "radius", "name", "metadata", "motion"},
    "line_segment": {"type", "start", "end", "radius", "name", "metadata", "motion"},
    "points": {"type", "points", "radius", "name", "metadata"},
}


def _check_obstacle(ob, path: str):
    """An obstacle's type, keys, metadata and radius: ``(type, radius)``."""
    if not isinstance(ob, dict) or "type" not in ob:
        raise _err(path, "must be an object with a 'type'")
    kind = ob["type"]
    if not isinstance(kind, str) or kind not in _OBSTACLE_KEYS:
        raise _err(f"{path}.type", f"unknown obstacle type {_short(kind)}; choose one of {sorted(_OBSTACLE_KEYS)}")
    extra = set(ob) - _OBSTACLE_KEYS[kind]
    if extra:
        raise _err(f"{path}.{sorted(extra)[0]}", f"unknown key for a {kind} obstacle")
    if not isinstance(ob.get("metadata", {}), dict):
        raise _err(f"{path}.metadata", f"must be a JSON object, got {_short(ob['metadata'])}")
    r = _num_array(ob.get("radius", 0.0), f"{path}.radius", ())
    if r < 0:
        raise _err(f"{path}.radius", f"must be >= 0, got {float(r)}")
    return kind, r


def _parse_obstacle(ob: dict, kind: str, r, path: str):
    """One obstacle: a PolynomialCurve, or ``(points (N, 3), radius)`` for a point set."""
    for key in {"polynomial": ("coeffs", "u_range"), "line_segment": ("start", "end"), "points": ("points",)}[kind]:
        if key not in ob:
            raise _err(f"{path}.{key}", "is missing")
    if kind == "polynomial":
        coeffs = _num_array(ob["coeffs"], f"{path}.coeffs", (3, None))
        if coeffs.shape[1] < 1:
            raise _err(f"{path}.coeffs", "needs at least one coefficient per axis")
        u_range = _num_array(ob["u_range"], f"{path}.u_range", (2,))
        if not u_range[0] < u_range[1]:
            raise _err(f"{path}.u_range", f"must satisfy u_min < u_max, got {u_range.tolist()}")
        try:
            return PolynomialCurve(coeffs, u_range, float(r))
        except ValueError as err:
            raise _err(f"{path}.{str(err).split(' ')[0].rstrip(':')}", str(err)) from None
    if kind == "line_segment":
        a = _num_array(ob["start"], f"{path}.start", (3,))
        b = _num_array(ob["end"], f"{path}.end", (3,))
        try:
            return line_segment(a, b, float(r))
        except ValueError as err:
            raise _err(path, str(err)) from None
    pts = _num_array(ob["points"], f"{path}.points", (None, 3))
    if pts.shape[0] == 0:
        raise _err(f"{path}.points", "is empty")
    return (pts, float(r))


def _build(goal, q0, radius, L_min, L_max, obstacles: list, obstacles_json: list, dtype) -> Scenario:
    """make_scenario of the parsed fields, then the point sets' radii (they are per obstacle)."""
    plain = [o[0] if isinstance(o, tuple) else o for o in obstacles]
    q0 = jnp.asarray(q0, dtype or jnp.result_type(float))
    try:
        scen = make_scenario(goal, plain, q0, arm_radius=float(radius), L_min=L_min, L_max=L_max)
    except ValueError as err:
        raise _err(_make_field(str(err)), str(err)) from None
    radii = [o[1] for o in obstacles if isinstance(o, tuple)]
    if radii:
        for k, r in zip([k for k, o in enumerate(obstacles_json) if o["type"] == "points"], radii, strict=True):
            try:
                check_scale(r, "radius", q0.dtype, "values")
            except ValueError as err:
                raise _err(f"obstacles[{k}].radius", str(err)) from None
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


def moving_to_dict(moving, name: str | None = None) -> dict:
    """The JSON structure of a MovingScenario: :func:`scenario_to_dict` of its scene
    with each moving curve's ``motion`` and the ``goal_path``."""
    scene = moving.scene
    if scene.q0.ndim != 2:
        raise ValueError("save one scenario at a time (this one is batched)")
    out = scenario_to_dict(scene, name)
    real = np.nonzero(np.asarray(scene.curve_mask))[0]
    motion = {k: np.asarray(v) for k, v in moving.motion._asdict().items()}
    for k, slot in enumerate(real):  # scenario_to_dict writes the curves first, in slot order
        row = {key: motion[key][slot].tolist() for key in _MOTION_KEYS}
        if any(np.any(np.asarray(v) != 0) for v in row.values()):
            out["obstacles"][k]["motion"] = row
    path = moving.goal_path
    attach = int(path.attach)
    out["goal"] = np.asarray(path.points[0]).tolist()
    out["goal_path"] = {"times": np.asarray(path.times).tolist(), "points": np.asarray(path.points).tolist(),
                        "attach": None if attach < 0 else int(np.flatnonzero(real == attach)[0])}
    return out


def load_moving_scenario(path, dtype=None):
    """Read a scenario JSON file as a :class:`~softplan_jax.scenarios._motion.MovingScenario`
    (with its ``motion`` and ``goal_path`` fields; a static file: nothing moves)."""
    return _read_scenario_file(path, moving_from_dict, dtype)


def save_moving_scenario(moving, path, name: str | None = None, overwrite: bool = False) -> None:
    """Write a MovingScenario as JSON (as :func:`save_scenario`)."""
    write_json_file(path, moving_to_dict(moving, name), overwrite)


def _read_scenario_file(path, from_dict, dtype):
    """``from_dict`` of the scenario file at ``path``; its ValueErrors name the file."""
    path = os.fspath(path)
    data = read_json_file(path, "scenario")
    try:
        return from_dict(data, dtype=dtype)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def read_json_file(path: str, kind: str):
    """The parsed JSON of the ``kind`` file at ``path`` (``kind``: "scenario", "gains", ...
    for the messages); a missing, unreadable, non-UTF-8 or non-JSON file is a ValueError."""
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{kind} file not found: {path}") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{kind} file {path} is not valid JSON: {err}") from None
    except UnicodeDecodeError as err:
        raise ValueError(f"{kind} file {path} is not UTF-8 text: {err}") from None
    except OSError as err:
        raise ValueError(f"cannot read {kind} file {path}: {err.strerror or err}") from None


def load_scenario(path, dtype=None) -> Scenario:
    """Read a scenario JSON file (format ``softplan-scenario/1``, see the documentation's "Scenario and gains files")."""
    return _read_scenario_file(path, scenario_from_dict, dtype)


def save_scenario(scenario: Scenario, path, name: str | None = None, overwrite: bool = False) -> None:
    """Write a scenario as JSON. Refuses to replace an existing file unless
    ``overwrite=True``; the file is written whole (via a temporary file) or not at all."""
    write_json_file(path, scenario_to_dict(scenario, name), overwrite)


def write_json_file(path, data: dict, overwrite: bool = False) -> None:
    """Write ``data`` as an indented JSON file, whole (via a temporary file in the
    same directory, then a rename) or not at all; an existing file is replaced
    only with ``overwrite=True`` (ValueError otherwise). A path that cannot be written
    (a missing folder, a directory, no permission) is a ValueError naming ``path``."""
    write_text(path, json.dumps(data, indent=2) + "\n", overwrite, ".json")
