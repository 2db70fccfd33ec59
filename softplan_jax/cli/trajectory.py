"""The trajectory file of ``softplan run --out`` (format ``softplan-trajectory/1``):
:func:`trajectory_record` gathers one run's arrays (configurations, tip and true
clearance at every step) and metadata, :func:`write_trajectory` writes them as
JSON (nested lists, non-finite numbers as null) or NPZ (one array per field, no
pickles), chosen by the file's extension, and :func:`read_trajectory` reads either
back (``softplan view``).
"""

from __future__ import annotations

import json
import math
import os

from .common import package_version
from .interrupt import atomic_output

__all__ = ["TRAJECTORY_FORMAT", "TRAJECTORY_FORMATS", "trajectory_record", "write_trajectory", "is_trajectory_file",
           "read_trajectory"]


TRAJECTORY_FORMAT = "softplan-trajectory/1"
TRAJECTORY_FORMATS = (".json", ".npz")


def trajectory_record(result, scenario, summary: dict) -> dict:
    """The content of a ``run --out`` file: arrays and metadata of one run.

    Args:
      result: the run's PlanResult (trimmed to the steps taken).
      scenario: the planned Scenario (for the goal).
      summary: the run's summary (scenario label, method, options, times).

    Returns:
      dict with ``q`` (T, n, 3), ``tip`` (T, 3), ``clearance`` (T, m) (float
      arrays, T = iterations + 1, m = the scenario's obstacles, the true
      clearance at every step), ``goal`` (3,), and the scalars ``format``,
      ``status``, ``iterations``, ``reached``, ``collided``, ``min_clearance``,
      ``final_error``, ``planner`` ("local" or "global"), ``reason`` ("" or why the
      goal was not reached), ``global_start`` (the step where the global search's
      path leaves the local one, or None), ``best_error`` (the reachability IK's best
      tip distance, or None) and the summary's metadata (``scenario``, ``method``,
      ``n_points``, ``repulsion``, ``dtype``, ``max_steps``,
      ``goal_tolerance``, ``compile_time_s``, ``run_time_s``, ``gains``: the
      preset name or the gains file as given, ``gains_file``: its absolute
      path or None), plus ``softplan_jax_version`` and ``gain_values``: the
      gains used, a dict of floats (``rep_max`` inf: no cap) and, for a gain
      function, lists (``rep_profile``, ``seg_weights``). In an NPZ file it is
      flattened to ``gain_values.k_att``, ... arrays; in JSON inf is null.
    """
    import numpy as np

    record = {
        "format": TRAJECTORY_FORMAT,
        "softplan_jax_version": package_version(),
        "q": np.asarray(result.q),
        "tip": np.asarray(result.tip),
        "clearance": np.asarray(result.clearance),
        "goal": np.asarray(scenario.goal),
        "status": result.status,
        "iterations": int(result.iterations),
        "reached": bool(result.reached),
        "collided": bool(result.collided),
        "min_clearance": float(result.min_clearance),
        "final_error": float(result.final_error),
        "planner": result.planner,
        "reason": result.reason,
        "global_start": result.global_start,
        "best_error": result.best_error,
    }
    for key in ("scenario", "method", "n_points", "repulsion", "dtype", "max_steps", "goal_tolerance",
                "compile_time_s", "run_time_s", "gains", "gains_file"):
        record[key] = summary[key]
    record["gain_values"] = {k: (math.inf if v is None else v) for k, v in summary["gain_values"].items()}
    return record


