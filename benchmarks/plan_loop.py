"""Scenes planned one at a time: what ``sp.plan`` costs per scene once its rollout is compiled.

A loop of ``sp.plan`` calls over the scenes of ``random_scenarios(1, --scenes)`` (one padded
shape: one compiled rollout), as a user plans a suite scene by scene. Each variant runs in a
fresh process (the persistent compilation cache off), variants alternating round by round:

1. ``sp.plan`` of the first scene (compiles the rollout; not timed);
2. **pass 1**: every other scene, one call each: wall time per call, and the XLA
   compilations during the pass (jax.monitoring's backend-compile events: the rollout's and
   every eager operation's);
3. **pass 2**: the same scenes again (every step count seen before).

Both variants get the same scenes; their per-scene iterations are compared. Before the
change that measured it, trimming a result to the steps taken sliced the device arrays at
each new step count, which compiled three slice programs per new count.

    git worktree add /tmp/previous <commit>
    python benchmarks/plan_loop.py --base /tmp/previous    # ~2 min on 2 CPUs
    python benchmarks/plan_loop.py --quick                 # this checkout, 8 scenes

Writes ``results/plan_loop.{md,json}`` and ``results/figures/plan_loop.png``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

# The measurement, run in a fresh process per variant (its package first on sys.path).
WORKER = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import softplan_jax as sp

n, steps = int(sys.argv[1]), int(sys.argv[2])
compiles = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, sec, **kw: compiles.append(sec) if event == "/jax/core/compile/backend_compile_duration" else None)
suite = sp.random_scenarios(1, n)
scenes = [jax.tree_util.tree_map(lambda x, b=b: x[b], suite) for b in range(n)]
sp.plan(scenes[0], max_steps=steps)
out = {}
for name in ("pass1", "pass2"):
    del compiles[:]
    times, its = [], []
    for sc in scenes[1:]:
        t0 = time.perf_counter()
        r = sp.plan(sc, max_steps=steps)
        times.append(time.perf_counter() - t0)
        its.append(int(r.iterations))
    out[name] = dict(times=times, iterations=its, compiles=len(compiles), compile_s=sum(compiles))
print(json.dumps(out))
"""


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", help="a checkout of the previous version (its softplan_jax/ is measured too)")
    ap.add_argument("--rounds", type=int, default=2, help="fresh processes per variant, alternating (default 2)")
    ap.add_argument("--scenes", type=int, default=48, help="scenes of random_scenarios(1, N) (default 48)")
    ap.add_argument("--max-steps", type=int, default=300, help="max_steps of each plan (default 300)")
    ap.add_argument("--quick", action="store_true", help="one round, 8 scenes")
    ap.add_argument("--out", default=None, help="output prefix (default results/plan_loop)")
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds, args.scenes = 1, 8
    for name in ("rounds", "max_steps"):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be >= 1")
    if args.scenes < 2:
        ap.error("--scenes must be >= 2 (the first compiles)")
    if args.base and not os.path.isdir(os.path.join(args.base, "softplan_jax")):
        ap.error(f"--base: {args.base} holds no softplan_jax/ folder")
    return args


def main(argv=None) -> dict:
    from _common import finish_machine, log, machine_info, machine_lines, output_paths, run_fresh, write_results

    args = parse_args(argv)
    variants = {"this": REPO} | ({"previous": os.path.abspath(args.base)} if args.base else {})
    machine = machine_info("float64")
    runs = {v: [] for v in variants}
    for k in range(args.rounds):
        for v in (list(variants) if k % 2 == 0 else list(reversed(variants))):
            r = run_fresh(WORKER, [args.scenes, args.max_steps], variants[v])
            runs[v].append(r)
            log(f"round {k + 1}/{args.rounds} [{v}]: per plan, median pass 1 "
                f"{1e3 * statistics.median(r['pass1']['times']):.1f} ms ({r['pass1']['compiles']} compilations), "
                f"pass 2 {1e3 * statistics.median(r['pass2']['times']):.1f} ms ({r['pass2']['compiles']})")
    finish_machine(machine)

    def per_plan(v, p):  # ms per plan over the rounds: min of the rounds' medians, and the median of all calls
        meds = [statistics.median(r[p]["times"]) for r in runs[v]]
        return dict(min_of_medians_ms=1e3 * min(meds),
                    median_ms=1e3 * statistics.median([t for r in runs[v] for t in r[p]["times"]]),
                    mean_ms=1e3 * statistics.mean([t for r in runs[v] for t in r[p]["times"]]))

    summary = {v: {p: dict(per_plan(v, p), compiles=runs[v][0][p]["compiles"],
                           compile_s=runs[v][0][p]["compile_s"]) for p in ("pass1", "pass2")} for v in variants}
    its = runs["this"][0]["pass1"]["iterations"]
    report = dict(machine=machine, args=vars(args), runs=runs, summary=summary,
                  distinct_step_counts=len(set(its)))
    if "previous" in runs:
        report["same_iterations"] = runs["previous"][0]["pass1"]["iterations"] == its
    prefix, figdir = output_paths("plan_loop", args.quick, args.out)
    md = ["# Scenes planned one at a time", "", *machine_lines(machine),
          f"- command: `python benchmarks/plan_loop.py {' '.join(argv if argv is not None else sys.argv[1:])}`",
          f"- `sp.plan(scene, max_steps={args.max_steps})` over scenes 2-{args.scenes} of "
          f"random_scenarios(1, {args.scenes}) (one padded shape; scene 1 compiled the rollout first); "
          f"{len(set(its))} distinct step counts among {len(its)} scenes; {args.rounds} fresh process(es) per "
          "variant, alternating; persistent compilation cache off",
          "- per plan: the smallest of the rounds' medians / the median and mean of every call; compilations: "
          "XLA backend compilations during the pass (first round)", "",
          "| variant | pass | per plan (min of medians / median / mean) | compilations (seconds) |",
          "|---|---|---|---|"]
    for v in variants:
        for p, label in (("pass1", "1: new step counts"), ("pass2", "2: the same scenes again")):
            s = summary[v][p]
            md.append(f"| {v} | {label} | {s['min_of_medians_ms']:.1f} / {s['median_ms']:.1f} / {s['mean_ms']:.1f} ms"
                      f" | {s['compiles']} ({s['compile_s']:.2f} s) |")
    if "previous" in variants:
        ratio = summary["previous"]["pass1"]["mean_ms"] / summary["this"]["pass1"]["mean_ms"]
        md += ["", f"- pass 1, previous / this (mean per plan): **{ratio:.2f}x**",
               f"- per-scene iterations identical between the variants: {report['same_iterations']}"]
    write_results(prefix, report, "\n".join(md) + "\n")
    _figure(summary, variants, os.path.join(figdir, "plan_loop.png"))
    print("\n".join(md))
    return report


def _figure(summary, variants, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    width = 0.38
    for i, v in enumerate(variants):
        vals = [summary[v][p]["mean_ms"] for p in ("pass1", "pass2")]
        ax.bar([x + (i - 0.5 * (len(variants) - 1)) * width for x in (0, 1)], vals, width, label=v)
    ax.set_xticks([0, 1], ["pass 1: new step counts", "pass 2: seen before"])
    ax.set_ylabel("ms per sp.plan call (mean)")
    ax.set_title("Scenes planned one at a time")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
