"""The fair comparison: curve obstacles vs N-point models, each
with gains tuned for it, on held-out random scenes, with intervals, paired
tests and plots.

One command regenerates everything, in one process (progress on stderr)::

    python benchmarks/science.py            # full: train seed 0 (64 scenes), held-out seed 1 (1,024 scenes)
    python benchmarks/science.py --quick    # smoke run (curve and N = 10, grid only), into benchmarks/results/quick/

Every rollout is the library's default planner (safe step, escapes) with its
collision checks inside the scan (``make_options(method, N)``, i.e. what
:func:`softplan_jax.plan_batch` runs): the true clearance at every step and
during the motion between steps, against the real curves. Phases:

1. **Grid search** on the TRAINING seed (``random_scenarios(train_seed,
   n_train)``, ``train_steps`` steps): for every method (curve, N = 1, 10, 50,
   100) every (d0, dt, eta) of the grid. The configuration with the best
   training score ``reached - 3 x collided`` (ties: more reached, then the
   grid's order) is the grid's choice. The report says whether a choice sits
   at the edge of the grid. The whole grid gives the d0 x dt sensitivity heat
   maps and tables (training seed).
2. **Gradient tuning** on the same training seed (its first ``grad_scenes``
   scenes): :func:`softplan_jax.tuning.pathwise.tune_gains` (optax adam on log d0,
   log eta, log dt, from the default gains, the learning rate decaying from
   ``lr`` to ``lr_final`` along a cosine) of the differentiable surrogate
   :func:`softplan_jax.tuning.pathwise.rollout_loss`: mean and final tip error
   (success) plus a softplus penalty on the true clearance below a margin
   (clearance). Gradient pathologies, handled: the gains are tuned in log
   space (they stay positive, steps are relative); the gradient is clipped by
   global norm before adam (the Khatib field grows as 1/d^3 near contact and
   rollouts are chaotic: single scenes give huge gradients, which would
   otherwise dominate adam's second moment); the horizon is the training one
   (``train_steps``) so reverse mode does not multiply hundreds of step
   Jacobians; the rollout's status logic only freezes the state (no gradient
   through the discrete status); the surrogate is noisy from update to
   update, so the decaying step and the best iterate on the training loss
   (not the last) are kept; a non-finite gradient stops the tuning and the
   default gains are kept (reported). Diagnostics, not counted in its cost:
   the training score of the gradient's gains (the grid's measure) and the
   surrogate loss at the grid's choice.
3. **Held-out evaluation** on ``random_scenarios(eval_seed, n_eval)``
   (``max_steps`` steps) of every setting (default gains, the grid's and the
   gradient's per-method gains) x every method. Per-scene records (scene x
   setting x method -> status, iterations, min clearance) go to the JSON
   file. Rates with 95 % Wilson intervals; paired comparisons on the same
   scenes (exact McNemar on reached and on collided; paired bootstrap of the
   difference of rates): curve vs each N per setting, and gradient vs grid
   per method.
4. **Cost per step**: planning-only rollouts (``check_collisions=False``) of
   the first ``timing_chunks`` held-out chunks with the default gains, the
   methods interleaved, compile excluded.
5. **Figures** (``benchmarks/results/figures/science_*.png``): rates vs N
   with error bars and the curve method as a band; d0 x dt heat maps of the
   collision and success rates (every method, both etas, the grid's choice
   boxed); the gradient's loss and path over the (d0, dt) plane; cost per
   step vs N; the paper scenes with the "paper" preset as 3D view + top view
   + clearance panels.

Budget accounting: compile times (ahead-of-time, per program) are measured
apart from run times, per phase; the grid's and the gradient's run times and
rollout counts are both in the report.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from _stats import fmt_rate, mcnemar_exact, paired_bootstrap, wilson  # noqa: E402

STATUSES = ("reached", "collided", "stalled", "max_steps", "non_finite")
CODES = {"reached": "r", "collided": "c", "stalled": "s", "max_steps": "m", "non_finite": "n"}
TUNED = ("d0", "eta", "dt")
SETTING_NAMES = {"default": "default gains", "grid": "grid-search gains", "grad": "gradient-tuned gains"}


def parse_args(argv=None):
    from _common import held_out_parser

    ap = held_out_parser(__doc__, "rollout steps on the training seed (default 100)",
                         "rollout steps on the held-out seed (default 150)")
    ap.add_argument("--methods", default=None, help="comma list of curve and point counts N (default "
                    "curve,1,10,50,100; quick curve,10)")
    ap.add_argument("--grid-d0", default=None, help="default 0.07,0.1,0.15,0.2,0.3,0.4 (quick 0.07,0.3)")
    ap.add_argument("--grid-dt", default=None, help="default 0.1,0.2,0.4,0.6,0.8 (quick 0.1,0.3)")
    ap.add_argument("--grid-eta", default=None, help="default 0.001,0.004 (quick 0.001)")
    ap.add_argument("--grad-updates", type=int, default=None, help="optax updates per method (default 40)")
    ap.add_argument("--grad-scenes", type=int, default=None, help="training scenes per gradient (default 32)")
    ap.add_argument("--lr", type=float, default=0.2, help="adam's initial learning rate on the log-gains")
    ap.add_argument("--lr-final", type=float, default=0.02, help="learning rate at the last update (cosine decay)")
    ap.add_argument("--chunk", type=int, default=None, help="scenes per vmapped call (default 64; quick 8)")
    ap.add_argument("--timing-chunks", type=int, default=None,
                    help="held-out chunks timed per method, planning only (default 3; quick 1)")
    ap.add_argument("--settings", default=None, help="held-out gain settings (default default,grid,grad; quick "
                    "default,grid: the gradient's compile alone takes minutes)")
    ap.add_argument("--skip-paper-figures", action="store_true", help="(quick: skipped)")
    ap.add_argument("--out", default=None, help="output prefix (default results/science or results/quick/science)")
    args = ap.parse_args(argv)
    q = args.quick
    defaults = dict(n_train=8 if q else 64, n_eval=16 if q else 1024, train_steps=40 if q else 100,
                    max_steps=60 if q else 150, grad_updates=2 if q else 40, grad_scenes=4 if q else 32,
                    chunk=8 if q else 64, timing_chunks=1 if q else 3,
                    grid_d0="0.07,0.3" if q else "0.07,0.1,0.15,0.2,0.3,0.4",
                    grid_dt="0.1,0.3" if q else "0.1,0.2,0.4,0.6,0.8", grid_eta="0.001" if q else "0.001,0.004",
                    methods="curve,10" if q else "curve,1,10,50,100",
                    settings="default,grid" if q else "default,grid,grad")
    for k, v in defaults.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    args.skip_paper_figures = args.skip_paper_figures or q
    args.method_list = [m if m == "curve" else int(m) for m in args.methods.split(",")]
    args.grid_axes = {k: sorted(float(x) for x in getattr(args, f"grid_{k}").split(",")) for k in TUNED}
    args.grid = [(a, b, c) for a in args.grid_axes["d0"] for b in args.grid_axes["dt"] for c in args.grid_axes["eta"]]
    args.setting_list = args.settings.split(",")
    unknown = set(args.setting_list) - set(SETTING_NAMES)
    if unknown:
        raise ValueError(f"unknown settings {sorted(unknown)}; choose from {list(SETTING_NAMES)}")
    if args.grad_scenes > args.n_train or min(args.n_train, args.n_eval, args.chunk, args.grad_updates) < 1:
        raise ValueError("need 1 <= grad_scenes <= n_train and n_train, n_eval, chunk, grad_updates >= 1")
    return args


def mlabel(m) -> str:
    return "curve" if m == "curve" else f"N={m}"


class Runner:
    """Batched rollouts of the library's default planner, compiled ahead of time
    once per (method, checks, max_steps, chunk) -- the compile timed apart --
    and run chunk by chunk; gains are arguments (no recompilation)."""

    def __init__(self, chunk: int):
        import jax

        self.jax = jax
        self.chunk = chunk
        self.compile_s: dict = {}

    @staticmethod
    def options(method, check: bool = True):
        from softplan_jax.planning._planner import make_options

        return make_options("curve" if method == "curve" else "points", 10 if method == "curve" else method,
                            check_collisions=check)

    def batches(self, suite):
        """Index arrays of the chunks (the last padded with copies of the last scene)."""
        n = suite.q0.shape[0]
        chunk = min(self.chunk, n)
        pad = (-n) % chunk
        take = np.concatenate([np.arange(n), np.full(pad, n - 1)])
        return [(c0, take[c0: c0 + chunk]) for c0 in range(0, n + pad, chunk)]

    def ensure_compiled(self, suite, gains, method, max_steps: int, check: bool = True, log=None) -> float:
        """Compile the program for this shape ahead of time (jax keeps it for the
        later calls); returns the compile seconds (0 if already compiled)."""
        from softplan_jax.planning._programs import rollout_batch

        jax = self.jax
        _, idx = self.batches(suite)[0]
        key = (mlabel(method), "checked" if check else "planning", int(max_steps), len(idx))
        if key in self.compile_s:
            return 0.0
        batch = jax.tree_util.tree_map(lambda x: x[idx], suite)
        t0 = time.perf_counter()
        rollout_batch.lower(batch, gains, self.options(method, check), max_steps, seed=0).compile()
        self.compile_s[key] = time.perf_counter() - t0
        if log:
            log(f"compiled {'/'.join(map(str, key))} in {self.compile_s[key]:.1f} s")
        return self.compile_s[key]

    def run(self, suite, gains, method, max_steps: int, seed: int, log=None):
        """Checked rollouts of every scene of ``suite``. Chunk c0's escapes use
        ``seed * 100003 + c0``. -> dict(status names, iterations, min_clearance,
        seconds per scene-step of each chunk, run seconds, compile seconds)."""
        from softplan_jax.base._status import status_name
        from softplan_jax.planning._programs import rollout_batch

        jax = self.jax
        n = suite.q0.shape[0]
        compile_s = self.ensure_compiled(suite, gains, method, max_steps, True, log)
        opts = self.options(method)
        status, iters, minc, per_step = [], [], [], []
        t_run = 0.0
        for c0, idx in self.batches(suite):
            batch = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], suite)
            t0 = time.perf_counter()
            r = jax.block_until_ready(rollout_batch(batch, gains, opts, max_steps, seed=seed * 100003 + c0))
            dt = time.perf_counter() - t0
            t_run += dt
            per_step.append(dt / (len(idx) * (max_steps + 1)))
            status += [status_name(s) for s in np.asarray(r.status)]
            iters.append(np.asarray(r.iterations))
            minc.append(np.asarray(r.min_clearance))
            if log:
                log(f"{min(c0 + len(idx), n)}/{n}")
        return dict(status=status[:n], iterations=np.concatenate(iters)[:n],
                    min_clearance=np.concatenate(minc)[:n], per_step=per_step, seconds=t_run,
                    compile_seconds=compile_s)


def counts_of(status) -> dict:
    return {s: int(sum(x == s for x in status)) for s in STATUSES}


def score_of(c: dict) -> int:
    """The grid's training score."""
    return c["reached"] - 3 * c["collided"]


