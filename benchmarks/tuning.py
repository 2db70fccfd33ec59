"""Does the gradient tuner beat the other tuners at equal budgets, on held-out scenes? Two parts:
gradient tuning of constant gains against grid, random and CMA-ES search (this module), and
``--tuners``: the recipe's gain function against Optuna's TPE and CMA-ES over several tuner
seeds (``_tuners.py``, its own options and report, ``results/tuners``).

One command regenerates each part, in one process (progress on stderr)::

    python benchmarks/tuning.py            # train seed 0 (64 scenes), held-out seed 1 (1,024 scenes)
    python benchmarks/tuning.py --quick    # smoke run, written to benchmarks/results/quick/
    python benchmarks/tuning.py --tuners [--quick]

Every rollout is the library's default planner (safe step, escapes, collision
checks in the scan). Per obstacle model (curve, N = 10, N = 50):

1. **grid**: the grid of ``benchmarks/science.py`` (d0 x dt x eta, 60 settings)
   on all training scenes; choice = best ``reached - 3 collided``.
   Budget: B_grid = 60 x 64 = 3,840 rollouts of ``--train-steps`` steps.
2. **random search**: B_grid / ``--fraction`` rollouts: settings drawn
   log-uniformly in the grid's box, each on all training scenes, same choice rule.
3. **CMA-ES** (``cma``, Hansen's reference implementation: the well-kept
   derivative-free optimiser for a few continuous parameters with noisy
   evaluations; log d0, log dt, log eta from the grid box's geometric centre, sigma0 0.5,
   population ``--cma-popsize``): each candidate is scored by the mean
   :func:`softplan_jax.tuning.smoothing.rollout_score` (the gradient's score) on a
   minibatch of ``--pairs`` training scenes shared by the generation;
   B_grid / ``--fraction`` rollouts; its final mean is the choice. ``cma-g``:
   the same on the gradient's parameter space, with the gradient's per-coordinate
   scales (``CMA_stds`` proportional to ``--sigma``, geometric mean 1): the control for it.
4. **gradient**: :func:`softplan_jax.tuning.smoothing.tune_smoothed` (its defaults:
   SGD with momentum 0.5, step ``--lr`` decaying to a tenth, the mean of the
   last third of the iterates) from the same centre, B_grid / ``--fraction``
   rollouts (updates x 2 x pairs), on ``--grad-names`` (default d0 and dt; eta
   stays at the centre: its gradient is noise on the validation seed) with
   ``dt`` parametrised against the Euler
   step's stability bound (``GainSpace(stable_dt=True)``), sigma ``--sigma``
   (one per tuned gain: 0.3 for log d0, 0.7 for dt's logit), stepping along the
   natural gradient ``sigma^2 grad J`` (``--natural``), each update clipped to
   ``--max-step`` per coordinate (``--box``: projected onto the grid's box
   instead or as well; validation chose the clip).
5. **gain function** (beyond the grid's reach; with the ablation
   ``gradient+``: the same extra updates on the three gains alone): the 20-parameter
   :class:`~softplan_jax.planning._planner.GainFunction` space (log d0, dt, eta; a
   14-knot repulsion profile over d / d0; 3 segment weights),
   ``tune_smoothed`` from the gradient's result for ``--fn-updates`` more
   updates of ``--fn-pairs`` pairs: dt as in the gradient's space
   (``--fn-stable-dt``), sigma ``--fn-gain-sigma`` for d0, dt, eta and
   ``--fn-sigma`` for the profile and the weights, the natural gradient from
   step ``--fn-lr`` (``--fn-natural``), clipped as the gradient's.

The tuners' settings (start, optimiser, step size, pairs, averaging) were
chosen on a validation seed (``random_scenarios(2, 256)``), never on the
held-out one; the validation scripts and logs (``benchmarks/tuning_validation/``),
and the rerun of the gradient and random search with tuner seeds 0-4
(``tuning_seeds.py``), left the folder; git keeps them.

Held-out: every choice (and the default gains) on ``random_scenarios(eval
seed, n_eval)``, ``--max-steps`` steps; success = reached without collision;
Wilson 95 % intervals; paired comparisons on the same scenes (exact McNemar,
paired bootstrap of the difference); tip path length of the scenes both
settings reached. Writes ``results/tuning.{md,json}`` and
``results/figures/tuning_*.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from _stats import mcnemar_exact, paired_bootstrap, pct_interval, wilson  # noqa: E402

TUNED = ("d0", "dt", "eta")
SETTINGS = ("default", "grid", "random", "cma", "cma-g", "gradient", "gradient+", "function")


def parse_args(argv=None):
    from _common import held_out_parser

    ap = held_out_parser(__doc__, "rollout steps when tuning (default 100)",
                         "rollout steps held out (default 150)")
    ap.add_argument("--methods", default=None, help="comma list of curve and point counts N (default curve,10,50)")
    ap.add_argument("--grid-d0", default="0.07,0.1,0.15,0.2,0.3,0.4")
    ap.add_argument("--grid-dt", default="0.1,0.2,0.4,0.6,0.8")
    ap.add_argument("--grid-eta", default="0.001,0.004")
    ap.add_argument("--fraction", type=float, default=5.0,
                    help="budget of random / CMA / gradient = grid's / this (a number >= 1, e.g. 2.5)")
    ap.add_argument("--pairs", type=int, default=None, help="antithetic pairs per gradient (default 16; quick 4)")
    ap.add_argument("--sigma", default="0.3,0.7", help="the gradient's smoothing scale (theta units): one number, "
                    "or one per --grad-names entry")
    ap.add_argument("--natural", action=argparse.BooleanOptionalAction, default=True,
                    help="the gradient's step along the natural gradient sigma^2 * grad J (tune_smoothed natural=)")
    ap.add_argument("--lr", type=float, default=3.75, help="the gradient's first step size (cosine decay to a tenth; "
                    "with --natural in units of sigma^2)")
    ap.add_argument("--grad-names", default="d0,dt", help="gains the gradient tunes (the others stay at the start)")
    ap.add_argument("--stable-dt", action=argparse.BooleanOptionalAction, default=True,
                    help="the gradient's dt as logit(dt k_att / 2) (GainSpace(stable_dt=True))")
    ap.add_argument("--box", action=argparse.BooleanOptionalAction, default=False,
                    help="project the gradient's iterates onto the grid's box (tune_smoothed bounds=)")
    ap.add_argument("--max-step", type=float, default=0.3,
                    help="clip each coordinate of each gradient update (theta units; 0: no clipping)")
    ap.add_argument("--fn-stable-dt", action=argparse.BooleanOptionalAction, default=True,
                    help="the gain-function stage (and its ablation) with dt as logit(dt k_att / 2)")
    ap.add_argument("--fn-gain-sigma", default="0.3,0.7,0.3",
                    help="smoothing scales of d0, dt, eta in the gain-function stage and its ablation")
    ap.add_argument("--fn-sigma", type=float, default=0.3,
                    help="smoothing scale of the repulsion profile and the segment weights")
    ap.add_argument("--fn-natural", action=argparse.BooleanOptionalAction, default=True,
                    help="the gain-function stage (and its ablation) along the natural gradient")
    ap.add_argument("--fn-lr", type=float, default=3.75, help="first step size of the gain-function stage")
    ap.add_argument("--start", choices=("centre", "default"), default="centre",
                    help="start of CMA-ES and the gradient: the grid box's geometric centre, or the default gains")
    ap.add_argument("--fn-updates", type=int, default=None, help="updates of the gain function (default 24)")
    ap.add_argument("--fn-pairs", type=int, default=None, help="antithetic pairs per update of the gain function "
                    "(default 32; quick 4)")
    ap.add_argument("--fn-knots", type=int, default=14)
    ap.add_argument("--cma-popsize", type=int, default=6)
    ap.add_argument("--chunk", type=int, default=None, help="scenes per vmapped call (default 64; quick 8)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the tuners' draws")
    ap.add_argument("--out", default=None, help="output prefix (default results/tuning or results/quick/tuning)")
    args = ap.parse_args(argv)
    q = args.quick
    defaults = dict(n_train=8 if q else 64, n_eval=16 if q else 1024, train_steps=30 if q else 100,
                    max_steps=40 if q else 150, pairs=4 if q else 16, fn_pairs=4 if q else 32,
                    fn_updates=2 if q else 24,
                    chunk=8 if q else 64, methods="curve" if q else "curve,10,50")
    for k, v in defaults.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    args.method_list = [m if m == "curve" else int(m) for m in args.methods.split(",")]
    args.grid_axes = {k: sorted(float(x) for x in getattr(args, f"grid_{k}").split(",")) for k in TUNED}
    if q:
        args.grid_axes = {k: v[:: max(1, len(v) // 2)] for k, v in args.grid_axes.items()}
    args.grid = [(a, b, c) for a in args.grid_axes["d0"] for b in args.grid_axes["dt"] for c in args.grid_axes["eta"]]
    if not math.isfinite(args.fraction):
        raise ValueError(f"--fraction must be finite, got {args.fraction}")
    for name in ("n_train", "n_eval", "train_steps", "max_steps", "fraction", "fn_updates", "chunk", "cma_popsize"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if min(args.pairs, args.fn_pairs, args.fn_knots) < 2:
        raise ValueError("--pairs, --fn-pairs and --fn-knots must be >= 2")
    for name in ("sigma", "fn_gain_sigma"):
        try:
            setattr(args, name, [float(x) for x in str(getattr(args, name)).split(",")])
        except ValueError:
            raise ValueError(f"--{name.replace('_', '-')} must be a number or a comma list of numbers, "
                             f"got {getattr(args, name)!r}") from None
    if not all(math.isfinite(v) and v > 0 for v in (*args.sigma, *args.fn_gain_sigma, args.lr, args.fn_sigma,
                                                     args.fn_lr)):
        raise ValueError("--sigma, --lr, --fn-gain-sigma, --fn-sigma and --fn-lr must be finite and > 0")
    if len(args.fn_gain_sigma) not in (1, len(TUNED)):
        raise ValueError(f"--fn-gain-sigma must give one number or {len(TUNED)} (d0, dt, eta), "
                         f"got {len(args.fn_gain_sigma)}")
    if not (math.isfinite(args.max_step) and args.max_step >= 0):
        raise ValueError(f"--max-step must be finite and >= 0, got {args.max_step}")
    args.grad_names = tuple(args.grad_names.split(","))
    if not args.grad_names or any(k not in TUNED for k in args.grad_names) or len(set(args.grad_names)) < len(
            args.grad_names) or len(args.grad_names) < 2:
        raise ValueError(f"--grad-names must be two or three distinct names of {','.join(TUNED)}")
    if len(args.sigma) not in (1, len(args.grad_names)):
        raise ValueError(f"--sigma must give one number or {len(args.grad_names)} (one per --grad-names entry), "
                         f"got {len(args.sigma)}")
    args.budget = int(len(args.grid) * args.n_train / args.fraction)
    if args.budget < 2 * args.pairs:
        raise ValueError(f"the budget ({args.budget} rollouts) is below one gradient (2 x {args.pairs} pairs)")
    return args


def mlabel(m) -> str:
    return "curve" if m == "curve" else f"N={m}"


def plan_kw(m) -> dict:
    return dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))


def box_centre(args) -> dict:
    """The grid box's geometric centre (the prior random search samples; the start of CMA-ES
    and the gradient unless ``--start default``)."""
    return {k: math.sqrt(args.grid_axes[k][0] * args.grid_axes[k][-1]) for k in TUNED}


def draw_in_box(args, rng) -> dict:
    """One random-search setting: d0, dt, eta log-uniform in the grid's box."""
    lo = np.log([args.grid_axes[k][0] for k in TUNED])
    hi = np.log([args.grid_axes[k][-1] for k in TUNED])
    return dict(zip(TUNED, np.exp(rng.uniform(lo, hi)).tolist(), strict=True))


