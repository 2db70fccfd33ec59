"""What a sweep tells: its progress lines (or the user's callback) and its summary
(counts, rates with 95 % Wilson intervals, throughput) from the merged table."""

from __future__ import annotations

import math
import sys

from . import _store as store

__all__ = ["reporter", "summary"]


def reporter(progress, n, n_chunks, out, already, fallback, name="sweep", resumable=True):
    """The per-chunk progress callback: a line on stderr (starting with ``name``), the user's
    callable, or nothing. ``n_chunks``: this process's chunks, ``already`` of them done before;
    ``resumable``: count the scenes "this run" (a sweep), else out of ``n``."""
    state = dict(chunks=already, scenes=0, local=0, glob=0)
    if progress is True and already:
        print(f"{name}: resuming {out}: {already}/{n_chunks} chunks done", file=sys.stderr, flush=True)

    def say(rows, timing, elapsed, compile_s):
        state["chunks"] += 1
        state["scenes"] += len(rows)
        state["local"] += sum(r["planner"] == "local" for r in rows)
        state["glob"] += sum(r["planner"] == "global" for r in rows)
        left = n_chunks - state["chunks"]
        run = max(elapsed - compile_s, 1e-9)
        rate = state["scenes"] / run
        info = dict(chunk=timing["chunk"], chunks=n_chunks, chunks_done=state["chunks"], scenes_done=state["scenes"],
                    n=n, reached=state["local"] + state["glob"], local=state["local"], **{"global": state["glob"]},
                    elapsed_s=elapsed, compile_s=compile_s, eta_s=left * timing["scenes"] / rate if left else 0.0)
        if callable(progress):
            progress(info)
        elif progress:
            pct = 100.0 * info["reached"] / state["scenes"]
            share = f" (global {100.0 * state['glob'] / state['scenes']:.1f} %)" if fallback else ""
            scenes = f"{state['scenes']:,} scenes this run" if resumable else f"{state['scenes']:,}/{n:,} scenes"
            line = (f"{name}: {state['chunks']}/{n_chunks} chunks, {scenes}, reached "
                    f"{pct:.1f} %{share}, {rate:,.1f} scenes/s, "
                    f"{elapsed:.1f} s" + (f", eta {info['eta_s']:.0f} s" if left else "")
                    + f" (compile {compile_s:.1f} s)")
            print(line, file=sys.stderr, flush=True)

    return say


def _rate(k, n):
    """A rate k / n and its 95 % Wilson interval."""
    lo, hi = store.wilson_interval(k, n)
    return k / n, [lo, hi]


def summary(header, merged, out, resumed, processes=1) -> dict:
    """The summary of :func:`~softplan_jax.sweeps.sweep` from its header and the merged table's aggregates."""
    n = header["n"]
    counts = merged["status_counts"]
    local, glob = merged["planners"]["local"], merged["planners"]["global"]
    reached = local + glob
    s = dict(out=out, n=n, seed=header["seed"], chunk=header["chunk"], chunks=math.ceil(n / header["chunk"]),
             method=header["method"], n_points=header["n_points"] if header["method"] == "points" else None,
             max_steps=header["max_steps"], fallback=header["fallback"], dtype=header["dtype"],
             devices=header["devices"], gains=header["gains"]["preset"] or "custom", resumed_chunks=resumed,
             sessions=merged["sessions"], processes=processes, status_counts=counts, reached=reached, reached_local=local,
             reached_global=glob)
    collided = counts.get("collided", 0) + counts.get("start_in_collision", 0)
    for name, k in (("success", reached), ("local", local), ("global", glob), ("collision", collided)):
        s[f"{name}_rate"], s[f"{name}_ci95"] = _rate(k, n)
    run_s, fb_s = merged["seconds"], merged["fallback_s"]
    s.update(mean_iterations_reached=merged["iterations_reached"] / reached if reached else None,
             mean_path_length_reached=merged["path_length_reached"] / reached if reached else None,
             min_clearance=merged["min_clearance"], steps_taken=merged["local_steps"],
             generation_s=merged["generation_s"], compile_s=merged["compile_s"], run_s=run_s, fallback_s=fb_s,
             scenes_per_s=n / run_s if run_s > 0 else None,
             steps_per_s=merged["local_steps"] / (run_s - fb_s) if run_s - fb_s > 0 else None)
    return s
