"""A/B against another checkout: is this version faster, and does it give the same results?

Both versions run in one process, the other one imported under its own name from its
``softplan_jax`` folder (``--base``), interleaved round by round so that a shared machine's
load falls on both alike; without ``--base`` the package runs alone (a smoke run). Cases
(``--only``, default all):

* ``plan``: ``plan(tree)`` at ``max_steps`` = its iterations + 5, 600 and 2,000;
* ``plan_batch``: ``plan_batch(random_scenarios(--seed, --batch), max_steps=600)`` (``--chunk C``: in
  chunks of C scenes; ``--steps T``: max_steps T);
* ``track_batch``: ``track_batch(random_moving_scenarios(--seed, --track-batch), max_steps=600)``;
* ``plan_loop``: ``plan`` over the scenes of ``random_scenarios(--seed, --loop)`` one at a time
  (a compiled rollout serves them all; what a new step count costs);
* ``suite``: ``random_scenarios(--seed, --batch)`` drawn;
* ``fallback``: ``plan_fallback`` on the first ``--fallback`` scenes of the batch that the
  local planner leaves stalled or at max_steps (two calls: the first compiles).

Each case: one first call per version (tracing and compilation included), then ``--rounds``
rounds alternating the versions; min and median of the warm calls, compile = first call -
fastest warm call. Results compared between the versions: statuses, iterations, q within
the steps taken and paired success (reached by both, by one only, McNemar's exact p) for the
batches, iterations (the loop), every array bit for bit (the suite),
statuses (the fallback). ``--fresh``: each version's first ``plan(tree)`` also in a fresh
process with the compilation cache off (a real compilation, no warm jit cache).

    git worktree add /tmp/previous <commit>
    python benchmarks/ab.py --base /tmp/previous/softplan_jax            # ~15 min on 2 CPUs
    python benchmarks/ab.py --base /tmp/previous/softplan_jax --only plan,plan_batch --rounds 5
    python benchmarks/ab.py --base /tmp/previous/softplan_jax --only plan_batch --seed 2 --rounds 1  # held out
    python benchmarks/ab.py --quick                                       # the package alone, small

Writes ``results/ab.{md,json}`` and ``results/figures/ab.png`` (``--out PREFIX`` elsewhere).
For bit-identical arrays over a fixed set of runs, ``benchmarks/baselines.py``.
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
    bar_figure,
    finish_machine,
    fmt_s,
    load_variant,
    log,
    machine_info,
    machine_lines,
    output_paths,
    run_fresh,
    write_results,
)
from _stats import mcnemar_exact  # noqa: E402

import softplan_jax  # noqa: E402

CASES = ("plan", "plan_batch", "track_batch", "plan_loop", "suite", "fallback")

# A fresh process's first plan(tree): the package on the worker's path, the cache off.
FRESH_PLAN = """
import json, time, jax
jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
tree = sp.paper_scenario("tree")
t0 = time.perf_counter()
r = sp.plan(tree, max_steps=600)
first = time.perf_counter() - t0
t0 = time.perf_counter()
sp.plan(tree, max_steps=600)
print(json.dumps(dict(first=first, warm=time.perf_counter() - t0, iterations=int(r.iterations))))
"""


def timed(fn):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - t0


def measure(cases: dict, rounds: int) -> dict:
    """cases: {name: {version: fn}}. Each fn once (compile + run), then ``rounds`` times per
    version, the versions alternating. {name: {version: {result, first, runs, min, median, compile}}}."""
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
    """Per-scene agreement of two batched rollouts (status, iterations, q within the steps taken),
    and their paired success: scenes reached by both, by one only, McNemar's exact p."""
    new, old = jax.device_get(new), jax.device_get(old)
    reached_new, reached_old = np.asarray(new.reached, bool), np.asarray(old.reached, bool)
    only_new, only_old = int(np.sum(reached_new & ~reached_old)), int(np.sum(reached_old & ~reached_new))
    paired = dict(reached_new=int(reached_new.sum()), reached_old=int(reached_old.sum()),
                  reached_both=int(np.sum(reached_new & reached_old)), only_new=only_new, only_old=only_old,
                  mcnemar_p=mcnemar_exact(only_new, only_old))
    same_status = np.asarray(new.status) == np.asarray(old.status)
    same_it = np.asarray(new.iterations) == np.asarray(old.iterations)
    dq = []
    for b in range(len(same_status)):
        k = int(min(new.iterations[b], old.iterations[b])) + 1
        dq.append(float(np.max(np.abs(np.asarray(new.q[b, :k]) - np.asarray(old.q[b, :k])))))
    dq = np.asarray(dq)
    return dict(scenes=int(len(dq)), status_differs=int(np.sum(~same_status)), iterations_differ=int(np.sum(~same_it)),
                q_max_diff=float(dq.max()), q_over_1e9=int(np.sum(dq > 1e-9)), steps_taken=int(np.sum(new.iterations)),
                **paired)


