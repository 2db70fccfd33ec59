"""How fast ``random_scenarios`` draws a suite, and what that costs a sweep, against another
version of the package (``--against``: its ``softplan_jax`` folder, e.g. from a checkout of
commit 1313f8a, where every scene went through ``make_scenario`` one at a time).

For each size of ``--sizes``, ``random_scenarios(r, B)`` of each version in interleaved
rounds (min and median), and whether the two give the same arrays bit for bit; then, unless
``--no-sweep``, ``softplan_jax.sweeps.sweep`` of ``--sweep-n`` scenes (600 steps, no
fallback) of each version, warm (a first sweep of 256 scenes compiles), interleaved.

    git worktree add /tmp/old 1313f8a
    python benchmarks/suite_speed.py --against /tmp/old/softplan_jax   # ~5 min on 2 CPUs
    python benchmarks/suite_speed.py --quick                           # this version alone, B = 64

Writes ``benchmarks/results/suite_speed.{md,json}``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", default=None, help="another version's softplan_jax folder (default: none)")
    ap.add_argument("--quick", action="store_true", help="B = 64, one round, no sweep, into results/quick/")
    ap.add_argument("--sizes", default=None, help="comma list of suite sizes (default 64,1024)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 4)")
    ap.add_argument("--sweep-n", type=int, default=2048, help="scenes of the timed sweep (default 2048)")
    ap.add_argument("--no-sweep", action="store_true", help="time the suites only")
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/suite_speed)")
    args = ap.parse_args(argv)
    args.sizes = args.sizes or ("64" if args.quick else "64,1024")
    args.rounds = args.rounds if args.rounds is not None else (1 if args.quick else 4)
    try:
        args.size_list = [int(x) for x in args.sizes.split(",")]
    except ValueError:
        ap.error(f"--sizes: a comma list of integers, got {args.sizes!r}")
    if not args.size_list or min(args.size_list) < 1 or args.rounds < 1 or args.sweep_n < 1:
        ap.error("--sizes, --rounds and --sweep-n must be >= 1")
    if args.against and not os.path.exists(os.path.join(args.against, "__init__.py")):
        ap.error(f"--against: {args.against} is not a softplan_jax package folder")
    args.sweep = not (args.no_sweep or args.quick)
    return args


def main(argv=None):
    args = parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from _common import finish_machine, load_variant, log, machine_info, machine_lines, output_paths, write_results

    import softplan_jax as this

    out, _ = output_paths("suite_speed", args.quick, args.out)
    machine = machine_info("float64")
    versions = {"this": this}
    if args.against:
        versions = {"against": load_variant("against", args.against), "this": this}
    rows = []
    for b in args.size_list:
        t = {k: [] for k in versions}
        names = list(versions)
        for r in range(args.rounds):
            for name in names if r % 2 == 0 else names[::-1]:
                t0 = time.perf_counter()
                jax.block_until_ready(jax.tree_util.tree_leaves(versions[name].random_scenarios(r, b)))
                t[name].append(time.perf_counter() - t0)
        leaves = [jax.tree_util.tree_leaves(m.random_scenarios(11, b)) for m in versions.values()]
        same = all(np.array_equal(np.asarray(x), np.asarray(y)) and x.dtype == y.dtype
                   for x, y in zip(leaves[0], leaves[-1], strict=True))
        row = dict(what=f"random_scenarios(r, {b})", bit_identical=same,
                   **{f"{k}_min_s": min(v) for k, v in t.items()},
                   **{f"{k}_median_s": statistics.median(v) for k, v in t.items()})
        rows.append(row)
        log(f"{row}")
    if args.sweep:
        t = {k: [] for k in versions}
        reached = {}
        with tempfile.TemporaryDirectory() as tmp:
            for name, m in versions.items():  # compile
                m.sweeps.sweep(256, os.path.join(tmp, f"warm_{name}"), seed=5, progress=False)
            names = list(versions)
            for r in range(2):
                for name in names if r % 2 == 0 else names[::-1]:
                    folder = os.path.join(tmp, name)
                    shutil.rmtree(folder, ignore_errors=True)
                    t0 = time.perf_counter()
                    s = versions[name].sweeps.sweep(args.sweep_n, folder, seed=1, progress=False)
                    t[name].append(time.perf_counter() - t0)
                    reached[name] = s["reached"]
                    log(f"sweep {name}: {t[name][-1]:.1f} s, reached {s['reached']}")
        rows.append(dict(what=f"sweep({args.sweep_n})", bit_identical=len(set(reached.values())) == 1,
                         **{f"{k}_min_s": min(v) for k, v in t.items()},
                         **{f"{k}_median_s": statistics.median(v) for k, v in t.items()},
                         **{f"{k}_reached": v for k, v in reached.items()}))
    machine = finish_machine(machine)
    lines = ["# random_scenarios and a sweep: this version against another", "",
             f"- generated by `python benchmarks/suite_speed.py {' '.join(argv or sys.argv[1:])}`; "
             f"against: {args.against or '(none)'}", *machine_lines(machine), "",
             "| what | " + " | ".join(f"{k} min / median" for k in versions) + " | ratio (min) | same results |",
             "|---|" + "---|" * len(versions) + "---|---|"]
    for r in rows:
        cells = " | ".join(f"{r[f'{k}_min_s']:.3f} s / {r[f'{k}_median_s']:.3f} s" for k in versions)
        ratio = f"{r['against_min_s'] / r['this_min_s']:.1f}x" if "against" in versions else "-"
        lines.append(f"| {r['what']} | {cells} | {ratio} | {'yes' if r['bit_identical'] else 'NO'} |")
    md = "\n".join(lines) + "\n"
    write_results(out, dict(machine=machine, rows=rows, against=args.against), md)
    print(md)


if __name__ == "__main__":
    main(sys.argv[1:])
