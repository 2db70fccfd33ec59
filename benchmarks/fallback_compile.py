"""The global fallback's compile and run time, against a previous version.

The fallback (:func:`softplan_jax.search.fallback.rescue_batch`, the part of
``plan_fallback`` after the local planner) runs one program: reachability's
goal configurations, the certified global search and the check of its path in
one loop with one exact solve site (earlier versions ran three programs; the
per-program table shows whichever a variant compiles). Each variant is measured
in a fresh subprocess with the persistent compilation cache off (a real
compilation every time), variants alternating round by round:

1. ``plan_batch(random_scenarios(1, --batch), max_steps=600)`` (not timed: it is
   the local planner's program, the same in both variants);
2. the fallback on the first ``--scenes`` scenes it left stalled or at max_steps
   (at most), called twice: **extra compile** = first call - second call (the
   fallback's compile time), **run** = the second call;
3. per program, the tracing, lowering and XLA compile seconds of the first call,
   from ``jax_log_compiles``.

Both variants get the same scenes and seeds; their statuses are compared. With
``--base``, the run time is also measured **interleaved in one process**: both
packages imported side by side (the previous one under its own name), each warmed
up once, then ``--run-rounds`` rounds alternating the two (min and median): the
figure to compare, since the fresh processes above run minutes apart on a shared
machine.

    git worktree add /tmp/previous <commit>
    python benchmarks/fallback_compile.py --base /tmp/previous     # ~10 min on 2 CPUs
    python benchmarks/fallback_compile.py --quick                   # this checkout, 4 scenes

Writes ``results/fallback_compile.{md,json}`` and ``results/figures/fallback_compile.png``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

# The measurement, run in a fresh process per variant (its package first on sys.path).
WORKER = r"""
import json, logging, re, sys, time
import jax
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_log_compiles", True)
import numpy as np
import softplan_jax as sp
from softplan_jax.planning.planner import make_options
from softplan_jax.search.fallback import rescue_batch

batch, scenes = int(sys.argv[1]), int(sys.argv[2])
log = []
pats = [("compile", re.compile(r"Finished XLA compilation of (.+?) in ([0-9.e-]+) sec")),
        ("lower", re.compile(r"Finished jaxpr to MLIR module conversion (.+?) in ([0-9.e-]+) sec")),
        ("trace", re.compile(r"Finished tracing (.+?) for jit in ([0-9.e-]+) sec"))]
class H(logging.Handler):
    def emit(self, record):
        msg = record.getMessage()
        for kind, pat in pats:
            m = pat.search(msg)
            if m:
                name = m.group(1) if kind != "trace" else f"jit({m.group(1)})"
                log.append((kind, name, float(m.group(2))))
h = H(level=logging.DEBUG)
for name in ("jax._src.dispatch", "jax._src.interpreters.pxla", "jax._src.pjit", "jax"):
    lg = logging.getLogger(name); lg.addHandler(h); lg.setLevel(logging.DEBUG); lg.propagate = False

suite = sp.random_scenarios(1, batch)
r = jax.device_get(sp.plan_batch(suite, max_steps=600))
left = np.nonzero(np.isin(r.status, [int(sp.Status.STALLED), int(sp.Status.MAX_STEPS)]))[0][:scenes]
take = lambda tree: jax.tree_util.tree_map(lambda x: np.asarray(x)[left], tree)
sub, rsub = take(suite), take(r)
opts = make_options("curve", 10)
log.clear()
times, statuses = [], []
for call in range(2):
    t0 = time.perf_counter()
    res = rescue_batch(sub, rsub, opts, seed=0)[1]
    times.append(time.perf_counter() - t0)
    statuses.append([x.status for x in res])
    if call == 0:
        first_log = list(log)
programs = {}
for kind, name, sec in first_log:
    p = programs.setdefault(name, dict(compile=0.0, trace=0.0, lower=0.0, count=0))
    p[kind] += sec
    p["count"] += kind == "compile"
