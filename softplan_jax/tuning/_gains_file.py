"""Gains files: tuned :class:`~softplan_jax.planning._gains.Gains` or
:class:`~softplan_jax.planning._gains.GainFunction` kept as JSON (format ``softplan-gains/1``; docs:
"Scenario and gains files"): the obstacle model they were tuned for (``method``, ``n_points``), the
seven scalar ``gains`` (``rep_max`` null: no cap), a gain function's ``rep_profile``,
``seg_weights`` and optional ``goal_profile``, and free ``metadata``. Every malformed file is
rejected with a ValueError that names the field (``gains file field gains.d0: must be a finite
positive number, got -1``), the values checked by the planner's rules
(:func:`~softplan_jax.planning._planner.check_gains`); loading with ``method`` / ``n_points``
refuses a file tuned for another obstacle model."""

from __future__ import annotations

import json
import math
import os
import re

import jax.numpy as jnp
import numpy as np

from ..planning._planner import check_gains
from ..planning._step import GOAL_GAINS, GainFunction, Gains
from ..scenarios._json_format import read_json_file, write_json_file

__all__ = ["GAINS_FORMAT", "gains_to_dict", "gains_from_dict", "save_gains", "load_gains"]

GAINS_FORMAT = "softplan-gains/1"
_METHODS = ("curve", "points")
_TOP_KEYS = ("format", "method", "n_points", "gains", "metadata")
_ARRAYS = ("rep_profile", "seg_weights")


def _err(field: str, msg: str) -> ValueError:
    return ValueError(f"gains file field {field}: {msg}")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(v) -> bool:
    try:
        return math.isfinite(v)
    except OverflowError:  # a JSON integer beyond float range
        return False


def _check_model(method, n_points):
    """``method`` / ``n_points`` arguments: a known method and an int N >= 1 (or None)."""
    if method is not None and method not in _METHODS:
        raise ValueError(f"method must be 'curve' or 'points', got {method!r}")
    if n_points is not None and (not isinstance(n_points, (int, np.integer)) or isinstance(n_points, bool)
                                 or n_points < 1):
        raise ValueError(f"n_points must be an integer >= 1, got {n_points!r}")


def _model(method: str, n_points) -> str:
    return f"'{method}' (N={n_points})" if method == "points" else f"'{method}'"


def gains_to_dict(gains: Gains | GainFunction, method: str = "curve", n_points: int = 10,
                  metadata: dict | None = None) -> dict:
    """The JSON structure (format ``softplan-gains/1``) of gains tuned for an obstacle model.

    Args:
      gains: a :class:`Gains` or :class:`GainFunction` of concrete values
        (validated by :func:`~softplan_jax.planning._planner.check_gains`).
      method: the obstacle model the gains were tuned for, "curve" or "points".
      n_points: N of the N-point model (meaningful for method "points").
      metadata: optional JSON object stored as given (how, on what, when tuned).

    Returns:
      a dict of plain Python values (``rep_max = inf`` written as None), ready for
      ``json.dumps``.
    """
    _check_model(method, n_points)
    if method is None:
        raise ValueError("method must be 'curve' or 'points', got None")
    if n_points is None:
        raise ValueError("n_points must be an integer >= 1, got None")
    check_gains(gains, jnp.result_type(float))
    if metadata is not None:
        if not isinstance(metadata, dict):
            raise ValueError(f"metadata must be a dict (a JSON object), got {type(metadata).__name__}")
        try:
            json.dumps(metadata, allow_nan=False)
        except (TypeError, ValueError) as err:
            raise ValueError(f"metadata must be JSON-serialisable (finite numbers): {err}") from None
    values = {}
    for k in Gains._fields:
        v = float(np.asarray(getattr(gains, k)))
        values[k] = None if (k == "rep_max" and math.isinf(v)) else v
    if isinstance(gains, GainFunction):
        for k in _ARRAYS:
            values[k] = [float(x) for x in np.asarray(getattr(gains, k)).reshape(-1)]
        if gains.goal_profile is not None:
            values["goal_profile"] = np.asarray(gains.goal_profile, np.float64).tolist()
    out = {"format": GAINS_FORMAT, "method": method, "n_points": int(n_points), "gains": values}
    if metadata is not None:
        out["metadata"] = metadata
    return out