def gains_dict(g) -> dict:
    return {k: float(v) for k, v in g._asdict().items()}


def edge_of(choice: dict, axes: dict) -> list[str]:
    """The tuned gains whose chosen value is the smallest or largest of the grid's axis."""
    return [f"{k} = {choice[k]:g} ({'smallest' if choice[k] == axes[k][0] else 'largest'})"
            for k in ("d0", "dt") if len(axes[k]) > 1 and choice[k] in (axes[k][0], axes[k][-1])]


def main(argv=None) -> dict:
    args = parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import optax
    from _common import FIGURES_DIR, RESULTS_DIR, log, machine_info

    import softplan_jax as sp
    from softplan_jax.tuning.pathwise import LossWeights, tune_gains

    t_all = time.perf_counter()
    machine = machine_info("float64")
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", "science")
    fig_dir = os.path.join(os.path.dirname(out), "figures") if args.quick or args.out else FIGURES_DIR
    os.makedirs(fig_dir, exist_ok=True)
    phases: dict = {}

    def stamp(msg):
        log(f"[science {time.perf_counter() - t_all:7.0f} s] {msg}")

    def phase_done(name, t0, compile_s=0.0):
        phases[name] = dict(wall=time.perf_counter() - t0, compile=compile_s)
        stamp(f"phase {name}: {phases[name]['wall']:.0f} s wall (compile {compile_s:.0f} s)")

    t0 = time.perf_counter()
    stamp(f"suites: train random_scenarios({args.train_seed}, {args.n_train}), "
          f"held-out random_scenarios({args.eval_seed}, {args.n_eval})")
    train = sp.random_scenarios(args.train_seed, args.n_train)
    heldout = sp.random_scenarios(args.eval_seed, args.n_eval)
    base = sp.default_gains(jnp.float64)
    runner = Runner(args.chunk)
    phase_done("suites", t0)

    # ---- 0. the paper scenes with the "paper" preset (figures only)
    t0 = time.perf_counter()
    paper_figs = paper_figures(args, fig_dir, sp, stamp)
    phase_done("paper figures", t0)

    def with_gains(choice):
        return base._replace(**{k: jnp.asarray(v, jnp.float64) for k, v in choice.items()})

    # ---- 1. grid search on the training seed
    t0 = time.perf_counter()
    grid_rows, grid_choice, grid_cost = {}, {}, {}
    for m in args.method_list:
        lab = mlabel(m)
        rows, run_s, comp_s = [], 0.0, 0.0
        for k, (d0, dt, eta) in enumerate(args.grid):
            res = runner.run(train, with_gains(dict(d0=d0, dt=dt, eta=eta)), m, args.train_steps,
                             seed=args.train_seed, log=stamp if k == 0 else None)
            run_s += res["seconds"]
            comp_s += res["compile_seconds"]
            c = counts_of(res["status"])
            rows.append(dict(d0=d0, dt=dt, eta=eta, counts=c, score=score_of(c),
                             scenes="".join(CODES[s] for s in res["status"])))
            stamp(f"grid {lab} {k + 1}/{len(args.grid)} d0={d0:g} dt={dt:g} eta={eta:g}: "
                  f"reached {c['reached']}, collided {c['collided']} ({res['seconds']:.1f} s)")
        grid_cost[lab] = dict(seconds=run_s, compile_seconds=comp_s, rollouts=len(args.grid) * args.n_train,
                              steps=args.train_steps)
        best = max(rows, key=lambda r: (r["score"], r["counts"]["reached"]))  # max keeps the first of ties
        grid_rows[lab] = rows
        grid_choice[lab] = dict(d0=best["d0"], dt=best["dt"], eta=best["eta"])
        edge = edge_of(grid_choice[lab], args.grid_axes)
        stamp(f"grid choice {lab}: {grid_choice[lab]} (score {best['score']}"
              f"{'; at the edge: ' + ', '.join(edge) if edge else '; interior'})")
    phase_done("grid search", t0, sum(c["compile_seconds"] for c in grid_cost.values()))

    # ---- 2. gradient tuning on the training seed
    t0 = time.perf_counter()
    grad_choice, grad_info = {}, {}
    sub = jax.tree_util.tree_map(lambda x: x[: args.grad_scenes], train)
    weights = LossWeights()
    diag_s = 0.0

    def make_opt():
        sched = optax.cosine_decay_schedule(args.lr, max(args.grad_updates, 1), alpha=args.lr_final / args.lr)
        return optax.chain(optax.clip_by_global_norm(1.0), optax.adam(sched))

    for m in args.method_list if "grad" in args.setting_list else []:
        lab = mlabel(m)
        kw = dict(max_steps=args.train_steps, method="curve" if m == "curve" else "points",
                  n_points=10 if m == "curve" else m, weights=weights, tune=TUNED, progress=False)
        t_m = time.perf_counter()
        history = [base]
        try:
            tr = tune_gains(sub, base, steps=args.grad_updates, optimizer=make_opt(), **kw)
            losses, comp = tr.losses.tolist(), tr.compile_seconds
            history += tr.history
            # losses[k] is the loss of history[k] (the default gains, then the gains after update k).
            k_best = int(np.argmin(tr.losses))
            g = history[k_best]
            note = f"best iterate: after update {k_best} of {args.grad_updates}"
        except FloatingPointError as err:  # a non-finite gradient: keep the default gains, say so
            g, losses, comp, k_best, note = base, [], 0.0, 0, f"stopped: {err}; the default gains kept"
        wall = time.perf_counter() - t_m
        grad_choice[lab] = {k: float(getattr(g, k)) for k in TUNED}
        # Diagnostics (not part of the gradient's cost): its gains scored as the grid scores
        # its configurations, and the surrogate loss at the grid's choice.
        t_d = time.perf_counter()
        res = runner.run(train, g, m, args.train_steps, seed=args.train_seed)
        c = counts_of(res["status"])
        grid_loss = None
        if lab in grid_choice:
            grid_loss = float(tune_gains(sub, with_gains(grid_choice[lab]), steps=1, optimizer=optax.sgd(0.0),
                                         **kw).losses[0])
        diag_s += time.perf_counter() - t_d
        grad_info[lab] = dict(seconds=wall - comp, compile_seconds=comp, losses=losses, best_update=k_best,
                              note=note, value_and_grad_calls=args.grad_updates + 1, scenes=args.grad_scenes,
                              steps=args.train_steps,
                              path=[{k: float(getattr(h, k)) for k in TUNED} for h in history],
                              train_counts=c, train_score=score_of(c), surrogate_at_grid_choice=grid_loss)
        stamp(f"grad {lab}: {grad_choice[lab]}, loss {losses[:1]} -> best {min(losses) if losses else None} "
              f"({wall - comp:.0f} s + compile {comp:.0f} s) {note}; training score {score_of(c)} "
              f"(grid's best {max(r['score'] for r in grid_rows[lab]) if lab in grid_rows else None}); "
              f"surrogate at the grid's choice {grid_loss}")
    phase_done("gradient tuning", t0, sum(g["compile_seconds"] for g in grad_info.values()))
    phases["gradient tuning"]["wall"] -= diag_s
    phases["gradient diagnostics"] = dict(wall=diag_s, compile=0.0)

    # ---- 3. held-out evaluation
    def setting_gains(setting, m):
        if setting == "default":
            return base
        return with_gains((grid_choice if setting == "grid" else grad_choice)[mlabel(m)])

    records, summary = {}, []
    t_eval, comp_eval = time.perf_counter(), 0.0
    for setting in args.setting_list:
        records[setting] = {}
        for m in args.method_list:
            lab = mlabel(m)
            res = runner.run(heldout, setting_gains(setting, m), m, args.max_steps, seed=args.eval_seed,
                             log=lambda s, lab=lab, setting=setting: stamp(f"held-out {setting}/{lab}: {s}"))
            comp_eval += res["compile_seconds"]
            c = counts_of(res["status"])
            reached = np.array([s == "reached" for s in res["status"]])
            records[setting][lab] = dict(
                status=res["status"], iterations=res["iterations"].tolist(),
                min_clearance=[float(x) if np.isfinite(x) else None for x in res["min_clearance"]])
            summary.append(dict(
                setting=setting, method=lab, n=args.n_eval, counts=c,
                intervals={s: wilson(c[s], args.n_eval) for s in STATUSES},
                gains=gains_dict(setting_gains(setting, m)),
                mean_iterations_reached=float(res["iterations"][reached].mean()) if reached.any() else None,
                checked_per_step_median=float(np.median(res["per_step"])),
                seconds=res["seconds"], compile_seconds=res["compile_seconds"]))
            stamp(f"held-out {setting}/{lab}: " + ", ".join(f"{k} {v}" for k, v in c.items())
                  + f" ({res['seconds']:.0f} s)")
            write(args, out, machine, t_all, phases, grid_rows, grid_choice, grid_cost, grad_choice, grad_info,
                  summary, records, runner, {}, [], argv, final=False)
    phase_done("held-out evaluation", t_eval, comp_eval)

    # ---- 4. planning-only cost per scene-step (default gains, methods interleaved)
    t0 = time.perf_counter()
    timing = cost_per_step(args, runner, heldout, base, stamp)
    phase_done("cost per step", t0, sum(v for k, v in runner.compile_s.items() if k[1] == "planning"))

    # ---- 5. figures and the report
    t0 = time.perf_counter()
    figs = make_figures(args, summary, grid_rows, grid_choice, grad_info, timing, fig_dir) + paper_figs
    phase_done("figures", t0)
    return write(args, out, machine, t_all, phases, grid_rows, grid_choice, grid_cost, grad_choice, grad_info,
                 summary, records, runner, timing, figs, argv, final=True)


