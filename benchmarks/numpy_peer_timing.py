"""Step time of the NumPy/SciPy peer (numpy_baseline.py) on the tree scenario,
optionally against another version of the module, interleaved in one process.

    python benchmarks/numpy_peer_timing.py                       # this version only
    git show c252f9f:benchmarks/numpy_baseline.py > /tmp/nb_old.py
    python benchmarks/numpy_peer_timing.py --old /tmp/nb_old.py  # old vs this, interleaved

The states are every other state of this version's run (default gains,
<= 125 steps); each round times every version's ``numpy_step`` on all of them
(the order of the versions alternates between rounds) and keeps the median
step time; the table gives the min and median of those over the rounds.
Prints Markdown; writes nothing.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def _load(path: str, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv=None) -> list:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default=None, help="path of another numpy_baseline.py to time against")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--methods", default="curve,10", help="comma list: curve and/or point counts N")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy_baseline as new

    versions = {"this": new}
    if args.old:
        versions = {"old": _load(args.old, "numpy_baseline_old"), "this": new}
    sc = new.to_numpy_scenario("tree")
    g = new.numpy_gains()
    rows = []
    for m in args.methods.split(","):
        method, n = ("curve", 10) if m == "curve" else ("points", int(m))
        run = new.numpy_plan(sc, method, n, 125)
        states = run.q[:-1][::2]
        preps = {k: v._prepare(v.to_numpy_scenario("tree"), method, n, "kdtree") for k, v in versions.items()}
        per_round = {k: [] for k in versions}
        for r in range(args.rounds):
            for k in (list(versions) if r % 2 == 0 else list(versions)[::-1]):
                ts = []
                for q in states:
                    t0 = time.perf_counter()
                    versions[k].numpy_step(q, preps[k], g)
                    ts.append(time.perf_counter() - t0)
                per_round[k].append(float(np.median(ts)))
        for k, v in per_round.items():
            rows.append(dict(method=method, n_points=None if method == "curve" else n, version=k, states=len(states),
                             rounds=args.rounds, min_s=min(v), median_s=float(np.median(v))))
    print(f"| method | version | min / step | median / step |  (tree, {rows[0]['states']} states x "
          f"{args.rounds} rounds; load average {os.getloadavg()[0]:.2f})")
    print("|---|---|---|---|")
    for r in rows:
        lab = "curve" if r["method"] == "curve" else f"{r['n_points']} points"
        print(f"| {lab} | {r['version']} | {r['min_s'] * 1e3:.2f} ms | {r['median_s'] * 1e3:.2f} ms |")
    return rows


if __name__ == "__main__":
    main()