def _parse(data) -> tuple[Gains | GainFunction, str, int | None]:
    """(gains as float64 NumPy scalars/arrays, method, n_points) from the JSON structure;
    every malformed field a ValueError naming it."""
    if not isinstance(data, dict):
        raise _err("(top)", f"must be a JSON object, got {type(data).__name__}")
    if "format" not in data:
        raise _err("format", f"is missing (expected {GAINS_FORMAT!r})")
    if data["format"] != GAINS_FORMAT:
        raise _err("format", f"must be {GAINS_FORMAT!r}, got {data['format']!r}")
    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown:
        raise _err(unknown[0], f"unknown key (allowed: {list(_TOP_KEYS)})")
    if "method" not in data:
        raise _err("method", "is missing ('curve' or 'points')")
    method = data["method"]
    if method not in _METHODS:
        raise _err("method", f"must be 'curve' or 'points', got {method!r}")
    n_points = data.get("n_points")
    if n_points is None and method == "points":
        raise _err("n_points", "is missing (needed for method 'points')")
    if n_points is not None and (not isinstance(n_points, int) or isinstance(n_points, bool) or n_points < 1):
        raise _err("n_points", f"must be an integer >= 1, got {n_points!r}")
    if "metadata" in data and not isinstance(data["metadata"], dict):
        raise _err("metadata", f"must be a JSON object, got {data['metadata']!r}")
    if "gains" not in data:
        raise _err("gains", "is missing")
    g = data["gains"]
    if not isinstance(g, dict):
        raise _err("gains", f"must be a JSON object of gain values, got {g!r}")
    allowed = list(Gains._fields) + list(_ARRAYS) + ["goal_profile"]
    unknown = sorted(set(g) - set(allowed))
    if unknown:
        raise _err(f"gains.{unknown[0]}", f"unknown gain (allowed: {allowed})")
    vals = {}
    for k in Gains._fields:
        field = f"gains.{k}"
        if k not in g:
            raise _err(field, "is missing")
        v = g[k]
        if k == "rep_max" and v is None:
            vals[k] = np.float64(np.inf)
            continue
        if not _is_number(v) or not _finite(v):
            what = "a finite number (null for no cap)" if k == "rep_max" else "a finite number"
            raise _err(field, f"must be {what}, got {v!r}")
        if not (v > 0 or (k == "damping" and v == 0)):
            rule = "a finite number >= 0" if k == "damping" else "a finite positive number"
            raise _err(field, f"must be {rule}, got {v!r}")
        vals[k] = np.float64(v)
    present = [k for k in _ARRAYS if k in g]
    if len(present) == 1:
        other = next(k for k in _ARRAYS if k not in g)
        raise _err(f"gains.{other}", f"is missing (a gain function needs both rep_profile and seg_weights; "
                   f"the file has {present[0]} only)")
    for k in present:
        field, v = f"gains.{k}", g[k]
        if not isinstance(v, list) or not all(_is_number(x) for x in v):
            raise _err(field, f"must be a list of numbers, got {v!r}")
        if not all(_finite(x) for x in v):
            raise _err(field, f"must be finite numbers, got {v!r}")
        least = 2 if k == "rep_profile" else 1
        if len(v) < least:
            raise _err(field, f"needs at least {least} numbers, got {len(v)}")
        vals[k] = np.asarray(v, dtype=np.float64)
    if "goal_profile" in g:
        v = g["goal_profile"]
        if not present:
            raise _err("gains.goal_profile", "needs rep_profile and seg_weights (a gain function)")
        rows_ok = isinstance(v, list) and len(v) == len(GOAL_GAINS) and all(
            isinstance(r, list) and len(r) >= 2 and all(_is_number(x) for x in r) for r in v)
        if not rows_ok or len({len(r) for r in v}) != 1:
            raise _err("gains.goal_profile", f"must be {len(GOAL_GAINS)} lists of K >= 2 numbers (rows "
                       f"{', '.join(GOAL_GAINS)}), all of one length, got {v!r}")
        if not all(_finite(x) for r in v for x in r):
            raise _err("gains.goal_profile", f"must be finite numbers, got {v!r}")
        vals["goal_profile"] = np.asarray(v, dtype=np.float64)
    gains = GainFunction(**vals) if present else Gains(**vals)
    return gains, method, n_points