def write(args, out, machine, t_all, phases, grid_rows, grid_choice, grid_cost, grad_choice, grad_info,
          summary, records, runner, timing, figs, argv, final: bool) -> dict:
    from _common import finish_machine, log, write_results

    total = time.perf_counter() - t_all
    finish_machine(machine)
    argv = sys.argv[1:] if argv is None else list(argv)
    report = dict(
        machine=machine, command=" ".join(["python benchmarks/science.py", *argv]),
        args={k: v for k, v in vars(args).items()}, seconds=total, complete=final, phases=phases,
        grid=grid_rows, grid_choice=grid_choice, grid_cost=grid_cost,
        grid_edges={lab: edge_of(c, args.grid_axes) for lab, c in grid_choice.items()},
        grad_choice=grad_choice, grad=grad_info, summary=summary,
        paired=paired_of(records), paired_grad_vs_grid=paired_settings(records, "grad", "grid"),
        cost_per_step=timing,
        compile_seconds={"/".join(map(str, k)): v for k, v in runner.compile_s.items()},
        figures=figs,
        scenes=dict(train=dict(seed=args.train_seed, n=args.n_train, steps=args.train_steps,
                               grad_scenes=args.grad_scenes),
                    heldout=dict(seed=args.eval_seed, n=args.n_eval, steps=args.max_steps)),
        records_note=("records[setting][method][field][i] is scene i of random_scenarios(eval_seed, n_eval); "
                      "grid[method][k].scenes[i] the status code (r reached, c collided, s stalled, m max_steps, "
                      "n non_finite) of scene i of random_scenarios(train_seed, n_train); the escapes of the "
                      "chunk of scenes starting at c0 use seed * 100003 + c0 (chunk args.chunk)"),
        records=records)
    write_results(out, report, markdown(args, report))
    log(f"[science {total:7.0f} s] wrote {out}.md and .json ({'complete' if final else 'partial'})")
    return report


