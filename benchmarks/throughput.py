"""Batched throughput against batch size, on 1 and on 2 host devices (or on an accelerator).

For each batch size B (``--sizes``, default 1, 4, 16, 64, 256, 1024, 4096) the
checked rollout that :func:`softplan_jax.plan_batch` runs (collision checks in
the loop, the safe step, escapes) of ``random_scenarios(0, B)`` with at most
``--steps`` steps, the curve method and the 10-point reference, is compiled
ahead (``rollout_batch.lower(...).compile()``, compile time apart) and timed in
``--rounds`` interleaved rounds, results left on the device. The rollout
engine steps ``--lanes`` scenes side by side per device (``B``: the whole
batch at once; default: the engine's 64) and refills a lane when its scene
ends, so the cost follows the steps taken: the table gives taken
scenario-steps per second (the sum over scenes of iterations + 1, divided by
the wall time) and scenes per second. Each device count runs in its own
process (``XLA_FLAGS=--xla_force_host_platform_device_count=K``;
``rollout_batch`` shards the batch over the K devices with ``shard_map``), one
after the other; on a GPU, ``--devices 1`` is the one accelerator.

    python benchmarks/throughput.py           # ~20 min on 2 CPUs
    python benchmarks/throughput.py --quick   # B = 4 and 16, 20 steps, one round, into results/quick/
    # on a GPU: benchmarks/gpu.py (suites drawn ahead on a CPU, a profile, the single plan)

Writes ``benchmarks/results/throughput.{md,json}`` and
``benchmarks/results/figures/throughput.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

METHODS = {"curve": ("curve", 10), "points10": ("points", 10)}


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (B = 4, 16; 20 steps; 1 round) into results/quick/")
    ap.add_argument("--sizes", default=None, help="comma list of batch sizes (default 1,4,16,64,256,1024,4096)")
    ap.add_argument("--devices", default="1,2", help="comma list of host device counts (default 1,2)")
    ap.add_argument("--steps", type=int, default=None, help="planner steps per rollout (default 100; quick 20)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 2; quick 1)")
    ap.add_argument("--lanes", default="64", help="comma list of lane counts, an int or B (the whole batch side "
                                                   "by side); default 64, the engine's")
    ap.add_argument("--dtype", default="float64", choices=("float64", "float32"))
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/throughput)")
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    for key, full, quick in (("sizes", "1,4,16,64,256,1024,4096", "4,16"), ("steps", 100, 20), ("rounds", 2, 1)):
        if getattr(args, key) is None:
            setattr(args, key, quick if args.quick else full)
    try:
        args.size_list = [int(x) for x in args.sizes.split(",")]
        args.device_list = [int(x) for x in args.devices.split(",")]
    except ValueError:
        ap.error(f"--sizes and --devices: comma lists of integers, got {args.sizes!r}, {args.devices!r}")
    try:
        args.lane_list = [x.strip() if x.strip() == "B" else int(x) for x in args.lanes.split(",")]
    except ValueError:
        ap.error(f"--lanes: a comma list of integers or B, got {args.lanes!r}")
    if not args.lane_list or any(x != "B" and x < 1 for x in args.lane_list):
        ap.error("--lanes: lane counts must be >= 1 (or B)")
    if not args.size_list or any(b < 1 for b in args.size_list):
        ap.error("--sizes: batch sizes must be >= 1")
    if not args.device_list or any(k < 1 for k in args.device_list):
        ap.error("--devices: counts must be >= 1")
    if args.steps < 1 or args.rounds < 1:
        ap.error("--steps and --rounds must be >= 1")
    return args


def worker(args) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from _common import log

    import softplan_jax as sp

    k = len(jax.local_devices())
    dtype = np.dtype(args.dtype)
    g = sp.default_gains(dtype)
    calls = {}
    for method, (name, n_points) in METHODS.items():
        opts = sp.make_options(name, n_points)
        for b in args.size_list:
            suite = sp.random_scenarios(0, b, dtype=dtype)
            for lanes in args.lane_list:
                lanes_b = b if lanes == "B" else lanes
                t0 = time.perf_counter()
                sp.planning.rollout_batch.lower(suite, g, opts, args.steps, devices=k, lanes=lanes_b).compile()
                compile_s = time.perf_counter() - t0
                r = jax.block_until_ready(sp.planning.rollout_batch(suite, g, opts, args.steps, devices=k,
                                                                    lanes=lanes_b))  # compiles nothing
                taken = int(np.sum(np.asarray(r.iterations) + 1))
                calls[(method, b, lanes)] = (suite, opts, lanes_b, compile_s, taken)
                log(f"  [{k} device(s)] {method} B={b} lanes={lanes}: compiled in {compile_s:.1f} s, "
                    f"{taken:,} steps taken")
    times = {key: [] for key in calls}
    for r in range(args.rounds):
        for key, (suite, opts, lanes_b, _, _) in calls.items():
            t0 = time.perf_counter()
            jax.block_until_ready(sp.planning.rollout_batch(suite, g, opts, args.steps, devices=k, lanes=lanes_b).q)
            times[key].append(time.perf_counter() - t0)
        log(f"  [{k} device(s)] round {r + 1}/{args.rounds}")
    rows = []
    for (method, b, lanes), t in times.items():
        _, _, lanes_b, compile_s, taken = calls[(method, b, lanes)]
        rows.append(dict(devices=k, method=method, batch=b, lanes=min(lanes_b, -(-b // k)), dtype=args.dtype,
                         compile_s=compile_s,
                         min_s=min(t), median_s=statistics.median(t), steps_taken=taken,
                         steps_per_s_best=taken / min(t), steps_per_s_median=taken / statistics.median(t),
                         scenes_per_s_median=b / statistics.median(t)))
    return dict(devices=k, device_kind=jax.devices()[0].device_kind, rows=rows,
                loadavg_end=[round(x, 2) for x in os.getloadavg()])


def run_worker(args, k: int) -> dict:
    from _common import host_devices_env

    env = host_devices_env(k)
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", str(k), "--sizes", args.sizes,
           "--steps", str(args.steps), "--rounds", str(args.rounds), "--lanes", args.lanes, "--dtype", args.dtype]
    p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"worker with {k} device(s) failed (exit {p.returncode})")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _lanes_label(row) -> str:
    """"B" where every scene of the device's share steps side by side, else the lane count."""
    return "B" if row["lanes"] * row["devices"] >= row["batch"] else str(row["lanes"])


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for method, color in (("curve", "C0"), ("points10", "C1")):
        for k, style in ((1, "-"), (2, "--"), (4, ":")):
            for lanes in sorted({_lanes_label(r) for r in rows}, key=str):
                rs = sorted((r for r in rows if r["method"] == method and r["devices"] == k
                             and _lanes_label(r) == lanes), key=lambda r: r["batch"])
                if rs:
                    ax.plot([r["batch"] for r in rs], [r["steps_per_s_median"] for r in rs], style, color=color,
                            marker="o" if lanes == "B" else "s",
                            label=f"{'curve' if method == 'curve' else '10 points'}, {k} device(s), lanes {lanes}")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("batch size B (scenarios per call)")
    ax.set_ylabel("taken scenario-steps / s (median)")
    ax.set_title("plan_batch's rollout, float64, random scenes")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    args = parse_args(argv)
    if args.worker is not None:
        res = worker(args)
        print(json.dumps(res))
        return res
    from _common import finish_machine, log, machine_info, machine_lines, output_paths, write_results

    out, fig_dir = output_paths("throughput", args.quick, args.out)
    machine = machine_info(args.dtype)
    t0 = time.perf_counter()
    workers = []
    for k in args.device_list:
        log(f"--- {k} host device(s)")
        workers.append(run_worker(args, k))
    machine = finish_machine(machine)
    rows = [r for w in workers for r in w["rows"]]
    fig = os.path.join(fig_dir, "throughput.png")
    os.makedirs(os.path.dirname(fig), exist_ok=True)
    plot(rows, fig)
    best = {}
    for r in rows:
        key = (r["method"], r["devices"])
        if key not in best or r["steps_per_s_median"] > best[key]["steps_per_s_median"]:
            best[key] = r
    argv = sys.argv[1:] if argv is None else argv
    lines = ["# Batched throughput against batch size", "",
             f"- generated by `python benchmarks/throughput.py{' ' + ' '.join(argv) if argv else ''}` in "
             f"{time.perf_counter() - t0:.0f} s; checked rollouts (what `plan_batch` runs) of at most "
             f"{args.steps} steps of `random_scenarios(0, B)`, {args.dtype}, {args.rounds} interleaved rounds per "
             f"device count; device: {workers[0]['device_kind']}",
             *machine_lines(machine), "",
             "Taken scenario-steps per second (the sum over scenes of iterations + 1, over the wall time; median "
             "over rounds, best in brackets); compile apart.", "",
             "| devices | method | B | lanes per device | compile | per taken scenario-step (median) "
             "| taken scenario-steps / s | scenes / s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['devices']} | {r['method']} | {r['batch']:,} | {r['lanes']:,} | {r['compile_s']:.1f} s "
                     f"| {1e6 / r['steps_per_s_median']:.1f} µs | {r['steps_per_s_median']:,.0f} "
                     f"({r['steps_per_s_best']:,.0f}) | {r['scenes_per_s_median']:,.1f} |")
    lines += ["", "Best batch size per (method, devices):", ""]
    for (method, k), r in sorted(best.items()):
        lines.append(f"- {method}, {k} device(s): B = {r['batch']:,}, lanes {r['lanes']:,}: "
                     f"{r['steps_per_s_median']:,.0f} taken scenario-steps/s")
    lines += ["", f"![throughput](figures/{os.path.basename(fig)})"]
    md = "\n".join(lines) + "\n"
    write_results(out, dict(machine=machine, args={k: v for k, v in vars(args).items()}, rows=rows,
                            workers=workers), md)
    log(f"wrote {out}.md/.json and {fig}")
    print(md)


if __name__ == "__main__":
    main(sys.argv[1:])
