"""Scenario-steps per second of :func:`softplan_jax.plan_batch` on 1 and on 2
(or more) host devices, each device count in its own subprocess.

    python benchmarks/devices.py                     # 10,000 scenarios, 200 steps, 1 and 2 devices
    python benchmarks/devices.py --quick             # 64 scenarios, 40 steps (a smoke test)
    python benchmarks/devices.py --devices 1,2,4 --n 2000

Each worker (``--worker K``, started with
``XLA_FLAGS=--xla_force_host_platform_device_count=K``; the device count is fixed
when jax starts) plans the same seeded suite (``random_scenarios(seed, n)``: 1-8
curves of degree 1-2, padded to 8 slots) with the library's defaults — the curve
method, the safe step, escapes, collision checks in the scan — via
``plan_batch(..., chunk=C, progress=True)``, sharded over its K devices:

* **compile** apart: ``rollout_batch.lower(<one chunk>, devices=K).compile()``
  before the timed run (the timed run then compiles nothing);
* **run**: wall time of the whole chunked ``plan_batch`` call, results copied to
  the host; scenario-steps per second = n x (max_steps + 1) / run (every scan
  step is computed for every scenario, finished or not: a finished rollout is
  frozen but its step still runs under vmap);
* the Rollout's size in host memory, and the worker's peak resident memory;
* per-scenario status and iterations, compared between device counts: sharded
  and unsharded programs agree to rounding, not bit for bit, and a rollout that
  amplifies rounding can end differently.

The load average is recorded around every worker: other jobs share this
machine's cores, and K host devices only run in parallel on K free cores.
Writes ``benchmarks/results/devices.{md,json}`` (quick: ``results/quick/``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=None, help="scenarios (default 10000; quick 64)")
    ap.add_argument("--max-steps", type=int, default=None, help="planner steps per rollout (default 200; quick 40)")
    ap.add_argument("--chunk", type=int, default=None, help="scenarios per call (default 512; quick 32)")
    ap.add_argument("--devices", default="1,2", help="comma list of host device counts (default 1,2)")
    ap.add_argument("--seed", type=int, default=0, help="seed of random_scenarios (default 0)")
    ap.add_argument("--quick", action="store_true", help="64 scenarios, 40 steps, chunks of 32")
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/devices)")
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--dump", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    quick = dict(n=64, max_steps=40, chunk=32)
    full = dict(n=10000, max_steps=200, chunk=512)
    for key in quick:
        if getattr(args, key) is None:
            setattr(args, key, (quick if args.quick else full)[key])
    if args.n < 1 or args.max_steps < 1 or args.chunk < 1:
        ap.error("--n, --max-steps and --chunk must be >= 1")
    try:
        args.device_list = [int(k) for k in args.devices.split(",")]
    except ValueError:
        ap.error(f"--devices: a comma list of integers, got {args.devices!r}")
    if any(k < 1 for k in args.device_list):
        ap.error("--devices: counts must be >= 1")
    return args


def _loadavg():
    return [round(x, 2) for x in os.getloadavg()]


def worker(args) -> dict:
    """Plan the suite on this process's devices; returns the measurements (and writes
    statuses and iterations to ``args.dump``)."""
    import resource

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import softplan_jax as sp
    from softplan_jax.planning.batching import round_chunk

    devices = jax.local_devices()
    assert len(devices) == args.worker, (devices, args.worker)
    load_start = _loadavg()
    t0 = time.perf_counter()
    suite = sp.random_scenarios(args.seed, args.n)
    gen_s = time.perf_counter() - t0
    gains = sp.default_gains()
    opts = sp.make_options("curve")
    T = int(args.max_steps)
    size = round_chunk(args.chunk, args.n, len(devices))
    first = jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x)[:size]), suite)
    if size > args.n:  # a suite smaller than one chunk: pad it the way plan_batch does
        from softplan_jax.planning.batching import pad_batch

        first = pad_batch(first, size)
    t0 = time.perf_counter()
    sp.planning.rollout_batch.lower(first, gains, opts, T).compile()
    compile_s = time.perf_counter() - t0
    compiles = sp.planning.rollout_batch.cache_size()
    t0 = time.perf_counter()
    r = sp.plan_batch(suite, gains=gains, max_steps=T, chunk=args.chunk, progress=True)
    r = jax.tree_util.tree_map(np.asarray, r)
    run_s = time.perf_counter() - t0
    scan_steps = T + 1
    if args.dump:
        np.savez_compressed(args.dump, status=r.status, iterations=r.iterations, final_error=r.final_error,
                            min_clearance=r.min_clearance)
    status = np.asarray(r.status)
    return dict(
        devices=len(devices),
        device_names=[str(d) for d in devices],
        n=args.n,
        max_steps=T,
        scan_steps=scan_steps,
        chunk=size,
        chunks=-(-args.n // size),
        generation_s=gen_s,
        compile_s=compile_s,
        recompiled_in_run=sp.planning.rollout_batch.cache_size() - compiles,
        run_s=run_s,
        scenario_steps_per_s=args.n * scan_steps / run_s,
        rollout_bytes=int(sum(x.nbytes for x in jax.tree_util.tree_leaves(r))),
        peak_rss_bytes=int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024,
        status_counts={sp.planning.status_name(int(k)): int((status == k).sum()) for k in np.unique(status)},
        loadavg_start=load_start,
        loadavg_end=_loadavg(),
        xla_flags=os.environ.get("XLA_FLAGS", ""),
        jax=jax.__version__,
    )


def run_worker(args, k: int, dump: str) -> dict:
    from _common import host_devices_env

    env = host_devices_env(k)
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", str(k), "--n", str(args.n), "--max-steps",
           str(args.max_steps), "--chunk", str(args.chunk), "--seed", str(args.seed), "--dump", dump]
    p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"worker with {k} device(s) failed (exit {p.returncode})")
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.worker is not None:
        res = worker(args)
        print(json.dumps(res))
        return res

    import platform

    from _common import RESULTS_DIR, log, write_results

    base = os.path.join(RESULTS_DIR, "quick") if args.quick else RESULTS_DIR
    out = args.out or os.path.join(base, "devices")
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    t_start = time.perf_counter()
    rows, dumps = [], {}
    for k in args.device_list:
        log(f"--- {k} host device(s): {args.n} scenarios x {args.max_steps} steps, chunks of {args.chunk}")
        dump = f"{out}.{k}dev.npz"
        rows.append(run_worker(args, k, dump))
        dumps[k] = dict(np.load(dump))
        os.remove(dump)
        r = rows[-1]
        log(f"{k} device(s): compile {r['compile_s']:.1f} s, run {r['run_s']:.1f} s, "
            f"{r['scenario_steps_per_s']:,.0f} scenario-steps/s, load {r['loadavg_start']} -> {r['loadavg_end']}")
    base_k = args.device_list[0]
    for r in rows:
        a, b = dumps[base_k], dumps[r["devices"]]
        r["vs_first"] = dict(
            devices=base_k,
            same_status=int((a["status"] == b["status"]).sum()),
            same_iterations=int(((a["status"] == b["status"]) & (a["iterations"] == b["iterations"])).sum()),
            max_final_error_diff_same_outcome=float(
                np.max(np.abs(a["final_error"] - b["final_error"])[
                    (a["status"] == b["status"]) & (a["iterations"] == b["iterations"])], initial=0.0)
            ),
            speedup=r["scenario_steps_per_s"] / rows[0]["scenario_steps_per_s"],
        )
    report = dict(
        quick=args.quick, n=args.n, max_steps=args.max_steps, chunk=args.chunk, seed=args.seed, rows=rows,
        cpu_count=os.cpu_count(), platform=platform.platform(),
        command="python benchmarks/devices.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        wall_time_s=time.perf_counter() - t_start,
    )
    text = markdown(report)
    write_results(out, report, text)
    log(f"wrote {out}.md and .json")
    print(text)
    return report


def markdown(report) -> str:
    rows = report["rows"]
    lines = [
        "# plan_batch on 1 and on several host devices",
        "",
        f"- generated by `{report['command'].strip()}` in {report['wall_time_s']:.0f} s"
        + (" (QUICK MODE: a smoke test, not a result)" if report["quick"] else ""),
        f"- machine: {report['platform']}, {report['cpu_count']} CPUs, shared with other jobs (load averages "
        "below: 1, 5, 15 min); jax " + rows[0]["jax"],
        f"- suite: `random_scenarios(seed={report['seed']}, n={report['n']})` (1-8 curves, 8 slots); "
        f"`plan_batch` with the defaults (curve method, safe step, escapes, collision checks in the scan), "
        f"max_steps {report['max_steps']} ({report['max_steps'] + 1} scan steps), float64, chunks of "
        f"{rows[0]['chunk']} (rounded to the device count), progress on",
        "- each device count in its own process (`XLA_FLAGS=--xla_force_host_platform_device_count=K`); "
        "compile apart (`rollout_batch.lower(...).compile()` on one chunk); *run* = wall time of the whole "
        "chunked call, results on the host; scenario-steps/s = scenarios x scan steps / run (finished "
        "rollouts still run their frozen steps)",
        "",
        "| host devices | compile | run | scenario-steps/s | speed-up | Rollout in memory | peak RSS "
        "| load avg start -> end | same status / iterations as " + f"{rows[0]['devices']} device(s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        v = r["vs_first"]
        lines.append(
            f"| {r['devices']} | {r['compile_s']:.1f} s | {r['run_s']:.1f} s | {r['scenario_steps_per_s']:,.0f} "
            f"| {v['speedup']:.2f}x | {r['rollout_bytes'] / 1e9:.2f} GB | {r['peak_rss_bytes'] / 1e9:.2f} GB "
            f"| {r['loadavg_start']} -> {r['loadavg_end']} | {v['same_status']:,} / {v['same_iterations']:,} "
            f"of {r['n']:,} |"
        )
    lines += [
        "",
        "Statuses: " + "; ".join(f"{r['devices']} device(s): {r['status_counts']}" for r in rows) + ".",
        "",
        "Sharded and unsharded programs agree to rounding, not bit for bit (XLA optimises a partitioned "
        "program differently); a rollout that amplifies rounding (a near-tie of the stall or contact test, "
        "an escape) can then end differently. *same status / iterations* counts the scenarios whose status, "
        "and status and iteration count, match the first device count's.",
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