def _leaves_equal(a, b) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb, strict=True))


def _random_moving(pkg):
    """``random_moving_scenarios`` of a version: under ``moving`` (its place since the package was
    split into layers), else at the top level (earlier versions)."""
    moving = getattr(pkg, "moving", None)
    return getattr(moving, "random_moving_scenarios", None) or pkg.random_moving_scenarios


def build_cases(pkgs: dict, args) -> tuple[dict, dict]:
    """``({case name: {version: fn}}, {kind: case name})`` for the cases of ``args.only``."""
    cases, names = {}, {}
    if "plan" in args.only:
        tree = {v: p.paper_scenario("tree") for v, p in pkgs.items()}
        steps = softplan_jax.plan(tree["new"], max_steps=1999).iterations  # a program no case shares
        for T in (steps + 5, 600, 2000):
            cases[f"plan(tree), max_steps {T}"] = {v: (lambda p=p, v=v, T=T: p.plan(tree[v], max_steps=T).q)
                                                   for v, p in pkgs.items()}
    batch = {v: p.random_scenarios(args.seed, args.batch) for v, p in pkgs.items()}
    if "plan_batch" in args.only or "fallback" in args.only:
        chunked = f", chunk {args.chunk}" if args.chunk else ""
        names["plan_batch"] = f"plan_batch({args.batch} scenes, max_steps {args.steps}{chunked})"
        cases[names["plan_batch"]] = {v: (lambda p=p, v=v: p.plan_batch(batch[v], max_steps=args.steps, chunk=args.chunk))
                                      for v, p in pkgs.items()}
    if "track_batch" in args.only:
        moving = {v: _random_moving(p)(args.seed, args.track_batch) for v, p in pkgs.items()}
        names["track_batch"] = f"track_batch({args.track_batch} moving scenes, max_steps 600)"
        cases[names["track_batch"]] = {v: (lambda p=p, v=v: p.track_batch(moving[v], max_steps=600))
                                       for v, p in pkgs.items()}
    if "plan_loop" in args.only:
        loop = {v: p.random_scenarios(args.seed, args.loop) for v, p in pkgs.items()}
        scenes = {v: [jax.tree_util.tree_map(lambda x, b=b: x[b], s) for b in range(args.loop)] for v, s in loop.items()}
        names["plan_loop"] = f"plan loop ({args.loop} scenes one at a time)"
        cases[names["plan_loop"]] = {v: (lambda p=p, v=v: [int(p.plan(s).iterations) for s in scenes[v]])
                                     for v, p in pkgs.items()}
    if "suite" in args.only:
        names["suite"] = f"random_scenarios({args.seed}, {args.batch})"
        cases[names["suite"]] = {v: (lambda p=p: p.random_scenarios(args.seed, args.batch)) for v, p in pkgs.items()}
    return cases, names


def agreement(res: dict, names: dict) -> dict:
    """Each compared case's agreement between the versions."""
    out = {}
    for kind, name in names.items():
        if "previous" not in res.get(name, {}):
            continue
        new, old = res[name]["new"]["result"], res[name]["previous"]["result"]
        if kind in ("plan_batch", "track_batch"):
            out[kind] = compare_batches(new, old)
        elif kind == "plan_loop":
            out[kind] = dict(scenes=len(new), iterations_differ=sum(a != b for a, b in zip(new, old, strict=True)))
        elif kind == "suite":
            out[kind] = dict(bit_identical=_leaves_equal(new, old))
    return out


