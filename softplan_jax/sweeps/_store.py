"""The files of a sweep folder: the header ``sweep.json``, the per-chunk tables and timings
``chunks/NNNNNN.{csv,json}``, trajectory shards ``trajectories/NNNNNN.npz``, the merged
``scenes.csv`` and ``chunks.csv``, and ``summary.json``; each written whole or not at all
(a temporary file, then ``os.replace``), a chunk's table last, so a chunk is done exactly
when its table exists; CSV that pandas and polars read as it is, byte for byte the same
when written twice from the same results (the documentation's "Sweeps at scale")."""

from __future__ import annotations

import csv
import io
import json
import math
import os

import numpy as np

__all__ = ["FORMAT", "COLUMNS", "CHUNK_COLUMNS", "atomic_write", "chunk_paths", "write_chunk", "completed_chunks",
           "write_header", "read_header", "header_differences", "remove_sweep_files", "merge_tables", "finite_json",
           "write_summary", "read_table",
           "write_trajectories", "load_trajectory", "wilson_interval"]

FORMAT = "softplan-sweep/1"

# The scene table: (column, type). planner: "local" (reached by the local planner of eq. 9),
# "global" (reached by the fallback's certified search), "none" (not reached).
COLUMNS = (("index", "int"), ("chunk", "int"), ("status", "str"), ("reached", "bool"), ("planner", "str"),
           ("iterations", "int"), ("local_iterations", "int"), ("escapes", "int"), ("min_clearance", "float"),
           ("path_length", "float"), ("final_error", "float"), ("reason", "str"))

# The chunk table (from the chunks' timing files).
CHUNK_COLUMNS = ("chunk", "first", "scenes", "session", "seconds", "generation_s", "compile_s", "fallback_s",
                 "local_steps")

_HEADER, _SUMMARY, _SCENES, _CHUNKS = "sweep.json", "summary.json", "scenes.csv", "chunks.csv"
_CHUNK_DIR, _TRAJ_DIR = "chunks", "trajectories"


