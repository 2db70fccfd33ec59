"""The fair comparison of issue 10: curve obstacles vs N-point models, each
with gains tuned for it, on held-out random scenes, with intervals, paired
tests and plots.

One command regenerates everything (progress on stderr)::

    python -m benchmarks.science            # full: train seed 0, held-out seed 1 (1,000 scenes)
    python -m benchmarks.science --quick    # smoke run, written to benchmarks/results/quick/

Phases:

1. **Grid search** on the TRAINING seed (``random_scenarios(train_seed,
   n_train)``): for every method (curve, N = 1, 10, 50, 100) every (d0, dt,
   eta) of the grid, one batched rollout (the library's default planner: safe
   step, escapes). The configuration with the best training score
   ``reached - 3 x collided`` is the grid's choice. The eta = 1e-3 slice gives
   the d0 x dt sensitivity heat maps (training seed).
2. **Gradient tuning** on the same training scenes: :func:`softplan_jax.tuning.tune_gains`
   (optax adam on log d0, log eta, log dt, from the default gains) of the
   differentiable surrogate :func:`softplan_jax.tuning.rollout_loss`: mean and
   final tip error (success) plus a softplus penalty on the true clearance
   below a margin (clearance). Gradient pathologies, handled: the gains are
   tuned in log space (they stay positive, steps are relative); the gradient
   is clipped by global norm (the Khatib field grows as 1/d^3 near contact and
   rollouts are chaotic: single scenes give huge gradients); the horizon is
   short (``--train-steps``) so reverse mode does not multiply hundreds of
   step Jacobians; the rollout's status logic only freezes the state (no
   gradient through the discrete status); a non-finite gradient stops the
   tuning, and the last finite gains are kept (reported).
3. **Held-out evaluation** on ``random_scenarios(eval_seed, n_eval)`` for the
   default gains, the grid's and the gradient's per-method gains:
   planning-only batched rollouts, then the exact collision check
   (:func:`softplan_jax.planner.apply_collision_checks`) against the true
   curves. Per-scene records (scene x setting x method -> status,
   iterations, min clearance) go to the JSON file. Rates with 95 % Wilson
   intervals; paired curve-vs-N comparisons (exact McNemar on reached and
   on collided; paired bootstrap of the difference in success).
4. **Figures** (``benchmarks/results/figures/science_*.png``): rates vs N
   with error bars and the curve method as a band; d0 x dt heat maps of the
   collision rate (curve, N = 10); cost per step vs N; the paper scenes with
   the "paper" preset as 3D view + top view + clearance panels.

Budget accounting: the grid's and the gradient's wall times (compile
excluded, reported separately) and rollout counts are both in the report.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from stats import fmt_rate, mcnemar_exact, paired_bootstrap, pct_interval, wilson  # noqa: E402

STATUSES = ("reached", "collided", "stalled", "max_steps", "non_finite")
TUNED = ("d0", "eta", "dt")


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (small sizes) into results/quick/")
    ap.add_argument("--train-seed", type=int, default=0)
    ap.add_argument("--eval-seed", type=int, default=1)
    ap.add_argument("--n-train", type=int, default=None, help="training scenes (default 32; quick 8)")
    ap.add_argument("--n-eval", type=int, default=None, help="held-out scenes (default 1000; quick 16)")
    ap.add_argument("--train-steps", type=int, default=None, help="rollout steps on the training seed (default 100)")
    ap.add_argument("--max-steps", type=int, default=None, help="rollout steps on the held-out seed (default 150)")
    ap.add_argument("--methods", default="curve,1,10,50,100", help="comma list of curve and point counts N")
    ap.add_argument("--grid-d0", default="0.04,0.07,0.1,0.15")
    ap.add_argument("--grid-dt", default="0.05,0.1,0.2")
    ap.add_argument("--grid-eta", default="0.001,0.004")
    ap.add_argument("--grad-updates", type=int, default=None, help="optax updates per method (default 6)")
    ap.add_argument("--grad-scenes", type=int, default=None, help="training scenes per gradient (default 16)")
    ap.add_argument("--lr", type=float, default=0.1, help="adam learning rate on the log-gains")
    ap.add_argument("--chunk", type=int, default=None, help="scenes per vmapped call (default 100; quick 8)")
    ap.add_argument("--settings", default="default,grid,grad", help="held-out gain settings")
    ap.add_argument("--skip-paper-figures", action="store_true")
    ap.add_argument("--no-grid", action="store_true", help="skip the grid search (e.g. a run of --settings grad only)")
    ap.add_argument("--grid-choice", default=None, metavar="JSON",
                    help="with --no-grid: the grid's choices of an earlier run, {label: {d0, dt, eta}}")
    ap.add_argument("--no-grad", action="store_true", help="skip the gradient tuning (e.g. --settings grid only)")
    ap.add_argument("--merge", nargs="+", metavar="JSON", default=None,
                    help="merge the held-out settings of these science JSON files into the first (no planning)")
    ap.add_argument("--out", default=None, help="output prefix (default results/science or results/quick/science)")
    args = ap.parse_args(argv)
    q = args.quick
    defaults = dict(n_train=8 if q else 32, n_eval=16 if q else 1000, train_steps=40 if q else 100,
                    max_steps=60 if q else 150, grad_updates=2 if q else 6, grad_scenes=4 if q else 16,
                    chunk=8 if q else 100)
    for k, v in defaults.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    args.method_list = [m if m == "curve" else int(m) for m in args.methods.split(",")]
    args.grid = [(float(a), float(b), float(c)) for a in args.grid_d0.split(",") for b in args.grid_dt.split(",")
                 for c in args.grid_eta.split(",")]
    args.setting_list = args.settings.split(",")
    return args


def mlabel(m) -> str:
    return "curve" if m == "curve" else f"N={m}"


class Runner:
    """Batched planning-only rollouts + exact collision checks, compiled once
    per (method, max_steps, chunk); gains are arguments (no recompilation)."""

    def __init__(self, chunk: int):
        import jax

        from softplan_jax.planner import apply_collision_checks

        self.jax = jax
        self.chunk = chunk
        self.check = jax.jit(jax.vmap(apply_collision_checks, in_axes=(0, 0, None)), static_argnums=2)
        self.compile_s: dict = {}

    def options(self, method):
        from softplan_jax.planner import make_options

        return make_options("curve" if method == "curve" else "points", 10 if method == "curve" else method,
                            check_collisions=False)

    def run(self, suite, gains, method, max_steps: int, seed: int, log=None):
        """-> dict(status names, iterations, min_clearance, plan_seconds per chunk, check_seconds)."""
        from softplan_jax.planner import rollout_batch, status_name

        jax = self.jax
        opts = self.options(method)
        n = suite.q0.shape[0]
        chunk = min(self.chunk, n)
        pad = (-n) % chunk
        take = np.concatenate([np.arange(n), np.full(pad, n - 1)])
        key = (mlabel(method), max_steps, chunk)
        status, iters, minc, plan_s, check_s = [], [], [], [], 0.0
        for c0 in range(0, n + pad, chunk):
            idx = take[c0: c0 + chunk]
            batch = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], suite)
            t0 = time.perf_counter()
            r = jax.block_until_ready(rollout_batch(batch, gains, opts, max_steps, seed=seed * 100003 + c0))
            t1 = time.perf_counter()
            r = jax.block_until_ready(self.check(r, batch, opts))
            t2 = time.perf_counter()
            if key not in self.compile_s:  # the first chunk of a shape includes compilation
                self.compile_s[key] = t2 - t0
            else:
                plan_s.append((t1 - t0) / (chunk * (max_steps + 1)))
                check_s += t2 - t1
            status += [status_name(s) for s in np.asarray(r.status)]
            iters.append(np.asarray(r.iterations))
            minc.append(np.asarray(r.min_clearance))
            if log:
                log(f"{min(c0 + chunk, n)}/{n}")
        return dict(status=status[:n], iterations=np.concatenate(iters)[:n],
                    min_clearance=np.concatenate(minc)[:n], plan_per_step=plan_s, check_seconds=check_s)


def counts_of(status) -> dict:
    return {s: int(sum(x == s for x in status)) for s in STATUSES}


def gains_dict(g) -> dict:
    return {k: float(v) for k, v in g._asdict().items()}


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.merge:
        return merge(args.merge, argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import optax
    from _common import FIGURES_DIR, RESULTS_DIR, finish_machine, log, machine_info, write_results

    import softplan_jax as sp
    from softplan_jax.tuning import LossWeights, tune_gains

    t_all = time.perf_counter()
    machine = machine_info("float64")
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", "science")
    fig_dir = os.path.join(os.path.dirname(out), "figures") if args.quick or args.out else FIGURES_DIR
    os.makedirs(fig_dir, exist_ok=True)

    def stamp(msg):
        log(f"[science {time.perf_counter() - t_all:7.0f} s] {msg}")

    stamp(f"suites: train random_scenarios({args.train_seed}, {args.n_train}), "
          f"held-out random_scenarios({args.eval_seed}, {args.n_eval})")
    train = sp.random_scenarios(args.train_seed, args.n_train)
    heldout = sp.random_scenarios(args.eval_seed, args.n_eval)
    base = sp.default_gains(jnp.float64)
    runner = Runner(args.chunk)

    # ---- 0. the paper scenes with the "paper" preset (figures only)
    paper_figs = make_figures(args, [], {}, fig_dir, sp, stamp, paper=True)

    # ---- 1. grid search on the training seed
    grid_rows, grid_choice, grid_cost = {}, {}, {}
    for m in [] if args.no_grid else args.method_list:
        rows = []
        t_m = time.perf_counter()
        compile_before = sum(runner.compile_s.values())
        for k, (d0, dt, eta) in enumerate(args.grid):
            g = base._replace(d0=jnp.asarray(d0), dt=jnp.asarray(dt), eta=jnp.asarray(eta))
            res = runner.run(train, g, m, args.train_steps, seed=args.train_seed)
            c = counts_of(res["status"])
            rows.append(dict(d0=d0, dt=dt, eta=eta, counts=c, score=c["reached"] - 3 * c["collided"]))
            stamp(f"grid {mlabel(m)} {k + 1}/{len(args.grid)} d0={d0} dt={dt} eta={eta}: "
                  f"reached {c['reached']}, collided {c['collided']}")
        compile_m = sum(runner.compile_s.values()) - compile_before
        grid_cost[mlabel(m)] = dict(seconds=time.perf_counter() - t_m - compile_m, compile_seconds=compile_m,
                                    rollouts=len(args.grid) * args.n_train, steps=args.train_steps)
        best = max(rows, key=lambda r: (r["score"], r["counts"]["reached"]))
        grid_rows[mlabel(m)] = rows
        grid_choice[mlabel(m)] = dict(d0=best["d0"], dt=best["dt"], eta=best["eta"])
        stamp(f"grid choice {mlabel(m)}: {grid_choice[mlabel(m)]} (score {best['score']})")
    if args.no_grid and args.grid_choice:
        grid_choice = json.loads(args.grid_choice)

    # ---- 2. gradient tuning on the training seed
    grad_choice, grad_info = {}, {}
    sub = jax.tree_util.tree_map(lambda x: x[: args.grad_scenes], train)
    opt = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(args.lr))
    weights = LossWeights()
    for m in [] if args.no_grad else args.method_list:
        t0 = time.perf_counter()
        note = ""
        try:
            tr = tune_gains(sub, base, steps=args.grad_updates, max_steps=args.train_steps,
                            method="curve" if m == "curve" else "points", n_points=10 if m == "curve" else m,
                            weights=weights, tune=TUNED, optimizer=opt, progress=False)
            losses, comp = tr.losses.tolist(), tr.compile_seconds
            # The best iterate on the training loss (losses[k] is the loss of the gains after update k).
            k_best = int(np.argmin(tr.losses))
            g = base if k_best == 0 else tr.history[k_best - 1]
            note = f"best iterate: after update {k_best} of {args.grad_updates}"
        except FloatingPointError as err:  # a non-finite gradient: keep the default gains, say so
            g, losses, comp, note = base, [], 0.0, f"stopped: {err}"
        wall = time.perf_counter() - t0
        grad_choice[mlabel(m)] = {k: float(getattr(g, k)) for k in TUNED}
        grad_info[mlabel(m)] = dict(seconds=wall - comp, compile_seconds=comp, losses=losses, note=note,
                                    value_and_grad_calls=args.grad_updates + 1, scenes=args.grad_scenes,
                                    steps=args.train_steps)
        stamp(f"grad {mlabel(m)}: {grad_choice[mlabel(m)]}, loss {losses[:1]} -> {losses[-1:]} "
              f"({wall - comp:.0f} s + compile {comp:.0f} s) {note}")

    # ---- 3. held-out evaluation
    def setting_gains(setting, m):
        if setting == "default":
            return base
        choice = (grid_choice if setting == "grid" else grad_choice)[mlabel(m)]
        return base._replace(**{k: jnp.asarray(v) for k, v in choice.items()})

    def write(final: bool):
        total = time.perf_counter() - t_all
        figs = make_figures(args, summary, grid_rows, fig_dir, sp, stamp, paper=False) + paper_figs
        finish_machine(machine)
        report = dict(machine=machine, args={k: v for k, v in vars(args).items()}, seconds=total,
                      complete=final, grid=grid_rows, grid_choice=grid_choice, grid_cost=grid_cost,
                      grad_choice=grad_choice, grad=grad_info, summary=summary, paired=paired_of(records),
                      compile_seconds={"/".join(map(str, k)): v for k, v in runner.compile_s.items()},
                      figures=figs,
                      scenes=dict(train=dict(seed=args.train_seed, n=args.n_train),
                                  heldout=dict(seed=args.eval_seed, n=args.n_eval)),
                      records=records)
        write_results(out, report, markdown(args, report, argv))
        stamp(f"wrote {out}.md and .json ({'complete' if final else 'partial'}) at {total:.0f} s")
        return report

    records, summary = {}, []
    for setting in args.setting_list:
        records[setting] = {}
        for m in args.method_list:
            t0 = time.perf_counter()
            res = runner.run(heldout, setting_gains(setting, m), m, args.max_steps, seed=args.eval_seed,
                             log=lambda s, m=m, setting=setting: stamp(f"held-out {setting}/{mlabel(m)}: {s}"))
            c = counts_of(res["status"])
            reached = np.array([s == "reached" for s in res["status"]])
            records[setting][mlabel(m)] = dict(
                status=res["status"], iterations=res["iterations"].tolist(),
                min_clearance=[float(x) if np.isfinite(x) else None for x in res["min_clearance"]])
            summary.append(dict(
                setting=setting, method=mlabel(m), n=args.n_eval, counts=c,
                intervals={s: wilson(c[s], args.n_eval) for s in STATUSES},
                gains=gains_dict(setting_gains(setting, m)),
                mean_iterations_reached=float(res["iterations"][reached].mean()) if reached.any() else None,
                plan_per_step_median=float(np.median(res["plan_per_step"])) if res["plan_per_step"] else None,
                plan_per_step_min=float(np.min(res["plan_per_step"])) if res["plan_per_step"] else None,
                seconds=time.perf_counter() - t0))
            stamp(f"held-out {setting}/{mlabel(m)}: " + ", ".join(f"{k} {v}" for k, v in c.items()))
            if (setting, m) != (args.setting_list[-1], args.method_list[-1]):
                write(final=False)
    return write(final=True)


def paired_of(records) -> list:
    """Paired comparisons curve vs each N, per setting (same held-out scenes)."""
    paired = []
    for setting in records:
        rec = records[setting]
        if "curve" not in rec:
            continue
        cur = rec["curve"]
        for lab, r in rec.items():
            if lab == "curve":
                continue
            row = dict(setting=setting, method=lab)
            for outcome in ("reached", "collided"):
                x = np.array([s == outcome for s in cur["status"]])
                y = np.array([s == outcome for s in r["status"]])
                b, c = int((x & ~y).sum()), int((~x & y).sum())
                row[outcome] = dict(curve_only=b, n_only=c, mcnemar_p=mcnemar_exact(b, c),
                                    diff=list(paired_bootstrap(x, y, n_boot=5000, seed=1)))
            paired.append(row)
    return paired


def merge(paths, argv) -> dict:
    """Merge the held-out settings of later science JSON files into the first one
    (same held-out seed and size required); rewrite its Markdown, JSON and figures."""
    from _common import write_results

    import softplan_jax as sp

    with open(paths[0], encoding="utf-8") as fh:
        rep = json.load(fh)
    for path in paths[1:]:
        with open(path, encoding="utf-8") as fh:
            other = json.load(fh)
        if other["scenes"]["heldout"] != rep["scenes"]["heldout"]:
            raise ValueError(f"{path}: a different held-out suite ({other['scenes']['heldout']})")
        for setting, rec in other["records"].items():
            if setting in rep["records"]:
                continue
            rep["records"][setting] = rec
            rep["summary"] += [r for r in other["summary"] if r["setting"] == setting]
            if setting not in rep["args"]["setting_list"]:
                rep["args"]["setting_list"].append(setting)
        rep.setdefault("merged_from", []).append(dict(path=os.path.relpath(path, HERE), seconds=other["seconds"],
                                                      args=other["args"]))
    args = argparse.Namespace(**rep["args"])
    # A method whose gains in a setting equal its gains in an evaluated setting has the same
    # held-out result (same scenes, same escape seeds, deterministic): copy it, and say so.
    for setting in args.setting_list:
        rec = rep["records"].setdefault(setting, {})
        for m in args.method_list:
            lab = mlabel(m)
            if lab in rec:
                continue
            choice = (rep["grid_choice"] if setting == "grid" else rep["grad_choice"]).get(lab)
            for src in [x for x in rep["records"] if lab in rep["records"][x]]:
                row = next((r for r in rep["summary"] if r["setting"] == src and r["method"] == lab), None)
                if row and choice and all(abs(row["gains"][k] - v) <= 1e-12 * abs(v) for k, v in choice.items()):
                    rec[lab] = rep["records"][src][lab]
                    rep["summary"].append(dict(row, setting=setting, copied_from=src))
                    break
    order = {(s, mlabel(m)): i for i, (s, m) in enumerate((s, m) for s in args.setting_list for m in args.method_list)}
    rep["summary"].sort(key=lambda r: order.get((r["setting"], r["method"]), 1 << 30))
    rep["records"] = {s: {mlabel(m): rep["records"][s][mlabel(m)] for m in args.method_list
                          if mlabel(m) in rep["records"].get(s, {})} for s in args.setting_list}
    rep["paired"] = paired_of(rep["records"])
    out = os.path.splitext(paths[0])[0]
    fig_dir = os.path.join(os.path.dirname(out), "figures")
    os.makedirs(fig_dir, exist_ok=True)
    paper = [f for f in rep["figures"] if "science_paper_" in f]
    rep["figures"] = make_figures(args, rep["summary"], rep["grid"], fig_dir, sp, print, paper=False) + paper
    rep["complete"] = all(s in rep["records"] for s in args.setting_list)
    rep["command"] = "python -m benchmarks.science"
    write_results(out, rep, markdown(args, rep, None))
    return rep


def make_figures(args, summary, grid_rows, fig_dir, sp, stamp, paper: bool = True) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []

    def save(fig, name):
        path = os.path.join(fig_dir, name)
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(os.path.relpath(path, os.path.dirname(fig_dir)))

    if paper:
        if args.skip_paper_figures:
            return written
        from softplan_jax import plotting

        for name in ("sim1", "sim2", "tree"):
            for method, n in (("curve", 10), ("points", 10)):
                sc, g, o = sp.apply_preset("paper", sp.paper_scenario(name))
                r = sp.plan(sc, method, n, gains=g, max_steps=150, **o)
                lab = "curve method" if method == "curve" else f"{n}-point model"
                fig = plotting.plot_snapshots_with_clearance(
                    sc, r, title=f"{name}, {lab}, 'paper' preset: {r.status} after {r.iterations} iterations, "
                    f"min clearance {r.min_clearance:.3f}")
                save(fig, f"science_paper_{name}_{'curve' if method == 'curve' else f'N{n}'}.png")
                stamp(f"figure {name} {method}: {r.status} {r.iterations}")
        return written

    ns = [m for m in args.method_list if m != "curve"]
    # Rates vs N, one row per setting.
    panels = [("reached", "success (reached)"), ("collided", "collided"),
              (("stalled", "max_steps"), "stalled or out of steps")]
    settings = args.setting_list
    fig, axes = plt.subplots(len(settings), 3, figsize=(14, 3.6 * len(settings)), squeeze=False)
    for i, setting in enumerate(settings):
        rows = {r["method"]: r for r in summary if r["setting"] == setting}
        for j, (key, name) in enumerate(panels):
            ax = axes[i, j]
            keys = key if isinstance(key, tuple) else (key,)

            def rate(r, keys=keys):
                k = sum(r["counts"][s] for s in keys)
                lo, hi = wilson(k, r["n"])
                return k / r["n"], lo, hi

            if "curve" in rows:
                p, lo, hi = rate(rows["curve"])
                ax.axhspan(lo, hi, color="tab:green", alpha=0.25, label="curve method (95 % CI)")
                ax.axhline(p, color="tab:green", lw=1.5)
            pts = [(n, *rate(rows[f"N={n}"])) for n in ns if f"N={n}" in rows]
            if pts:
                x, p, lo, hi = map(np.asarray, zip(*pts, strict=True))
                ax.errorbar(x, p, yerr=[np.maximum(p - lo, 0.0), np.maximum(hi - p, 0.0)], fmt="o-",
                            color="tab:blue", capsize=4,
                            label="N-point model (95 % Wilson)")
            ax.set_xscale("log")
            ax.set_xticks(ns)
            ax.set_xticklabels([str(n) for n in ns])
            ax.set_ylim(-0.02, 1.02)
            ax.set_xlabel("N (points per curve)")
            ax.set_ylabel("rate")
            ax.set_title(f"{name} — {setting} gains", fontsize=10)
            ax.grid(alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
    fig.suptitle(f"held-out random_scenarios({args.eval_seed}, {args.n_eval}), {args.max_steps} steps"
                 + (" — QUICK MODE" if args.quick else ""), fontsize=12)
    fig.tight_layout()
    save(fig, "science_rates_vs_n.png")

    # Heat maps of the collision rate over d0 x dt (training seed, eta = the grid's smallest).
    shown = [lab for lab in ("curve", "N=10") if lab in grid_rows]
    d0s = dts = []
    eta0 = None
    if not grid_rows:
        shown = []
    if shown:
        d0s = sorted({r["d0"] for rows in grid_rows.values() for r in rows})
        dts = sorted({r["dt"] for rows in grid_rows.values() for r in rows})
        eta0 = min(r["eta"] for rows in grid_rows.values() for r in rows)
        fig, axes = plt.subplots(1, len(shown), figsize=(5.5 * len(shown), 4.2), squeeze=False)
        for ax, lab in zip(axes[0], shown, strict=True):
            M = np.full((len(d0s), len(dts)), np.nan)
            for r in grid_rows[lab]:
                if r["eta"] == eta0:
                    n = sum(v for v in r["counts"].values() if v is not None)
                    M[d0s.index(r["d0"]), dts.index(r["dt"])] = r["counts"]["collided"] / n
            im = ax.imshow(M, origin="lower", cmap="Reds", vmin=0, vmax=max(0.05, float(np.nanmax(M))),
                           aspect="auto")
            for a in range(len(d0s)):
                for b in range(len(dts)):
                    ax.text(b, a, f"{100 * M[a, b]:.0f} %", ha="center", va="center", fontsize=9)
            ax.set_xticks(range(len(dts)))
            ax.set_xticklabels([f"{x:g}" for x in dts])
            ax.set_yticks(range(len(d0s)))
            ax.set_yticklabels([f"{x:g}" for x in d0s])
            ax.set_xlabel("dt")
            ax.set_ylabel("d0")
            ax.set_title(f"collision rate, {lab} (eta = {eta0:g})", fontsize=10)
            fig.colorbar(im, ax=ax)
        fig.suptitle(f"sensitivity on the TRAINING seed: random_scenarios({args.train_seed}, {args.n_train}), "
                     f"{args.train_steps} steps" + (" — QUICK MODE" if args.quick else ""), fontsize=11)
        fig.tight_layout()
        save(fig, "science_heatmap_d0_dt.png")

    # Cost per step vs N (default gains).
    # The setting with the most per-step timings (rows rebuilt from a log have none).
    timed_setting = max(settings, key=lambda st: sum(1 for r in summary if r["setting"] == st
                                                     and r.get("plan_per_step_median")), default=None)
    rows = {r["method"]: r for r in summary if r["setting"] == timed_setting}
    if rows and any(r["plan_per_step_median"] for r in rows.values()):
        fig, ax = plt.subplots(figsize=(6, 4))
        pts = [(n, rows[f"N={n}"]["plan_per_step_median"], rows[f"N={n}"]["plan_per_step_min"])
               for n in ns if f"N={n}" in rows and rows[f"N={n}"]["plan_per_step_median"]]
        if pts:
            x, med, mn = map(np.asarray, zip(*pts, strict=True))
            ax.plot(x, 1e6 * med, "o-", label="N-point model, median over chunks")
            ax.plot(x, 1e6 * mn, "o:", color="tab:blue", alpha=0.5, label="N-point model, min")
        if "curve" in rows and rows["curve"]["plan_per_step_median"]:
            ax.axhline(1e6 * rows["curve"]["plan_per_step_median"], color="tab:green", label="curve method, median")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("N (points per curve)")
        ax.set_ylabel("planning time per scene-step [µs]")
        ax.set_title(f"batched planning cost, {timed_setting} gains (shared 2-core machine;\n"
                     "compile excluded, collision check excluded)",
                     fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, "science_cost_per_step.png")

    return written


def markdown(args, rep, argv) -> str:
    n = args.n_eval
    cmd = rep.get("command") or (
        "python -m benchmarks.science" + (" " + " ".join(argv) if argv else " " + " ".join(sys.argv[1:])))
    L = [f"# Curve vs N-point obstacles: tuned per method, held-out evaluation{' (QUICK MODE)' if args.quick else ''}",
         ""]
    if args.quick:
        L += ["**Quick mode: tiny sizes, for checking the pipeline only; no conclusion should be drawn.**", ""]
    L += machine_lines_safe(rep["machine"])
    L += [f"- command: `{cmd.strip()}`; wall time {rep['seconds']:.0f} s on this machine (compile included)"
          + ("" if rep.get("complete", True) else " — stopped before every setting was evaluated"),
          f"- training seed {args.train_seed} ({args.n_train} scenes, {args.train_steps} steps); held-out seed "
          f"{args.eval_seed} ({n} scenes, {args.max_steps} steps); planner: the library's default (safe step, "
          "escapes); float64",
          "- rates: count (% [95 % Wilson interval]); success = reached the goal without collision; collided = "
          "true clearance <= contact tolerance at a step or between steps (exact check against the real curves)",
          ""]
    if rep.get("rebuilt_from_log"):
        L.append(f"- **rebuilt**: {rep['rebuilt_from_log']}")
    for mf in rep.get("merged_from", []):
        L.append(f"- merged: the held-out settings {mf['args']['setting_list']} of a parallel run "
                 f"(`{mf['path']}`, wall time {mf['seconds']:.0f} s, started while this run was under way)")
    copied = [f"{r['setting']}/{r['method']}" for r in rep["summary"] if r.get("copied_from")]
    if copied:
        L += [f"- rows {copied} were not re-run: their gains equal those of another setting for the same "
              "method, so their held-out records are identical (same scenes and escape seeds) and were copied", ""]
    L += ["", "## Tuning (training seed)", "",
          f"Grid: d0 x dt x eta = {len(args.grid)} configurations, score = reached - 3 x collided on the training "
          f"scenes. Gradient: {args.grad_updates} adam updates (lr {args.lr}, clipped to global norm 1) of the "
          f"rollout loss on {args.grad_scenes} training scenes, log d0 / log eta / log dt, from the default gains.",
          "",
          "| method | grid choice (d0, dt, eta) | grid cost | gradient result (d0, dt, eta) | gradient cost | "
          "gradient loss first -> last |",
          "|---|---|---|---|---|---|"]
    for lab in rep["grid_choice"]:
        if lab not in rep["grad_choice"]:
            continue
        gc, gr = rep["grid_choice"][lab], rep["grad_choice"][lab]
        cost, gi = rep["grid_cost"][lab], rep["grad"][lab]
        loss = f"{gi['losses'][0]:.4f} -> {gi['losses'][-1]:.4f}" if gi["losses"] else gi["note"]
        L.append(f"| {lab} | {gc['d0']:g}, {gc['dt']:g}, {gc['eta']:g} | {cost['seconds']:.0f} s ({cost['rollouts']} "
                 f"rollouts of {cost['steps']} steps; + {cost['compile_seconds']:.0f} s compile) | "
                 f"{gr['d0']:.4g}, {gr['dt']:.4g}, {gr['eta']:.3g} | {gi['seconds']:.0f} s "
                 f"({gi['value_and_grad_calls']} value+grad on {gi['scenes']} scenes x {gi['steps']} steps; "
                 f"+ {gi['compile_seconds']:.0f} s compile) | {loss} |")
    L += ["", "## Held-out results", "",
          "| gains | method | reached | collided | stalled | max steps | non-finite | mean its (reached) | "
          "plan / scene-step (median) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["summary"]:
        c = r["counts"]
        it = f"{r['mean_iterations_reached']:.1f}" if r["mean_iterations_reached"] is not None else "—"
        ps = f"{1e6 * r['plan_per_step_median']:.0f} µs" if r["plan_per_step_median"] else "—"
        L.append(f"| {r['setting']} | {r['method']} | {fmt_rate(c['reached'], n)} | {fmt_rate(c['collided'], n)} | "
                 f"{fmt_rate(c['stalled'], n)} | {fmt_rate(c['max_steps'], n)} | {fmt_rate(c['non_finite'], n)} | "
                 f"{it} | {ps} |")
    L += ["", "Gains per row are in the JSON (`summary[].gains`). Per-step cost: planning-only batched rollout, "
          "compile excluded, on a machine shared with other jobs (load average in the header): read ratios, not "
          "absolute figures.", "",
          "## Paired comparisons, curve vs N (same held-out scenes)", "",
          "Discordant pairs: *curve only* = scenes where the curve method has the outcome and the N-point model "
          "not; exact two-sided McNemar p; difference of rates (curve - N) with a 95 % paired-bootstrap interval.",
          "",
          "| gains | N | reached: curve only / N only, p | success diff [95 %] | collided: curve only / N only, p | "
          "collision diff [95 %] |",
          "|---|---|---|---|---|---|"]
    for p in rep["paired"]:
        a, b = p["reached"], p["collided"]
        L.append(f"| {p['setting']} | {p['method']} | {a['curve_only']} / {a['n_only']}, {a['mcnemar_p']:.2g} | "
                 f"{100 * a['diff'][0]:+.1f} [{100 * a['diff'][1]:+.1f}, {100 * a['diff'][2]:+.1f}] | "
                 f"{b['curve_only']} / {b['n_only']}, {b['mcnemar_p']:.2g} | "
                 f"{100 * b['diff'][0]:+.1f} [{100 * b['diff'][1]:+.1f}, {100 * b['diff'][2]:+.1f}] |")
    if not rep["grid"]:
        return "\n".join(L) + "\n"
    L += ["", "## Sensitivity (training seed): collision rate over the grid", "",
          "| method | " + " | ".join(f"d0 {r['d0']:g}, dt {r['dt']:g}, eta {r['eta']:g}"
                                     for r in next(iter(rep["grid"].values()))) + " |",
          "|---|" + "---|" * len(args.grid)]
    for lab, rows in rep["grid"].items():
        L.append(f"| {lab} | " + " | ".join(pct_interval(r["counts"]["collided"], args.n_train) for r in rows) + " |")
    L += ["", "## Figures", ""] + [f"- `{f}`" for f in rep["figures"]]
    return "\n".join(L) + "\n"


def machine_lines_safe(m):
    from _common import machine_lines

    return machine_lines(m)


if __name__ == "__main__":
    main()