def cost_per_step(args, runner, suite, gains, stamp) -> dict:
    """Planning-only seconds per scene-step of the first held-out chunks, round
    robin over the methods (so the machine's load falls on all alike)."""
    import jax

    from softplan_jax.planning._programs import rollout_batch

    batches = runner.batches(suite)[: args.timing_chunks]
    for m in args.method_list:
        runner.ensure_compiled(suite, gains, m, args.max_steps, check=False, log=stamp)
    times = {mlabel(m): [] for m in args.method_list}
    for rnd in range(2):
        for c0, idx in batches:
            batch = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], suite)
            for m in args.method_list:
                t0 = time.perf_counter()
                jax.block_until_ready(rollout_batch(batch, gains, runner.options(m, False), args.max_steps,
                                                    seed=args.eval_seed * 100003 + c0))
                times[mlabel(m)].append((time.perf_counter() - t0) / (len(idx) * (args.max_steps + 1)))
        stamp(f"cost per step, round {rnd + 1}/2: " + ", ".join(f"{k} {1e6 * np.median(v):.0f} us"
                                                              for k, v in times.items()))
    return {k: dict(median=float(np.median(v)), min=float(np.min(v)), samples=v) for k, v in times.items()}


def paired_rows(x_rec, y_rec) -> dict:
    row = {}
    for outcome in ("reached", "collided"):
        x = np.array([s == outcome for s in x_rec["status"]])
        y = np.array([s == outcome for s in y_rec["status"]])
        b, c = int((x & ~y).sum()), int((~x & y).sum())
        row[outcome] = dict(x_only=b, y_only=c, mcnemar_p=mcnemar_exact(b, c),
                            diff=list(paired_bootstrap(x, y, n_boot=5000, seed=1)))
    return row