def atomic_write(path: str, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all (temporary file in the same folder,
    fsync, ``os.replace``)."""
    folder, name = os.path.split(path)
    tmp = os.path.join(folder, f".{name}.tmp.{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _json_bytes(obj) -> bytes:
    return (json.dumps(obj, indent=2, allow_nan=False) + "\n").encode()


def chunk_paths(out: str, chunk: int) -> dict:
    """The files of chunk ``chunk``: ``table`` (CSV), ``timing`` (JSON), ``trajectories`` (npz)."""
    stem = f"{chunk:06d}"
    return dict(table=os.path.join(out, _CHUNK_DIR, stem + ".csv"), timing=os.path.join(out, _CHUNK_DIR, stem + ".json"),
                trajectories=os.path.join(out, _TRAJ_DIR, stem + ".npz"))


def _cell(value, kind: str) -> str:
    if kind == "bool":
        return "true" if value else "false"
    if kind == "int":
        return str(int(value))
    if kind == "float":
        return repr(float(value))  # shortest round-trip form: inf, nan, 0.1
    return str(value)


def _table_bytes(rows: list[dict]) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([c for c, _ in COLUMNS])
    for row in rows:
        w.writerow([_cell(row[c], kind) for c, kind in COLUMNS])
    return buf.getvalue().encode()


def write_chunk(out: str, chunk: int, rows: list[dict], timing: dict) -> None:
    """Commit one chunk: its timing file, then its table (the table marks the chunk done)."""
    p = chunk_paths(out, chunk)
    os.makedirs(os.path.dirname(p["table"]), exist_ok=True)
    atomic_write(p["timing"], _json_bytes(timing))
    atomic_write(p["table"], _table_bytes(rows))


def completed_chunks(out: str, clean: bool = True) -> set:
    """The chunks whose tables exist; with ``clean``, stale temporary files of a killed run
    are removed (only while no other process writes into ``out``)."""
    done = set()
    for d in (_CHUNK_DIR, _TRAJ_DIR):
        folder = os.path.join(out, d)
        if not os.path.isdir(folder):
            continue
        for name in os.listdir(folder):
            if name.startswith(".") and ".tmp." in name:
                if not clean:
                    continue
                os.remove(os.path.join(folder, name))
            elif d == _CHUNK_DIR and name.endswith(".csv") and name[:-4].isdigit():
                done.add(int(name[:-4]))
    return done


def write_header(out: str, header: dict) -> None:
    atomic_write(os.path.join(out, _HEADER), _json_bytes(header))


def read_header(out: str) -> dict | None:
    """The folder's header, or None when it holds none."""
    path = os.path.join(out, _HEADER)
    if not os.path.exists(path):
        return None
    try:
        with open(path, encoding="utf-8") as fh:
            header = json.load(fh)
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"out: cannot read {path}: {err}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise ValueError(f"out: {path} is not a sweep header (format {FORMAT})")
    return header


def header_differences(old: dict, new: dict, ignore=("versions", "created")) -> list[str]:
    """``field (a there, b here)`` for every field of the two headers that differs."""
    keys = sorted((set(old) | set(new)) - set(ignore))
    return [f"{k} ({json.dumps(old.get(k))} there, {json.dumps(new.get(k))} here)" for k in keys
            if old.get(k) != new.get(k)]


def remove_sweep_files(out: str) -> None:
    """Remove what a sweep writes into ``out`` (its header, tables, summary, chunk files and
    trajectory shards); any other file stays."""
    for name in (_HEADER, _SUMMARY, _SCENES, _CHUNKS):
        path = os.path.join(out, name)
        if os.path.isfile(path):
            os.remove(path)
    for d, ext in ((_CHUNK_DIR, (".csv", ".json")), (_TRAJ_DIR, (".npz",))):
        folder = os.path.join(out, d)
        if not os.path.isdir(folder):
            continue
        for name in os.listdir(folder):
            stem, e = os.path.splitext(name)
            if (e in ext and stem.isdigit()) or (name.startswith(".") and ".tmp." in name):
                os.remove(os.path.join(folder, name))
        if not os.listdir(folder):
            os.rmdir(folder)


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The 95 % Wilson score interval of a rate k / n (Wilson 1927):
    ``(p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)``.

    Args:
      k: successes, 0 <= k <= n.
      n: trials (0: the interval is (nan, nan)).
      z: the normal quantile (default: 97.5 %, a two-sided 95 % interval).

    Returns:
      ``(low, high)`` within [0, 1].
    """
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (0.0 if k == 0 else max(0.0, mid - half), 1.0 if k == n else min(1.0, mid + half))


def merge_tables(out: str, n_chunks: int) -> dict:
    """Write ``scenes.csv`` (every chunk's rows, in order) and ``chunks.csv`` (every chunk's
    timing), streaming: one chunk at a time in memory. Returns the aggregates of the scene
    rows (counts per status and planner, steps, least clearance, ...) and of the timings."""
    counts, planners = {}, {"local": 0, "global": 0, "none": 0}
    agg = dict(scenes=0, iterations=0, local_steps=0, iterations_reached=0, escapes=0, min_clearance=math.inf,
               path_length_reached=0.0)
    timing = {c: 0.0 for c in ("seconds", "generation_s", "compile_s", "fallback_s")}
    sessions = set()
    scenes_tmp = os.path.join(out, f".{_SCENES}.tmp.{os.getpid()}")
    chunks_buf = io.StringIO()
    cw = csv.writer(chunks_buf, lineterminator="\n")
    cw.writerow(CHUNK_COLUMNS)
    col = {c: i for i, (c, _) in enumerate(COLUMNS)}
    try:
        with open(scenes_tmp, "w", encoding="utf-8", newline="") as dst:
            dst.write(",".join(c for c, _ in COLUMNS) + "\n")
            for c in range(n_chunks):
                p = chunk_paths(out, c)
                with open(p["table"], encoding="utf-8", newline="") as src:
                    lines = src.read().splitlines(keepends=True)[1:]
                dst.writelines(lines)
                for row in csv.reader(lines):
                    counts[row[col["status"]]] = counts.get(row[col["status"]], 0) + 1
                    planners[row[col["planner"]]] += 1
                    it = int(row[col["iterations"]])
                    agg["scenes"] += 1
                    agg["iterations"] += it
                    agg["local_steps"] += int(row[col["local_iterations"]])
                    agg["escapes"] += int(row[col["escapes"]])
                    agg["min_clearance"] = min(agg["min_clearance"], float(row[col["min_clearance"]]))
                    if row[col["reached"]] == "true":
                        agg["iterations_reached"] += it
                        agg["path_length_reached"] += float(row[col["path_length"]])
                with open(p["timing"], encoding="utf-8") as fh:
                    t = json.load(fh)
                cw.writerow([_cell(t[k], "float" if k in timing else "str" if k == "session" else "int")
                             for k in CHUNK_COLUMNS])
                sessions.add(t["session"])
                for k in timing:
                    timing[k] += float(t[k])
            dst.flush()
            os.fsync(dst.fileno())
        os.replace(scenes_tmp, os.path.join(out, _SCENES))
    finally:
        if os.path.exists(scenes_tmp):
            os.remove(scenes_tmp)
    atomic_write(os.path.join(out, _CHUNKS), chunks_buf.getvalue().encode())
    return dict(status_counts=dict(sorted(counts.items())), planners=planners, sessions=len(sessions),
                **agg, **timing)


def finite_json(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no inf or nan)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_json(v) for v in obj]
    return obj


def write_summary(out: str, summary: dict) -> None:
    """Write ``summary.json`` (non-finite numbers as null)."""
    atomic_write(os.path.join(out, _SUMMARY), _json_bytes(finite_json(summary)))


def read_table(path: str) -> dict:
    """A sweep's scene table (``scenes.csv`` or a chunk's table, or the folder: its
    ``scenes.csv``) as NumPy columns, without pandas.

    Args:
      path: a CSV file written by a sweep, or a sweep folder.

    Returns:
      ``{column: array}``: int64, float64, bool or str arrays, one entry per scene.
    """
    if os.path.isdir(path):
        path = os.path.join(path, _SCENES)
    kinds = dict(COLUMNS)
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.reader(fh)
        names = next(reader)
        cols = [[] for _ in names]
        for row in reader:
            for i, v in enumerate(row):
                cols[i].append(v)
    conv = {"int": lambda v: np.asarray(v, np.int64), "float": lambda v: np.asarray(v, np.float64),
            "bool": lambda v: np.asarray([x == "true" for x in v], bool), "str": lambda v: np.asarray(v, str)}
    return {name: conv[kinds.get(name, "str")](c) for name, c in zip(names, cols, strict=True)}


def write_trajectories(path: str, trajectories: list) -> None:
    """One shard of trajectories: ``trajectories`` a list of ``(index, q (k+1, n, 3), tip (k+1, 3),
    status, planner)``. The shard holds them back to back: ``index`` (t,), ``offsets`` (t + 1,)
    into the steps, ``q`` (steps, n, 3), ``tip`` (steps, 3), ``status`` and ``planner`` (t,) strings."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    lengths = [t[1].shape[0] for t in trajectories]
    buf = io.BytesIO()
    np.savez_compressed(buf, index=np.asarray([t[0] for t in trajectories], np.int64),
                        offsets=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
                        q=np.concatenate([t[1] for t in trajectories]), tip=np.concatenate([t[2] for t in trajectories]),
                        status=np.asarray([t[3] for t in trajectories], str),
                        planner=np.asarray([t[4] for t in trajectories], str))
    atomic_write(path, buf.getvalue())


