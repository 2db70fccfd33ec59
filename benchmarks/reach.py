"""Reach every goal that can be reached: the global fallback on held-out scenes.

One command, progress on stderr::

    python benchmarks/reach.py            # held-out seed 1, 1,024 scenes, per-scene timing on all of them
    python benchmarks/reach.py --quick    # smoke run, written to benchmarks/results/quick/

On ``random_scenarios(seed, n)`` with the default curve planner (default
gains, ``--max-steps`` steps):

1. **Reachability of every scene** (:func:`softplan_jax.reachability`, the
   multi-start IK with exact clearances): the denominator.
2. **The batch** (:func:`softplan_jax.plan_fallback`): the local planner, then
   for each scene it leaves stalled or at max_steps reachability and the
   certified global search. Success = reached (the planner's own statuses);
   rates with Wilson 95 % intervals; paired against today's planner (the same
   local rollouts) on the same scenes.
3. **Independent check of every global path**: the brute-force
   :func:`softplan_jax.dense_trajectory_clearance` (``--dense`` substeps per
   step, 40 samples per arm segment, 300 per curve) must find no clearance
   <= 0; and every global step's swept proof is recomputed.
4. **Time per scene**, one scene at a time, interleaved: ``plan`` (today's
   planner), ``plan_fallback`` and ``reachability`` (the goal alone) on the
   same scene, one after the other, after one untimed ``plan`` of the scene
   (the first plan of a new scene costs more than the next ones, and that
   would favour whichever variant runs second); median and 95th percentile;
   compile times apart (the first call of each, on a scene the search solved).
5. **The paper scenes**: ``plan`` and ``plan_fallback`` give the same arrays
   (the local planner reaches them first).

Writes ``results/reach.{md,json}`` and ``results/figures/reach_*.png``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def parse_args(argv=None):
    """The command line, checked (ValueError naming the option)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (small sizes) into results/quick/")
    ap.add_argument("--seed", type=int, default=1, help="held-out seed of random_scenarios")
    ap.add_argument("--n", type=int, default=None, help="scenes (default 1024; quick 8)")
    ap.add_argument("--max-steps", type=int, default=600, help="local planner steps (plan's default)")
    ap.add_argument("--timing-scenes", type=int, default=None, help="scenes timed one by one (default all; quick 4)")
    ap.add_argument("--chunk", type=int, default=1, help="scenes per compiled search call")
    ap.add_argument("--dense", type=int, default=2, help="substeps per step of the brute-force check")
    ap.add_argument("--out", default=None, help="output prefix (default results/reach; quick: results/quick/reach)")
    args = ap.parse_args(argv)
    for name in ("n", "max_steps", "timing_scenes", "chunk", "dense"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    return args


def main(argv=None):
    args = parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from _common import FIGURES_DIR, RESULTS_DIR, finish_machine, log, machine_info, machine_lines, write_results
    from _stats import paired_table, pct_interval, wilson

    import softplan_jax as sp

    n = args.n or (8 if args.quick else 1024)
    n_time = min(4 if args.quick else n, n) if args.timing_scenes is None else min(args.timing_scenes, n)
    if args.out is not None:
        out_dir = os.path.dirname(os.path.abspath(args.out))
        fig_dir = os.path.join(out_dir, "figures")
    else:
        out_dir = os.path.join(RESULTS_DIR, "quick") if args.quick else RESULTS_DIR
        fig_dir = os.path.join(out_dir, "figures") if args.quick else FIGURES_DIR
    machine = machine_info("float64")
    scenes = sp.random_scenarios(args.seed, n)
    reach_opts = sp.search.ReachOptions()

    # 1. Reachability of every scene.
    t0 = time.perf_counter()
    decided = sp.search.reachability(scenes, options=reach_opts)
    t_reach_all = time.perf_counter() - t0
    ik_ok = np.asarray(decided.reachable)
    log(f"reach: IK certified {int(ik_ok.sum())}/{n} goals reachable ({t_reach_all:.1f} s incl. compile)")

    # 2. The batch: today's planner and the fallback, from the same local rollouts.
    t0 = time.perf_counter()
    results = sp.plan_fallback(scenes, max_steps=args.max_steps, chunk=args.chunk, progress=True)
    t_batch = time.perf_counter() - t0
    local = sp.plan_batch(scenes, max_steps=args.max_steps)
    local_reached = np.asarray(local.reached)
    reached = np.array([r.reached for r in results])
    collided = np.array([r.collided or r.status == "collided" for r in results])
    status = [r.status for r in results]
    planner = [r.planner for r in results]
    reason = [r.reason for r in results]
    glob = [b for b in range(n) if planner[b] == "global"]
    log(f"reach: batch {t_batch:.1f} s; reached {reached.sum()}/{n} (local {local_reached.sum()}), "
        f"{len(glob)} by the global search")

    # 3. Independent checks of every global path.
    dense = jax.jit(lambda qs, s: sp.geometry.dense_trajectory_clearance(qs, s, substeps=args.dense, arm_samples=40,
                                                                curve_samples=300))
    dense_min, proof_fail = [], 0
    for i, b in enumerate(glob):
        r = results[b]
        s = jax.tree_util.tree_map(lambda x, b=b: x[b], scenes)
        part = np.asarray(r.q[r.global_start:])
        # Padded with the last configuration to a power of two: a few compiled checks for all paths.
        size = max(128, 1 << int(np.ceil(np.log2(part.shape[0]))))
        q = jnp.asarray(np.concatenate([part, np.repeat(part[-1:], size - part.shape[0], axis=0)]))
        dense_min.append(float(jnp.min(dense(q, s))))
        c_a = np.asarray(r.clearance[r.global_start:-1]).min(axis=1)
        qa, qb = np.asarray(r.q[r.global_start:-1]), np.asarray(r.q[r.global_start + 1:])
        B = np.asarray(jax.vmap(lambda a, b_: sp.geometry.motion_bound(a, b_)[-1])(jnp.asarray(qa), jnp.asarray(qb)))
        proof_fail += int(np.sum(c_a - B <= 1e-6))
        if (i + 1) % 10 == 0:
            log(f"reach: dense check {i + 1}/{len(glob)} global paths")
    dense_min = np.array(dense_min)

    # 4. Time per scene, interleaved. First calls compile: a scene the search solved is
    # planned once untimed by both (plan_fallback then compiles reachability and the search too).
    warm = jax.tree_util.tree_map(lambda x: x[glob[0] if glob else 0], scenes)
    t0 = time.perf_counter()
    sp.plan(warm, max_steps=args.max_steps)
    compile_local = time.perf_counter() - t0
    t0 = time.perf_counter()
    sp.plan_fallback(warm, max_steps=args.max_steps)
    compile_fb = time.perf_counter() - t0
    t0 = time.perf_counter()
    sp.search.reachability(warm)
    compile_ik = time.perf_counter() - t0
    t_local, t_fb, t_ik = [], [], []
    for b in range(n_time):
        s = jax.tree_util.tree_map(lambda x, b=b: x[b], scenes)
        # The first plan of a new scene costs up to ~0.5 s more than the next ones (measured); an
        # untimed plan first, so that neither variant pays that for the other.
        sp.plan(s, max_steps=args.max_steps)
        t0 = time.perf_counter()
        sp.plan(s, max_steps=args.max_steps)
        t_local.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        sp.plan_fallback(s, max_steps=args.max_steps)
        t_fb.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        sp.search.reachability(s)
        t_ik.append(time.perf_counter() - t0)
        if (b + 1) % 64 == 0 or b + 1 == n_time:
            log(f"reach: timed {b + 1}/{n_time} scenes one by one")
    t_local, t_fb, t_ik = np.array(t_local), np.array(t_fb), np.array(t_ik)
    searched_t = np.array([planner[b] == "global" or reason[b] != "" for b in range(n_time)])

    # 5. The paper scenes.
    paper = {}
    for name in ("sim1", "sim2", "tree"):
        s = sp.paper_scenario(name)
        a, f = sp.plan(s), sp.plan_fallback(s)
        same = all(np.array_equal(getattr(a, k), getattr(f, k)) for k in ("q", "tip", "clearance")) and \
            (a.status, a.iterations, a.reached) == (f.status, f.iterations, f.reached)
        paper[name] = dict(status=f.status, planner=f.planner, iterations=f.iterations, identical=bool(same))

    # Report.
    k_ik = int(ik_ok.sum())
    k_reached_ik = int(np.sum(reached & ik_ok))
    k_local_ik = int(np.sum(local_reached & ik_ok))
    labelled = [b for b in range(n) if not reached[b]]
    unlabelled = [b for b in labelled if status[b] != "unreachable" and reason[b] == ""]
    reached_not_ik = int(np.sum(reached & ~ik_ok))
    tab = paired_table(local_reached, reached)
    report = dict(
        machine=finish_machine(machine),
        settings=dict(seed=args.seed, n=n, max_steps=args.max_steps, reach_options=reach_opts._asdict(),
                      chunk=args.chunk, dense_substeps=args.dense, timing_scenes=n_time),
        ik_reachable=k_ik,
        reached_among_ik=k_reached_ik, reached_among_ik_rate=k_reached_ik / max(k_ik, 1),
        reached_among_ik_ci=wilson(k_reached_ik, k_ik),
        local_reached_among_ik=k_local_ik, local_reached_among_ik_ci=wilson(k_local_ik, k_ik),
        reached_all=int(reached.sum()), local_reached_all=int(local_reached.sum()),
        reached_but_ik_unreachable=reached_not_ik,
        paired=dict(table=tab, mcnemar_p=tab["mcnemar_p"]),
        collisions=int(collided.sum()),
        global_paths=len(glob), dense_min_clearance=float(dense_min.min()) if len(glob) else None,
        dense_collisions=int(np.sum(dense_min <= 0)), swept_proof_failures=proof_fail,
        statuses={k: status.count(k) for k in sorted(set(status))},
        reasons={k: reason.count(k) for k in sorted(set(reason)) if k},
        unlabelled=unlabelled,
        time_batch_s=t_batch, time_reachability_all_s=t_reach_all,
        time_local=dict(median=float(np.median(t_local)), p95=float(np.percentile(t_local, 95)),
                        compile_first=compile_local),
        time_fallback=dict(median=float(np.median(t_fb)), p95=float(np.percentile(t_fb, 95)),
                           compile_first=compile_fb,
                           searched_median=float(np.median(t_fb[searched_t])) if searched_t.any() else None),
        time_reachability=dict(median=float(np.median(t_ik)), p95=float(np.percentile(t_ik, 95)),
                               compile_first=compile_ik,
                               ratio_to_local_median=float(np.median(t_ik / t_local))),
        paper=paper,
        per_scene=[dict(status=status[b], planner=planner[b], reason=reason[b], ik=bool(ik_ok[b]),
                        local_reached=bool(local_reached[b]), best_error=results[b].best_error) for b in range(n)],
    )
    md = _markdown(report, machine_lines(machine), pct_interval)
    prefix = os.path.abspath(args.out) if args.out is not None else os.path.join(out_dir, "reach")
    write_results(prefix, report, md)
    _figure(t_local, t_fb, searched_t, results, scenes, glob, fig_dir)
    log(f"reach: wrote {prefix}.md/.json")
    print(md)
    return report


def _markdown(rep, machine, pct_interval) -> str:
    k, n = rep["ik_reachable"], rep["settings"]["n"]
    lines = [
        "# Reach every goal that can be reached",
        "",
        *machine,
        f"- held-out `random_scenarios({rep['settings']['seed']}, {n})`, default curve planner and gains, "
        f"{rep['settings']['max_steps']} local steps; `ReachOptions()` defaults; regenerate with "
        "`python benchmarks/reach.py`",
        "",
        "| | scenes | reached | 95 % interval |",
        "|---|---|---|---|",
        f"| IK: a certified collision-free goal configuration | {n} | {k} | |",
        f"| today's planner, among IK-reachable | {k} | {rep['local_reached_among_ik']} | "
        f"{pct_interval(rep['local_reached_among_ik'], k)} |",
        f"| with the fallback, among IK-reachable | {k} | {rep['reached_among_ik']} | "
        f"{pct_interval(rep['reached_among_ik'], k)} |",
        "",
        f"- paired on the same scenes (today -> fallback): {rep['paired']['table']}, exact McNemar "
        f"p = {rep['paired']['mcnemar_p']:.2g}",
        f"- collisions reported: {rep['collisions']}; global paths: {rep['global_paths']}; brute-force "
        f"minimum clearance over them: {rep['dense_min_clearance']}; contacts found by the brute force: "
        f"{rep['dense_collisions']}; global steps whose swept proof fails on recomputation: "
        f"{rep['swept_proof_failures']}",
        f"- statuses: {rep['statuses']}; reasons: {rep['reasons']}; not reached and not labelled: "
        f"{len(rep['unlabelled'])}; reached although IK found no goal configuration: "
        f"{rep['reached_but_ik_unreachable']}",
        "",
        f"Time per scene, one scene at a time ({rep['settings']['timing_scenes']} scenes, interleaved):",
        "",
        "| | median | 95th percentile | first call (compiles; a scene that needs the search) |",
        "|---|---|---|---|",
        f"| today's planner (`plan`) | {rep['time_local']['median']:.3f} s | {rep['time_local']['p95']:.3f} s | "
        f"{rep['time_local']['compile_first']:.1f} s |",
        f"| with the fallback (`plan_fallback`) | {rep['time_fallback']['median']:.3f} s | "
        f"{rep['time_fallback']['p95']:.3f} s | {rep['time_fallback']['compile_first']:.1f} s |",
        f"| reachability of the goal alone (`reachability`) | {rep['time_reachability']['median']:.3f} s | "
        f"{rep['time_reachability']['p95']:.3f} s | {rep['time_reachability']['compile_first']:.1f} s |",
        "",
        f"- reachability / today's planner, per scene: median ratio "
        f"{rep['time_reachability']['ratio_to_local_median']:.2f}",
        f"- scenes where the fallback ran: median {rep['time_fallback']['searched_median']} s",
        f"- the batch (`plan_fallback` on all {n} at once, chunk {rep['settings']['chunk']}): "
        f"{rep['time_batch_s']:.1f} s including compilation; reachability of all {n}: "
        f"{rep['time_reachability_all_s']:.1f} s including compilation",
        "",
        "Paper scenes (plan vs plan_fallback): "
        + ", ".join(f"{k}: {v['status']} by {v['planner']}, identical arrays {v['identical']}"
                    for k, v in rep["paper"].items()),
        "",
    ]
    return "\n".join(lines)


def _figure(t_local, t_fb, searched, results, scenes, glob, fig_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(fig_dir, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    bins = np.logspace(np.log10(max(min(t_local.min(), t_fb.min()), 1e-3)), np.log10(max(t_fb.max(), 1e-2)), 40)
    ax.hist(t_local, bins=bins, alpha=0.6, label="today's planner (plan)")
    ax.hist(t_fb, bins=bins, alpha=0.6, label="with the fallback (plan_fallback)")
    ax.set_xscale("log")
    ax.set_xlabel("time per scene (s)")
    ax.set_ylabel("scenes")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "reach_time.png"), dpi=120)
    plt.close(fig)
    if glob:
        import jax

        from softplan_jax import plotting

        b = glob[0]
        s = jax.tree_util.tree_map(lambda x: x[b], scenes)
        fig = plotting.plot_snapshots(s, results[b], title=f"scene {b}: found by the global search")
        fig.savefig(os.path.join(fig_dir, "reach_example.png"), dpi=120)
        plt.close(fig)


if __name__ == "__main__":
    main()
