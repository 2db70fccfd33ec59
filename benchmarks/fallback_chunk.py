"""The warm start's fallback chunk on a CPU: what the bound on the fallback loop's trips buys.

Under ``vmap`` the pairs whose certificate failed are solved ``chunk`` at a time,
``chunk = max(8, ceil(pairs / trips))`` (:mod:`softplan_jax.geometry.warm_start`,
"Fallback cost"). On an accelerator every trip through that loop is a serial round of
small kernels, so ``trips`` is small (``FALLBACK_TRIPS``, 64); on a CPU a trip costs
little beyond its pairs' solves, and a wide chunk mostly solves slots that nothing
failed in. This script times the bound a CPU program is traced with
(``CPU_FALLBACK_TRIPS``) at 64 (the accelerators' value), 192 (the CPU default) and
without a bound (a chunk of 8 at every width), interleaved in one process (rounds
alternate the variants; min and median; compile apart), on the batches of
``benchmarks/engine.py``:

* ``plan_batch(random_scenarios(1, --batch), max_steps=600)`` at 64 lanes (the CPU
  default) and 256;
* ``track_batch(random_moving_scenarios(1, --track-batch), max_steps=600)`` (every
  scene in its own lane).

The arrays of every variant are compared bit for bit with the first: the bound sets
how many pairs are solved side by side, not which.

    python benchmarks/fallback_chunk.py            # ~8 min on 2 CPUs
    python benchmarks/fallback_chunk.py --quick    # small batches, one round, into results/quick/

Writes ``benchmarks/results/fallback_chunk.{md,json}``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import jax
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import (  # noqa: E402
    finish_machine,
    lanes_program,
    log,
    machine_info,
    machine_lines,
    output_paths,
    write_results,
)

UNBOUNDED = 10**9  # trips: no bound, a chunk of FALLBACK_CHUNK (8) at every width


def _compiled(world, opts, lanes, trips):
    """run_lanes of ``world`` with the trip bound ``trips`` (:func:`_common.lanes_program`):
    (call, compile seconds)."""
    import softplan_jax as sp
    from softplan_jax.planning.programs import batch_keys, strong_gains

    dtype = jax.tree_util.tree_leaves(world)[0].dtype
    gains = strong_gains(sp.default_gains(), dtype)
    keys = batch_keys(0, jax.tree_util.tree_leaves(world)[0].shape[0])
    c, seconds = lanes_program(opts, 600, lanes, trips)(world, gains, keys=keys)
    return (lambda: jax.block_until_ready(c(world, gains, keys=keys))), seconds


def _same(a, b) -> bool:
    return all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
               for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--track-batch", type=int, default=256)
    ap.add_argument("--trips", default=f"64,192,{UNBOUNDED}", help="comma list of trip bounds (first: reference)")
    ap.add_argument("--quick", action="store_true", help="small batches, one round (a smoke run)")
    ap.add_argument("--out", default=None, help="output prefix (default results/fallback_chunk)")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    if min(args.rounds, args.batch, args.track_batch) < 1:
        ap.error("--rounds, --batch and --track-batch must be >= 1")
    try:
        trips = [int(t) for t in args.trips.split(",")]
    except ValueError:
        ap.error(f"--trips must be a comma list of ints, got {args.trips!r}")
    if not trips or min(trips) < 1:
        ap.error("--trips must list ints >= 1")
    if args.quick:
        args.rounds, args.batch, args.track_batch = 1, 64, 16
    if jax.default_backend() != "cpu":
        ap.error("this benchmark measures the CPU bound; run it where jax's backend is the CPU")
    prefix, _ = output_paths("fallback_chunk", args.quick, args.out)
    machine = machine_info("float64")
    t_start = time.perf_counter()

    import softplan_jax as sp
    from softplan_jax.geometry import warm_start as ws
    from softplan_jax.planning.planner import make_options
    from softplan_jax.planning.tracking import make_track_options

    scenes = sp.random_scenarios(1, args.batch)
    movings = sp.moving.random_moving_scenarios(1, args.track_batch)
    cases = {
        "plan_batch, 64 lanes": (scenes, make_options("curve", 10), 64),
        "plan_batch, 256 lanes": (scenes, make_options("curve", 10), 256),
        "track_batch": (movings, make_track_options("curve", 10), args.track_batch),
    }
    label = {t: ("no bound (chunk 8)" if t >= UNBOUNDED else f"trips {t}") for t in trips}
    calls, outs, rows = {}, {}, []
    for case, (world, opts, lanes) in cases.items():
        batch = jax.tree_util.tree_leaves(world)[0].shape[0]
        scene = world.scene if hasattr(world, "motion") else world
        for t in trips:
            calls[(case, t)], compile_s = _compiled(world, opts, lanes, t)
            outs[(case, t)] = calls[(case, t)]()  # the first run, untimed
            chunk = ws.fallback_chunk(min(lanes, batch) * scene.curve_mask.shape[-1] * scene.q0.shape[-2], t)
            rows.append(dict(case=case, trips=t, variant=label[t], chunk=chunk, compile_s=compile_s, runs=[],
                             identical=_same(outs[(case, t)], outs[(case, trips[0])])))
            log(f"{case} [{label[t]}]: chunk {chunk}, compile {compile_s:.1f} s, "
                f"arrays identical to {label[trips[0]]}: {rows[-1]['identical']}")
    by = {(r["case"], r["trips"]): r for r in rows}
    for r in range(args.rounds):
        order = trips if r % 2 == 0 else trips[::-1]
        for case in cases:
            for t in order:
                t0 = time.perf_counter()
                calls[(case, t)]()
                by[(case, t)]["runs"].append(time.perf_counter() - t0)
        log(f"round {r + 1} of {args.rounds} done")
    for row in rows:
        row["min_s"], row["median_s"] = min(row["runs"]), statistics.median(row["runs"])
    for row in rows:
        ref = by[(row["case"], trips[0])]
        row["speed_vs_first_min"] = ref["min_s"] / row["min_s"]
        row["speed_vs_first_median"] = ref["median_s"] / row["median_s"]

    machine = finish_machine(machine)
    report = dict(machine=machine, args=vars(args), cpu_default=ws.CPU_FALLBACK_TRIPS, rows=rows,
                  seconds=time.perf_counter() - t_start)
    md = ["# The fallback loop's trip bound on a CPU", ""] + machine_lines(machine) + [
        f"- command: `python benchmarks/fallback_chunk.py{' --quick' if args.quick else ''}`; "
        f"{report['seconds']:.0f} s; {args.rounds} interleaved round(s)",
        f"- batches: `random_scenarios(1, {args.batch})` and `random_moving_scenarios(1, {args.track_batch})`, "
        "max_steps 600; the package's default is the CPU bound "
        f"`CPU_FALLBACK_TRIPS` = {ws.CPU_FALLBACK_TRIPS}; accelerators use `FALLBACK_TRIPS` = {ws.FALLBACK_TRIPS}",
        "",
        f"| case | bound | chunk | min | median | speed vs {label[trips[0]]} (min / median) | compile | "
        "arrays identical |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        md.append(f"| {row['case']} | {row['variant']} | {row['chunk']} | {row['min_s']:.3f} s | "
                  f"{row['median_s']:.3f} s | {row['speed_vs_first_min']:.3f}x / {row['speed_vs_first_median']:.3f}x | "
                  f"{row['compile_s']:.1f} s | {'yes' if row['identical'] else 'NO'} |")
    write_results(prefix, report, "\n".join(md) + "\n")
    log(f"wrote {prefix}.md")
    print("\n".join(md))


if __name__ == "__main__":
    main()
