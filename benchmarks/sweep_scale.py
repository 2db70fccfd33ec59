"""Batches at scale: peak memory and run time of ``softplan sweep`` and ``softplan batch`` against the
number of scenes.

Each sweep runs as its own process, ``python -m softplan_jax.cli sweep --n N --out DIR --json
--no-progress`` (the curve method, default settings, float64), into a fresh folder. Its peak
resident memory is the child's own ``ru_maxrss`` (``os.wait4``: that process alone, not the largest
of all children as ``RUSAGE_CHILDREN`` gives); its wall time is measured here (interpreter start,
imports and compilation included); compile time, run time, scenes per second and steps taken per
second (the local planner's steps, not the frozen ones after a scene finished) and the outcome
shares with 95 % Wilson intervals come from the sweep's own summary.

The question: does peak memory stay flat in N? Both commands plan chunk by chunk and hold at
most two chunks, so their peaks should not depend on N (``softplan batch`` also holds its suite,
drawn whole first, about 1 kB a scene, and a few per-scene numbers).

Default: ``sweep`` at N = 2,000, 10,000 and 100,000, and 10,000 with ``--fallback`` (the global
fallback on the scenes the local planner leaves); ``batch`` at N = 1,024 and 8,192 (its defaults:
600 steps, chunks of 512). ``--quick``: sweeps of 200 and 400 scenes at 100 steps and 24 with
``--fallback``, batches of 64 and 256 (a smoke test, not a result). ``--only sweep`` or ``--only
batch`` runs one command's rows. Writes ``results/sweep_scale.{md,json}``.

    python benchmarks/sweep_scale.py                       # about 50 min on 2 CPUs
    python benchmarks/sweep_scale.py --only batch          # the batch rows alone, a few minutes
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

QUICK = dict(sizes="200,400", fallback_sizes="24", batch_sizes="64,256", max_steps=100, chunk=64, batch_chunk=64)
FULL = dict(sizes="2000,10000,100000", fallback_sizes="10000", batch_sizes="1024,8192", max_steps=600, chunk=256,
            batch_chunk=512)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default=None, help=f"comma list of N (default {FULL['sizes']}; quick {QUICK['sizes']})")
    ap.add_argument("--fallback-sizes", default=None,
                    help=f"comma list of N run with --fallback (default {FULL['fallback_sizes']}; quick "
                    f"{QUICK['fallback_sizes']}; '' for none)")
    ap.add_argument("--batch-sizes", default=None,
                    help=f"comma list of N of softplan batch (default {FULL['batch_sizes']}; quick "
                    f"{QUICK['batch_sizes']})")
    ap.add_argument("--only", choices=("sweep", "batch"), default=None, help="one command's rows only")
    ap.add_argument("--max-steps", type=int, default=None, help="planner steps (default 600; quick 100)")
    ap.add_argument("--chunk", type=int, default=None, help="the sweep's scenes per planner call (default 256; quick 64)")
    ap.add_argument("--batch-chunk", type=int, default=None, help="the batch's chunk (default 512; quick 64)")
    ap.add_argument("--seed", type=int, default=0, help="the sweeps' seed (default 0)")
    ap.add_argument("--float32", action="store_true", help="float32 (default float64)")
    ap.add_argument("--work", default=None, help="folder of the sweep folders (default: a temporary one, removed)")
    ap.add_argument("--quick", action="store_true", help="N = 200, 400 and 24 with the fallback, 100 steps")
    ap.add_argument("--out", default=None,
                    help="output prefix (default benchmarks/results/sweep_scale; quick: results/quick/sweep_scale)")
    args = ap.parse_args(argv)
    for key, val in (QUICK if args.quick else FULL).items():
        if getattr(args, key) is None:
            setattr(args, key, val)
    try:
        args.size_list = [int(v) for v in args.sizes.split(",") if v.strip()]
        args.fallback_list = [int(v) for v in args.fallback_sizes.split(",") if v.strip()]
        args.batch_list = [int(v) for v in args.batch_sizes.split(",") if v.strip()]
    except ValueError:
        ap.error("--sizes, --fallback-sizes and --batch-sizes: comma lists of integers")
    if (any(v < 1 for v in args.size_list + args.fallback_list + args.batch_list) or args.max_steps < 1
            or args.chunk < 1 or args.batch_chunk < 1):
        ap.error("sizes, --max-steps, --chunk and --batch-chunk must be >= 1")
    if args.only == "batch":
        args.size_list, args.fallback_list = [], []
    if args.only == "sweep":
        args.batch_list = []
    return args


def child_env() -> dict:
    """This process's environment with the repository first on PYTHONPATH."""
    env = dict(os.environ)
    repo = os.path.dirname(HERE)
    env["PYTHONPATH"] = os.pathsep.join([repo] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def run_sweep(n: int, fallback: bool, folder: str, args) -> dict:
    """One sweep in its own process: its summary, wall time and peak RSS."""
    cmd = [sys.executable, "-m", "softplan_jax.cli", "sweep", "--n", str(n), "--out", folder, "--seed",
           str(args.seed), "--chunk", str(args.chunk), "--max-steps", str(args.max_steps), "--json", "--no-progress"]
    cmd += ["--fallback"] if fallback else []
    cmd += ["--float32"] if args.float32 else []
    return dict(n=n, fallback=fallback, **run_child(cmd))


def run_batch(n: int, args) -> dict:
    """One ``softplan batch`` in its own process: its summary, wall time and peak RSS."""
    cmd = [sys.executable, "-m", "softplan_jax.cli", "batch", "--n", str(n), "--seed", str(args.seed), "--chunk",
           str(args.batch_chunk), "--max-steps", str(args.max_steps), "--json", "--no-progress"]
    cmd += ["--float32"] if args.float32 else []
    return dict(n=n, **run_child(cmd))


def run_child(cmd: list) -> dict:
    """``cmd`` in its own process: ``dict(wall_s, peak_rss_mb, command, summary)`` (its JSON summary)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err, env=child_env(), cwd=os.path.dirname(HERE))
        _, status, usage = os.wait4(p.pid, 0)  # this child's own rusage
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {p.returncode}:\n{stderr[-3000:]}")
    return dict(wall_s=wall, peak_rss_mb=usage.ru_maxrss / 1024.0, command=" ".join(cmd), summary=json.loads(stdout))


def _pct(s, name):
    lo, hi = s[f"{name}_ci95"]
    return f"{100 * s[f'{name}_rate']:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def markdown(report: dict) -> str:
    from _common import fmt_s, machine_lines

    L = ["# Batches at scale: peak memory and run time against N"
         + (" (QUICK MODE: a smoke test, not a result)" if report["quick"] else ""), ""]
    L += machine_lines(report["machine"])
    L += ["- each command in its own process, peak RSS = its ru_maxrss"]
    if report["runs"]:
        L += ["", f"`softplan sweep`, curve method, default gains, {report['max_steps']} steps, chunks of "
              f"{report['chunk']}, seed {report['seed']}:", "",
              "| N | fallback | wall | compile | run | scenes/s | steps taken/s | peak RSS | reached [95 %] | "
              "local | global |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["runs"]:
        s = r["summary"]
        L.append(f"| {r['n']:,} | {'yes' if r['fallback'] else 'no'} | {fmt_s(r['wall_s'])} | {fmt_s(s['compile_s'])} "
                 f"| {fmt_s(s['run_s'])} | {s['scenes_per_s'] or 0:,.1f} | {s['steps_per_s'] or 0:,.0f} "
                 f"| {r['peak_rss_mb']:,.0f} MB | {_pct(s, 'success')} | {_pct(s, 'local')} | "
                 f"{_pct(s, 'global') if r['fallback'] else '-'} |")
    plain = [r for r in report["runs"] if not r["fallback"]]
    if len(plain) >= 2:
        a, b = min(plain, key=lambda r: r["n"]), max(plain, key=lambda r: r["n"])
        slope = (b["peak_rss_mb"] - a["peak_rss_mb"]) * 1024.0 / max(b["n"] - a["n"], 1)
        L += ["", f"Peak memory from N = {a['n']:,} to {b['n']:,}: {a['peak_rss_mb']:,.0f} -> "
              f"{b['peak_rss_mb']:,.0f} MB ({slope:+.2f} kB per scene; `softplan batch` keeps about 250 kB per scene)."]
    L += batch_lines(report)
    L += ["", "Run time excludes compilation; scenes/s = N / run time, steps taken/s = the local planner's steps "
          "/ (run time - fallback time). Commands:", ""]
    L += [f"    {r['command']}" for r in report["runs"] + report["batches"]]
    return "\n".join(L) + "\n"


def batch_lines(report: dict) -> list:
    """The batch rows: peak RSS against N, and its growth."""
    from _common import fmt_s

    runs = report["batches"]
    if not runs:
        return []
    L = ["", f"`softplan batch`, curve method, default gains, {report['max_steps']} steps, chunks of "
         f"{report['batch_chunk']}, seed {report['seed']}:", "",
         "| N | wall | compile | run | scenes/s | steps taken/s | peak RSS | reached [95 %] |",
         "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        s = r["summary"]
        lo, hi = s["success_ci95"]
        L.append(f"| {r['n']:,} | {fmt_s(r['wall_s'])} | {fmt_s(s['compile_time_s'])} | {fmt_s(s['run_time_s'])} "
                 f"| {s['scenes_per_s']:,.1f} | {s['steps_per_s']:,.0f} | {r['peak_rss_mb']:,.0f} MB "
                 f"| {100 * s['success_rate']:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] |")
    if len(runs) >= 2:
        a, b = min(runs, key=lambda r: r["n"]), max(runs, key=lambda r: r["n"])
        L += ["", f"Peak memory of `batch --n {b['n']:,}`: {b['peak_rss_mb'] / a['peak_rss_mb']:.2f}x that of "
              f"`--n {a['n']:,}`."]
    return L


def main(argv=None) -> int:
    args = parse_args(argv)
    from _common import QUICK_DIR, RESULTS_DIR, finish_machine, log, machine_info, write_results

    machine = machine_info("float32" if args.float32 else "float64")
    out = args.out or os.path.join(QUICK_DIR if args.quick else RESULTS_DIR, "sweep_scale")
    work = args.work or tempfile.mkdtemp(prefix="sweep_scale_")
    runs = []
    try:
        for n, fallback in [(n, False) for n in args.size_list] + [(n, True) for n in args.fallback_list]:
            folder = os.path.join(work, f"n{n}{'_fallback' if fallback else ''}")
            if os.path.exists(folder):
                shutil.rmtree(folder)
            log(f"sweep --n {n}{' --fallback' if fallback else ''} ...")
            r = run_sweep(n, fallback, folder, args)
            log(f"  {r['wall_s']:.1f} s, peak RSS {r['peak_rss_mb']:,.0f} MB, "
                f"{r['summary']['scenes_per_s'] or 0:,.1f} scenes/s")
            runs.append(r)
        batches = []
        for n in args.batch_list:
            log(f"batch --n {n} ...")
            batches.append(run_batch(n, args))
            log(f"  {batches[-1]['wall_s']:.1f} s, peak RSS {batches[-1]['peak_rss_mb']:,.0f} MB")
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    report = dict(quick=args.quick, machine=finish_machine(machine), seed=args.seed, chunk=args.chunk,
                  batch_chunk=args.batch_chunk, max_steps=args.max_steps, runs=runs, batches=batches)
    text = markdown(report)
    write_results(out, report, text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