def paired_of(records) -> list:
    """Paired comparisons curve (x) vs each N (y), per setting (same held-out scenes)."""
    paired = []
    for setting, rec in records.items():
        if "curve" not in rec:
            continue
        for lab, r in rec.items():
            if lab != "curve":
                paired.append(dict(setting=setting, method=lab, **paired_rows(rec["curve"], r)))
    return paired


def paired_settings(records, a: str, b: str) -> list:
    """Paired comparisons of setting a (x) vs setting b (y), per method."""
    if a not in records or b not in records:
        return []
    return [dict(method=lab, **paired_rows(records[a][lab], records[b][lab]))
            for lab in records[a] if lab in records[b]]


def paper_figures(args, fig_dir, sp, stamp) -> list[str]:
    if args.skip_paper_figures:
        return []
    from softplan_jax import plotting

    written = []
    for name in ("sim1", "sim2", "tree"):
        for method, n in (("curve", 10), ("points", 10)):
            sc, g, o = sp.apply_preset("paper", sp.paper_scenario(name))
            r = sp.plan(sc, method, n, gains=g, max_steps=150, **o)
            lab = "curve method" if method == "curve" else f"{n}-point model"
            fig = plotting.plot_snapshots_with_clearance(
                sc, r, title=f"{name}, {lab}, 'paper' preset: {r.status} after {r.iterations} iterations, "
                f"min clearance {r.min_clearance:.3f}")
            written.append(_save(fig, fig_dir, f"science_paper_{name}_{'curve' if method == 'curve' else f'N{n}'}.png"))
            stamp(f"figure {name} {method}: {r.status} {r.iterations}")
    return written


def _save(fig, fig_dir, name) -> str:
    import matplotlib.pyplot as plt

    path = os.path.join(fig_dir, name)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return os.path.relpath(path, os.path.dirname(fig_dir))