def fallback_case(pkgs: dict, batch_result, args) -> dict:
    """plan_fallback on the first ``args.fallback`` scenes the local planner left, twice per version."""
    r = jax.device_get(batch_result)
    left = [b for b in range(args.batch) if softplan_jax.STATUS_NAMES[int(r.status[b])] in ("stalled", "max_steps")]
    left = left[: args.fallback]
    if not left:
        log("  plan_fallback: the local planner left no scene of the batch; case skipped")
        return {}
    fb = {}
    for v, p in pkgs.items():
        sub = jax.tree_util.tree_map(lambda x: np.asarray(x)[left], p.random_scenarios(args.seed, args.batch))
        t0 = time.perf_counter()
        p.plan_fallback(sub, max_steps=600)
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
    return fb


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", help="the softplan_jax folder of the other version (omit: this package alone)")
    ap.add_argument("--only", default=",".join(CASES), help=f"comma list of cases (default all: {', '.join(CASES)})")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=1,
                    help="seed of the random scenes of every case but plan (default 1; a held-out check: 2)")
    ap.add_argument("--chunk", type=int, default=None, help="plan_batch in chunks of this many scenes")
    ap.add_argument("--steps", type=int, default=600, help="plan_batch's max_steps")
    ap.add_argument("--track-batch", type=int, default=256)
    ap.add_argument("--loop", type=int, default=48, help="scenes of the plan loop")
    ap.add_argument("--fallback", type=int, default=64, help="scenes of the fallback case")
    ap.add_argument("--fresh", action="store_true", help="each version's first plan(tree) in a fresh process too")
    ap.add_argument("--quick", action="store_true", help="small sizes, one round (a smoke run)")
    ap.add_argument("--out", default=None, help="output prefix (default results/ab; quick: results/quick/ab)")
    args = ap.parse_args(argv)
    args.only = [c.strip() for c in args.only.split(",") if c.strip()]
    bad = sorted(set(args.only) - set(CASES))
    if bad or not args.only:
        ap.error(f"--only: unknown case(s) {bad}; the cases: {', '.join(CASES)}")
    for name in ("rounds", "batch", "track_batch", "loop", "fallback", "steps") + (("chunk",) if args.chunk else ()):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be >= 1")
    if args.base and not os.path.isfile(os.path.join(args.base, "__init__.py")):
        ap.error(f"--base {args.base!r} is not a package folder (no __init__.py)")
    if args.quick:
        args.rounds, args.batch, args.track_batch, args.loop, args.fallback = 1, 32, 8, 4, 1
    return args


def main(argv=None):
    args = parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    args.out, fig_dir = output_paths("ab", args.quick, args.out)
    machine = machine_info("float64")
    pkgs = {"new": softplan_jax}
    if args.base:
        pkgs["previous"] = load_variant("previous", args.base)
    cases, names = build_cases(pkgs, args)
    log(f"ab: {len(cases)} cases x {len(pkgs)} versions, {args.rounds} rounds")
    res = measure(cases, args.rounds)
    report = dict(machine=machine, args=vars(args), cases={
        name: {v: {k: x for k, x in d.items() if k != "result"} for v, d in r.items()} for name, r in res.items()})
    report["agreement"] = agreement(res, names)
    if "fallback" in args.only:
        report["fallback"] = fallback_case(pkgs, res[names["plan_batch"]]["new"]["result"], args)
    if args.fresh:
        here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        roots = {"new": here, **({"previous": os.path.dirname(os.path.abspath(args.base))} if args.base else {})}
        report["fresh"] = {v: run_fresh(FRESH_PLAN, [], root) for v, root in roots.items()}
    finish_machine(machine)
    md = markdown(report, argv if argv is not None else sys.argv[1:])
    write_results(args.out, report, md)
    bar_figure({n: {v: d["min"] for v, d in r.items()} for n, r in report["cases"].items()},
               os.path.join(fig_dir, os.path.basename(args.out) + ".png"), "warm run time, min over rounds [s] (log)",
               "A/B: this version against another")
    print(md)
    return report


def markdown(report: dict, argv) -> str:
    """The report's Markdown."""
    md = ["# A/B: this version against another", "", *machine_lines(report["machine"]),
          f"- command: `python benchmarks/ab.py {' '.join(argv)}`",
          f"- {report['args']['rounds']} interleaved rounds per case; min / median of the warm calls; "
          "compile = first call - fastest warm call", "",
          "| case | version | min | median | compile | previous / new (min) |", "|---|---|---|---|---|---|"]
    for name, r in report["cases"].items():
        for v, d in r.items():
            ratio = f"**{r['previous']['min'] / d['min']:.2f}x**" if v == "new" and "previous" in r else ""
            md.append(f"| {name} | {v} | {fmt_s(d['min'])} | {fmt_s(d['median'])} | {fmt_s(d['compile'])} | {ratio} |")
    md += ["", "Agreement between the versions:", ""]
    for kind, a in report["agreement"].items():
        md.append(f"- {kind}: " + ", ".join(f"{k} {v}" for k, v in a.items()))
    if not report["agreement"]:
        md.append("- (one version only)")
    for v, f in report.get("fallback", {}).items():
        if isinstance(f, dict):
            md.append(f"- `plan_fallback` on {f['scenes']} scenes, {v}: first call {f['first']:.1f} s, second "
                      f"{f['second']:.1f} s; reached {f['reached']}, by the global search {f['planner_global']}")
    if "same_statuses" in report.get("fallback", {}):
        md.append(f"- fallback statuses identical: {report['fallback']['same_statuses']}")
    for v, f in report.get("fresh", {}).items():
        md.append(f"- fresh process, cache off, {v}: first `plan(tree)` {f['first']:.2f} s (warm {fmt_s(f['warm'])})")
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    main()
