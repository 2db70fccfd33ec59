"""Sweeps at scale: plan a seeded random suite of any size in chunks, in constant
memory, streamed to disk, resumable, with the global fallback where asked.

**The scenes.** Scene ``i`` of the sweep with seed ``s`` is scene ``i mod B`` of
``random_scenarios(seed_b, B)`` with ``B = SCENE_BLOCK`` (64) and ``seed_b`` drawn
from ``numpy.random.SeedSequence(s, spawn_key=(b,))`` for the block ``b = i // B``;
its escapes' random walks use the key ``jax.random.fold_in(PRNGKey(s), i)``. So a
scene depends on the seed, its index and the suite's options (obstacles, slots,
dtype), never on ``n`` or the chunk size: the first K scenes of every sweep with
the same seed are the same scenes (prefix-consistent), and
:func:`sweep_scenarios` / :func:`sweep_keys` give any of them again.
``softplan batch --n N`` plans ``random_scenarios(seed, N)``, whose scenes depend
on N: the two see different scenes drawn from the same distribution. The
outcomes of a scene agree across chunk sizes to rounding only (a vmapped
program rounds by its batch shape, see :func:`~softplan_jax.plan_batch`), and
the fallback's searches are seeded per chunk; ``chunk`` is part of a sweep's
identity.

**The loop.** Chunk ``c`` holds scenes ``[c C, (c + 1) C)`` (C = ``chunk``, the last
chunk padded to C with copies of its last scene, so every call has one shape and
the planner compiles once): one :func:`~softplan_jax.planning.planner.plan_batch`
call (lanes refilled as scenes finish, so the cost follows the steps taken), then,
with ``fallback``, :func:`~softplan_jax.search.fallback.rescue` (reachability and
the certified search of :func:`~softplan_jax.plan_fallback`) on the chunk's scenes
the local planner left stalled or at max_steps. While chunk c runs, chunk c + 1's
scenes are generated on the host. Each chunk's summary rows (and trajectories,
when asked) are written to disk (:mod:`.store`) and dropped: the process holds at
most two chunks, whatever ``n``.

**Several processes.** Under ``jax.distributed`` every process runs the same call;
process ``i`` of ``P`` plans the chunks ``c % P == i`` into the shared folder, and
process 0 merges (:mod:`.processes`). The table does not depend on ``P``.

**Resuming.** A chunk is done when its table exists (written last, atomically). A
sweep run again into the same folder with the same arguments skips the done
chunks; the chunks are independent (their scenes, keys and fallback seeds depend
on their index only), so the merged table is the one an uninterrupted run writes.
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

from ..base.compilation_cache import package_jit
from ..base.status import STATUS_NAMES
from ..planning.batching import batch_mesh, pad_batch, round_chunk
from ..planning.planner import check_gains, make_options, plan_batch
from ..planning.presets import PRESETS, apply_preset
from ..planning.step import GainFunction, Gains
from ..scenarios import random_scenarios
from ..search.fallback import rescue_batch
from ..search.reach import ReachOptions, check_reach_options
from . import processes, report, store

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
    """Scenes of a sweep by index, generated block by block (:data:`SCENE_BLOCK` scenes)."""

    def __init__(self, seed, obstacles, slots, dtype):
        self.seed, self.args = seed, (tuple(int(v) for v in obstacles), int(slots), str(jnp.dtype(dtype)))

    def _get(self, b):
        return _block(self.seed, b, *self.args)

    def take(self, start, stop):
        parts = []
        for b in range(start // SCENE_BLOCK, (stop - 1) // SCENE_BLOCK + 1):
            lo, hi = max(start, b * SCENE_BLOCK) - b * SCENE_BLOCK, min(stop, (b + 1) * SCENE_BLOCK) - b * SCENE_BLOCK
            parts.append(jax.tree_util.tree_map(lambda x, lo=lo, hi=hi: x[lo:hi], self._get(b)))
        return parts[0] if len(parts) == 1 else jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)


def sweep_scenarios(seed: int, start: int, stop: int, *, obstacles=(1, 8), slots: int = 8, dtype=None):
    """Scenes ``start .. stop - 1`` of the sweep suite (module docstring), as one batched Scenario.

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
        from ..planning.presets import preset

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

    The scenes, the loop, the files and resuming: module docstring and :mod:`.store`.
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
        its own local devices into ``out``, a folder every process sees (:mod:`.processes`);
        every process returns the summary.
      trajectories: None (no paths kept), "all", or an int K: the paths of scenes 0 .. K-1 (a
        uniform sample: the scenes are independent draws), to ``trajectories/*.npz``
        (:func:`~softplan_jax.sweeps.store.load_trajectory`).
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
    for name, v in (("fallback", fallback), ("resume", resume), ("overwrite", overwrite)):
        if not isinstance(v, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {v!r}")
    if not (isinstance(progress, (bool, np.bool_)) or callable(progress)):
        raise ValueError(f"progress must be True, False or a callable, got {progress!r}")
    if out is None or not str(out):
        raise ValueError("out: give the sweep folder")
    out = os.path.abspath(os.fspath(out))
    try:
        lo, hi = (int(v) for v in obstacles)
    except (TypeError, ValueError):
        raise ValueError(f"obstacles must be (min, max), got {obstacles!r}") from None
    if not 1 <= lo <= hi <= slots:
        raise ValueError(f"obstacles: need 1 <= min <= max <= slots ({slots}), got {obstacles!r}")
    if {"method", "n_points"} & set(options):
        raise ValueError("pass method and n_points once")
    dt = _check_dtype(dtype)
    if isinstance(devices, str):
        raise ValueError(f"devices must be None or an int (sweep runs on local devices), got {devices!r}")
    mesh = batch_mesh(devices)
    n_dev = 1 if mesh is None else mesh.size
    size = round_chunk(chunk, n, n_dev)
    n_chunks = math.ceil(n / size)
    preset_name, g, extra = _check_gains(gains, dt)
    opts = make_options(method, n_points, **{**extra, **options})
    reach = check_reach_options(ReachOptions() if reach is None else reach) if fallback else None
    keep = _check_trajectories(trajectories, n)
    header = dict(format=store.FORMAT, n=n, seed=seed, chunk=size, scene_block=SCENE_BLOCK, method=opts.method,
                  n_points=opts.n_points, max_steps=max_steps, fallback=bool(fallback), reach=_jsonable(reach),
                  obstacles=[lo, hi], slots=slots, dtype=str(dt), devices=n_dev,
                  trajectories=None if not keep else ("all" if trajectories == "all" else keep),
                  gains=dict(preset=preset_name, values=_jsonable(g)), options=_jsonable(opts),
                  versions=_versions(), created=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    header = json.loads(json.dumps(store.finite_json(header), default=str))
    procs = processes.current()
    _meet_over_folder(procs, out, header, bool(resume), bool(overwrite))

    done = store.completed_chunks(out, clean=False)
    mine = processes.share(range(n_chunks), procs)
    todo = [c for c in mine if c not in done]
    say = report.reporter(progress, n, len(mine), out, len(mine) - len(todo), fallback, procs.prefix("sweep"))
    scenes = _Scenes(seed, (lo, hi), slots, dt)
    run = _Run(out, n, seed, size, max_steps, opts, g, preset_name, reach, keep, devices, scenes)
    try:
        run.loop(todo, say)
    except BaseException as err:  # the others stop waiting for this process's chunks
        procs.post("written", f"{type(err).__name__}: {err}")
        raise
    procs.meet("written")
    if not procs.lead:  # process 0 merges; the others read its summary
        procs.meet("merged")
        with open(os.path.join(out, "summary.json"), encoding="utf-8") as fh:
            return json.load(fh)
    try:
        merged = store.merge_tables(out, n_chunks)
        summary = report.summary(header, merged, out, len(done), procs.count)
        store.write_summary(out, summary)
    except BaseException as err:
        procs.post("merged", f"{type(err).__name__}: {err}")
        raise
    procs.meet("merged")
    return summary


def _meet_over_folder(procs, out, header, resume, overwrite) -> None:
    """Process 0 prepares ``out`` (header, stale temporary files); then every other process
    checks the header against its own arguments (:mod:`.processes`)."""
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


class _Run:
    """The chunk loop of one sweep session."""

    def __init__(self, out, n, seed, size, max_steps, opts, gains, preset_name, reach, keep, devices, scenes):
        self.out, self.n, self.seed, self.size, self.max_steps = out, n, seed, size, max_steps
        self.opts, self.gains, self.preset_name, self.reach, self.keep = opts, gains, preset_name, reach, keep
        self.devices, self.scenes = devices, scenes
        self.local_options = {k: v for k, v in opts._asdict().items() if k not in ("method", "n_points")}
        self.session = f"{os.getpid()}-{time.time_ns()}"
        p = None if preset_name is None else PRESETS[preset_name]
        self.preset_pose = p is not None and (p.start_theta is not None or p.start_phi is not None)
        self.compile_s = None

    def launch(self, c):
        """Generate chunk c's scenes and start its planning (asynchronous)."""
        t0 = time.perf_counter()
        a, b = c * self.size, min(self.n, (c + 1) * self.size)
        scenes, keys = pad_batch((self.scenes.take(a, b), sweep_keys(self.seed, a, b)), self.size)
        if self.preset_name is not None and self.preset_pose:  # the preset's start pose
            scenes = apply_preset(self.preset_name, scenes._replace(q0=jnp.asarray(scenes.q0)))[0]
            scenes = scenes._replace(q0=np.asarray(scenes.q0))
        t1 = time.perf_counter()
        r = plan_batch(scenes, self.opts.method, self.opts.n_points, self.gains, self.max_steps, keys,
                       devices=self.devices, **self.local_options)
        if self.compile_s is None:
            self.compile_s = time.perf_counter() - t1  # the first call returns after tracing and compiling
        return dict(chunk=c, first=a, m=b - a, scenes=scenes, rollout=r, generation_s=t1 - t0)

    def finish(self, p):
        """Collect chunk p's rollouts, run the fallback, and commit its rows (and trajectories)."""
        m, r, first = p["m"], p["rollout"], p["first"]
        get = lambda x: np.asarray(x)[:m]  # noqa: E731
        status, iters, escapes = get(r.status), get(r.iterations), get(r.escapes)
        reached, clear, err = get(r.reached), get(r.min_clearance), get(r.final_error)
        tip = get(r.tip)
        path = np.linalg.norm(np.diff(tip, axis=1), axis=-1).sum(axis=1)  # frozen after the end: no extra length
        rows = [dict(index=first + k, chunk=p["chunk"], status=STATUS_NAMES[int(status[k])], reached=bool(reached[k]),
                     planner="local" if reached[k] else "none", iterations=int(iters[k]), local_iterations=int(iters[k]),
                     escapes=int(escapes[k]), min_clearance=float(clear[k]), path_length=float(path[k]),
                     final_error=float(err[k]), reason="") for k in range(m)]
        kept = {k: None for k in range(min(m, max(0, self.keep - first)))}  # scene k of the chunk: its path
        t_fb = time.perf_counter()
        if self.reach is not None:
            self._fallback(p, rows, kept)
        fallback_s = time.perf_counter() - t_fb if self.reach is not None else 0.0
        if kept:
            q = np.asarray(r.q)
            traj = []
            for k, res in kept.items():
                it = rows[k]["iterations"]
                qk, tk = (q[k, : it + 1], tip[k, : it + 1]) if res is None else (res.q, res.tip)
                traj.append((first + k, qk, tk, rows[k]["status"], rows[k]["planner"]))
            store.write_trajectories(store.chunk_paths(self.out, p["chunk"])["trajectories"], traj)
        return rows, dict(chunk=p["chunk"], first=first, scenes=m, session=self.session,
                          generation_s=p["generation_s"], fallback_s=fallback_s, local_steps=int(iters.sum()))

    def _fallback(self, p, rows, kept):
        """rescue() on the chunk's scenes the local planner left stalled or at max_steps."""
        # A seed per chunk (its index only): a resumed chunk searches as the first run did.
        chunk_seed = int(np.random.SeedSequence(self.seed, spawn_key=(1, p["chunk"])).generate_state(1)[0] >> 1)
        head = lambda tree: jax.tree_util.tree_map(lambda x: x[: p["m"]], tree)  # noqa: E731  (not the padding)
        idx, results = rescue_batch(head(p["scenes"]), head(p["rollout"]), self.opts, reach=self.reach,
                                    seed=chunk_seed)
        for k, res in zip(idx, results, strict=True):
            k = int(k)
            rows[k].update(status=res.status, reached=bool(res.reached), iterations=int(res.iterations),
                           min_clearance=float(res.min_clearance), final_error=float(res.final_error),
                           path_length=float(np.linalg.norm(np.diff(res.tip, axis=0), axis=-1).sum()),
                           planner=("global" if res.planner == "global" else "local") if res.reached else "none",
                           reason=res.reason)
            if k in kept:
                kept[k] = res

    def loop(self, todo, say):
        """Launch chunk c + 1 before finishing chunk c: the host generates while the device plans."""
        t_start = last = time.perf_counter()
        pending = None
        for c in [*todo, None]:
            launched = self.launch(c) if c is not None else None
            if pending is not None:
                rows, timing = self.finish(pending)
                now = time.perf_counter()
                first_of_session = timing["chunk"] == todo[0]
                compile_s = self.compile_s if first_of_session else 0.0
                timing.update(seconds=now - last - compile_s, compile_s=compile_s)
                store.write_chunk(self.out, pending["chunk"], rows, timing)
                last = now
                say(rows, timing, now - t_start, self.compile_s or 0.0)
            pending = launched
