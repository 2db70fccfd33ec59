"""Timed trajectory files (format ``softplan-timed-trajectory/1``): a CSV table for
the controller, one row per sample, and a JSON file with the same samples and
what they mean (units, the arm, the actuator layout, the limits, the plan's
status and path, the check of every sample). Numbers are written with 17
significant digits, so that loading gives back the very same arrays.
"""

from __future__ import annotations

import io
import json
import math
import os

import numpy as np

from ..actuators._layout import KINDS, ActuatorLayout
from ..actuators._limits import actuator_limits, check_limits
from ..base._files import write_text
from ._trajectory import PATH_KINDS, Trajectory

__all__ = ["TIMED_FORMAT", "UNITS", "csv_columns", "trajectory_to_dict", "trajectory_from_dict", "save_trajectory",
           "load_trajectory"]

TIMED_FORMAT = "softplan-timed-trajectory/1"
UNITS = {"time": "s", "length": "m (the scene's length unit)", "angle": "rad", "speed": "m/s",
         "acceleration": "m/s^2"}
_ROWS = ("t", "q", "lengths", "speeds", "tip")


def csv_columns(kind: str, n: int, k: int) -> list[str]:
    """The CSV header: ``t``, ``L_i theta_i phi_i`` per segment, ``{kind}_i_m`` lengths,
    ``speed_{kind}_i_m``, ``tip_x tip_y tip_z`` (segments i and actuators m 0-based)."""
    q = [f"{name}_{i}" for i in range(n) for name in ("L", "theta", "phi")]
    lengths = [f"{kind}_{i}_{m}" for i in range(n) for m in range(k)]
    return ["t", *q, *lengths, *("speed_" + c for c in lengths), "tip_x", "tip_y", "tip_z"]


def _table(traj: Trajectory) -> np.ndarray:
    T = traj.t.shape[0]
    return np.concatenate([traj.t[:, None], traj.q.reshape(T, -1), traj.lengths.reshape(T, -1),
                           traj.speeds.reshape(T, -1), traj.tip], axis=1)


def _clean(x):
    """Arrays to lists, non-finite floats to None (strict JSON)."""
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def trajectory_to_dict(traj: Trajectory, arm: dict | None = None) -> dict:
    """The JSON form of a trajectory (see the documentation's file formats page).

    Args:
      traj: the Trajectory.
      arm: extra facts about the arm to record (e.g. ``{"radius": 0.05, "length_limits": [..]}``).
    """
    r = traj.report
    limits = traj.limits.to_dict() | {"max_tip_speed": traj.max_tip_speed}
    return _clean({
        "format": TIMED_FORMAT,
        "units": UNITS,
        "arm": {"segments": traj.layout.n_segments, "start": traj.q[0], **(arm or {})},
        "actuators": traj.layout.to_dict(),
        "limits": limits,
        "plan": {"status": traj.status, "path": traj.path, "duration": traj.duration, "stops": traj.stops,
                 "waypoints": traj.waypoints, "waypoint_times": traj.waypoint_times,
                 "linear_spans": traj.linear_spans.astype(int)},
        "check": {"within_limits": r.ok, "first_violation": r.first, "usage": r.usage, "tightest": r.tightest,
                  "where": {k: list(v) for k, v in r.where.items()}, "violations": r.violations},
        "columns": csv_columns(traj.layout.kind, traj.layout.n_segments, traj.layout.count),
        "samples": {name: getattr(traj, name) for name in _ROWS},
    })


def _field(d, key, where):
    if not isinstance(d, dict) or key not in d:
        raise ValueError(f"timed trajectory file: missing field {where}{key}")
    return d[key]