def load_trajectory(out: str, index: int) -> dict:
    """The trajectory of scene ``index`` of the sweep in ``out`` (written with ``trajectories``).

    Args:
      out: the sweep folder.
      index: the scene's index in the sweep.

    Returns:
      ``dict(q=(k+1, n, 3), tip=(k+1, 3), status=str, planner=str)``: the planned path,
      start first (for ``planner == "global"``: the local path, then the fallback's).

    Raises:
      ValueError: no such scene, or its trajectory was not kept.
    """
    header = read_header(out)
    if header is None:
        raise ValueError(f"out: {out} holds no sweep")
    if not 0 <= int(index) < header["n"]:
        raise ValueError(f"index must be in 0..{header['n'] - 1}, got {index}")
    path = chunk_paths(out, int(index) // header["chunk"])["trajectories"]
    if not os.path.exists(path):
        raise ValueError(f"the trajectory of scene {index} was not kept (sweep trajectories={header['trajectories']})")
    with np.load(path) as z:
        hit = np.nonzero(z["index"] == int(index))[0]
        if hit.size == 0:
            raise ValueError(f"the trajectory of scene {index} was not kept "
                             f"(sweep trajectories={header['trajectories']})")
        i = int(hit[0])
        a, b = int(z["offsets"][i]), int(z["offsets"][i + 1])
        return dict(q=z["q"][a:b], tip=z["tip"][a:b], status=str(z["status"][i]), planner=str(z["planner"][i]))