def grad_kwargs(args) -> dict:
    """The gradient's step settings for :func:`softplan_jax.tuning.smoothing.tune_smoothed`:
    sigma (one, or one per tuned gain), the
    natural gradient, first step, and the guards (``--box``: the grid's box on the tuned
    gains; ``--max-step``)."""
    bounds = {k: (args.grid_axes[k][0], args.grid_axes[k][-1]) for k in args.grad_names} if args.box else None
    sigma = args.sigma[0] if len(args.sigma) == 1 else tuple(args.sigma)
    return dict(sigma=sigma, natural=args.natural, learning_rate=args.lr, bounds=bounds,
                max_step=args.max_step or None)


def fn_kwargs(args, space) -> dict:
    """The gain-function stage's settings for :func:`softplan_jax.tuning.smoothing.tune_smoothed` on
    ``space`` (the 20-parameter function, or its ablation on the three gains): sigma
    ``--fn-gain-sigma`` for d0, dt, eta and ``--fn-sigma`` for the profile and segment weights,
    the natural gradient (``--fn-natural``), first step ``--fn-lr``, the clip ``--max-step``."""
    gain_sigma = args.fn_gain_sigma * (len(TUNED) if len(args.fn_gain_sigma) == 1 else 1)
    sigma = tuple(gain_sigma) + (args.fn_sigma,) * (space.size - len(TUNED))
    return dict(sigma=sigma, natural=args.fn_natural, learning_rate=args.fn_lr, max_step=args.max_step or None)


