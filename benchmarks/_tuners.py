"""The second part of ``tuning.py`` (``--tuners``): the gradient tuner against the tuners
practitioners reach for first (Optuna's TPE, CMA-ES), at equal rollouts, on constant gains and
on the goal-distance gain function, judged on held-out scenes over several tuner seeds.

One command regenerates the comparison (progress on stderr; about 25 min on 2 CPUs)::

    python benchmarks/tuning.py --tuners            # train seed 0 (64 scenes), held-out seed 1 (1,024), 5 tuner seeds
    python benchmarks/tuning.py --tuners --quick    # smoke run, written to benchmarks/results/quick/

Every tuner sees the same training scenes and the same objective, the mean
:func:`softplan_jax.tuning.rollout_score` with ``--weights`` (default the recipe's
:data:`~softplan_jax.tuning._tuner.RECIPE_WEIGHTS`: failures, progress and the time to a
plan), of the library's default planner (``--train-steps`` steps), and the same budget
of ``--budget`` rollouts. Two parameter spaces:

* **const**: d0 and dt (eta at the start's 0.002), the issue's setting: log d0 and the
  logit of dt's fraction of the Euler bound (``GainSpace(("d0", "dt"), stable_dt=True)``);
* **fn**: the recipe's gain function (:data:`~softplan_jax.tuning._tuner.RECIPE_SPACE`):
  d0, dt and a ``--goal-knots``-knot goal-distance profile of k_att, v_max, eta and d0
  (2 + 4 K parameters; all zeros: the constant gains).

The tuners, per space and tuner seed:

* **tpe**: Optuna's ``TPESampler(seed=s)`` (its defaults: 10 random start-up trials,
  independent Parzen estimators), each trial one setting on all ``--n-train`` training
  scenes (a deterministic objective, fixed escape keys), ``budget / n_train`` trials, over
  the box d0 0.07-0.4, dt 0.1-0.8 (log-uniform, the grid's box) and each profile entry in
  [-1.5, 1.5]; the choice: the best trial.
* **cma**: CMA-ES (``cma``, Hansen's implementation) from the start with
  ``CMA_stds`` = the gradient's smoothing scales (its first population is the
  gradient's smoothing distribution), population ``--cma-popsize``, each candidate on
  all training scenes; the choice: its final mean (``xfavorite``) when it ends on a
  generation, else the best candidate.
* **grad**: :func:`softplan_jax.tuning.tune_smoothed` with its recipe (natural gradient,
  step 3.75, clip 0.3, mean of the last third of the iterates), ``budget / (2 pairs)``
  updates of ``--pairs`` antithetic pairs, tuner seed ``s``; fn: ``tune_smoothed(train)``'s
  own defaults.
* and once: **default** gains; **grid** (the grid of ``benchmarks/science.py``, d0 x dt x
  eta, 60 settings on all training scenes, the best mean score; 60 x 64 rollouts).

All start from the recipe's start (:func:`~softplan_jax.tuning._tuner.recipe_start`, the
grid box's geometric centre). Held-out: every choice on ``random_scenarios(eval seed,
n_eval)``, ``--max-steps`` steps: success (reached without collision, Wilson 95 %
intervals), steps to the goal, tip path length, the held-out score (the tuning
objective at the held-out length), and the time to a plan with the fallback
(steps where reached, else ``max_steps`` + the fallback's ``--fallback-steps``).
Paired comparisons on the same scenes (bootstrap 95 % intervals over scenes). Writes
``results/tuners.{md,json}`` and ``results/figures/tuners.png``.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from _stats import paired_bootstrap, pct_interval  # noqa: E402

TUNERS = ("tpe", "cma", "grad")
SPACES = ("const", "fn")
BOX = dict(d0=(0.07, 0.4), dt=(0.1, 0.8))
PROFILE_BOX = (-1.5, 1.5)


def parse_args(argv=None):
    from _common import held_out_parser

    ap = held_out_parser(__doc__, "rollout steps when tuning (default 100; quick 30)",
                         "rollout steps held out (default 150; quick 40)")
    ap.add_argument("--budget", type=int, default=None, help="rollouts per tuner run (default 3072; quick 32)")
    ap.add_argument("--pairs", type=int, default=None, help="the gradient's antithetic pairs (default 32; quick 4)")
    ap.add_argument("--seeds", default=None, help="comma list of tuner seeds (default 0,1,2,3,4; quick 0,1)")
    ap.add_argument("--goal-knots", type=int, default=None, help="knots of the fn space's profile (default 6; quick 2)")
    ap.add_argument("--cma-popsize", type=int, default=None, help="CMA-ES population (default 6 const, 12 fn)")
    ap.add_argument("--fallback-steps", type=float, default=None,
                    help="the fallback's time in planner steps, for the time to a plan (default 5 x train steps)")
    ap.add_argument("--weights", default="steps=1",
                    help="the objective's ScoreWeights as name=value pairs over the defaults (default: the recipe)")
    ap.add_argument("--tuners", default=",".join(TUNERS), help="comma list of tpe, cma, grad")
    ap.add_argument("--spaces", default=",".join(SPACES), help="comma list of const, fn")
    ap.add_argument("--no-grid", action="store_true", help="skip the grid")
    ap.add_argument("--out", default=None, help="output prefix (default results/tuners or results/quick/tuners)")
    args = ap.parse_args(argv)
    q = args.quick
    defaults = dict(n_train=8 if q else 64, n_eval=16 if q else 1024, train_steps=30 if q else 100,
                    max_steps=40 if q else 150, budget=32 if q else 3072, pairs=4 if q else 32,
                    seeds="0,1" if q else "0,1,2,3,4", goal_knots=2 if q else 6)
    for k, v in defaults.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    for name in ("n_train", "n_eval", "train_steps", "max_steps", "budget", "pairs"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.goal_knots < 2:
        raise ValueError(f"--goal-knots must be >= 2, got {args.goal_knots}")
    try:
        args.seed_list = [int(s) for s in args.seeds.split(",")]
    except ValueError:
        raise ValueError(f"--seeds must be a comma list of ints, got {args.seeds!r}") from None
    args.tuner_list = [t for t in args.tuners.split(",") if t]
    args.space_list = [s for s in args.spaces.split(",") if s]
    if not args.tuner_list or set(args.tuner_list) - set(TUNERS):
        raise ValueError(f"--tuners must name some of {','.join(TUNERS)}, got {args.tuners!r}")
    if not args.space_list or set(args.space_list) - set(SPACES):
        raise ValueError(f"--spaces must name some of {','.join(SPACES)}, got {args.spaces!r}")
    if args.budget < args.n_train or args.budget < 2 * args.pairs:
        raise ValueError(f"--budget ({args.budget}) must cover one trial ({args.n_train}) and one gradient "
                         f"({2 * args.pairs})")
    args.weight_items = {}
    for item in filter(None, args.weights.split(",")):
        name, _, value = item.partition("=")
        try:
            args.weight_items[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--weights must be name=value pairs, got {item!r}") from None
    if args.fallback_steps is None:
        args.fallback_steps = 5.0 * args.train_steps
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import cma
    import jax.numpy as jnp
    import optuna
    from _common import finish_machine, log, machine_info, output_paths, write_results

    import softplan_jax as sp
    from softplan_jax.planning._planner import make_options
    from softplan_jax.tuning import GainSpace, ScoreWeights, rollout_score, score_batch, tune_smoothed
    from softplan_jax.tuning._objective import check_weights
    from softplan_jax.tuning._tuner import RECIPE_SPACE, recipe_sigma, recipe_start

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    weights = check_weights(ScoreWeights(**args.weight_items))
    t_all = time.perf_counter()
    machine = machine_info("float64")
    out, fig_dir = output_paths("tuners", args.quick, args.out)

    def stamp(msg):
        log(f"[tuners {time.perf_counter() - t_all:6.0f} s] {msg}")

    train = sp.random_scenarios(args.train_seed, args.n_train)
    heldout = sp.random_scenarios(args.eval_seed, args.n_eval)
    n_seg = train.q0.shape[-2]
    start = recipe_start(jnp.float64)
    opts = make_options("curve", 10)
    spaces = dict(const=GainSpace(("d0", "dt"), stable_dt=True), fn=RECIPE_SPACE._replace(goal_knots=args.goal_knots))
    bases = {k: v.base(start, n_seg) for k, v in spaces.items()}

    def mean_scores(thetas, space, base, key):
        """Mean training score of each setting (rows of thetas), every one on all training scenes
        with the same escape keys (one vmapped call per setting)."""
        esc = jax.random.split(key, args.n_train)
        out_ = []
        for th in np.atleast_2d(thetas):
            rep = jnp.repeat(jnp.asarray(th, jnp.float64)[None], args.n_train, axis=0)
            L, _, _ = score_batch(rep, space, base, train, esc, opts, args.train_steps, weights)
            out_.append(float(np.mean(np.asarray(L))))
        return out_

    def theta_box(space):
        """Per-coordinate (lo, hi) of the derivative-free tuners' search box, in theta units."""
        lo, hi = [], []
        for k in space.names:
            if k == "dt" and space.stable_dt:  # logit(dt k_att / 2)
                a, b = (math.log(v * float(start.k_att) / 2) - math.log1p(-v * float(start.k_att) / 2)
                        for v in BOX[k])
            else:
                a, b = (math.log(v) for v in BOX[k])
            lo.append(a)
            hi.append(b)
        extra = space.size - len(space.names)
        return np.array(lo + [PROFILE_BOX[0]] * extra), np.array(hi + [PROFILE_BOX[1]] * extra)

    def run_tpe(space, base, seed):
        lo, hi = theta_box(space)
        key = jax.random.PRNGKey(10_000 + seed)
        study = optuna.create_study(direction="minimize", sampler=optuna.samplers.TPESampler(seed=seed))
        trials = args.budget // args.n_train
        for i in range(trials):
            trial = study.ask()
            th = np.array([trial.suggest_float(f"x{j}", lo[j], hi[j]) for j in range(space.size)])
            v = mean_scores(th, space, base, key)[0]
            study.tell(trial, v)
            stamp(f"tpe {space_tag(space)} seed {seed}: trial {i + 1}/{trials} score {v:.4f} best {study.best_value:.4f}")
        best = study.best_trial
        return np.array([best.params[f"x{j}"] for j in range(space.size)]), trials * args.n_train

    def run_cma(space, base, seed):
        key = jax.random.PRNGKey(20_000 + seed)
        sig = np.asarray(recipe_sigma(space))
        pop = args.cma_popsize or (6 if space.size <= 3 else 12)
        es = cma.CMAEvolutionStrategy(np.asarray(space.encode(base)).tolist(), 1.0,
                                      dict(popsize=pop, seed=seed + 1, verbose=-9, CMA_stds=sig.tolist()))
        spent, best_v, gen = 0, math.inf, 0
        while spent + pop * args.n_train <= args.budget:
            xs = es.ask()
            vals = mean_scores(np.asarray(xs), space, base, key)
            es.tell(xs, vals)
            spent += pop * args.n_train
            gen += 1
            best_v = min(best_v, min(vals))
            stamp(f"cma {space_tag(space)} seed {seed}: generation {gen} mean score {np.mean(vals):.4f} "
                  f"best {best_v:.4f} ({spent} rollouts)")
        if spent == 0:  # the budget is below one generation: its best candidate of a partial one
            xs = es.ask()[: args.budget // args.n_train]
            vals = mean_scores(np.asarray(xs), space, base, key)
            spent = len(xs) * args.n_train
            return np.asarray(xs[int(np.argmin(vals))]), spent
        return np.asarray(es.result.xfavorite), spent

    def run_grad(space, base, seed):
        updates = max(1, args.budget // (2 * args.pairs))
        kw = dict(updates=updates, pairs=args.pairs, max_steps=args.train_steps, weights=weights, seed=seed,
                  progress=False)
        if space.goal_knots and space == RECIPE_SPACE and not args.quick:
            r = tune_smoothed(train, **kw)  # the recipe itself: tune_smoothed(train)'s defaults
        else:
            r = tune_smoothed(train, space, start, **kw)
        return np.asarray(r.theta), r.rollouts

    def space_tag(space):
        return "fn" if space.goal_knots else "const"

    def heldout_eval(gains):
        r = sp.plan_batch(heldout, gains=gains, max_steps=args.max_steps, seed=args.eval_seed)
        reached, collided = np.asarray(r.reached), np.asarray(r.collided)
        its = np.asarray(r.iterations)
        path = np.linalg.norm(np.diff(np.asarray(r.tip), axis=1), axis=-1).sum(1)
        # The tuning objective itself (rollout_score) at the held-out length.
        score = np.asarray(jax.vmap(lambda ro, sc: rollout_score(ro, sc, weights))(r, heldout))
        plan_time = np.where(reached, its, args.max_steps + args.fallback_steps)
        return dict(success=reached & ~collided, collided=collided, steps=its, path=path, score=score,
                    plan_time=plan_time)

    runs: dict = {}
    t0 = time.perf_counter()
    runs["default"] = dict(theta=None, gains=sp.default_gains(jnp.float64), rollouts=0, seconds=0.0)
    if not args.no_grid:
        grid = [(a, b, c) for a in (0.07, 0.1, 0.15, 0.2, 0.3, 0.4) for b in (0.1, 0.2, 0.4, 0.6, 0.8)
                for c in (0.001, 0.004)]
        if args.quick:
            grid = grid[::15]
        g3 = GainSpace(("d0", "dt", "eta"))
        b3 = g3.base(start, n_seg)
        thetas = np.log(np.asarray(grid))
        t0 = time.perf_counter()
        vals = []
        for i, th in enumerate(thetas):
            vals += mean_scores(th, g3, b3, jax.random.PRNGKey(0))
            stamp(f"grid {i + 1}/{len(grid)} d0, dt, eta = {grid[i]}: score {vals[-1]:.4f}")
        best = int(np.argmin(vals))
        runs["grid"] = dict(theta=thetas[best], gains=g3.decode(jnp.asarray(thetas[best]), b3),
                            rollouts=len(grid) * args.n_train, seconds=time.perf_counter() - t0)
    runner = dict(tpe=run_tpe, cma=run_cma, grad=run_grad)
    for space_name in args.space_list:
        space, base = spaces[space_name], bases[space_name]
        for tuner in args.tuner_list:
            for seed in args.seed_list:
                name = f"{tuner}-{space_name}/{seed}"
                stamp(f"=== {name}")
                t0 = time.perf_counter()
                theta, spent = runner[tuner](space, base, seed)
                runs[name] = dict(theta=theta, gains=space.decode(jnp.asarray(theta, jnp.float64), base),
                                  rollouts=spent, seconds=time.perf_counter() - t0)
                stamp(f"{name}: {spent} rollouts, {runs[name]['seconds']:.1f} s")
    stamp(f"held-out: {len(runs)} settings on {args.n_eval} scenes")
    evals = {}
    for name, run in runs.items():
        evals[name] = heldout_eval(run["gains"])
        e = evals[name]
        stamp(f"held-out {name}: success {e['success'].mean():.3f}, score {e['score'].mean():.4f}")
    report = summarise(args, runs, evals, weights)
    report["machine"] = finish_machine(machine)
    report["wall_seconds"] = time.perf_counter() - t_all
    md = markdown(args, report)
    write_results(out, report, md)
    figure(report, os.path.join(fig_dir, "tuners.png"))
    stamp(f"wrote {out}.md and .json, {os.path.join(fig_dir, 'tuners.png')}")
    print(md)
    return report


def _boot_ratio(a, b, n_boot=10_000, seed=0):
    """mean(a) / mean(b) of paired samples with a 95 % bootstrap interval over the pairs."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(a), size=(n_boot, len(a)))
    r = a[idx].mean(1) / b[idx].mean(1)
    return float(a.mean() / b.mean()), float(np.percentile(r, 2.5)), float(np.percentile(r, 97.5))


def summarise(args, runs, evals, weights) -> dict:
    """Per-setting held-out rows, per-tuner seed summaries (worst seed included) and the paired
    comparisons of the targets."""
    rows = {}
    for name, e in evals.items():
        n = len(e["success"])
        ok = e["success"]
        run = runs[name]
        g = run["gains"]
        rows[name] = dict(
            success=int(ok.sum()), n=n, success_pct=100 * ok.mean(), success_ci=pct_interval(int(ok.sum()), n),
            collided=int(e["collided"].sum()), steps_reached=float(e["steps"][ok].mean()) if ok.any() else None,
            path_reached=float(e["path"][ok].mean()) if ok.any() else None, score=float(e["score"].mean()),
            plan_time=float(e["plan_time"].mean()), rollouts=run["rollouts"], seconds=run["seconds"],
            d0=float(g.d0), dt=float(g.dt), eta=float(g.eta),
            goal_profile=None if getattr(g, "goal_profile", None) is None else np.asarray(g.goal_profile).tolist())
    groups = {}
    for name in rows:
        if "/" in name:
            groups.setdefault(name.split("/")[0], []).append(name)
    summary = {}
    for grp, names in groups.items():
        sc = [rows[n]["score"] for n in names]
        su = [rows[n]["success_pct"] for n in names]
        st = [rows[n]["steps_reached"] for n in names]
        summary[grp] = dict(seeds=len(names), score_mean=float(np.mean(sc)), score_worst=float(np.max(sc)),
                            success_mean=float(np.mean(su)), success_worst=float(np.min(su)),
                            steps_mean=float(np.mean(st)), steps_worst=float(np.max(st)),
                            plan_time_mean=float(np.mean([rows[n]["plan_time"] for n in names])),
                            seconds_mean=float(np.mean([rows[n]["seconds"] for n in names])),
                            rollouts=rows[names[0]]["rollouts"])
    paired = []

    def compare(a, b, label):
        ea, eb = evals[a], evals[b]
        d = paired_bootstrap(ea["success"], eb["success"])
        both = ea["success"] & eb["success"]
        ratio = _boot_ratio(ea["steps"][both], eb["steps"][both]) if both.sum() > 1 else (None, None, None)
        sd = paired_bootstrap(ea["score"], eb["score"])  # works for floats: the mean difference
        tr = _boot_ratio(ea["plan_time"], eb["plan_time"])
        paired.append(dict(a=a, b=b, label=label, success_diff=[100 * x for x in d], steps_ratio=list(ratio),
                           both_reached=int(both.sum()), score_diff=list(sd), plan_time_ratio=list(tr)))

    seeds = args.seed_list
    # Target 1: the gradient-tuned function against TPE's best constant gains (the seed with the best
    # held-out success: the strongest opponent), seed by seed.
    if "grad-fn" in groups and "tpe-const" in groups:
        best_tpe = max(groups["tpe-const"], key=lambda n: (rows[n]["success_pct"], -rows[n]["score"]))
        for s in seeds:
            compare(f"grad-fn/{s}", best_tpe, "target 1: the function vs TPE's best constants")
    # Target 2: on the function, the gradient against TPE and CMA-ES at equal rollouts, seed by seed
    # (same seed index), and the worst gradient seed against the best opponent seed.
    for opp in ("tpe-fn", "cma-fn"):
        if "grad-fn" in groups and opp in groups:
            for s in seeds:
                compare(f"grad-fn/{s}", f"{opp}/{s}", f"target 2: gradient vs {opp.split('-')[0]} on the function")
            worst = max(groups["grad-fn"], key=lambda n: rows[n]["score"])
            best = min(groups[opp], key=lambda n: rows[n]["score"])
            compare(worst, best, f"target 2, worst gradient seed vs best {opp.split('-')[0]} seed")
    if "grad-const" in groups and "tpe-const" in groups:
        for s in seeds:
            compare(f"grad-const/{s}", f"tpe-const/{s}", "constants: gradient vs TPE")
    if "grid" in rows and "grad-fn" in groups:
        for s in seeds:
            compare(f"grad-fn/{s}", "grid", "the function vs the grid")
    return dict(args={k: v for k, v in vars(args).items()}, weights=weights._asdict(), rows=rows, summary=summary,
                paired=paired)


def _f(x, fmt="{:.1f}"):
    return "–" if x is None else fmt.format(x)


def markdown(args, rep) -> str:
    from _common import machine_lines

    rows, summary, paired = rep["rows"], rep["summary"], rep["paired"]
    L = ["# Tuners at equal rollouts: the gradient against Optuna's TPE and CMA-ES (held-out scenes)", ""]
    L += machine_lines(rep["machine"])
    L += [f"- command: `python benchmarks/tuning.py --tuners{' --quick' if args.quick else ''}`, one process; wall "
          f"{rep['wall_seconds']:.0f} s, compile included",
          f"- training: `random_scenarios({args.train_seed}, {args.n_train})`, {args.train_steps} steps; held-out: "
          f"`random_scenarios({args.eval_seed}, {args.n_eval})`, {args.max_steps} steps; tuner seeds {args.seeds}; "
          f"budget {args.budget} rollouts per run",
          f"- objective (every tuner): mean rollout_score with {rep['weights']}",
          f"- fn: d0, dt and a {args.goal_knots}-knot goal-distance profile of k_att, v_max, eta, d0 "
          f"({2 + 4 * args.goal_knots} parameters); const: d0, dt",
          f"- time to a plan: steps where reached, else {args.max_steps} + the fallback's "
          f"{args.fallback_steps:g} steps",
          "- success: reached without collision, count (% [Wilson 95 %]); steps and path: mean over the scenes "
          "that setting reached", ""]
    L += ["## Per tuner, over the seeds", "",
          "| tuner | space | seeds | rollouts | wall per run (s) | held-out score, mean / worst | success %, "
          "mean / worst | steps, mean / worst | time to a plan (steps) |", "|---|---|---|---|---|---|---|---|---|"]
    for grp, s in summary.items():
        t, sp_ = grp.split("-")
        L.append(f"| {t} | {sp_} | {s['seeds']} | {s['rollouts']} | {s['seconds_mean']:.1f} | {s['score_mean']:.4f} / "
                 f"{s['score_worst']:.4f} | {s['success_mean']:.1f} / {s['success_worst']:.1f} | "
                 f"{s['steps_mean']:.1f} / {s['steps_worst']:.1f} | {s['plan_time_mean']:.1f} |")
    L += ["", "## Every setting", "",
          "| setting | d0, dt, eta | rollouts | wall (s) | success | collided | steps | path | score | time to a plan |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        prof = " + profile" if r["goal_profile"] is not None else ""
        L.append(f"| {name} | {r['d0']:.3g}, {r['dt']:.3g}, {r['eta']:.3g}{prof} | {r['rollouts']} | "
                 f"{r['seconds']:.1f} | {r['success']} ({r['success_ci']}) | {r['collided']} | "
                 f"{_f(r['steps_reached'])} | {_f(r['path_reached'], '{:.2f}')} | {r['score']:.4f} | "
                 f"{r['plan_time']:.1f} |")
    L += ["", "## Paired comparisons (held-out, same scenes)", "",
          "| comparison | a | b | success a - b, points [95 %] | steps a / b on both reached [95 %] | "
          "score a - b [95 %] | time to a plan a / b [95 %] |", "|---|---|---|---|---|---|---|"]
    for p in paired:
        d, r, s, t = p["success_diff"], p["steps_ratio"], p["score_diff"], p["plan_time_ratio"]
        ratio = "–" if r[0] is None else f"{r[0]:.3f} [{r[1]:.3f}, {r[2]:.3f}] ({p['both_reached']})"
        L.append(f"| {p['label']} | {p['a']} | {p['b']} | {d[0]:+.1f} [{d[1]:+.1f}, {d[2]:+.1f}] | {ratio} | "
                 f"{s[0]:+.4f} [{s[1]:+.4f}, {s[2]:+.4f}] | {t[0]:.3f} [{t[1]:.3f}, {t[2]:.3f}] |")
    L += ["", "## Targets", ""] + targets(rep)
    return "\n".join(L) + "\n"


def targets(rep) -> list:
    """The issue's targets, judged from the paired comparisons (met / missed, by how much)."""
    out = []
    t1 = [p for p in rep["paired"] if p["label"].startswith("target 1")]
    if t1:
        succ = [p["success_diff"] for p in t1]
        steps = [p["steps_ratio"] for p in t1]
        by_success = [d[1] > 0 and d[0] >= 2 for d in succ]
        # -10 % steps "at equal success": success not lower, the ratio's interval below 1
        by_steps = [r[0] is not None and r[2] < 1 and r[0] <= 0.9 and d[0] >= 0
                    for r, d in zip(steps, succ, strict=True)]
        ok = [a or b for a, b in zip(by_success, by_steps, strict=True)]
        out.append(f"- target 1 (function vs TPE's best constants, +2 points or -10 % steps, interval excluding 0): "
                   f"**{'met' if all(ok) else 'missed'}** for {sum(ok)} of {len(ok)} gradient seeds; success "
                   f"differences {', '.join(f'{d[0]:+.1f} [{d[1]:+.1f}, {d[2]:+.1f}]' for d in succ)}; step ratios "
                   f"{', '.join('–' if r[0] is None else f'{r[0]:.3f} [{r[1]:.3f}, {r[2]:.3f}]' for r in steps)}")
    for opp in ("tpe", "cma"):
        t2 = [p for p in rep["paired"] if p["label"] == f"target 2: gradient vs {opp} on the function"]
        worst = [p for p in rep["paired"] if p["label"] == f"target 2, worst gradient seed vs best {opp} seed"]
        if t2:
            wins = [p["score_diff"][2] < 0 for p in t2]
            w = worst[0]["score_diff"] if worst else None
            out.append(f"- target 2 (gradient vs {opp.upper()} on the function, held-out score, lower is better): "
                       f"gradient better with an interval excluding 0 for {sum(wins)} of {len(wins)} seeds; worst "
                       f"gradient seed vs best {opp.upper()} seed {w[0]:+.4f} [{w[1]:+.4f}, {w[2]:+.4f}]: "
                       f"**{'met' if all(wins) and w is not None and w[2] < 0 else 'missed'}**")
    return out


def figure(rep, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = rep["rows"]
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"tpe": "tab:orange", "cma": "tab:green", "grad": "tab:blue"}
    markers = {"const": "o", "fn": "^"}
    groups = sorted({n.split("/")[0] for n in rows if "/" in n})
    for i, grp in enumerate(groups):
        t, s = grp.split("-")
        names = [n for n in rows if n.split("/")[0] == grp]
        x = [rows[n]["steps_reached"] for n in names]
        y = [rows[n]["success_pct"] for n in names]
        lab = f"{t.upper() if t != 'grad' else 'gradient'} ({'constants' if s == 'const' else 'function'})"
        ax1.scatter(x, y, c=colours[t], marker=markers[s], label=lab, alpha=0.8)
        ax2.scatter([i] * len(names), [rows[n]["score"] for n in names], c=colours[t], marker=markers[s], alpha=0.8)
    for ref, st in (("default", "x"), ("grid", "s")):
        if ref in rows:
            ax1.scatter([rows[ref]["steps_reached"]], [rows[ref]["success_pct"]], c="k", marker=st, label=ref)
    ax1.set_xlabel("mean steps to the goal (scenes reached)")
    ax1.set_ylabel("held-out success (%)")
    ax1.set_title("Held-out success and speed, one point per tuner seed")
    ax1.legend(fontsize=7)
    ax2.set_xticks(range(len(groups)))
    ax2.set_xticklabels(groups, rotation=30, fontsize=8)
    ax2.set_ylabel("held-out score (the tuning objective; lower is better)")
    ax2.set_title(f"Equal budgets ({rep['args']['budget']} rollouts per run)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    try:
        main()
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
