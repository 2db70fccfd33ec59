"""The package's programs beside the rollouts, with and without its XLA options.

``closest_point`` (the tree scene's branches, stacked), ``planning.planner_step`` (the tree,
curve method) and the brute-force ``geometry.dense_trajectory_clearance`` (five configurations
of the tree) are compiled with the rollouts' XLA CPU options
(``base.compilation_cache.package_jit``). Each variant runs in a fresh process (the
persistent compilation cache off), variants alternating round by round: "options" as the
package ships, "defaults" with ``SOFTPLAN_XLA_OPTIONS=0`` (XLA's defaults, what these
programs were compiled with before). Per program: the first call (trace + compile + run),
and the warm calls (min and median). The values of the two variants are compared (they
agree to rounding, not bit for bit: the options change XLA's code).

    python benchmarks/package_programs.py           # ~1 min on 2 CPUs
    python benchmarks/package_programs.py --quick   # one round, 3 warm calls

Writes ``results/package_programs.{md,json}`` and ``results/figures/package_programs.png``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

PROGRAMS = ("closest_point", "planner_step", "dense_trajectory_clearance")

# The measurement, run in a fresh process per variant.
WORKER = r"""
import json, sys, time
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.planning.planner import make_options

calls = int(sys.argv[1])
tree = sp.paper_scenario("tree")
qs = tree.q0 + jnp.linspace(0.0, 0.2, 5)[:, None, None] * jnp.array([0.0, 1.0, 0.5])
cases = {
    "closest_point": lambda: sp.closest_point(tree.q0, tree.curves).distance,
    "planner_step": lambda: sp.planning.planner_step(tree.q0, tree, sp.default_gains(), make_options("curve")),
    "dense_trajectory_clearance": lambda: sp.geometry.dense_trajectory_clearance(qs, tree),
}
out = {}
for name, f in cases.items():
    t0 = time.perf_counter()
    value = np.asarray(jax.block_until_ready(f()))
    first = time.perf_counter() - t0
    warm = []
    for _ in range(calls):
        t0 = time.perf_counter()
        jax.block_until_ready(f())
        warm.append(time.perf_counter() - t0)
    out[name] = dict(first=first, warm=warm, value=value.ravel().tolist())
print(json.dumps(out))
"""

VARIANTS = {"options": {"SOFTPLAN_XLA_OPTIONS": "1"}, "defaults": {"SOFTPLAN_XLA_OPTIONS": "0"}}


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=2, help="fresh processes per variant, alternating (default 2)")
    ap.add_argument("--calls", type=int, default=10, help="warm calls per program (default 10)")
    ap.add_argument("--quick", action="store_true", help="one round, 3 warm calls")
    ap.add_argument("--out", default=None, help="output prefix (default results/package_programs)")
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds, args.calls = 1, 3
    for name in ("rounds", "calls"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1")
    return args


def main(argv=None) -> dict:
    import numpy as np
    from _common import finish_machine, log, machine_info, machine_lines, output_paths, run_fresh, write_results

    args = parse_args(argv)
    machine = machine_info("float64")
    runs = {v: [] for v in VARIANTS}
    for k in range(args.rounds):
        for v in (list(VARIANTS) if k % 2 == 0 else list(reversed(VARIANTS))):
            r = run_fresh(WORKER, [args.calls], REPO, env=VARIANTS[v])
            runs[v].append(r)
            log(f"round {k + 1}/{args.rounds} [{v}]: first calls " +
                ", ".join(f"{p} {r[p]['first']:.2f} s" for p in PROGRAMS))
    finish_machine(machine)
    summary = {v: {p: dict(first_min_s=min(r[p]["first"] for r in runs[v]),
                           warm_min_ms=1e3 * min(t for r in runs[v] for t in r[p]["warm"]),
                           warm_median_ms=1e3 * statistics.median([t for r in runs[v] for t in r[p]["warm"]]))
                   for p in PROGRAMS} for v in VARIANTS}
    diff = {p: float(np.max(np.abs(np.asarray(runs["options"][0][p]["value"]) -
                                   np.asarray(runs["defaults"][0][p]["value"])))) for p in PROGRAMS}
    report = dict(machine=machine, args=vars(args), summary=summary, max_abs_difference=diff,
                  runs={v: [{p: {k: r[p][k] for k in ("first", "warm")} for p in PROGRAMS} for r in rs]
                        for v, rs in runs.items()})
    prefix, figdir = output_paths("package_programs", args.quick, args.out)
    md = ["# The package's programs with and without its XLA options", "", *machine_lines(machine),
          f"- command: `python benchmarks/package_programs.py {' '.join(argv if argv is not None else sys.argv[1:])}`",
          f"- {args.rounds} fresh process(es) per variant, alternating; persistent compilation cache off; "
          f"{args.calls} warm calls per program and process; first call: trace + compile + run (min over the rounds)",
          "- options: the package's XLA options (package_jit); defaults: `SOFTPLAN_XLA_OPTIONS=0`", "",
          "| program | first call, options / defaults | warm min (median), options | warm min (median), defaults "
          "| max abs difference |", "|---|---|---|---|---|"]
    for p in PROGRAMS:
        a, b = summary["options"][p], summary["defaults"][p]
        md.append(f"| `{p}` | {a['first_min_s']:.2f} / {b['first_min_s']:.2f} s | {a['warm_min_ms']:.3g} "
                  f"({a['warm_median_ms']:.3g}) ms | {b['warm_min_ms']:.3g} ({b['warm_median_ms']:.3g}) ms "
                  f"| {diff[p]:.2g} |")
    write_results(prefix, report, "\n".join(md) + "\n")
    _figure(summary, os.path.join(figdir, "package_programs.png"))
    print("\n".join(md))
    return report


def _figure(summary, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    width = 0.38
    for i, v in enumerate(VARIANTS):
        xs = [x + (i - 0.5) * width for x in range(len(PROGRAMS))]
        axes[0].bar(xs, [summary[v][p]["first_min_s"] for p in PROGRAMS], width, label=v)
        axes[1].bar(xs, [summary[v][p]["warm_min_ms"] for p in PROGRAMS], width, label=v)
    for ax, title in zip(axes, ("first call (s)", "warm call, min (ms, log)"), strict=True):
        ax.set_xticks(range(len(PROGRAMS)), ["closest_point", "planner_step", "dense clearance"], fontsize=8)
        ax.set_title(title, fontsize=9)
    axes[1].set_yscale("log")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
