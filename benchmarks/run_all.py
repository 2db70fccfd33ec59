"""Regenerate every benchmark result: each script of benchmarks/README.md, one after the
other, each in its own process (so that each sets jax's precision and devices itself).

    python benchmarks/run_all.py                       # everything, as in benchmarks/README.md (hours)
    python benchmarks/run_all.py --quick               # every script's --quick, into benchmarks/results/quick/
    python benchmarks/run_all.py --only closest,evasion
    python benchmarks/run_all.py --skip gpu,throughput
    python benchmarks/run_all.py --only ab --with "ab:--base /tmp/previous/softplan_jax"

A script that fails does not stop the others; the exit code is non-zero if any
failed. At the end, the wall time of every script (compile included) is printed
and written to ``results/run_all.md`` (quick: ``results/quick/run_all.md``).
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")

# The held-out runs of safe_step.py whose reports are committed (seed 1, 1,000 scenes, 600 steps).
_HELD_OUT = ["--seed", "1", "--n", "1000", "--chunk", "64", "--max-steps", "600"]

# Every script, in the order run_all runs them (the quick ones first), with its full runs: a list
# of argument lists (one process each). Its quick runs: QUICK's, else `NAME.py --quick`.
SCRIPTS = {
    "closest": [[]],
    "paper_tables": [[], ["--presets"]],
    "speed_targets": [[]],
    "safe_step": [
        _HELD_OUT + ["--variants", "default", "--methods", "curve,10,50"],
        _HELD_OUT + ["--variants", "default", "--float32"],
        _HELD_OUT + ["--variants", "plain,safe", "--out", os.path.join(RESULTS, "safe_step_float64_seed1_n1000_before")],
    ],
    "science": [[]],
    "tuning": [[], ["--tuners"]],
    "reach": [[]],
    "evasion": [[]],
    "timing": [[]],
    "throughput": [[]],
    # this version alone; against another: --with "ab:--base OTHER/softplan_jax" (its docstring)
    "ab": [[]],
    "baselines": [["save", "--fallback"]],
    "sweep_scale": [["--only", "sweep"], ["--only", "batch", "--out", os.path.join(RESULTS, "sweep_scale_batch")]],
    # made for one GPU (its docstring); here the single plan and plan_batch's defaults on this machine
    "gpu": [["--parts", "plan,defaults", "--out", os.path.join(RESULTS, "gpu_this_machine")]],
    # a headless Chromium on the view of the tree (the system's chromium; .ci/run installs it)
    "viewer_latency": [[]],
    # the loaded arm: PCC plans under load and the load-aware planner (about an hour on 2 cores)
    "loaded": [["--seed", "1", "--n", "1000", "--between", "0"]],
}

# Scripts with more than one part: each part's quick run.
QUICK = {"paper_tables": [["--quick"], ["--presets", "--quick"]], "tuning": [["--quick"], ["--tuners", "--quick"]],
         "sweep_scale": [["--quick"]]}


def _names(text: str, ap) -> list:
    names = [s.strip() for s in text.split(",") if s.strip()]
    bad = sorted(set(names) - set(SCRIPTS))
    if bad:
        ap.error(f"unknown script(s) {bad}; the scripts: {', '.join(SCRIPTS)}")
    return names


def plan_runs(args) -> list:
    """[(name, argv), ...]: the processes to run, in order."""
    runs = []
    for name, full in SCRIPTS.items():
        if (args.only and name not in args.only) or name in args.skip:
            continue
        for argv in QUICK.get(name, [["--quick"]]) if args.quick else full:
            runs.append((name, list(argv) + args.extra.get(name, [])))
    return runs


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="every script's --quick, into results/quick/")
    ap.add_argument("--only", default="", help=f"comma list of scripts to run (default all: {', '.join(SCRIPTS)})")
    ap.add_argument("--skip", default="", help="comma list of scripts to skip")
    ap.add_argument("--with", dest="extra_args", action="append", default=[], metavar="NAME:ARGS",
                    help="further arguments for one script's runs, e.g. 'engine:--base /tmp/prev/softplan_jax'")
    ap.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = ap.parse_args(argv)
    args.only, args.skip = set(_names(args.only, ap)), set(_names(args.skip, ap))
    args.extra = {}
    for item in args.extra_args:
        name, sep, rest = item.partition(":")
        if not sep:
            ap.error(f"--with {item!r}: write NAME:ARGS")
        args.extra.setdefault(_names(name, ap)[0], []).extend(shlex.split(rest))
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    runs = plan_runs(args)
    times, failed = [], []
    for name, extra in runs:
        cmd = [sys.executable, os.path.join(HERE, f"{name}.py"), *extra]
        print(f"$ {shlex.join(cmd)}", file=sys.stderr, flush=True)
        if args.dry_run:
            continue
        t0 = time.perf_counter()
        rc = subprocess.call(cmd, stdout=subprocess.DEVNULL)
        times.append((name, extra, time.perf_counter() - t0, rc))
        if rc:
            failed.append(name)
            print(f"{name} failed (exit code {rc})", file=sys.stderr, flush=True)
    if args.dry_run:
        return 0
    lines = [f"# run_all.py{' --quick' if args.quick else ''}: wall time per script (compile included)", "",
             "| script | arguments | wall time | exit code |", "|---|---|---|---|"]
    lines += [f"| {name} | `{shlex.join(extra)}` | {t:.0f} s | {rc} |" for name, extra, t, rc in times]
    lines += ["", f"Total {sum(t for _, _, t, _ in times):.0f} s; failed: {', '.join(failed) or 'none'}."]
    text = "\n".join(lines) + "\n"
    print(text)
    out = os.path.join(RESULTS, "quick" if args.quick else "", "run_all.md")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w", encoding="utf-8") as fh:
        fh.write(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