def make_figures(args, summary, grid_rows, grid_choice, grad_info, timing, fig_dir) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    written = []
    quick = " — QUICK MODE" if args.quick else ""
    ns = [m for m in args.method_list if m != "curve"]

    # Rates vs N, one row per setting.
    panels = [(("reached",), "success (reached)"), (("collided",), "collided"),
              (("stalled", "max_steps", "non_finite"), "stalled, out of steps or non-finite")]
    settings = [s for s in args.setting_list if any(r["setting"] == s for r in summary)]
    if settings and ns:
        fig, axes = plt.subplots(len(settings), 3, figsize=(14, 3.6 * len(settings)), squeeze=False)
        for i, setting in enumerate(settings):
            rows = {r["method"]: r for r in summary if r["setting"] == setting}
            for j, (keys, name) in enumerate(panels):
                ax = axes[i, j]

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
                                color="tab:blue", capsize=4, label="N-point model (95 % Wilson)")
                ax.set_xscale("log")
                ax.set_xticks(ns)
                ax.set_xticklabels([str(n) for n in ns])
                ax.minorticks_off()
                ax.set_ylim(-0.02, 1.02)
                ax.set_xlabel("N (points per curve)")
                ax.set_ylabel("rate")
                ax.set_title(f"{name} — {SETTING_NAMES[setting]}", fontsize=10)
                ax.grid(alpha=0.3)
        handles, labels = axes[0, 0].get_legend_handles_labels()
        top = 1 - 0.15 / len(settings)
        fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=9, bbox_to_anchor=(0.5, top))
        fig.suptitle(f"held-out random_scenarios({args.eval_seed}, {args.n_eval}), {args.max_steps} steps; "
                     f"gains tuned per method on random_scenarios({args.train_seed}, {args.n_train}){quick}",
                     fontsize=12, y=1.0 + 0.02 / len(settings))
        fig.tight_layout(rect=(0, 0, 1, top))
        written.append(_save(fig, fig_dir, "science_rates_vs_n.png"))

    # Heat maps over d0 x dt (training seed): one row per eta, one column per method.
    if grid_rows:
        d0s, dts, etas = args.grid_axes["d0"], args.grid_axes["dt"], args.grid_axes["eta"]
        labs = list(grid_rows)
        for outcome, cmap, fname, what in (("collided", "Reds", "science_heatmap_d0_dt.png", "collision rate"),
                                           ("reached", "Greens", "science_heatmap_reached.png", "success rate")):
            fig, axes = plt.subplots(len(etas), len(labs), figsize=(3.4 * len(labs) + 1.2, 3.1 * len(etas) + 0.6),
                                     squeeze=False, layout="constrained")
            for col, lab in enumerate(labs):
                for row, eta in enumerate(etas):
                    ax = axes[row, col]
                    M = np.full((len(d0s), len(dts)), np.nan)
                    for r in grid_rows[lab]:
                        if r["eta"] == eta:
                            M[d0s.index(r["d0"]), dts.index(r["dt"])] = 100 * r["counts"][outcome] / args.n_train
                    im = ax.imshow(M, origin="lower", cmap=cmap, vmin=0, vmax=100, aspect="auto")
                    for a in range(len(d0s)):
                        for b in range(len(dts)):
                            v = M[a, b]
                            ax.text(b, a, f"{v:.0f}", ha="center", va="center", fontsize=8,
                                    color="white" if v > 60 else "black")
                    gc = grid_choice.get(lab)
                    if gc and gc["eta"] == eta:
                        ax.add_patch(Rectangle((dts.index(gc["dt"]) - 0.5, d0s.index(gc["d0"]) - 0.5), 1, 1,
                                               fill=False, ec="tab:blue", lw=2.5))
                    ax.set_xticks(range(len(dts)))
                    ax.set_xticklabels([f"{x:g}" for x in dts], fontsize=8)
                    ax.set_yticks(range(len(d0s)))
                    ax.set_yticklabels([f"{x:g}" for x in d0s], fontsize=8)
                    if row == len(etas) - 1:
                        ax.set_xlabel("dt")
                    if col == 0:
                        ax.set_ylabel(f"d0   (eta = {eta:g})")
                    ax.set_title(f"{lab}, eta = {eta:g}", fontsize=10)
            fig.colorbar(im, ax=axes, shrink=0.8, label=f"{what} [% of the {args.n_train} training scenes]")
            fig.suptitle(f"{what} over d0 x dt on the TRAINING seed: random_scenarios({args.train_seed}, "
                         f"{args.n_train}), {args.train_steps} steps; blue box: the grid's choice{quick}",
                         fontsize=11)
            written.append(_save(fig, fig_dir, fname))

    # The gradient's training loss and its path in the (d0, dt) plane.
    if grad_info:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.6))
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for i, (lab, gi) in enumerate(grad_info.items()):
            col = colors[i % len(colors)]
            if gi["losses"]:
                ax1.plot(range(len(gi["losses"])), gi["losses"], "-", color=col, label=lab)
                ax1.plot(gi["best_update"], gi["losses"][gi["best_update"]], "*", color=col, ms=12)
            if gi["surrogate_at_grid_choice"] is not None:
                ax1.axhline(gi["surrogate_at_grid_choice"], color=col, ls="--", lw=1)
            path = gi["path"]
            ax2.plot([p["dt"] for p in path], [p["d0"] for p in path], ".-", color=col, lw=1, ms=3, label=lab)
            best = path[gi["best_update"]]
            ax2.plot(best["dt"], best["d0"], "*", color=col, ms=12)
            if lab in grid_choice:
                ax2.plot(grid_choice[lab]["dt"], grid_choice[lab]["d0"], "s", mfc="none", color=col, ms=11, mew=2)
        ax1.set_xlabel("update")
        ax1.set_ylabel("surrogate loss (training scenes)")
        ax1.set_title("gradient tuning: loss per update (star: best iterate, kept);\n"
                      "dashed: the surrogate at the grid's choice", fontsize=10)
        ax1.grid(alpha=0.3)
        ax1.legend(fontsize=8)
        ax2.plot([0.1], [0.07], "kx", ms=10, mew=2, label="default gains (start)")
        ax2.set_xlabel("dt")
        ax2.set_ylabel("d0")
        ax2.set_title("path of the gains (star: kept; square: grid's choice)", fontsize=10)
        ax2.add_patch(Rectangle((args.grid_axes["dt"][0], args.grid_axes["d0"][0]),
                                args.grid_axes["dt"][-1] - args.grid_axes["dt"][0],
                                args.grid_axes["d0"][-1] - args.grid_axes["d0"][0],
                                fill=False, ls=":", ec="0.5", label="grid's range"))
        ax2.grid(alpha=0.3)
        ax2.legend(fontsize=8)
        fig.suptitle(f"gradient tuning on random_scenarios({args.train_seed}, {args.n_train})[:{args.grad_scenes}], "
                     f"{args.train_steps} steps{quick}", fontsize=11)
        fig.tight_layout()
        written.append(_save(fig, fig_dir, "science_gradient.png"))

    # Cost per scene-step vs N.
    if timing and ns:
        fig, ax = plt.subplots(figsize=(6.5, 4.3))
        pts = [(n, timing[f"N={n}"]["median"], timing[f"N={n}"]["min"]) for n in ns if f"N={n}" in timing]
        if pts:
            x, med, mn = map(np.asarray, zip(*pts, strict=True))
            ax.plot(x, 1e6 * med, "o-", color="tab:blue", label="N-point model, planning only (median)")
            ax.plot(x, 1e6 * mn, "o:", color="tab:blue", alpha=0.5, label="N-point model, planning only (min)")
        if "curve" in timing:
            ax.axhline(1e6 * timing["curve"]["median"], color="tab:green", label="curve method, planning only (median)")
            ax.axhline(1e6 * timing["curve"]["min"], color="tab:green", ls=":", alpha=0.6,
                       label="curve method, planning only (min)")
        checked = {r["method"]: r["checked_per_step_median"] for r in summary if r["setting"] == "default"}
        cp = [(n, checked[f"N={n}"]) for n in ns if f"N={n}" in checked]
        if cp:
            x, y = map(np.asarray, zip(*cp, strict=True))
            ax.plot(x, 1e6 * y, "s--", color="tab:gray", label="N points, with collision checks (median)")
        if "curve" in checked:
            ax.axhline(1e6 * checked["curve"], color="tab:gray", ls="-.", label="curve, with collision checks")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(ns)
        ax.set_xticklabels([str(n) for n in ns])
        ax.minorticks_off()
        ax.set_xlabel("N (points per curve)")
        ax.set_ylabel("time per scene-step [µs]")
        ax.set_title(f"batched cost per scene-step, default gains, chunks of {min(args.chunk, args.n_eval)}\n"
                     f"(shared 2-core machine; compile excluded){quick}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
        written.append(_save(fig, fig_dir, "science_cost_per_step.png"))
    return written


def markdown(args, rep) -> str:
    from _common import machine_lines

    n = args.n_eval
    L = [f"# Curve vs N-point obstacles: tuned per method, held-out evaluation{' (QUICK MODE)' if args.quick else ''}",
         ""]
    if args.quick:
        L += ["**Quick mode: tiny sizes, for checking the pipeline only; no conclusion should be drawn.**", ""]
    if not rep["complete"]:
        L += ["**Partial report: the run is still under way (or stopped) before every row was evaluated.**", ""]
    L += machine_lines(rep["machine"])
    L += [f"- command: `{rep['command']}`, one process, nothing merged or copied from other runs; wall time "
          f"{rep['seconds']:.0f} s ({rep['seconds'] / 60:.1f} min) on this machine, compile included",
          f"- training seed {args.train_seed} ({args.n_train} scenes, {args.train_steps} steps); held-out seed "
          f"{args.eval_seed} ({n} scenes, {args.max_steps} steps); planner: the library's default (safe step, "
          "escapes) with its collision checks in the scan; float64",
          "- rates: count (% [95 % Wilson interval]); success = reached the goal without collision; collided = "
          "true clearance <= contact tolerance at a step or between steps (exact check against the real curves)",
          "", "Time per phase (wall, compile included; compile apart):", "",
          "| phase | wall | of which compile |", "|---|---|---|"]
    for name, p in rep["phases"].items():
        L.append(f"| {name} | {p['wall']:.0f} s | {p['compile']:.0f} s |")

    # ---- tuning
    L += ["", "## Tuning (training seed)", "",
          f"Grid: d0 {args.grid_axes['d0']} x dt {args.grid_axes['dt']} x eta {args.grid_axes['eta']} = "
          f"{len(args.grid)} configurations per method, each on all {args.n_train} training scenes; score = "
          "reached - 3 x collided (ties: more reached, then the first in grid order). Gradient: "
          f"{args.grad_updates} adam updates (learning rate {args.lr:g} decaying to {args.lr_final:g} along a "
          "cosine; gradient clipped to global norm 1 first) of the rollout loss (`tuning.rollout_loss`, default "
          f"weights) on the first {args.grad_scenes} training scenes, in log d0 / log eta / log dt, from the "
          "default gains; the iterate with the lowest training loss is kept. Costs are run time with the "
          "compile apart; *training score* scores the gradient's gains on all training scenes as the grid "
          "scores its configurations (a diagnostic, not part of its cost).", "",
          "| method | grid choice (d0, dt, eta) | its score | grid cost | gradient result (d0, dt, eta) | "
          "its score | gradient cost | surrogate: start -> kept (update) ; at the grid's choice |",
          "|---|---|---|---|---|---|---|---|"]
    for lab, gc in rep["grid_choice"].items():
        cost = rep["grid_cost"][lab]
        best = max(r["score"] for r in rep["grid"][lab])
        cells = [lab, f"{gc['d0']:g}, {gc['dt']:g}, {gc['eta']:g}", str(best),
                 f"{cost['seconds']:.0f} s + {cost['compile_seconds']:.0f} s compile ({cost['rollouts']} rollouts "
                 f"of {cost['steps']} steps)"]
        gi, gr = rep["grad"].get(lab), rep["grad_choice"].get(lab)
        if gi:
            loss = (f"{gi['losses'][0]:.3f} -> {min(gi['losses']):.3f} ({gi['best_update']})" if gi["losses"]
                    else gi["note"])
            at_grid = gi["surrogate_at_grid_choice"]
            loss += f" ; {at_grid:.3f}" if at_grid is not None else ""
            cells += [f"{gr['d0']:.3g}, {gr['dt']:.3g}, {gr['eta']:.3g}", str(gi["train_score"]),
                      f"{gi['seconds']:.0f} s + {gi['compile_seconds']:.0f} s compile ({gi['value_and_grad_calls']} "
                      f"loss+gradient on {gi['scenes']} scenes x {gi['steps']} steps)", loss]
        else:
            cells += ["—"] * 4
        L.append("| " + " | ".join(cells) + " |")
    edges = {lab: e for lab, e in rep["grid_edges"].items() if e}
    L += [""]
    if edges:
        L += ["**At the edge of the grid** (the grid's choice is the smallest or largest value tried): "
              + "; ".join(f"{lab}: {', '.join(e)}" for lab, e in edges.items())
              + ". A wider grid might choose differently there.", ""]
    else:
        L += [f"Every grid choice is interior in d0 and dt (eta has only the two values {args.grid_axes['eta']}).",
              ""]

    # ---- held-out
    L += ["## Held-out results", "",
          "| gains | method | d0, dt, eta | reached | collided | stalled | max steps | non-finite | "
          "mean its (reached) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["summary"]:
        c, g = r["counts"], r["gains"]
        it = f"{r['mean_iterations_reached']:.1f}" if r["mean_iterations_reached"] is not None else "—"
        L.append(f"| {r['setting']} | {r['method']} | {g['d0']:.3g}, {g['dt']:.3g}, {g['eta']:.3g} | "
                 f"{fmt_rate(c['reached'], n)} | {fmt_rate(c['collided'], n)} | {fmt_rate(c['stalled'], n)} | "
                 f"{fmt_rate(c['max_steps'], n)} | {fmt_rate(c['non_finite'], n)} | {it} |")
    L += ["", "Per-scene records of every row (status, iterations, min clearance) are in the JSON "
          "(`records[setting][method]`, index = scene of the held-out suite).", ""]

    def paired_table(rows, first, xname, yname):
        out = [f"| {first} | reached: {xname} only / {yname} only, p | success diff [95 %] | "
               f"collided: {xname} only / {yname} only, p | collision diff [95 %] |", "|---|---|---|---|---|"]
        for p in rows:
            a, b = p["reached"], p["collided"]
            head = f"{p['setting']}, {p['method']}" if "setting" in p else p["method"]
            out.append(f"| {head} | {a['x_only']} / {a['y_only']}, {a['mcnemar_p']:.2g} | "
                       f"{100 * a['diff'][0]:+.1f} [{100 * a['diff'][1]:+.1f}, {100 * a['diff'][2]:+.1f}] | "
                       f"{b['x_only']} / {b['y_only']}, {b['mcnemar_p']:.2g} | "
                       f"{100 * b['diff'][0]:+.1f} [{100 * b['diff'][1]:+.1f}, {100 * b['diff'][2]:+.1f}] |")
        return out

    if rep["paired"]:
        L += ["## Paired comparisons, curve vs N (same held-out scenes, same setting)", "",
              "Discordant pairs: *curve only* = scenes where the curve method has the outcome and the N-point "
              "model not; exact two-sided McNemar p; difference of rates (curve - N, percentage points) with a "
              "95 % paired-bootstrap interval (5,000 resamples of the scenes).", ""]
        L += paired_table(rep["paired"], "gains, N", "curve", "N") + [""]
    if rep["paired_grad_vs_grid"]:
        L += ["## Gradient vs grid (same method, same held-out scenes)", "",
              "Difference of rates gradient - grid (percentage points), paired as above.", ""]
        L += paired_table(rep["paired_grad_vs_grid"], "method", "grad", "grid") + [""]

    # ---- cost
    if rep["cost_per_step"]:
        checked = {r["method"]: r["checked_per_step_median"] for r in rep["summary"] if r["setting"] == "default"}
        cur = rep["cost_per_step"].get("curve")
        L += ["## Cost per scene-step (default gains)", "",
              f"Planning only (`check_collisions=False`): the first {args.timing_chunks} held-out chunks of "
              f"{min(args.chunk, n)} scenes x {args.max_steps + 1} steps, twice, the methods interleaved; with "
              "checks: the held-out run's chunks (median). Compile excluded. The machine is shared (load average "
              "above): read ratios, not absolute figures.", "",
              "| method | planning only, median | min | curve / this (median) | with collision checks, median |",
              "|---|---|---|---|---|"]
        for lab, t in rep["cost_per_step"].items():
            ratio = f"{cur['median'] / t['median']:.2f}x" if cur else "—"
            chk = f"{1e6 * checked[lab]:.0f} µs" if lab in checked else "—"
            L.append(f"| {lab} | {1e6 * t['median']:.0f} µs | {1e6 * t['min']:.0f} µs | {ratio} | {chk} |")
        L += [""]

    # ---- sensitivity
    if rep["grid"]:
        half = 50 * (wilson(args.n_train // 2, args.n_train)[1] - wilson(args.n_train // 2, args.n_train)[0])
        L += ["## Sensitivity (training seed): reached / collided over the grid", "",
              f"Each cell: scenes reached / collided of the {args.n_train} training scenes ({args.train_steps} "
              f"steps); **bold**: the grid's choice. With {args.n_train} scenes a rate's 95 % Wilson interval "
              f"reaches ±{half:.0f} "
              "points (0 of "
              f"{args.n_train}: [0, {100 * wilson(0, args.n_train)[1]:.1f} %]). The heat maps "
              "(`figures/science_heatmap_d0_dt.png`, `figures/science_heatmap_reached.png`) show the same.", ""]
        d0s, dts = args.grid_axes["d0"], args.grid_axes["dt"]
        for lab, rows in rep["grid"].items():
            gc = rep["grid_choice"][lab]
            for eta in args.grid_axes["eta"]:
                cell = {(r["d0"], r["dt"]): r for r in rows if r["eta"] == eta}
                L += [f"**{lab}, eta = {eta:g}**", "", "| d0 \\ dt | " + " | ".join(f"{x:g}" for x in dts) + " |",
                      "|---|" + "---|" * len(dts)]
                for d0 in d0s:
                    cs = []
                    for dt in dts:
                        r = cell.get((d0, dt))
                        s = f"{r['counts']['reached']} / {r['counts']['collided']}" if r else "—"
                        if (d0, dt, eta) == (gc["d0"], gc["dt"], gc["eta"]):
                            s = f"**{s}**"
                        cs.append(s)
                    L.append(f"| {d0:g} | " + " | ".join(cs) + " |")
                L += [""]
    if rep["figures"]:
        L += ["## Figures", ""] + [f"- `{f}`" for f in rep["figures"]]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
