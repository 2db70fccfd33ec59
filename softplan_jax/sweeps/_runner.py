"""Sweeps at scale: :func:`sweep` plans a seeded random suite of any size chunk by chunk
(:mod:`._chunks`), in constant memory, streamed to a folder (:mod:`._store`), resumable, on
one or several processes (:mod:`._processes`), with the global fallback where asked; and the
suite it plans, :func:`sweep_scenarios` and :func:`sweep_keys`, whose scene ``i`` depends on
the seed and ``i`` only (the documentation's "Sweeps at scale" gives the rules).
"""

from __future__ import annotations

import functools
import json
import math
import os
import platform
import time
import warnings
from importlib.metadata import PackageNotFoundError, version

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..planning._batching import batch_mesh, round_chunk
from ..planning._planner import check_gains, make_options
from ..planning._presets import PRESETS, apply_preset
from ..planning._step import GainFunction, Gains
from ..scenarios import random_scenarios
from ..search._reach import ReachOptions, check_reach_options
from . import _processes as processes
from . import _report as report
from . import _store as store
from ._chunks import ChunkLoop

__all__ = ["SCENE_BLOCK", "sweep", "sweep_scenarios", "sweep_keys"]

SCENE_BLOCK = 64  # scenes per call of random_scenarios (a constant: scene i must not depend on n or chunk)


def _int(name, v, lo=1):
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name} must be an int >= {lo}, got {v!r}")
    return int(v)


def _block_seed(seed: int, block: int) -> int:
    return int(np.random.SeedSequence(seed, spawn_key=(block,)).generate_state(1, np.uint64)[0])


@functools.cache
def _fold_keys():
    return package_jit(jax.vmap(jax.random.fold_in, in_axes=(None, 0)), None)


def sweep_keys(seed: int, start: int, stop: int) -> np.ndarray:
    """The escapes' keys of scenes ``start .. stop - 1`` of a sweep: ``fold_in(PRNGKey(seed), i)``.

    Returns:
      (stop - start, 2) uint32 raw keys (the ``seed`` argument of :func:`~softplan_jax.plan_batch`).
    """
    seed, start, stop = _int("seed", seed, 0), _int("start", start, 0), _int("stop", stop, 0)
    idx = np.arange(start, stop, dtype=np.uint32)
    return np.asarray(_fold_keys()(jax.random.PRNGKey(seed), idx))


@functools.lru_cache(maxsize=2)  # the blocks of the current chunk (and a rerun's in the same process)
def _block(seed: int, block: int, obstacles: tuple, slots: int, dtype: str):
    s = random_scenarios(_block_seed(seed, block), SCENE_BLOCK, obstacles=obstacles, curve_slots=slots, dtype=dtype)

    def frozen(x):
        x = np.asarray(x)
        x.flags.writeable = False
        return x

    return jax.tree_util.tree_map(frozen, s)


class _Scenes:
    """Scenes of a sweep by index, generated block by block (:data:`SCENE_BLOCK` scenes); with
    ``preset``, the start pose of that gain preset (if it has one)."""

    def __init__(self, seed, obstacles, slots, dtype, preset=None):
        self.seed, self.args = seed, (tuple(int(v) for v in obstacles), int(slots), str(jnp.dtype(dtype)))
        p = None if preset is None else PRESETS[preset]
        self.preset = preset if p is not None and (p.start_theta is not None or p.start_phi is not None) else None

    def _get(self, b):
        return _block(self.seed, b, *self.args)

    def take(self, start, stop):
        parts = []
        for b in range(start // SCENE_BLOCK, (stop - 1) // SCENE_BLOCK + 1):
            lo, hi = max(start, b * SCENE_BLOCK) - b * SCENE_BLOCK, min(stop, (b + 1) * SCENE_BLOCK) - b * SCENE_BLOCK
            parts.append(jax.tree_util.tree_map(lambda x, lo=lo, hi=hi: x[lo:hi], self._get(b)))
        return parts[0] if len(parts) == 1 else jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)

    def take_with_keys(self, start, stop):
        """``(scenes, keys)`` of scenes ``start .. stop - 1``: the chunk loop's source."""
        scenes = self.take(start, stop)
        if self.preset is not None:  # the preset's start pose
            scenes = apply_preset(self.preset, scenes._replace(q0=jnp.asarray(scenes.q0)))[0]
            scenes = scenes._replace(q0=np.asarray(scenes.q0))
        return scenes, sweep_keys(self.seed, start, stop)