print(json.dumps(dict(first=times[0], second=times[1], scenes=int(len(left)), statuses=statuses[0],
                      same_twice=statuses[0] == statuses[1], programs=programs)))
"""


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", help="a checkout of the previous version (its softplan_jax/ is measured too)")
    ap.add_argument("--rounds", type=int, default=2, help="fresh processes per variant, alternating (default 2)")
    ap.add_argument("--batch", type=int, default=1024, help="random scenes planned locally first (default 1024)")
    ap.add_argument("--scenes", type=int, default=64, help="most scenes handed to the fallback (default 64)")
    ap.add_argument("--run-rounds", type=int, default=3,
                    help="interleaved warm rounds of the run-time comparison in one process (with --base; default 3)")
    ap.add_argument("--quick", action="store_true", help="one round, 64 scenes planned, 4 to the fallback")
    ap.add_argument("--out", default=None, help="output prefix (default results/fallback_compile)")
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds, args.batch, args.scenes, args.run_rounds = 1, 64, 4, 1
    for name in ("rounds", "batch", "scenes", "run_rounds"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1")
    if args.base and not os.path.isdir(os.path.join(args.base, "softplan_jax")):
        ap.error(f"--base: {args.base} holds no softplan_jax/ folder")
    return args


def run_variant(path: str, args) -> dict:
    from _common import run_fresh

    return run_fresh(WORKER, [args.batch, args.scenes], path)


def main(argv=None) -> dict:
    from _common import finish_machine, log, machine_info, machine_lines, output_paths, write_results

    args = parse_args(argv)
    variants = {"this": REPO} | ({"previous": os.path.abspath(args.base)} if args.base else {})
    machine = machine_info("float64")
    runs = {v: [] for v in variants}
    for k in range(args.rounds):
        order = list(variants) if k % 2 == 0 else list(reversed(variants))
        for v in order:
            r = run_variant(variants[v], args)
            r["extra_compile"] = r["first"] - r["second"]
            runs[v].append(r)
            log(f"round {k + 1}/{args.rounds} [{v}]: {r['scenes']} scenes, first {r['first']:.1f} s, second "
                f"{r['second']:.1f} s, extra compile {r['extra_compile']:.1f} s")
    interleaved = _interleaved(variants, args) if "previous" in variants else None
    finish_machine(machine)

    def stat(v, key):
        xs = [r[key] for r in runs[v]]
        return dict(min=min(xs), median=statistics.median(xs))

    report = dict(machine=machine, args=vars(args), runs=runs, interleaved=interleaved,
                  summary={v: {k: stat(v, k) for k in ("extra_compile", "second", "first")} for v in variants})
    if "previous" in runs:
        pairs = zip(runs["this"], runs["previous"], strict=True)
        report["same_statuses"] = all(a["statuses"] == b["statuses"] for a, b in pairs)
    prefix, figdir = output_paths("fallback_compile", args.quick, args.out)
    md = ["# The global fallback's compile time", "", *machine_lines(machine),
          f"- command: `python benchmarks/fallback_compile.py {' '.join(argv if argv is not None else sys.argv[1:])}`",
          f"- {args.rounds} fresh process(es) per variant, alternating; persistent compilation cache off; the "
          f"fallback on {runs['this'][0]['scenes']} scenes of random_scenarios(1, {args.batch}) that the local "
          "planner left stalled or at max_steps; min / median over the rounds", "",
          "| variant | extra compile (first - second call) | run (second call) | first call |", "|---|---|---|---|"]
    for v in variants:
        s = report["summary"][v]
        md.append(f"| {v} | " + " | ".join(f"{s[k]['min']:.1f} / {s[k]['median']:.1f} s"
                                            for k in ("extra_compile", "second", "first")) + " |")
    if interleaved:
        md += ["", f"Run time interleaved in one process ({args.run_rounds} warm rounds, the same scenes; min / "
               "median):", "", "| variant | run |", "|---|---|"]
        md += [f"| {v} | {min(t):.1f} / {statistics.median(t):.1f} s |" for v, t in interleaved.items()]
        ratio = min(interleaved["this"]) / min(interleaved["previous"])
        md += ["", f"- this / previous (min): {ratio:.3f}"]
    md += ["", "Per program, first call of the first round (trace + lowering + XLA compile, seconds; "
           "compiles):", "",
           "| program | " + " | ".join(variants) + " |", "|---|" + "---|" * len(variants)]
    def cost(v, p):
        q = runs[v][0]["programs"].get(p, {})
        return sum(q.get(k, 0.0) for k in ("trace", "lower", "compile"))

    names = sorted({p for v in variants for p in runs[v][0]["programs"]},
                   key=lambda p: -max(cost(v, p) for v in variants))
    for p in names:
        cells = []
        for v in variants:
            q = runs[v][0]["programs"].get(p)
            cells.append("-" if q is None else
                         f"{q['trace']:.1f} + {q['lower']:.1f} + {q['compile']:.1f} ({q['count']})")
        md.append(f"| `{p}` | " + " | ".join(cells) + " |")
    if "same_statuses" in report:
        md += ["", f"- per-scene statuses identical between the variants: {report['same_statuses']}"]
    write_results(prefix, report, "\n".join(md) + "\n")
    _figure(report, variants, os.path.join(figdir, "fallback_compile.png"))
    print("\n".join(md))
    return report


def _interleaved(variants, args) -> dict:
    """Warm run time of both variants in this process, alternating (seconds per round)."""
    import jax
    import numpy as np
    from _common import load_variant, log

    jax.config.update("jax_enable_x64", True)
    pkgs = {"this": load_variant("this", os.path.join(REPO, "softplan_jax")),
            "previous": load_variant("previous", os.path.join(variants["previous"], "softplan_jax"))}
    calls = {}
    for v, p in pkgs.items():
        suite = p.random_scenarios(1, args.batch)
        r = jax.device_get(p.plan_batch(suite, max_steps=600))
        left = np.nonzero(np.isin(r.status, [int(p.Status.STALLED), int(p.Status.MAX_STEPS)]))[0][: args.scenes]
        take = lambda tree, left=left: jax.tree_util.tree_map(lambda x: np.asarray(x)[left], tree)  # noqa: E731
        fallback = importlib.import_module(p.__name__ + ".search.fallback")
        opts = importlib.import_module(p.__name__ + ".planning.planner").make_options("curve", 10)
        calls[v] = lambda fallback=fallback, sub=take(suite), rsub=take(r), opts=opts: fallback.rescue_batch(
            sub, rsub, opts, seed=0)
        calls[v]()  # warm-up: compile
    times = {v: [] for v in pkgs}
    for k in range(args.run_rounds):
        for v in (pkgs if k % 2 == 0 else reversed(list(pkgs))):
            t0 = time.perf_counter()
            calls[v]()
            times[v].append(time.perf_counter() - t0)
            log(f"interleaved round {k + 1}/{args.run_rounds} [{v}]: {times[v][-1]:.1f} s")
    return times


def _figure(report, variants, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.2))
    keys = ("extra_compile", "second")
    labels = ("extra compile", "run (warm)")
    width = 0.8 / len(variants)
    for i, v in enumerate(variants):
        vals = [report["summary"][v][k]["min"] for k in keys]
        ax.bar([j + i * width for j in range(len(keys))], vals, width, label=v)
    ax.set_xticks([j + 0.4 - width / 2 for j in range(len(keys))], labels)
    ax.set_ylabel("seconds (min over rounds)")
    ax.set_title(f"plan_fallback's fallback on {report['runs']['this'][0]['scenes']} scenes")
    ax.legend()
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