def _array(value, where, shape):
    try:
        a = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"timed trajectory file: {where} must be an array of numbers") from None
    if a.shape != shape and not (shape[0] is None and a.shape[1:] == shape[1:]):
        raise ValueError(f"timed trajectory file: {where} has shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"timed trajectory file: {where} holds non-finite numbers")
    return a


def _layout(d) -> ActuatorLayout:
    import jax.numpy as jnp

    from ..actuators._layout import check_arrangement

    kind = _field(d, "kind", "actuators.")
    if kind not in KINDS:
        raise ValueError(f"timed trajectory file: actuators.kind must be one of {', '.join(KINDS)}; got {kind!r}")
    angles = np.asarray(_field(d, "angles", "actuators."), np.float64)
    radius, angles = check_arrangement(np.asarray(_field(d, "radius", "actuators."), np.float64), angles,
                                       angles.shape[0] if angles.ndim == 2 else 0)
    return ActuatorLayout(radius=jnp.asarray(radius), angles=jnp.asarray(angles), kind=kind)


def trajectory_from_dict(d: dict, table: np.ndarray | None = None) -> Trajectory:
    """A Trajectory from its JSON form (``table``: the CSV's rows, replacing the JSON's samples).

    Raises:
      ValueError: a missing or malformed field (named), or another format.
    """
    if not isinstance(d, dict) or d.get("format") != TIMED_FORMAT:
        got = d.get("format") if isinstance(d, dict) else type(d).__name__
        raise ValueError(f"timed trajectory file: format must be {TIMED_FORMAT!r}; got {got!r}")
    try:
        layout = _layout(_field(d, "actuators", ""))
        lim = _field(d, "limits", "")
        limits = actuator_limits(*(lim.get(k) if isinstance(lim, dict) else None
                                   for k in ("min_length", "max_length", "max_speed", "max_acceleration")))
    except ValueError as err:
        raise ValueError(f"timed trajectory file: {err}") from None
    n, k = layout.n_segments, layout.count
    if table is None:
        s = _field(d, "samples", "")
        t = _array(_field(s, "t", "samples."), "samples.t", (None,))
        T = t.shape[0]
        rows = {"t": t, **{name: _array(_field(s, name, "samples."), f"samples.{name}", shape) for name, shape in
                           (("q", (T, n, 3)), ("lengths", (T, n, k)), ("speeds", (T, n, k)), ("tip", (T, 3)))}}
    else:
        T = table.shape[0]
        cuts = np.cumsum([1, 3 * n, n * k, n * k])
        t, q, lengths, speeds, tip = np.split(table, cuts, axis=1)
        rows = {"t": t[:, 0], "q": q.reshape(T, n, 3), "lengths": lengths.reshape(T, n, k),
                "speeds": speeds.reshape(T, n, k), "tip": tip}
    if T < 2 or np.any(np.diff(rows["t"]) <= 0):
        raise ValueError("timed trajectory file: samples.t must hold two or more increasing times")
    plan = _field(d, "plan", "")
    path = _field(plan, "path", "plan.")
    if path not in PATH_KINDS:
        raise ValueError(f"timed trajectory file: plan.path must be one of {', '.join(PATH_KINDS)}; got {path!r}")
    way = _array(_field(plan, "waypoints", "plan."), "plan.waypoints", (None, n, 3))
    tip_limit = d["limits"].get("max_tip_speed")
    return Trajectory(
        **rows, layout=layout, limits=limits, status=str(_field(plan, "status", "plan.")), path=path,
        duration=float(rows["t"][-1]), stops=_array(plan.get("stops", []), "plan.stops", (None,)), waypoints=way,
        waypoint_times=_array(_field(plan, "waypoint_times", "plan."), "plan.waypoint_times", (way.shape[0],)),
        linear_spans=np.asarray(plan.get("linear_spans", []), int),
        report=check_limits(limits, layout, rows["lengths"], rows["t"]),
        max_tip_speed=None if tip_limit is None else float(tip_limit))


def _csv_text(traj: Trajectory) -> str:
    buf = io.StringIO()
    header = ",".join(csv_columns(traj.layout.kind, traj.layout.n_segments, traj.layout.count))
    np.savetxt(buf, _table(traj), delimiter=",", fmt="%.17g", header=header, comments="")
    return buf.getvalue()


def save_trajectory(traj: Trajectory, path, arm: dict | None = None, overwrite: bool = False) -> None:
    """Write a timed trajectory as CSV (``.csv``: one row per sample) or JSON (``.json``: the same
    samples and their meaning), by the extension; whole or not at all.

    Raises:
      ValueError: another extension, an existing file (unless ``overwrite``), a path that cannot
        be written.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        write_text(path, _csv_text(traj), overwrite, ".csv")
    elif ext == ".json":
        write_text(path, json.dumps(trajectory_to_dict(traj, arm), allow_nan=False) + "\n", overwrite, ".json")
    else:
        raise ValueError(f"path: a timed trajectory is written as .csv or .json; got {path!r}")


def _read_csv(path: str, d: dict) -> np.ndarray:
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
        expected = d.get("columns")
        if header != expected:
            raise ValueError(f"timed trajectory file {path}: its header does not list the columns of its JSON "
                             f"file ({len(header)} columns, expected {len(expected or [])}: {', '.join(expected or [])})")
        try:
            table = np.loadtxt(fh, delimiter=",", ndmin=2)
        except ValueError as err:
            raise ValueError(f"timed trajectory file {path}: a row is not numbers: {err}") from None
    if table.shape[1] != len(header) or not np.all(np.isfinite(table)):
        raise ValueError(f"timed trajectory file {path}: rows must hold {len(header)} finite numbers")
    return table


def load_trajectory(path) -> Trajectory:
    """Read a timed trajectory: a ``.json`` file, or a ``.csv`` file with the JSON file of the same
    name beside it (for its units, layout and limits). The arrays are the ones saved.

    Raises:
      ValueError: a missing, unreadable or malformed file (the field named).
    """
    from ..scenarios._json_format import read_json_file

    path = os.fspath(path)
    stem, ext = os.path.splitext(path)
    if ext.lower() not in (".csv", ".json"):
        raise ValueError(f"path: a timed trajectory is read from .csv or .json; got {path!r}")
    meta = path if ext.lower() == ".json" else stem + ".json"
    if not os.path.exists(meta):
        raise ValueError(f"timed trajectory file: {path} needs its JSON file {meta} (units, layout, limits)")
    d = read_json_file(meta, "timed trajectory")
    if ext.lower() == ".json":
        return trajectory_from_dict(d)
    try:
        return trajectory_from_dict(d, _read_csv(path, d))
    except OSError as err:
        raise ValueError(f"cannot read timed trajectory file {path}: {err.strerror or err}") from None