def sweep_scenarios(seed: int, start: int, stop: int, *, obstacles=(1, 8), slots: int = 8, dtype=None):
    """Scenes ``start .. stop - 1`` of the sweep suite, as one batched Scenario: scene ``i`` is
    scene ``i mod 64`` of ``random_scenarios(seed_b, 64)`` (:data:`SCENE_BLOCK`), ``seed_b`` from
    ``numpy.random.SeedSequence(seed, spawn_key=(i // 64,))``, so it depends on the seed and ``i`` only.

    Args:
      seed: the sweep's seed, an int >= 0.
      start, stop: scene indices, 0 <= start < stop.
      obstacles, slots, dtype: as :func:`sweep`.

    Returns:
      A batched :class:`~softplan_jax.Scenario` (leading axis stop - start) of read-only NumPy arrays.
    """
    seed, start, stop = _int("seed", seed, 0), _int("start", start, 0), _int("stop", stop, 1)
    if stop <= start:
        raise ValueError(f"need start < stop, got {start}, {stop}")
    return _Scenes(seed, obstacles, slots, _check_dtype(dtype)).take(start, stop)


def _jsonable(x):
    """Options, gains and other NamedTuples as plain JSON values."""
    if hasattr(x, "_asdict"):
        return {k: _jsonable(v) for k, v in x._asdict().items()}
    if isinstance(x, (tuple, list)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.ndarray, np.generic, jax.Array)):
        return np.asarray(x).tolist()
    return x


def _versions() -> dict:
    try:
        own = version("softplan_jax")
    except PackageNotFoundError:
        own = "0.0.0+unknown"
    return dict(softplan_jax=own, jax=jax.__version__, numpy=np.__version__, python=platform.python_version())


def _check_dtype(dtype):
    dt = jnp.dtype(jnp.result_type(float) if dtype is None else dtype)
    if dt not in (jnp.dtype(jnp.float32), jnp.dtype(jnp.float64)):
        raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
    if dt == jnp.dtype(jnp.float64) and not jax.config.jax_enable_x64:
        raise ValueError("dtype float64 needs jax_enable_x64 (jax.config.update('jax_enable_x64', True))")
    return dt


def _check_gains(gains, dtype):
    """``(preset name or None, Gains, preset options)``."""
    if gains is None or isinstance(gains, str):
        name = "default" if gains is None else gains
        if name not in PRESETS:
            raise ValueError(f"gains: unknown preset {name!r}; choose one of {sorted(PRESETS)}, or pass Gains")
        from ..planning._presets import preset

        p = preset(name)
        return name, Gains(**{k: jnp.asarray(p.gains[k], dtype) for k in Gains._fields}), dict(p.options)
    if not isinstance(gains, (Gains, GainFunction)):
        raise ValueError(f"gains must be None, a preset name, Gains or GainFunction, got {type(gains).__name__}")
    return None, check_gains(gains, dtype), {}


def _check_trajectories(trajectories, n):
    """How many scenes (the first ones) keep their trajectory."""
    if trajectories is None:
        return 0
    if trajectories == "all":
        return n
    if isinstance(trajectories, str):
        raise ValueError(f"trajectories must be None, 'all' or an int >= 1, got {trajectories!r}")
    return min(_int("trajectories", trajectories), n)


