"""The chunk loop that :func:`~softplan_jax.sweeps.sweep` and ``softplan batch`` share: scenes
taken from a source a chunk at a time, padded to one shape, planned by
:func:`~softplan_jax.planning._planner.plan_batch` while the next chunk is generated, rescued by
the global fallback where asked, and reduced to one summary row per scene before the next
chunk, so the process holds at most two chunks whatever the number of scenes.
"""

from __future__ import annotations

import os
import time

import jax
import numpy as np

from ..base._status import STATUS_NAMES
from ..planning._batching import pad_batch
from ..planning._planner import plan_batch
from ..search._fallback import rescue_batch

__all__ = ["ChunkLoop", "SuiteSource"]


class SuiteSource:
    """Scenes and escape keys of an in-memory batched suite, by index range.

    Args:
      suite: a batched Scenario (leading axis B).
      keys: (B, 2) raw PRNG keys, one per scene (scene b's escapes).
    """

    def __init__(self, suite, keys):
        self.suite = jax.tree_util.tree_map(np.asarray, suite)
        self.keys = np.asarray(keys)

    def take(self, start: int, stop: int):
        """``(scenes, keys)`` of scenes ``start .. stop - 1`` (host arrays)."""
        return jax.tree_util.tree_map(lambda x: x[start:stop], (self.suite, self.keys))


class ChunkLoop:
    """Plan ``n`` scenes given by ``take`` in chunks of ``size`` scenes (one compiled shape).

    Args:
      take: ``take(start, stop) -> (scenes, keys)``: scenes ``start .. stop - 1`` as a batched
        Scenario of host arrays and their (stop - start, 2) raw escape keys.
      n, size: scenes in all, scenes per chunk (the last chunk is padded with copies of its
        last scene).
      options, gains, max_steps, devices: the local planner's, as
        :func:`~softplan_jax.planning._planner.plan_batch` (``options`` a PlanOptions).
      reach: ReachOptions of the global fallback, or None (no fallback).
      fallback_seed: ``chunk index -> int``: the seed of that chunk's fallback.
      keep: the trajectories of scenes ``0 .. keep - 1`` are kept (0: none).
    """

    def __init__(self, take, n, size, options, gains, max_steps, devices=None, *, reach=None,
                 fallback_seed=None, keep: int = 0):
        self.take, self.n, self.size = take, n, size
        self.options, self.gains, self.max_steps, self.devices = options, gains, max_steps, devices
        self.reach, self.fallback_seed, self.keep = reach, fallback_seed, keep
        self.local_options = {k: v for k, v in options._asdict().items() if k not in ("method", "n_points")}
        self.session = f"{os.getpid()}-{time.time_ns()}"
        self.compile_s = None

    def launch(self, c: int) -> dict:
        """Generate chunk c's scenes and start its planning (asynchronous)."""
        t0 = time.perf_counter()
        a, b = c * self.size, min(self.n, (c + 1) * self.size)
        scenes, keys = pad_batch(self.take(a, b), self.size)
        t1 = time.perf_counter()
        r = plan_batch(scenes, self.options.method, self.options.n_points, self.gains, self.max_steps, keys,
                       devices=self.devices, **self.local_options)
        if self.compile_s is None:
            self.compile_s = time.perf_counter() - t1  # the first call returns after tracing and compiling
        return dict(chunk=c, first=a, m=b - a, scenes=scenes, rollout=r, generation_s=t1 - t0)

    def finish(self, p: dict):
        """Collect chunk p's rollouts and run the fallback on it.

        Returns:
          ``(rows, timing, paths)``: one dict per scene (the sweep table's columns, plus
          ``collided``), the chunk's timing, and the kept trajectories as
          ``(index, q, tip, status, planner)``.
        """
        m, r, first = p["m"], p["rollout"], p["first"]
        get = lambda x: np.asarray(x)[:m]  # noqa: E731
        status, iters, escapes = get(r.status), get(r.iterations), get(r.escapes)
        reached, clear, err, collided = get(r.reached), get(r.min_clearance), get(r.final_error), get(r.collided)
        tip = get(r.tip)
        path = np.linalg.norm(np.diff(tip, axis=1), axis=-1).sum(axis=1)  # frozen after the end: no extra length
        rows = [dict(index=first + k, chunk=p["chunk"], status=STATUS_NAMES[int(status[k])], reached=bool(reached[k]),
                     planner="local" if reached[k] else "none", iterations=int(iters[k]), local_iterations=int(iters[k]),
                     escapes=int(escapes[k]), min_clearance=float(clear[k]), path_length=float(path[k]),
                     final_error=float(err[k]), reason="", collided=bool(collided[k])) for k in range(m)]
        kept = {k: None for k in range(min(m, max(0, self.keep - first)))}  # scene k of the chunk: its path
        t_fb = time.perf_counter()
        if self.reach is not None:
            self._fallback(p, rows, kept)
        fallback_s = time.perf_counter() - t_fb if self.reach is not None else 0.0
        paths = []
        if kept:
            q = np.asarray(r.q)
            for k, res in kept.items():
                it = rows[k]["iterations"]
                qk, tk = (q[k, : it + 1], tip[k, : it + 1]) if res is None else (res.q, res.tip)
                paths.append((first + k, qk, tk, rows[k]["status"], rows[k]["planner"]))
        timing = dict(chunk=p["chunk"], first=first, scenes=m, session=self.session, generation_s=p["generation_s"],
                      fallback_s=fallback_s, local_steps=int(iters.sum()))
        return rows, timing, paths

    def _fallback(self, p, rows, kept):
        """rescue_batch() on the chunk's scenes the local planner left stalled or at max_steps."""
        head = lambda tree: jax.tree_util.tree_map(lambda x: x[: p["m"]], tree)  # noqa: E731  (not the padding)
        idx, results = rescue_batch(head(p["scenes"]), head(p["rollout"]), self.options, reach=self.reach,
                                    seed=self.fallback_seed(p["chunk"]))
        for k, res in zip(idx, results, strict=True):
            k = int(k)
            rows[k].update(status=res.status, reached=bool(res.reached), iterations=int(res.iterations),
                           min_clearance=float(res.min_clearance), final_error=float(res.final_error),
                           path_length=float(np.linalg.norm(np.diff(res.tip, axis=0), axis=-1).sum()),
                           planner=("global" if res.planner == "global" else "local") if res.reached else "none",
                           reason=res.reason)
            if k in kept:
                kept[k] = res

    def run(self, todo, commit) -> None:
        """Plan the chunks ``todo``, launching chunk c + 1 before finishing chunk c (the host
        generates while the device plans); ``commit(rows, timing, paths, elapsed_s)`` after
        each chunk, its timing with ``seconds`` (wall, compile excluded) and ``compile_s``."""
        t_start = last = time.perf_counter()
        pending = None
        for c in [*todo, None]:
            launched = self.launch(c) if c is not None else None
            if pending is not None:
                rows, timing, paths = self.finish(pending)
                now = time.perf_counter()
                compile_s = self.compile_s if timing["chunk"] == todo[0] else 0.0
                timing.update(seconds=now - last - compile_s, compile_s=compile_s)
                commit(rows, timing, paths, now - t_start)
                last = now
            pending = launched
