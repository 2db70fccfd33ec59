"""Paid by the step: what one rollout engine that stops when the work is done buys.

The rollout engine (:mod:`softplan_jax.planning.engine`) stops a single rollout within
``step_chunk`` steps of its end, and a batch refills the lane of a finished
scene with the next scene, so cost follows the steps taken. This script times
the package against a previous version of it (``--base``: the ``softplan_jax``
folder of another checkout, imported under its own name), interleaved in one
process (rounds alternate the two; min and median; compile time, the first
call's extra time, apart):

* ``plan(tree)`` with ``max_steps`` = its iterations + 5, 600 (the default) and
  2,000 (targets: the default and 2,000 cost <= 1.3x the short one);
* ``plan_batch(random_scenarios(1, --batch), max_steps=600)``: scenes per
  second (target >= 3x the previous version's), per-scene status and
  iterations compared, and q within the steps taken;
* ``track_batch(random_moving_scenarios(1, --track-batch))``;
* ``plan_fallback`` on ``--fallback`` scenes of the batch that the local
  planner leaves stalled or at max_steps (one round: it takes minutes).

    git worktree add /tmp/previous <commit>
    python benchmarks/engine.py --base /tmp/previous/softplan_jax      # ~15 min on 2 CPUs
    python benchmarks/engine.py --quick                                 # the package alone, small

Writes ``benchmarks/results/engine.{md,json}`` and ``results/figures/engine.png``.
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
from _common import (  # noqa: E402
    finish_machine,
    fmt_s,
    load_variant,
    log,
    machine_info,
    machine_lines,
    output_paths,
    write_results,
)

import softplan_jax  # noqa: E402


def timed(fn):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - t0


def measure(cases: dict, rounds: int) -> dict:
    """cases: {name: {variant: fn}}. Each fn is called once (compile + run), then ``rounds``
    times per variant, the variants alternating. {name: {variant: {first, min, median, runs}}}."""
    out = {}
    for name, fns in cases.items():
        res = {v: {"runs": []} for v in fns}
        for v, fn in fns.items():
            res[v]["result"], res[v]["first"] = timed(fn)
            log(f"  {name} [{v}]: first call {res[v]['first']:.2f} s")
        for r in range(rounds):
            for v, fn in (fns.items() if r % 2 == 0 else reversed(list(fns.items()))):
                res[v]["result"], dt = timed(fn)
                res[v]["runs"].append(dt)
        for v in fns:
            runs = res[v]["runs"]
            res[v].update(min=min(runs), median=statistics.median(runs), compile=res[v]["first"] - min(runs))
            log(f"  {name} [{v}]: min {fmt_s(res[v]['min'])}, median {fmt_s(res[v]['median'])}")
        out[name] = res
    return out


def compare_batches(new, old) -> dict:
    """Per-scene agreement of two batched rollouts (status, iterations, q within the steps taken)."""
    new, old = jax.device_get(new), jax.device_get(old)
    same_status = np.asarray(new.status) == np.asarray(old.status)
    same_it = np.asarray(new.iterations) == np.asarray(old.iterations)
    dq = []
    for b in range(len(same_status)):
        k = int(min(new.iterations[b], old.iterations[b])) + 1
        dq.append(float(np.max(np.abs(np.asarray(new.q[b, :k]) - np.asarray(old.q[b, :k])))))
    dq = np.asarray(dq)
    return dict(scenes=int(len(dq)), status_differs=int(np.sum(~same_status)), iterations_differ=int(np.sum(~same_it)),
                q_max_diff=float(dq.max()), q_over_1e9=int(np.sum(dq > 1e-9)), steps_taken=int(np.sum(new.iterations)))


def _random_moving(pkg):
    """``random_moving_scenarios`` of a package version: under ``moving`` (its place since the
    package was split into layers), else at the top level (earlier versions)."""
    moving = getattr(pkg, "moving", None)
    return getattr(moving, "random_moving_scenarios", None) or pkg.random_moving_scenarios


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", help="the softplan_jax folder of the previous version (omit: the package alone)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--track-batch", type=int, default=256)
    ap.add_argument("--fallback", type=int, default=64, help="scenes for the plan_fallback case (0: skip)")
    ap.add_argument("--quick", action="store_true", help="small sizes, one round (a smoke run)")
    ap.add_argument("--out", default=None, help="output prefix (default results/engine; quick: results/quick/engine)")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    for name in ("rounds", "batch", "track_batch"):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be >= 1")
    if args.fallback < 0:
        ap.error("--fallback must be >= 0")
    if args.quick:
        args.rounds, args.batch, args.track_batch, args.fallback = 1, 32, 8, 0
    args.out, fig_dir = output_paths("engine", args.quick, args.out)
    machine = machine_info("float64")
    pkgs = {"new": softplan_jax}
    if args.base:
        if not os.path.isfile(os.path.join(args.base, "__init__.py")):
            ap.error(f"--base {args.base!r} is not a package folder (no __init__.py)")
        pkgs["previous"] = load_variant("previous", args.base)

    tree = {v: p.paper_scenario("tree") for v, p in pkgs.items()}
    steps = softplan_jax.plan(tree["new"], max_steps=1999).iterations  # a program of its own: no case shares it
    cases = {}
    for T in (steps + 5, 600, 2000):
        cases[f"plan(tree), max_steps {T}"] = {v: (lambda p=p, v=v, T=T: p.plan(tree[v], max_steps=T).q)
                                               for v, p in pkgs.items()}
    batch = {v: p.random_scenarios(1, args.batch) for v, p in pkgs.items()}
    cases[f"plan_batch({args.batch} scenes, max_steps 600)"] = {
        v: (lambda p=p, v=v: p.plan_batch(batch[v], max_steps=600)) for v, p in pkgs.items()}
    moving = {v: _random_moving(p)(1, args.track_batch) for v, p in pkgs.items()}
    cases[f"track_batch({args.track_batch} moving scenes, max_steps 600)"] = {
        v: (lambda p=p, v=v: p.track_batch(moving[v], max_steps=600)) for v, p in pkgs.items()}
    log(f"engine benchmark: {len(cases)} cases x {len(pkgs)} versions, {args.rounds} rounds")
    res = measure(cases, args.rounds)

    report = dict(machine=machine, args=vars(args), tree_iterations=int(steps), cases={})
    for name, r in res.items():
        report["cases"][name] = {v: {k: x for k, x in d.items() if k != "result"} for v, d in r.items()}
    bname = f"plan_batch({args.batch} scenes, max_steps 600)"
    tname = f"track_batch({args.track_batch} moving scenes, max_steps 600)"
    if "previous" in pkgs:
        report["batch_agreement"] = compare_batches(res[bname]["new"]["result"], res[bname]["previous"]["result"])
        report["track_agreement"] = compare_batches(res[tname]["new"]["result"], res[tname]["previous"]["result"])

    if args.fallback:
        r = jax.device_get(res[bname]["new"]["result"])
        names = softplan_jax.STATUS_NAMES
        left = [b for b in range(args.batch) if names[int(r.status[b])] in ("stalled", "max_steps")][: args.fallback]
        fb = {}
        for v, p in pkgs.items():
            sub = jax.tree_util.tree_map(lambda x, left=left: np.asarray(x)[left], batch[v])
            t0 = time.perf_counter()
            out = p.plan_fallback(sub, max_steps=600)
            first = time.perf_counter() - t0
            t0 = time.perf_counter()
            out = p.plan_fallback(sub, max_steps=600)
            second = time.perf_counter() - t0
            fb[v] = dict(first=first, second=second, compile=first - second, scenes=len(left),
                         reached=sum(o.reached for o in out), planner_global=sum(o.planner == "global" for o in out),
                         statuses=[o.status for o in out])
            log(f"  plan_fallback({len(left)} scenes) [{v}]: first {first:.1f} s, second {second:.1f} s")
        if "previous" in fb:
            fb["same_statuses"] = fb["new"]["statuses"] == fb["previous"]["statuses"]
        report["fallback"] = fb

    finish_machine(machine)
    md = ["# Paid by the step: the rollout engine against the previous version", "",
          *machine_lines(machine), f"- command: `python benchmarks/engine.py {' '.join(argv or sys.argv[1:])}`",
          f"- {args.rounds} interleaved rounds per case; min / median of the warm calls; "
          "compile = first call - fastest warm call", "",
          "| case | version | min | median | compile | previous / new (min) |", "|---|---|---|---|---|---|"]
    for name, r in report["cases"].items():
        for v, d in r.items():
            ratio = ""
            if v == "new" and "previous" in r:
                ratio = f"**{r['previous']['min'] / d['min']:.2f}x**"
            md.append(f"| {name} | {v} | {fmt_s(d['min'])} | {fmt_s(d['median'])} | {fmt_s(d['compile'])} | {ratio} |")
    plan_cases = [n for n in report["cases"] if n.startswith("plan(tree)")]
    short = report["cases"][plan_cases[0]]["new"]["min"]
    md += ["", "Targets (the new version, min times):", "",
           f"- `plan(tree)` at max_steps 600: **{report['cases'][plan_cases[1]]['new']['min'] / short:.2f}x** the "
           f"plan with max_steps {steps + 5} (target <= 1.3x); at 2,000: "
           f"**{report['cases'][plan_cases[2]]['new']['min'] / short:.2f}x**"]
    for v in pkgs:
        d = report["cases"][bname][v]
        md.append(f"- `plan_batch`, {v}: {args.batch / d['min']:.1f} scenes/s")
    if "batch_agreement" in report:
        a = report["batch_agreement"]
        md += [f"- batch agreement: status differs in {a['status_differs']} of {a['scenes']} scenes, iterations in "
               f"{a['iterations_differ']}; q within the steps taken: max |diff| {a['q_max_diff']:.2g} "
               f"({a['q_over_1e9']} scenes over 1e-9); {a['steps_taken']:,} steps taken of "
               f"{a['scenes'] * 601:,} the previous version computed",
               f"- tracking agreement: status differs in {report['track_agreement']['status_differs']} of "
               f"{report['track_agreement']['scenes']}, q max |diff| {report['track_agreement']['q_max_diff']:.2g}"]
    if "fallback" in report:
        for v in pkgs:
            f = report["fallback"][v]
            md.append(f"- `plan_fallback` on {f['scenes']} scenes the local planner leaves, {v}: first call "
                      f"{f['first']:.1f} s, second {f['second']:.1f} s (compile ~{f['compile']:.1f} s); reached "
                      f"{f['reached']}, by the global search {f['planner_global']}")
        if "same_statuses" in report["fallback"]:
            md.append(f"- fallback statuses identical: {report['fallback']['same_statuses']}")
    write_results(args.out, report, "\n".join(md) + "\n")
    _figure(report, os.path.join(fig_dir, os.path.basename(args.out) + ".png"))
    print("\n".join(md))


def _figure(report, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(report["cases"])
    versions = [v for v in ("previous", "new") if v in report["cases"][names[0]]]
    fig, ax = plt.subplots(figsize=(8, 0.6 * len(names) + 1.5))
    y = np.arange(len(names))
    for i, v in enumerate(versions):
        ax.barh(y + 0.4 * i, [report["cases"][n][v]["min"] for n in names], height=0.38, label=v)
    ax.set_yticks(y + 0.2 * (len(versions) - 1), names, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("warm run time, min over rounds [s] (log)")
    ax.legend()
    ax.set_title("Rollout engine: paid by the step")
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
