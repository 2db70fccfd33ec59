"""XLA CPU options for the rollout programs (issue 9, item 2), measured in one run.

Each variant compiles the checked rollout (``sp.plan``'s options, 200 steps)
with ``jax.jit(..., compiler_options=...)`` for the tree scene (single) and a
batch of random scenes (``random_scenarios(0, B)``, vmapped). Compile times are
reported apart; run times come from interleaved rounds (every variant once per
round), min and median. Each variant's results are compared with the default
(XLA's own options): q bitwise, statuses.

The variant that the package uses is
``softplan_jax.base.compilation_cache.CPU_COMPILER_OPTIONS``
(:func:`~softplan_jax.base.compilation_cache.rollout_compiler_options`).

    python benchmarks/xla_options.py            # ~4 min on 2 CPUs
    python benchmarks/xla_options.py --method points   # the 10-point model's rollouts
    python benchmarks/xla_options.py --quick    # smoke run into results/quick/

Writes ``benchmarks/results/xla_options.{md,json}`` (``xla_options_points.*`` for
``--method points``). The package uses the fusion-emitter option for curve-method
rollouts only (``compilation_cache.CURVE_CPU_COMPILER_OPTIONS``).
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
from _common import RESULTS_DIR, finish_machine, fmt_s, log, machine_info, machine_lines, write_results  # noqa: E402

import softplan_jax as sp  # noqa: E402
from softplan_jax.planning.planner import make_options, rollout  # noqa: E402

VARIANTS = {
    "XLA defaults": None,
    "no YNN fusions (the package's choice, N-point model)": {"xla_cpu_experimental_ynn_fusion_type": ""},
    "no YNN, no expensive LLVM passes": {"xla_cpu_experimental_ynn_fusion_type": "",
                                         "xla_llvm_disable_expensive_passes": True},
    "no YNN, backend optimisation level 1": {"xla_cpu_experimental_ynn_fusion_type": "",
                                             "xla_backend_optimization_level": 1},
    "no YNN, no fusion emitters (the package's choice, curve method)": {"xla_cpu_experimental_ynn_fusion_type": "",
                                   "xla_cpu_use_fusion_emitters": False},
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="batch 8, 2 rounds, 30 steps")
    ap.add_argument("--batch", type=int, default=None, help="random scenes in the batch (default 64)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 7)")
    ap.add_argument("--method", choices=("curve", "points"), default="curve",
                    help="obstacle model of the rollouts: curve (default) or points (10 per curve)")
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/xla_options[_points])")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    batch = args.batch or (8 if args.quick else 64)
    rounds = args.rounds or (2 if args.quick else 7)
    steps = 30 if args.quick else 200
    if batch < 1 or rounds < 1:
        ap.error("--batch and --rounds must be >= 1")
    stem = "xla_options" + ("_points" if args.method == "points" else "")
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", stem)
    machine = machine_info("float64")
    t_start = time.perf_counter()
    sc = sp.paper_scenario("tree")
    g = sp.default_gains()
    scs = sp.random_scenarios(0, batch)
    key = jax.random.PRNGKey(0)
    keys = jax.random.split(key, batch)
    o = make_options("curve") if args.method == "curve" else make_options("points", 10)  # checked, as sp.plan runs it

    def single(s, g, k):
        return rollout(s, g, o, steps, k)

    def batched(s, g, k):
        return jax.vmap(lambda s_, k_: rollout(s_, g, o, steps, k_))(s, k)

    compiled, rows = {}, {}
    for name, copts in VARIANTS.items():
        kw = {} if copts is None else {"compiler_options": copts}
        t0 = time.perf_counter()
        c1 = jax.jit(single, **kw).lower(sc, g, key).compile()
        t1 = time.perf_counter()
        cb = jax.jit(batched, **kw).lower(scs, g, keys).compile()
        t2 = time.perf_counter()
        compiled[name] = (c1, cb)
        rows[name] = dict(options=copts, compile_single_s=t1 - t0, compile_batch_s=t2 - t1, single=[], batch=[])
        log(f"{name}: compile single {t1 - t0:.1f} s, batch {t2 - t1:.1f} s")
    ref = None
    for name, (c1, cb) in compiled.items():
        r, rb = jax.device_get((c1(sc, g, key), cb(scs, g, keys)))
        if ref is None:
            ref = (r, rb)
        rows[name].update(
            q_identical=bool(np.array_equal(r.q, ref[0].q) and np.array_equal(rb.q, ref[1].q)),
            q_max_difference=float(max(np.max(np.abs(r.q - ref[0].q)), np.max(np.abs(rb.q - ref[1].q)))),
            statuses_equal=int(np.sum(rb.status == ref[1].status)) + int(r.status == ref[0].status),
        )
    for k in range(rounds):
        for name, (c1, cb) in compiled.items():
            t0 = time.perf_counter()
            jax.block_until_ready(c1(sc, g, key))
            t1 = time.perf_counter()
            jax.block_until_ready(cb(scs, g, keys))
            t2 = time.perf_counter()
            rows[name]["single"].append((t1 - t0) / (steps + 1))
            rows[name]["batch"].append((t2 - t1) / (batch * (steps + 1)))
        log(f"round {k + 1}/{rounds}")
    finish_machine(machine)
    base = rows["XLA defaults"]
    lines = [
        "# XLA CPU options of the rollout programs (issue 9, item 2)",
        "",
        f"- generated by `python benchmarks/xla_options.py{' --quick' if args.quick else ''}"
        f"{' --method points' if args.method == 'points' else ''}` in "
        f"{time.perf_counter() - t_start:.0f} s; checked rollouts ({steps} steps), float64, "
        f"{'curve method' if args.method == 'curve' else '10-point model'}; tree scene single "
        f"and a batch of {batch} random scenes (`random_scenarios(0, {batch})`); {rounds} interleaved rounds",
        *machine_lines(machine),
        "- per step: single rollout time / (steps + 1); batched: per scenario-step. min / median over rounds;",
        "  change: median against XLA's defaults. Results compared with the defaults' (q bitwise; statuses of "
        f"the {batch + 1} rollouts).",
        "",
        "| variant | compile single / batch | step, single | change | scenario-step, batch | change "
        "| q bitwise equal | max abs q difference | statuses equal |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in rows.items():
        ms, mb = statistics.median(r["single"]), statistics.median(r["batch"])
        r.update(single_median_s=ms, batch_median_s=mb,
                 single_change=ms / statistics.median(base["single"]) - 1,
                 batch_change=mb / statistics.median(base["batch"]) - 1)
        lines.append(
            f"| {name} | {r['compile_single_s']:.1f} s / {r['compile_batch_s']:.1f} s "
            f"| {fmt_s(min(r['single']))} / {fmt_s(ms)} | {100 * r['single_change']:+.0f} % "
            f"| {fmt_s(min(r['batch']))} / {fmt_s(mb)} | {100 * r['batch_change']:+.0f} % "
            f"| {'yes' if r['q_identical'] else 'no'} | {r['q_max_difference']:.2g} "
            f"| {r['statuses_equal']} / {batch + 1} |"
        )
    lines += [
        "",
        "The options change rounding (XLA fuses and orders the floating-point work differently), not the "
        "method: a different q after many steps is rounding amplified by the planner, as between any two "
        "compilers. Run times are from one run on a shared machine; compare ratios, not absolute figures.",
    ]
    md = "\n".join(lines) + "\n"
    write_results(out, dict(machine=machine, steps=steps, batch=batch, rounds=rounds, variants=rows), md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