def _json_ready(x):
    """Arrays to nested lists, non-finite floats to None (strict JSON)."""
    import numpy as np

    if isinstance(x, np.ndarray):
        return _json_ready(x.tolist())
    if isinstance(x, dict):
        return {k: _json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_ready(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_trajectory(path: str, record: dict) -> None:
    """Write :func:`trajectory_record` as JSON or NPZ, by the extension of ``path``."""

    ext = os.path.splitext(path)[1].lower()
    if ext not in TRAJECTORY_FORMATS:
        raise ValueError(f"unknown trajectory format {ext!r}; use .json or .npz")
    with atomic_output(path) as tmp:  # whole or not at all, also on Ctrl-C
        _write(tmp, ext, record)


def _write(path: str, ext: str, record: dict) -> None:
    import numpy as np

    if ext == ".json":
        with open(path, "w", encoding="utf-8") as fh:
            json.dump({k: _json_ready(v) for k, v in record.items()}, fh, allow_nan=False)
            fh.write("\n")
    elif ext == ".npz":
        # None (n_points of the curve method) has no array form: left out; a dict
        # (gain_values) becomes one array per entry, "name.key" (no pickles).
        flat = {}
        for k, v in record.items():
            if isinstance(v, dict):
                flat.update({f"{k}.{sub}": w for sub, w in v.items()})
            else:
                flat[k] = v
        arrays = {k: np.asarray(v) for k, v in flat.items() if v is not None}
        with open(path, "wb") as fh:  # np.savez would append .npz to a name without it
            np.savez(fh, **arrays)


def is_trajectory_file(path: str) -> bool:
    """Whether ``path`` holds a trajectory (an NPZ file, or JSON whose ``format`` is
    ``softplan-trajectory/1``) rather than a scenario; False for anything unreadable (the
    scenario loader then reports it)."""
    if path.lower().endswith(".npz"):
        return True
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096)
    except (OSError, UnicodeDecodeError):
        return False
    return f'"format": "{TRAJECTORY_FORMAT}"' in head or f'"format":"{TRAJECTORY_FORMAT}"' in head


def _no_nulls(value):
    """JSON's nulls (non-finite numbers) as NaN, in nested lists."""
    if isinstance(value, list):
        return [_no_nulls(v) for v in value]
    return float("nan") if value is None else value


def _array(record: dict, key: str, path: str, ndim: int, width: int | None = None):
    """A float array field of a trajectory record, checked: ``ndim`` dimensions, the last
    ``width`` long (if given), at least one row."""
    import numpy as np

    if record.get(key) is None:
        raise ValueError(f"trajectory file {path}: field {key} is missing")
    try:
        a = np.asarray(_no_nulls(record[key]), np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"trajectory file {path}: field {key} is not an array of numbers") from None
    if a.ndim != ndim or (width is not None and a.shape[-1] != width) or a.shape[0] < 1:
        raise ValueError(f"trajectory file {path}: field {key} has shape {a.shape}, expected {ndim} dimension(s)"
                         + (f" ending in {width}" if width else "") + ", at least one row")
    return a


def read_trajectory(path: str) -> dict:
    """A ``run --out`` file (JSON or NPZ) as a record like :func:`trajectory_record`'s: ``q``
    (T, n, 3), ``tip`` (T, 3), ``clearance`` (T, m), ``goal`` (3,) or (T, 3) (a tracked run's),
    ``time`` (T,) (tracked runs only, else None), the outcome's scalars and the metadata, plus
    ``path`` (as given).

    Raises:
      ValueError: an unreadable file, another format, or a missing or malformed field (named).
    """
    import numpy as np

    if path.lower().endswith(".npz"):
        try:
            with np.load(path, allow_pickle=False) as z:
                record = {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
        except (OSError, ValueError) as err:
            raise ValueError(f"trajectory file {path} is not a readable NPZ file: {err}") from None
    else:
        from ..scenarios._json_format import read_json_file

        record = read_json_file(path, "trajectory")
        if not isinstance(record, dict):
            raise ValueError(f"trajectory file {path}: expected a JSON object")
    if record.get("format") != TRAJECTORY_FORMAT:
        raise ValueError(f"trajectory file {path}: field format is {record.get('format')!r}, expected "
                         f"{TRAJECTORY_FORMAT!r}")
    q = _array(record, "q", path, 3, 3)
    if not np.all(np.isfinite(q)):
        raise ValueError(f"trajectory file {path}: field q holds non-finite numbers")
    out = dict(record, q=q, path=path)
    out["tip"] = _array(record, "tip", path, 2, 3)
    out["clearance"] = _array(record, "clearance", path, 2)
    try:
        goal = np.asarray(_no_nulls(record.get("goal")), np.float64)
    except (TypeError, ValueError):
        goal = np.zeros(0)
    if goal.shape not in ((3,), (q.shape[0], 3)) or not np.all(np.isfinite(goal)):
        raise ValueError(f"trajectory file {path}: field goal must be (3,) or (T, 3) finite numbers, got "
                         f"shape {goal.shape}")
    out["goal"] = goal
    out["time"] = _array(record, "time", path, 1) if record.get("time") is not None else None
    for key in ("tip", "clearance") + (("time",) if out["time"] is not None else ()):
        if out[key].shape[0] != q.shape[0]:
            raise ValueError(f"trajectory file {path}: field {key} has {out[key].shape[0]} rows for {q.shape[0]} "
                             "configurations")
    for key in ("status", "scenario"):
        if not isinstance(record.get(key), str):
            raise ValueError(f"trajectory file {path}: field {key} must be a string")
    return out