def _prepare_folder(out, header, resume: bool, overwrite: bool) -> None:
    """Make ``out`` ready: a new sweep's header, or the same sweep's to resume (ValueError otherwise)."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise ValueError(f"out: {out} exists and is not a folder")
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as err:
        raise ValueError(f"out: cannot create the folder {out}: {err}") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise ValueError(f"out: the folder {out} is not writable")
    if overwrite:
        store.remove_sweep_files(out)
        old = None
    else:
        old = store.read_header(out)
        if old is None and os.listdir(out):
            raise ValueError(f"out: {out} holds files but no sweep (no sweep.json); choose a new or empty folder, "
                             "or pass overwrite=True (--force) to write the sweep beside them")
        if old is not None and not resume:
            raise ValueError(f"out: {out} holds a sweep; pass resume=True to continue it or overwrite=True "
                             "(--force) to start anew")
    if old is not None:
        diff = store.header_differences(old, header)
        if diff:
            raise ValueError(f"out: {out} holds a sweep with other arguments: {'; '.join(diff)}; use another "
                             "folder, the same arguments, or overwrite=True (--force) to start anew")
        if old.get("versions") != header["versions"]:
            warnings.warn(f"resuming the sweep in {out} with other versions ({header['versions']}) than it was "
                          f"started with ({old.get('versions')}): its chunks may differ to rounding",
                          RuntimeWarning, stacklevel=4)
        return
    try:
        store.write_header(out, header)
    except OSError as err:
        raise ValueError(f"out: cannot write into {out}: {err}") from None


def sweep(n: int, out, seed: int = 0, *, chunk: int = 256, method: str = "curve", n_points: int = 10, gains=None,
          max_steps: int = 600, fallback: bool = False, reach: ReachOptions | None = None, obstacles=(1, 8),
          slots: int = 8, dtype=None, devices=None, trajectories=None, progress=True, resume: bool = True,
          overwrite: bool = False, **options) -> dict:
    """Plan ``n`` scenes of the sweep suite in chunks, streaming one summary row per scene to disk.

    The scenes, the loop, the files and resuming: the documentation's Performance page,
    "How a sweep works", and :mod:`._store`.
    Memory stays flat in ``n``: the process holds at most two chunks (their scenes and
    rollouts) and two blocks of 64 generated scenes; the rows go to disk chunk by
    chunk, and the summary is computed by streaming the merged table.

    Args:
      n: number of scenes, >= 1.
      out: the sweep folder (created if needed; a new sweep needs a new or empty folder).
      seed: int >= 0: the scenes, the escapes' keys and the fallback's seeds.
      chunk: scenes per planner call (one compiled shape; rounded up to a multiple of the
        device count, at most ``n``).
      method, n_points, max_steps, **options: the local planner's settings, as
        :func:`~softplan_jax.plan_batch` (``options``: further PlanOptions fields).
      gains: None (the default preset), a preset name ("default", "paper": gains, step
        options and start pose), or :class:`~softplan_jax.Gains` /
        :class:`~softplan_jax.GainFunction`.
      fallback: run the global fallback (:func:`~softplan_jax.plan_fallback`'s reachability
        and certified search) on every scene the local planner leaves stalled or at
        max_steps; the table says which planner reached each scene.
      reach: :class:`~softplan_jax.search.ReachOptions` of the fallback (default ReachOptions()).
      obstacles, slots: curves per scene drawn from ``obstacles[0] .. obstacles[1]``, padded to
        ``slots`` (as :func:`~softplan_jax.random_scenarios`).
      dtype: float32 or float64 (default: JAX's default float; float64 needs jax_enable_x64).
      devices: None (every local device) or an int k (the first k), as plan_batch. Under
        ``jax.distributed``, each process plans its share of the chunks (``c % P == i``) on
        its own local devices into ``out``, a folder every process sees (:mod:`._processes`);
        every process returns the summary.
      trajectories: None (no paths kept), "all", or an int K: the paths of scenes 0 .. K-1 (a
        uniform sample: the scenes are independent draws), to ``trajectories/*.npz``
        (:func:`~softplan_jax.sweeps._store.load_trajectory`).
      progress: True (one line per chunk on stderr), False, or a callable given a dict after
        each chunk is written: chunk (its index), chunks (this process's share of them),
        chunks_done (resumed ones included),
        n, and for this run: scenes_done, reached, local, global (reached by each planner),
        elapsed_s, compile_s, eta_s.
      resume: continue the sweep already in ``out`` if it has the same arguments.
      overwrite: remove the sweep files already in ``out`` and start anew.

    Returns:
      The summary (also ``out/summary.json``): status counts; success, local, global and
      collision rates over all ``n`` scenes with 95 % Wilson intervals (``*_ci95``); mean
      iterations and tip path length of the reached scenes; least clearance; steps taken
      by the local planner; times (generation, compile, run = the chunks' wall time after
      compilation, fallback) summed over every session and process that wrote a chunk;
      ``scenes_per_s = n / run_s`` and ``steps_per_s = steps_taken / (run_s - fallback_s)``
      (per process: P processes finish in about run_s / P); ``processes`` of this run.
      (Processes other than 0 return it as read from ``summary.json``: non-finite numbers
      as None.)

    Raises:
      ValueError: a bad argument (named), a folder that cannot be written or holds something
        else, or a sweep in ``out`` with other arguments (the differing fields named).
    """
    n, seed, max_steps = _int("n", n), _int("seed", seed, 0), _int("max_steps", max_steps)
    chunk, slots, n_points = _int("chunk", chunk), _int("slots", slots), _int("n_points", n_points)
    out, obstacles = _check_run_args(out, obstacles, slots, fallback, resume, overwrite, progress, options)
    dt = _check_dtype(dtype)
    if isinstance(devices, str):
        raise ValueError(f"devices must be None or an int (sweep runs on local devices), got {devices!r}")
    mesh = batch_mesh(devices)
    size = round_chunk(chunk, n, 1 if mesh is None else mesh.size)
    preset_name, g, extra = _check_gains(gains, dt)
    opts = make_options(method, n_points, **{**extra, **options})
    reach = check_reach_options(ReachOptions() if reach is None else reach) if fallback else None
    keep = _check_trajectories(trajectories, n)
    header = dict(format=store.FORMAT, n=n, seed=seed, chunk=size, scene_block=SCENE_BLOCK, method=opts.method,
                  n_points=opts.n_points, max_steps=max_steps, fallback=bool(fallback), reach=_jsonable(reach),
                  obstacles=list(obstacles), slots=slots, dtype=str(dt), devices=1 if mesh is None else mesh.size,
                  trajectories=None if not keep else ("all" if trajectories == "all" else keep),
                  gains=dict(preset=preset_name, values=_jsonable(g)), options=_jsonable(opts),
                  versions=_versions(), created=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    header = json.loads(json.dumps(store.finite_json(header), default=str))
    procs = processes.current()
    _meet_over_folder(procs, out, header, bool(resume), bool(overwrite))
    loop = ChunkLoop(_Scenes(seed, obstacles, slots, dt, preset_name).take_with_keys, n, size, opts, g, max_steps,
                     devices, reach=reach, fallback_seed=functools.partial(_chunk_seed, seed), keep=keep)
    resumed = _plan_share(loop, procs, out, header, progress)
    return _merge(procs, out, header, resumed)


def _check_run_args(out, obstacles, slots, fallback, resume, overwrite, progress, options):
    """The sweep's flags checked (ValueError); ``(out as an absolute path, (lo, hi))``."""
    for name, v in (("fallback", fallback), ("resume", resume), ("overwrite", overwrite)):
        if not isinstance(v, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {v!r}")
    if not (isinstance(progress, (bool, np.bool_)) or callable(progress)):
        raise ValueError(f"progress must be True, False or a callable, got {progress!r}")
    if out is None or not str(out):
        raise ValueError("out: give the sweep folder")
    try:
        lo, hi = (int(v) for v in obstacles)
    except (TypeError, ValueError):
        raise ValueError(f"obstacles must be (min, max), got {obstacles!r}") from None
    if not 1 <= lo <= hi <= slots:
        raise ValueError(f"obstacles: need 1 <= min <= max <= slots ({slots}), got {obstacles!r}")
    if {"method", "n_points"} & set(options):
        raise ValueError("pass method and n_points once")
    return os.path.abspath(os.fspath(out)), (lo, hi)


def _chunk_seed(seed: int, chunk: int) -> int:
    """The fallback's seed of a chunk: its index only, so a resumed chunk searches as the first run did."""
    return int(np.random.SeedSequence(seed, spawn_key=(1, chunk)).generate_state(1)[0] >> 1)


def _plan_share(loop: ChunkLoop, procs, out: str, header: dict, progress) -> int:
    """Plan this process's chunks not yet done into ``out``; the number already done before."""
    n_chunks = math.ceil(header["n"] / header["chunk"])
    done = store.completed_chunks(out, clean=False)
    mine = processes.share(range(n_chunks), procs)
    todo = [c for c in mine if c not in done]
    say = report.reporter(progress, header["n"], len(mine), out, len(mine) - len(todo), header["fallback"],
                          procs.prefix("sweep"))

    def commit(rows, timing, paths, elapsed):
        if paths:
            store.write_trajectories(store.chunk_paths(out, timing["chunk"])["trajectories"], paths)
        store.write_chunk(out, timing["chunk"], rows, timing)
        say(rows, timing, elapsed, loop.compile_s or 0.0)

    try:
        loop.run(todo, commit)
    except BaseException as err:  # the others stop waiting for this process's chunks
        procs.post("written", f"{type(err).__name__}: {err}")
        raise
    procs.meet("written")
    return len(done)


def _merge(procs, out: str, header: dict, resumed: int) -> dict:
    """Process 0 merges the tables and writes the summary; the others read it. The summary."""
    if not procs.lead:
        procs.meet("merged")
        with open(os.path.join(out, "summary.json"), encoding="utf-8") as fh:
            return json.load(fh)
    try:
        merged = store.merge_tables(out, math.ceil(header["n"] / header["chunk"]))
        summary = report.summary(header, merged, out, resumed, procs.count)
        store.write_summary(out, summary)
    except BaseException as err:
        procs.post("merged", f"{type(err).__name__}: {err}")
        raise
    procs.meet("merged")
    return summary


def _meet_over_folder(procs, out, header, resume, overwrite) -> None:
    """Process 0 prepares ``out`` (header, stale temporary files); then every other process
    checks the header against its own arguments (:mod:`._processes`)."""
    error = ""
    if procs.lead:
        try:
            _prepare_folder(out, header, resume, overwrite)
            store.completed_chunks(out, clean=True)
        except ValueError as err:
            error = str(err)
    procs.meet("prepared", error)
    if not procs.lead:
        try:
            _prepare_folder(out, header, resume=True, overwrite=False)
        except ValueError as err:
            error = str(err)
    procs.meet("checked", error)
