"""Regenerate every benchmark result: the closest-point benchmark and solver sweep,
the NumPy baseline, the paper's tables, the speed targets, the batched sweep, the
paper tables with gain presets (paper_presets), the tuned held-out comparison
(science) and the safe-step sweep (held-out seed 1, float64 and float32), one after the other
(each in its own process, so that each sets jax's precision
and devices itself).

    python benchmarks/run_all.py                 # everything, as in benchmarks/README.md
    python benchmarks/run_all.py --quick         # smoke run, written to benchmarks/results/quick/
    python benchmarks/run_all.py --sweep-n 200   # a smaller sweep (the default is batch_sweep's)

Extra arguments after ``--`` go to batch_sweep.py (e.g. ``-- --float32``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="quick mode of every script (results/quick/)")
    ap.add_argument("--sweep-n", type=int, default=None, help="scenarios in the batched sweep (--n)")
    ap.add_argument(
        "--skip",
        default="",
        help="comma list of scripts to skip: closest, numpy_baseline, paper_tables, speed_targets, batch_sweep, "
        "paper_presets, science, safe_step",
    )
    ap.add_argument("sweep_args", nargs="*", help="further batch_sweep.py arguments (after --)")
    args = ap.parse_args(argv)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    quick = ["--quick"] if args.quick else []
    quick_dir = os.path.join(HERE, "results", "quick")
    runs = [
        ("closest", quick),
        ("numpy_baseline", quick + (["--out", os.path.join(quick_dir, "numpy_baseline")] if args.quick else [])),
        ("paper_tables", quick),
        ("speed_targets", quick),
        ("batch_sweep", quick + (["--n", str(args.sweep_n)] if args.sweep_n else []) + args.sweep_args),
    ]
    runs.append(("paper_presets", quick))
    runs.append(("science", quick))
    if args.quick:
        runs.append(("safe_step", ["--n", "16", "--max-steps", "60", "--chunk", "16",
                                   "--out", os.path.join(quick_dir, "safe_step")]))
    else:
        held_out = ["--seed", "1", "--n", "1000", "--chunk", "64", "--max-steps", "600"]
        runs += [
            ("safe_step", held_out + ["--variants", "default", "--methods", "curve,10,50"]),
            ("safe_step", held_out + ["--variants", "default", "--float32"]),
            ("safe_step", held_out + ["--variants", "plain,safe", "--out",
                                      os.path.join(HERE, "results", "safe_step_float64_seed1_n1000_before")]),
        ]
    times = {}
    for k, (name, extra) in enumerate(runs):
        if name in skip:
            continue
        cmd = [sys.executable, os.path.join(HERE, f"{name}.py"), *extra]
        print(f"$ {' '.join(cmd)}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call(cmd, stdout=subprocess.DEVNULL)
        times[f"{name} ({k})" if name in times else name] = time.perf_counter() - t0
        if rc:
            print(f"{name} failed (exit code {rc})", file=sys.stderr)
            return rc
    for name, t in times.items():
        print(f"{name}: {t:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
