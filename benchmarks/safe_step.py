"""The clearance-bounded (safe) step and the escapes, measured on the random suite.

For each planner variant (``--variants``) and obstacle model (``--methods``),
every scene of ``random_scenarios(seed, n)`` is planned with a planning-only
rollout (``rollout_batch``, ``check_collisions=False``) and then checked with
``apply_collision_checks``: the exact clearance to the REAL curves at every
step and the between-step search over the motion (the rollout is cut at the
first contact, as a checked rollout would be). Reported per variant and
model: reached / collided / stalled / max-steps / non-finite rates with 95 %
Wilson intervals, iterations over successes, escapes used, and the safe
step's scale. Per-scene records (scene x variant x model -> status,
iterations, min clearance) go to the JSON file.

Variants:

* ``plain``: the paper's step as the earlier releases planned (``sp.PAPER_STEP``:
  ``step="plain"``, no escapes, stall test 60 steps / 1e-4);
* ``safe``: the same with the clearance-bounded step;
* ``default``: the library's defaults (safe step, escapes, stall test 30 steps / 0.02).

Usage (``run_all.py`` runs the three held-out runs whose reports are committed)::

    python benchmarks/safe_step.py --seed 0 --n 256            # training seed (the defaults were chosen on it)
    python benchmarks/safe_step.py --seed 1 --n 1000 --chunk 64 --max-steps 600 --variants default --methods curve,10,50
    python benchmarks/safe_step.py --seed 1 --n 1000 --chunk 64 --max-steps 600 --variants default --float32
    python benchmarks/safe_step.py --seed 1 --n 1000 --chunk 64 --max-steps 600 --variants plain,safe \\
        --out benchmarks/results/safe_step_float64_seed1_n1000_before
    python benchmarks/safe_step.py --quick                     # smoke run into results/quick/

Writes ``benchmarks/results/safe_step_<dtype>_seed<seed>_n<n>.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _stats import fmt_rate, wilson  # noqa: E402  (shared statistics; wilson re-exported for callers)

VARIANTS = ("plain", "safe", "default")


def variant_options(variant: str) -> dict:
    """PlanOptions fields of a variant (imported lazily: this module imports no jax)."""
    from softplan_jax.planning import PAPER_STEP

    return {
        "plain": dict(PAPER_STEP),  # the earlier default: the paper's step, no escapes, stall test 60 / 1e-4
        "safe": dict(PAPER_STEP, step="safe"),  # the same with the clearance-bounded step
        "default": {},  # the library's defaults: safe step, escapes, stall test 30 steps / 0.02
    }[variant]
STATUSES = ("reached", "collided", "stalled", "max_steps", "non_finite")


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of random_scenarios (default 0: the training seed)")
    ap.add_argument("--quick", action="store_true", help="smoke run (16 scenes, 60 steps) into results/quick/")
    ap.add_argument("--n", type=int, default=None, help="number of scenes (default 256; quick 16)")
    ap.add_argument("--chunk", type=int, default=None, help="scenes per vmapped call (default 128; quick 16)")
    ap.add_argument("--max-steps", type=int, default=None, help="planner steps (default 300, as plan; quick 60)")
    ap.add_argument("--variants", default="plain,safe,default", help="comma list of plain, safe, default")
    ap.add_argument("--methods", default="curve", help="comma list of 'curve' and point counts N (default curve)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override a PlanOptions field of every variant (e.g. safe_fraction=0.3)")
    ap.add_argument("--float32", action="store_true", help="float32 (default float64)")
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/safe_step_...)")
    args = ap.parse_args(argv)
    for key, full, quick in (("n", 256, 16), ("chunk", 128, 16), ("max_steps", 300, 60)):
        if getattr(args, key) is None:
            setattr(args, key, quick if args.quick else full)
    args.variant_list = args.variants.split(",")
    for v in args.variant_list:
        if v not in VARIANTS:
            ap.error(f"--variants: unknown variant {v!r}; choose from {sorted(VARIANTS)}")
    try:
        args.method_list = [m if m == "curve" else int(m) for m in args.methods.split(",")]
    except ValueError:
        ap.error(f"--methods: use 'curve' and integers, got {args.methods!r}")
    args.overrides = {}
    for item in args.set:
        field, _, value = item.partition("=")
        try:
            args.overrides[field] = json.loads(value)
        except json.JSONDecodeError:
            args.overrides[field] = value
    if args.n < 1 or args.chunk < 1 or args.max_steps < 1:
        ap.error("--n, --chunk and --max-steps must be >= 1")
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    import jax

    if not args.float32:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from _common import RESULTS_DIR, finish_machine, log, machine_info, machine_lines

    import softplan_jax as sp
    from softplan_jax.base._status import status_name
    from softplan_jax.planning import apply_collision_checks
    from softplan_jax.planning._planner import make_options
    from softplan_jax.planning._programs import rollout_batch

    dtype = jnp.float32 if args.float32 else jnp.float64
    dname = "float32" if args.float32 else "float64"
    machine = machine_info(dname)
    t_all = time.perf_counter()
    log(f"safe_step: random_scenarios({args.seed}, {args.n}) in {dname} ...")
    suite = sp.random_scenarios(args.seed, args.n, dtype=dtype)
    n = args.n
    chunk = min(args.chunk, n)
    pad = (-n) % chunk
    take = np.concatenate([np.arange(n), np.full(pad, n - 1)])
    gains = sp.default_gains(dtype)
    check = jax.jit(jax.vmap(apply_collision_checks, in_axes=(0, 0, None)), static_argnums=2)

    records: dict[str, dict] = {}
    summary = []
    for variant in args.variant_list:
        for method in args.method_list:
            label = f"{variant}/{'curve' if method == 'curve' else f'N={method}'}"
            kw = dict(variant_options(variant), **args.overrides)
            opts = make_options("curve" if method == "curve" else "points", 10 if method == "curve" else method,
                                check_collisions=False, **kw)
            status, iters, minc, escapes, alphas = [], [], [], [], []
            t0 = time.perf_counter()
            for c0 in range(0, n + pad, chunk):
                idx = take[c0: c0 + chunk]
                batch = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], suite)
                r = rollout_batch(batch, gains, opts, args.max_steps, seed=args.seed * 100003 + c0)
                r = jax.block_until_ready(check(r, batch, opts))
                status.append(np.asarray(r.status))
                iters.append(np.asarray(r.iterations))
                minc.append(np.asarray(r.min_clearance))
                escapes.append(np.asarray(r.escapes))
                steps = np.arange(r.q.shape[1])[None, :] < np.asarray(r.iterations)[:, None]
                a = np.asarray(r.step_scale)
                alphas.append(np.where(steps, a, np.nan))
                log(f"  {label}: {min(c0 + chunk, n)}/{n} scenes, {time.perf_counter() - t0:.0f} s")
            status = np.concatenate(status)[:n]
            iters = np.concatenate(iters)[:n]
            minc = np.concatenate(minc)[:n]
            escapes = np.concatenate(escapes)[:n]
            alphas = np.concatenate(alphas)[:n]
            names = [status_name(s) for s in status]
            counts = {s: int(sum(x == s for x in names)) for s in STATUSES}
            reached = np.array([x == "reached" for x in names])
            row = dict(
                label=label, variant=variant, method=str(method), n=n, counts=counts,
                intervals={s: wilson(counts[s], n) for s in STATUSES},
                mean_iterations_reached=float(iters[reached].mean()) if reached.any() else None,
                scenes_with_escapes=int((escapes > 0).sum()),
                reached_after_escape=int(((escapes > 0) & reached).sum()),
                min_clearance=float(np.nanmin(minc)),
                nan_min_clearance=int(np.isnan(minc).sum()),
                step_scale_below_1=float(np.nanmean(alphas < 1)) if np.isfinite(alphas).any() else None,
                collided_scenes=[int(i) for i in np.nonzero([x == "collided" for x in names])[0]],
                seconds=time.perf_counter() - t0,
                options={k: v for k, v in opts._asdict().items() if k != "solver"},
            )
            summary.append(row)
            records[label] = dict(status=names, iterations=iters.tolist(),
                                  min_clearance=[None if not np.isfinite(x) else float(x) for x in minc],
                                  escapes=escapes.tolist())
            log(f"  {label}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))

    total = time.perf_counter() - t_all
    finish_machine(machine)
    lines = [f"# Safe step and escapes on random_scenarios({args.seed}, {n}), {dname}", ""]
    lines += machine_lines(machine)
    lines += [
        f"- command: `python benchmarks/safe_step.py {' '.join(argv if argv is not None else sys.argv[1:])}`",
        f"- {args.max_steps} steps, default gains; total time {total:.0f} s (compile included)",
        "- collisions: `apply_collision_checks` (exact clearance at every step, between-step search over the "
        "motion) against the real curves, whatever model the planner used",
        "- rates: count (% [95 % Wilson interval])",
        "",
        "| variant / model | reached | collided | stalled | max steps | non-finite | mean iter. (reached) "
        "| escapes used | steps scaled < 1 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in summary:
        c = r["counts"]
        it = f"{r['mean_iterations_reached']:.1f}" if r["mean_iterations_reached"] is not None else "—"
        sb = f"{100 * r['step_scale_below_1']:.1f} %" if r["step_scale_below_1"] is not None else "—"
        lines.append(
            f"| {r['label']} | {fmt_rate(c['reached'], n)} | {fmt_rate(c['collided'], n)} | "
            f"{fmt_rate(c['stalled'], n)} | {fmt_rate(c['max_steps'], n)} | {fmt_rate(c['non_finite'], n)} | "
            f"{it} | {r['scenes_with_escapes']} scenes ({r['reached_after_escape']} then reached) | {sb} |"
        )
    lines.append("")
    for r in summary:
        if r["collided_scenes"]:
            lines.append(f"- {r['label']} collided in scenes {r['collided_scenes']}")
    report = "\n".join(lines) + "\n"
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", f"safe_step_{dname}_seed{args.seed}_n{n}")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out + ".md", "w", encoding="utf-8") as fh:
        fh.write(report)
    with open(out + ".json", "w", encoding="utf-8") as fh:
        json.dump(dict(machine=machine, args={k: v for k, v in vars(args).items()}, summary=summary,
                       records=records, seconds=total), fh, indent=1, default=str)
    print(report)
    return dict(summary=summary)


if __name__ == "__main__":
    main()