def _validated(gains, dtype):
    """``check_gains`` (the planner's rules) on the parsed gains, its error naming the field.
    ``damping`` 0 (the paper preset's plain pseudo-inverse) is accepted without a warning:
    :func:`~softplan_jax.plan` refuses it, with the reason, where the start pose makes it singular."""
    try:
        checked = check_gains(gains, dtype)
    except ValueError as err:
        m = re.match(r"gain (\w+) ", str(err)) or re.match(r"(rep_profile|seg_weights|goal_profile) ", str(err))
        raise _err(f"gains.{m.group(1)}" if m else "gains", str(err)) from None
    return checked


def _check_tuned_for(file_method, file_n, method, n_points, name: str | None):
    if method is None and n_points is None:
        return
    want = method or file_method
    mismatch = want != file_method or (
        want == "points" and n_points is not None and file_n is not None and n_points != file_n
    )
    if mismatch:
        where = f"gains file {name} was" if name else "these gains were"
        raise ValueError(f"{where} tuned for method {_model(file_method, file_n)}, "
                         f"not {_model(want, n_points if n_points is not None else file_n)}")


def gains_from_dict(d: dict, method: str | None = None, n_points: int | None = None, dtype=None):
    """Gains from the JSON structure of :func:`gains_to_dict` (format ``softplan-gains/1``).

    Args:
      d: the parsed JSON object.
      method: if given, the obstacle model the gains are for: a file tuned for
        another method is refused (ValueError).
      n_points: if given, N of the N-point model; compared when the method is "points".
      dtype: dtype of the returned arrays (default: jax's default float).

    Returns:
      a :class:`Gains` (no ``rep_profile`` / ``seg_weights``) or a
      :class:`GainFunction` (both), as arrays of ``dtype``.

    Raises:
      ValueError: naming the malformed field (``gains file field gains.d0: ...``),
        or saying which obstacle model the gains were tuned for.
    """
    _check_model(method, n_points)
    gains, file_method, file_n = _parse(d)
    _check_tuned_for(file_method, file_n, method, n_points, None)
    return _validated(gains, dtype or jnp.result_type(float))


def save_gains(gains: Gains | GainFunction, path, method: str = "curve", n_points: int = 10,
               metadata: dict | None = None, overwrite: bool = False) -> None:
    """Write gains as a JSON gains file (see :func:`gains_to_dict`).

    Refuses to replace an existing file unless ``overwrite=True`` (ValueError);
    the file is written whole (via a temporary file) or not at all.
    """
    write_json_file(path, gains_to_dict(gains, method, n_points, metadata), overwrite)


def load_gains(path, method: str | None = None, n_points: int | None = None, dtype=None) -> Gains | GainFunction:
    """Read a gains file (format ``softplan-gains/1``; see :func:`gains_from_dict`).

    Args:
      path: the JSON file.
      method, n_points: if given, the obstacle model the gains are for; a file
        tuned for another one is refused: ``gains file tuned.json was tuned for
        method 'curve', not 'points' (N=10)``.
      dtype: dtype of the arrays (default: jax's default float).

    Returns:
      a :class:`Gains` or a :class:`GainFunction`, ready for ``sp.plan(..., gains=...)``.
      (The file's ``metadata`` is not returned: ``json.load`` the file to read it.)

    Raises:
      ValueError: the file is missing, unreadable, not JSON, malformed (the
        message names the field) or tuned for another obstacle model.
    """
    path = os.fspath(path)
    _check_model(method, n_points)
    data = read_json_file(path, "gains")
    try:
        gains, file_method, file_n = _parse(data)
        gains = _validated(gains, dtype or jnp.result_type(float))
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None
    _check_tuned_for(file_method, file_n, method, n_points, path)
    return gains
