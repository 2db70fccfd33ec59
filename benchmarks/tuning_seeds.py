"""Seed spread of the tuning comparison (issue 22): the gradient and random search of
``benchmarks/tuning.py`` (same settings, same budget: 1/5 of the grid's rollouts) rerun
with several tuner seeds, each choice evaluated on the held-out scenes, paired with
the grid's choice there.

    python benchmarks/tuning_seeds.py            # seeds 0-4, curve / N = 10 / N = 50, ~20 min
    python benchmarks/tuning_seeds.py --quick    # smoke run into results/quick/

Every option of ``tuning.py`` is accepted (``--out PREFIX`` writes ``PREFIX_seeds.{md,json}``).

``tuning.py`` reports one tuner seed; the validation runs showed that the tuners'
choices move between seeds, so this script says how much of a difference is the seed.
Writes ``results/tuning_seeds.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from stats import paired_bootstrap, wilson  # noqa: E402
from tuning import TUNED, box_centre, choice_key, draw_in_box, grad_kwargs, mlabel, parse_args, plan_kw  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0,1,2,3,4", help="comma list of tuner seeds")
    ap.add_argument("--quick", action="store_true")
    given = sys.argv[1:] if argv is None else list(argv)
    own, rest = ap.parse_known_args(given)
    args = parse_args((["--quick"] if own.quick else []) + rest)
    try:
        seeds = [int(s) for s in own.seeds.split(",")]
    except ValueError:
        raise ValueError(f"--seeds must be a comma list of ints, got {own.seeds!r}") from None
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from _common import RESULTS_DIR, log, machine_info

    import softplan_jax as sp
    from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

    t_all = time.perf_counter()
    out = (args.out + "_seeds") if args.out else os.path.join(RESULTS_DIR, "quick" if own.quick else "", "tuning_seeds")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    train = sp.random_scenarios(args.train_seed, args.n_train)
    heldout = sp.random_scenarios(args.eval_seed, args.n_eval)
    base = sp.default_gains(jnp.float64)
    space_g = GainSpace(args.grad_names, stable_dt=args.stable_dt)

    def with3(d):
        return base._replace(**{k: jnp.asarray(d[k], jnp.float64) for k in TUNED})

    start = with3(box_centre(args)) if args.start == "centre" else base  # as tuning.py

    def success(suite, gains, m, steps, seed):
        r = sp.plan_batch(suite, gains=gains, max_steps=steps, seed=seed, chunk=args.chunk, **plan_kw(m))
        return np.asarray(r.reached) & ~np.asarray(r.collided)

    res: dict = dict(machine=machine_info("float64"), argv=given, seeds=seeds, methods={})
    for m in args.method_list:
        lab = mlabel(m)
        # the grid's choice: the best `reached - 3 collided` on the training scenes (tuning.py's rule)
        best = None
        for d0, dt, eta in args.grid:
            r = sp.plan_batch(train, gains=with3(dict(d0=d0, dt=dt, eta=eta)), max_steps=args.train_steps,
                              seed=args.train_seed, chunk=args.chunk, **plan_kw(m))
            key = choice_key(r.reached, r.collided)
            if best is None or key > best[0]:
                best = (key, dict(d0=d0, dt=dt, eta=eta))
        grid_ok = success(heldout, with3(best[1]), m, args.max_steps, args.eval_seed)
        log(f"[seeds {time.perf_counter() - t_all:5.0f} s] {lab} grid {best[1]}: {grid_ok.mean():.3f}")
        rows = []
        for seed in seeds:
            tr = tune_smoothed(train, space_g, start, updates=args.budget // (2 * args.pairs), pairs=args.pairs,
                               max_steps=args.train_steps, seed=seed, progress=False, **grad_kwargs(args),
                               **plan_kw(m))
            rng = np.random.default_rng(seed)
            rbest = None
            for _ in range(args.budget // args.n_train):
                d = draw_in_box(args, rng)
                r = sp.plan_batch(train, gains=with3(d), max_steps=args.train_steps, seed=args.train_seed,
                                  chunk=args.chunk, **plan_kw(m))
                key = choice_key(r.reached, r.collided)
                if rbest is None or key > rbest[0]:
                    rbest = (key, d)
            g_ok = success(heldout, tr.gains, m, args.max_steps, args.eval_seed)
            r_ok = success(heldout, with3(rbest[1]), m, args.max_steps, args.eval_seed)
            row = dict(seed=seed, gradient={k: float(getattr(tr.gains, k)) for k in TUNED}, random=rbest[1],
                       gradient_success=int(g_ok.sum()), random_success=int(r_ok.sum()))
            for name, ok in (("gradient_vs_grid", g_ok), ("random_vs_grid", r_ok)):
                d, a, b = paired_bootstrap(ok, grid_ok, 2000)
                row[name] = dict(diff=d, lo=a, hi=b)
            d, a, b = paired_bootstrap(g_ok, r_ok, 2000)
            row["gradient_vs_random"] = dict(diff=d, lo=a, hi=b)
            rows.append(row)
            log(f"[seeds {time.perf_counter() - t_all:5.0f} s] {lab} seed {seed}: gradient {g_ok.mean():.3f} "
                f"random {r_ok.mean():.3f} (grid {grid_ok.mean():.3f})")
        res["methods"][lab] = dict(grid=best[1], grid_success=int(grid_ok.sum()), n=args.n_eval, rows=rows)
    res["seconds"] = time.perf_counter() - t_all
    with open(out + ".json", "w", encoding="utf-8") as fh:
        json.dump(res, fh, indent=1)
    L = ["# Tuning: the spread over tuner seeds (held-out success, paired with the grid's choice)", "",
         f"- command: `{shlex.join(['python', 'benchmarks/tuning_seeds.py', *given])}`; wall time "
         f"{res['seconds']:.0f} s; training seed {args.train_seed} ({args.n_train} scenes), held-out seed "
         f"{args.eval_seed} ({args.n_eval} scenes, {args.max_steps} steps); budget {args.budget} rollouts each",
         f"- the gradient as `benchmarks/tuning.py` runs it with these arguments (same space, sigma, step, clip; "
         f"{args.budget // (2 * args.pairs)} updates of {args.pairs} pairs); random search log-uniform in the grid's "
         "box, same choice rule; success % [95 % Wilson]; differences in points [95 % paired bootstrap]",
         "", "| model | seed | gradient | random | gradient - grid | random - grid | gradient - random |",
         "|---|---|---|---|---|---|---|"]

    def pt(x):
        return f"{100 * x['diff']:+.1f} [{100 * x['lo']:+.1f}, {100 * x['hi']:+.1f}]"

    def pc(k, n):
        a, b = wilson(k, n)
        return f"{100 * k / n:.1f} [{100 * a:.1f}, {100 * b:.1f}]"

    for lab, r in res["methods"].items():
        L.append(f"| {lab} | grid {r['grid']['d0']:g}, {r['grid']['dt']:g}, {r['grid']['eta']:g} | "
                 f"{pc(r['grid_success'], r['n'])} | | | | |")
        for row in r["rows"]:
            L.append(f"| {lab} | {row['seed']} | {pc(row['gradient_success'], r['n'])} | "
                     f"{pc(row['random_success'], r['n'])} | {pt(row['gradient_vs_grid'])} | "
                     f"{pt(row['random_vs_grid'])} | {pt(row['gradient_vs_random'])} |")
        g = np.array([row["gradient_success"] for row in r["rows"]]) / r["n"]
        rr = np.array([row["random_success"] for row in r["rows"]]) / r["n"]
        L.append(f"| {lab} | mean (min-max) | {100 * g.mean():.1f} ({100 * g.min():.1f}-{100 * g.max():.1f}) | "
                 f"{100 * rr.mean():.1f} ({100 * rr.min():.1f}-{100 * rr.max():.1f}) | "
                 f"{100 * (g.mean() - r['grid_success'] / r['n']):+.1f} | "
                 f"{100 * (rr.mean() - r['grid_success'] / r['n']):+.1f} | {100 * (g - rr).mean():+.1f} |")
    with open(out + ".md", "w", encoding="utf-8") as fh:
        fh.write("\n".join(L) + "\n")
    log(f"wrote {out}.md and {out}.json")
    return res


if __name__ == "__main__":
    main()