def choice_key(reached, collided) -> tuple:
    """The grid's and random search's choice rule on the training scenes: the most
    ``reached - 3 collided``, then the most reached (the first such setting wins)."""
    return int(np.sum(reached)) - 3 * int(np.sum(collided)), int(np.sum(reached))


def main(argv=None) -> dict:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--tuners" in argv:  # the second part: the recipe against Optuna's TPE and CMA-ES, several tuner seeds
        import _tuners

        argv.remove("--tuners")
        return _tuners.main(argv)
    args = parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import cma
    import jax.numpy as jnp
    from _common import FIGURES_DIR, RESULTS_DIR, log, machine_info

    import softplan_jax as sp
    from softplan_jax.planning._planner import make_options
    from softplan_jax.tuning import GainSpace, ScoreWeights, score_batch, tune_smoothed

    t_all = time.perf_counter()
    machine = machine_info("float64")
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", "tuning")
    fig_dir = os.path.join(os.path.dirname(out), "figures") if args.quick or args.out else FIGURES_DIR
    os.makedirs(fig_dir, exist_ok=True)
    phases: dict = {}

    def stamp(msg):
        log(f"[tuning {time.perf_counter() - t_all:6.0f} s] {msg}")

    train = sp.random_scenarios(args.train_seed, args.n_train)
    heldout = sp.random_scenarios(args.eval_seed, args.n_eval)
    base = sp.default_gains(jnp.float64)
    space3 = GainSpace(TUNED)

    def with3(d):
        return base._replace(**{k: jnp.asarray(d[k], jnp.float64) for k in TUNED})

    # CMA-ES and the gradient start from the grid box's geometric centre (the prior random search
    # samples), or from the default gains (--start default).
    start = with3(box_centre(args)) if args.start == "centre" else base

    def evaluate(suite, gains, m, steps, seed):
        r = sp.plan_batch(suite, gains=gains, max_steps=steps, seed=seed, chunk=args.chunk, **plan_kw(m))
        tip = np.asarray(r.tip)
        return dict(reached=np.asarray(r.reached), collided=np.asarray(r.collided),
                    iterations=np.asarray(r.iterations),
                    status=[sp.planning.status_name(s) for s in np.asarray(r.status)],
                    path=np.linalg.norm(np.diff(tip, axis=1), axis=-1).sum(1))

    results: dict = dict(machine=machine, args={k: v for k, v in vars(args).items() if k != "grid"}, methods={})
    for m in args.method_list:
        lab = mlabel(m)
        stamp(f"=== {lab}")
        res: dict = dict(choices={}, cost={}, trace={})
        # ---- 1. grid
        t0 = time.perf_counter()
        rows = []
        for k, (d0, dt, eta) in enumerate(args.grid):
            e = evaluate(train, with3(dict(d0=d0, dt=dt, eta=eta)), m, args.train_steps, args.train_seed)
            rows.append(dict(d0=d0, dt=dt, eta=eta, score=choice_key(e["reached"], e["collided"])[0],
                             reached=int(e["reached"].sum()),
                             collided=int(e["collided"].sum())))
            stamp(f"grid {lab} {k + 1}/{len(args.grid)} d0={d0:g} dt={dt:g} eta={eta:g}: score {rows[-1]['score']}")
        best = max(rows, key=lambda r: (r["score"], r["reached"]))
        res["choices"]["grid"] = {k: best[k] for k in TUNED}
        res["cost"]["grid"] = dict(rollouts=len(rows) * args.n_train, seconds=time.perf_counter() - t0)
        res["grid_rows"] = rows
        # ---- 2. random search (same box, same choice rule)
        t0 = time.perf_counter()
        rng = np.random.default_rng(args.seed)
        n_cfg = args.budget // args.n_train
        rrows = []
        for k in range(n_cfg):
            d = draw_in_box(args, rng)
            e = evaluate(train, with3(d), m, args.train_steps, args.train_seed)
            rrows.append(dict(d, score=choice_key(e["reached"], e["collided"])[0], reached=int(e["reached"].sum())))
            stamp(f"random {lab} {k + 1}/{n_cfg} " + " ".join(f"{x}={d[x]:.3g}" for x in TUNED)
                  + f": score {rrows[-1]['score']}")
        rbest = max(rrows, key=lambda r: (r["score"], r["reached"]))
        res["choices"]["random"] = {k: rbest[k] for k in TUNED}
        res["cost"]["random"] = dict(rollouts=n_cfg * args.n_train, seconds=time.perf_counter() - t0)
        res["trace"]["random"] = rrows
        # ---- 3. CMA-ES on the gradient's score (minibatches of `pairs` scenes per generation): "cma" on the
        # three log-gains, "cma-g" on the gradient's own space (the control for its parametrisation)
        opts = make_options(**plan_kw(m))
        space_g = GainSpace(args.grad_names, stable_dt=args.stable_dt)

        for tag, space in (("cma", space3), ("cma-g", space_g)):
            t0 = time.perf_counter()
            per_call = 2  # two candidates per call: 2 x pairs rollouts, the gradient's batch shape (one program)
            cma_opts = dict(popsize=args.cma_popsize, seed=args.seed + 1, verbose=-9)
            if tag == "cma-g" and len(args.sigma) > 1:
                # the gradient's per-coordinate scales, at the same overall step (geometric mean 1)
                cma_opts["CMA_stds"] = (np.asarray(args.sigma) / np.exp(np.mean(np.log(args.sigma)))).tolist()
            es = cma.CMAEvolutionStrategy(np.asarray(space.encode(start)).tolist(), 0.5, cma_opts)
            spent, gen, ctrace = 0, 0, []
            key = jax.random.PRNGKey(args.seed + 7)
            while spent + args.cma_popsize * args.pairs <= args.budget:
                xs = es.ask()
                kg = jax.random.fold_in(key, gen)
                idx = jax.random.choice(kg, args.n_train, (args.pairs,), replace=args.pairs > args.n_train)
                esc = jax.random.split(jax.random.fold_in(kg, 1), args.pairs)
                vals = []
                for c in range(0, len(xs), per_call):
                    group = (xs[c : c + per_call] + [xs[-1]] * per_call)[:per_call]
                    thetas = jnp.repeat(jnp.asarray(group, jnp.float64), args.pairs, axis=0)
                    scenes = jax.tree_util.tree_map(lambda a, idx=idx: jnp.concatenate([a[idx]] * 2), train)
                    keys = jnp.concatenate([esc] * per_call)
                    L, _, _ = score_batch(thetas, space, base, scenes, keys, opts, args.train_steps, ScoreWeights())
                    L = np.asarray(L).reshape(per_call, args.pairs).mean(1)
                    vals += L[: min(per_call, len(xs) - c)].tolist()
                es.tell(xs, vals)
                spent += len(xs) * args.pairs
                gen += 1
                centre_g = space.decode(jnp.asarray(es.mean, jnp.float64), start)
                ctrace.append(dict(generation=gen, rollouts=spent, best=float(min(vals)), mean=float(np.mean(vals)),
                                   centre=[float(getattr(centre_g, k)) for k in TUNED]))
                stamp(f"{tag} {lab} generation {gen}: mean score {np.mean(vals):.4f} ({spent} rollouts) centre "
                      + " ".join(f"{x}={v:.3g}" for x, v in zip(TUNED, ctrace[-1]["centre"], strict=True)))
            final = space.decode(jnp.asarray(es.mean, jnp.float64), start)
            res["choices"][tag] = {k: float(getattr(final, k)) for k in TUNED}
            res["cost"][tag] = dict(rollouts=spent, seconds=time.perf_counter() - t0)
            res["trace"][tag] = ctrace
        # ---- 4. gradient (its space: --grad-names, --stable-dt), from the same start
        t0 = time.perf_counter()
        updates = args.budget // (2 * args.pairs)
        tr = tune_smoothed(train, space_g, start, updates=updates, pairs=args.pairs, max_steps=args.train_steps,
                           seed=args.seed, **grad_kwargs(args), **plan_kw(m))
        res["choices"]["gradient"] = {k: float(getattr(tr.gains, k)) for k in TUNED}
        res["cost"]["gradient"] = dict(rollouts=tr.rollouts, seconds=time.perf_counter() - t0,
                                       compile_seconds=tr.compile_seconds)
        res["trace"]["gradient"] = {k: np.asarray(v).tolist() for k, v in tr.history.items()}
        # ---- 5. the gain function (log d0, dt, eta + repulsion profile + segment weights), from the gradient's result
        t0 = time.perf_counter()
        n_seg = int(train.q0.shape[-2])
        fspace = GainSpace(TUNED, knots=args.fn_knots, segments=n_seg, stable_dt=args.fn_stable_dt)
        fr = tune_smoothed(train, fspace, tr.gains, updates=args.fn_updates, pairs=args.fn_pairs,
                           max_steps=args.train_steps, seed=args.seed + 1, **fn_kwargs(args, fspace), **plan_kw(m))
        fgains = fr.gains
        # ---- 5b. ablation: the same extra budget on the three gains alone ("gradient+")
        pspace = GainSpace(TUNED, stable_dt=args.fn_stable_dt)
        pr = tune_smoothed(train, pspace, tr.gains, updates=args.fn_updates, pairs=args.fn_pairs,
                           max_steps=args.train_steps, seed=args.seed + 1, **fn_kwargs(args, pspace), **plan_kw(m))
        res["choices"]["gradient+"] = {k: float(getattr(pr.gains, k)) for k in TUNED}
        res["cost"]["gradient+"] = dict(rollouts=tr.rollouts + pr.rollouts)
        res["trace"]["gradient+"] = {k: np.asarray(v).tolist() for k, v in pr.history.items()}
        res["choices"]["function"] = {k: np.asarray(v).tolist() for k, v in fgains._asdict().items()}
        res["cost"]["function"] = dict(rollouts=tr.rollouts + fr.rollouts, seconds=time.perf_counter() - t0,
                                       parameters=fspace.size)
        res["trace"]["function"] = {k: np.asarray(v).tolist() for k, v in fr.history.items()}
        # ---- held-out
        gains_of = dict(default=base, grid=with3(res["choices"]["grid"]), random=with3(res["choices"]["random"]),
                        cma=with3(res["choices"]["cma"]), gradient=tr.gains, function=fgains,
                        **{"cma-g": with3(res["choices"]["cma-g"])},
                        **{"gradient+": pr.gains})
        held = {}
        for name in SETTINGS:
            t0 = time.perf_counter()
            held[name] = evaluate(heldout, gains_of[name], m, args.max_steps, args.eval_seed)
            ok = held[name]["reached"] & ~held[name]["collided"]
            stamp(f"held-out {lab} {name}: success {pct_interval(int(ok.sum()), args.n_eval)}, "
                  f"collided {int(held[name]['collided'].sum())} ({time.perf_counter() - t0:.0f} s)")
        res["heldout"] = {name: dict(success=int((h["reached"] & ~h["collided"]).sum()),
                                     collided=int(h["collided"].sum()), n=args.n_eval,
                                     status="".join(s[0] for s in h["status"]),
                                     iterations=h["iterations"].tolist(), path=np.round(h["path"], 5).tolist())
                          for name, h in held.items()}
        res["paired"] = {}
        for a, b in (("gradient", "grid"), ("gradient", "random"), ("gradient", "cma"), ("gradient", "cma-g"),
                     ("gradient", "default"),
                     ("function", "grid"), ("function", "gradient+"), ("gradient+", "grid")):
            xa = held[a]["reached"] & ~held[a]["collided"]
            xb = held[b]["reached"] & ~held[b]["collided"]
            d, lo_, hi_ = paired_bootstrap(xa, xb, 5000)
            both = xa & xb
            res["paired"][f"{a} vs {b}"] = dict(
                only_a=int((xa & ~xb).sum()), only_b=int((~xa & xb).sum()),
                p=mcnemar_exact(int((xa & ~xb).sum()), int((~xa & xb).sum())), diff=d, lo=lo_, hi=hi_,
                both=int(both.sum()),
                path_a=float(held[a]["path"][both].mean()) if both.any() else float("nan"),
                path_b=float(held[b]["path"][both].mean()) if both.any() else float("nan"),
                iters_a=float(held[a]["iterations"][both].mean()) if both.any() else float("nan"),
                iters_b=float(held[b]["iterations"][both].mean()) if both.any() else float("nan"))
        results["methods"][lab] = res
        phases[lab] = time.perf_counter() - t_all - sum(phases.values())
    results["seconds"] = time.perf_counter() - t_all
    results["phases"] = phases
    machine["loadavg_end"] = [round(x, 2) for x in os.getloadavg()]
    with open(out + ".json", "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1)
    md = report(results, args)
    with open(out + ".md", "w", encoding="utf-8") as fh:
        fh.write(md)
    figures(results, args, fig_dir, sp)
    stamp(f"wrote {out}.md, {out}.json and figures in {fig_dir}")
    return results


def _fmt(d: dict) -> str:
    return ", ".join(f"{d[k]:.3g}" for k in TUNED)


def report(results: dict, args) -> str:
    mach = results["machine"]
    L = ["# Gradient tuning against grid, random and CMA-ES search (equal budgets, held-out scenes)", ""]
    L.append(f"- machine: {mach['platform']}, {mach['cpu']}, {mach['cpu_count']} CPUs; load average "
             f"{mach['loadavg_start']} at start, {mach.get('loadavg_end')} at end (shared machine)")
    L.append(f"- python {mach['python']}, numpy {mach['numpy']}, jax {mach['jax']}, softplan_jax "
             f"{mach['softplan_jax']}; float64")
    L.append(f"- command: `python benchmarks/tuning.py{' --quick' if args.quick else ''}`, one process; "
             f"wall time {results['seconds']:.0f} s, compile included")
    L.append(f"- training seed {args.train_seed} ({args.n_train} scenes, {args.train_steps} steps); held-out seed "
             f"{args.eval_seed} ({args.n_eval} scenes, {args.max_steps} steps); the library's default planner "
             "(safe step, escapes, collision checks)")
    L.append(f"- budgets in rollouts of {args.train_steps} steps: grid {len(args.grid)} x {args.n_train} = "
             f"{len(args.grid) * args.n_train}; random, CMA-ES and gradient {args.budget} (1/{args.fraction:g}); "
             f"gradient: {args.budget // (2 * args.pairs)} updates of {args.pairs} antithetic pairs on "
             f"{', '.join(args.grad_names)}{' (dt as logit(dt k_att / 2))' if args.stable_dt else ''}, sigma "
             f"{', '.join(f'{x:g}' for x in args.sigma)}, SGD from {args.lr:g}"
             f"{' along the natural gradient sigma^2 grad J' if args.natural else ''} (cosine to a tenth), mean of "
             "the last third of the iterates"
             f"{', projected onto the grid box' if args.box else ''}"
             f"{f', each update clipped to {args.max_step}' if args.max_step else ''}; "
             f"cma-g: CMA-ES on that same space{' with the same per-coordinate scales' if len(args.sigma) > 1 else ''}"
             "; start: "
             f"{'the grid box centre' if args.start == 'centre' else 'the default gains'}; gain function "
             f"({3 + args.fn_knots + 3} parameters): {args.fn_updates} more updates of {args.fn_pairs} pairs"
             f"{', dt as logit(dt k_att / 2)' if args.fn_stable_dt else ''}, sigma "
             f"{', '.join(f'{x:g}' for x in args.fn_gain_sigma)} (d0, dt, eta) and {args.fn_sigma:g} (profile, "
             f"weights), SGD from {args.fn_lr:g}{' along the natural gradient' if args.fn_natural else ''}"
             f"{f', clipped to {args.max_step}' if args.max_step else ''}")
    L.append("- success = reached without collision, count (% [95 % Wilson interval]); paired = same held-out "
             "scenes: discordant pairs, exact McNemar p, difference of success rates (points) with a 95 % "
             "paired-bootstrap interval")
    L.append("")
    L.append("## Held-out success")
    L.append("")
    L.append("| model | setting | d0, dt, eta | training rollouts | success | collided | mean its (reached) |")
    L.append("|---|---|---|---|---|---|---|")
    for lab, res in results["methods"].items():
        for name in SETTINGS:
            h = res["heldout"][name]
            ch = res["choices"].get(name)
            gains = "0.07, 0.1, 0.001" if name == "default" else _fmt(ch)
            if name == "function":
                gains += f" + {args.fn_knots}-knot profile, segment weights"
            cost = res["cost"].get(name, {}).get("rollouts", 0)
            its = [i for i, s in zip(h["iterations"], h["status"], strict=True) if s == "r"]
            lo, hi = wilson(h["success"], h["n"])
            mean_its = np.mean(its) if its else float("nan")
            L.append(f"| {lab} | {name} | {gains} | {cost} | {h['success']} ({100 * h['success'] / h['n']:.1f} % "
                     f"[{100 * lo:.1f}, {100 * hi:.1f}]) | {h['collided']} | {mean_its:.1f} |")
    L.append("")
    L.append("## Paired comparisons (held-out)")
    L.append("")
    L.append("| model | comparison | a only / b only, p | success diff a - b [95 %] | path length a / b (both reached) "
             "| its a / b |")
    L.append("|---|---|---|---|---|---|")
    for lab, res in results["methods"].items():
        for name, p in res["paired"].items():
            L.append(f"| {lab} | {name} | {p['only_a']} / {p['only_b']}, {p['p']:.2g} | {100 * p['diff']:+.1f} "
                     f"[{100 * p['lo']:+.1f}, {100 * p['hi']:+.1f}] | {p['path_a']:.3f} / {p['path_b']:.3f} "
                     f"| {p['iters_a']:.1f} / {p['iters_b']:.1f} |")
    L.append("")
    L.append("## Targets")
    L.append("")
    for lab, res in results["methods"].items():
        g, gr = res["heldout"]["gradient"], res["heldout"]["grid"]
        lo, _ = wilson(gr["success"], gr["n"])
        within = g["success"] / g["n"] >= lo
        rnd = res["paired"]["gradient vs random"]
        frac = res["cost"]["gradient"]["rollouts"] / res["cost"]["grid"]["rollouts"]
        if rnd["lo"] > 0:
            verdict = "**beats** it"
        elif rnd["diff"] > 0:
            verdict = "ahead, interval includes 0"
        else:
            verdict = "**does not beat** it"
        L.append(f"- {lab}: gradient {100 * g['success'] / g['n']:.1f} % with {frac:.2f} of the grid's rollouts vs "
                 f"grid {100 * gr['success'] / gr['n']:.1f} % (interval from {100 * lo:.1f} %): "
                 f"{'**met**' if within else '**missed**'}; vs random at equal budget {100 * rnd['diff']:+.1f} "
                 f"[{100 * rnd['lo']:+.1f}, {100 * rnd['hi']:+.1f}] points: {verdict}")
    for lab, res in results["methods"].items():
        f, gr, fp = res["heldout"]["function"], res["heldout"]["grid"], res["paired"]["function vs grid"]
        L.append(f"- {lab}: the {res['cost']['function']['parameters']}-parameter gain function "
                 f"{100 * f['success'] / f['n']:.1f} % vs the grid's 3-parameter setting "
                 f"{100 * gr['success'] / gr['n']:.1f} %, "
                 f"paired {100 * fp['diff']:+.1f} [{100 * fp['lo']:+.1f}, {100 * fp['hi']:+.1f}] points; tip path "
                 f"length on the {fp['both']} scenes both reached {fp['path_a']:.3f} vs {fp['path_b']:.3f} "
                 f"({res['cost']['function']['rollouts']} training rollouts in all)")
    L.append("")
    L.append("## Training traces")
    L.append("")
    for lab, res in results["methods"].items():
        t = res["trace"]["gradient"]
        J = ", ".join(f"{x:.3f}" for x in t["objective"])
        L.append(f"- {lab}, gradient: J per update {J}")
        c = res["trace"]["cma"]
        L.append(f"- {lab}, CMA-ES: mean score per generation " + ", ".join(f"{x['mean']:.3f}" for x in c))
    L.append("")
    L.append("Per-scene records (status letters, iterations, path length) are in the JSON.")
    return "\n".join(L) + "\n"


def figures(results: dict, args, fig_dir: str, sp) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labs = list(results["methods"])
    # held-out success with intervals
    fig, ax = plt.subplots(figsize=(8, 3.6))
    width = 0.8 / len(SETTINGS)
    for j, name in enumerate(SETTINGS):
        xs, ys, err = [], [], [[], []]
        for i, lab in enumerate(labs):
            h = results["methods"][lab]["heldout"][name]
            p = h["success"] / h["n"]
            lo, hi = wilson(h["success"], h["n"])
            xs.append(i + (j - (len(SETTINGS) - 1) / 2) * width)
            ys.append(100 * p)
            err[0].append(100 * (p - lo))
            err[1].append(100 * (hi - p))
        ax.bar(xs, ys, width, yerr=err, capsize=2, label=name)
    ax.set_xticks(range(len(labs)), labs)
    ax.set_ylabel("held-out success % (95 % Wilson)")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=7, ncol=3, loc="lower right")
    ax.set_title(f"held-out success, {args.n_eval} scenes")
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "tuning_heldout.png"), dpi=120)
    plt.close(fig)
    # training traces
    fig, axes = plt.subplots(1, len(labs), figsize=(4 * len(labs), 3.2), squeeze=False)
    for ax, lab in zip(axes[0], labs, strict=True):
        res = results["methods"][lab]
        t = res["trace"]["gradient"]
        x = np.asarray(t["rollouts"])
        J, se = np.asarray(t["objective"]), np.asarray(t["objective_se"])
        ax.plot(x, J, "o-", ms=3, label="gradient (3 gains)")
        ax.fill_between(x, J - 2 * se, J + 2 * se, alpha=0.2)
        f = res["trace"]["function"]
        xf = x[-1] + np.asarray(f["rollouts"])
        ax.plot(xf, f["objective"], "o-", ms=3, label="gain function (20)")
        c = res["trace"]["cma"]
        ax.plot([r["rollouts"] for r in c], [r["mean"] for r in c], "s-", ms=3, label="CMA-ES (mean score)")
        ax.set_xlabel("training rollouts")
        ax.set_ylabel("objective J (lower is better)")
        ax.set_title(lab)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "tuning_training.png"), dpi=120)
    plt.close(fig)
    # tuned repulsion functions
    import jax.numpy as jnp

    from softplan_jax.planning._step import GainFunction, repulsion, repulsion_scale

    fig, axes = plt.subplots(1, len(labs), figsize=(4 * len(labs), 3.2), squeeze=False)
    for ax, lab in zip(axes[0], labs, strict=True):
        res = results["methods"][lab]
        base = sp.default_gains(jnp.float64)
        for name in ("default", "grid", "gradient", "function"):
            ch = res["choices"].get(name)
            if name == "default":
                g = base
            elif name == "function":
                g = GainFunction(**{k: None if v is None else jnp.asarray(v, jnp.float64) for k, v in ch.items()})
            else:
                g = base._replace(**{k: jnp.asarray(ch[k], jnp.float64) for k in TUNED})
            d = np.linspace(1e-3, float(g.d0) * 1.05, 200)
            mags = [float(jnp.linalg.norm(repulsion(jnp.array([1.0, 0, 0]), x, g, "khatib",
                                                    repulsion_scale(g, jnp.asarray(x), 0)))) for x in d]
            ax.semilogy(d, np.maximum(mags, 1e-6), label=name + (" (segment 0)" if name == "function" else ""))
        ax.set_xlabel("clearance d [m]")
        ax.set_ylabel("repulsion speed |F_s|")
        ax.set_title(lab)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "tuning_functions.png"), dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
