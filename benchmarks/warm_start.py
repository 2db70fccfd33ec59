"""The warm-started, certified closest points of the planner.

Three parts, one process:

1. **Exactness.** ``random_scenarios(seed, n)`` (default 200) planned with
   :func:`softplan_jax.plan_batch` and the default options (warm start on,
   collision checks on, so each step's clearance record is the warm start's
   distance); at every step k <= iterations of every scene the full solver's
   distances (:func:`softplan_jax.geometry.obstacles.true_closest`, warm start off) at
   the same q_k. A miss: warm distance > full distance + 1e-9. Also the
   fallback rate: (segment, curve) pairs that took the full solve, per
   pair-step of real curves (steps k >= 1; step 0 solves every pair in full).
2. **The paper scenes** ``sim1``, ``sim2``, ``tree`` with the default options
   and with ``PAPER_STEP``, curve method: warm start on against off (off is
   the solver of every earlier release): status, iterations, max |q_on - q_off|.
3. **Speed.** Planning-only rollouts (``check_collisions=False``): the tree
   scene single and a batch of random scenes (default 256), warm start on,
   off, and the 10-point model; compiled ahead (compile time apart),
   interleaved rounds, min and median per step.

    python benchmarks/warm_start.py            # ~15 min on 2 CPUs
    python benchmarks/warm_start.py --quick    # smoke run (8 scenes, the tree, a batch of 16) into results/quick/

Writes ``benchmarks/results/warm_start.{md,json}``.
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
    RESULTS_DIR,
    finish_machine,
    fmt_s,
    log,
    machine_info,
    machine_lines,
    rollout_wrappers,
    write_results,
)

import softplan_jax as sp  # noqa: E402
from softplan_jax.geometry import obstacles  # noqa: E402
from softplan_jax.planning.planner import make_options  # noqa: E402
from softplan_jax.planning.programs import rollout  # noqa: E402

MISS = 1e-9


def exactness(seed: int, n: int, max_steps: int, chunk: int):
    """Misses of the warm start against the full solver on every step of n random scenes."""
    scs_all = sp.random_scenarios(seed, n)
    solver = make_options().solver

    @jax.jit
    def full_distances(sc, qs):
        return jax.vmap(lambda q: obstacles.true_closest(q, sc, solver).distance)(qs)

    misses = better = compared = 0
    worst = -np.inf
    fb_pairs = pair_steps = steps_with_fb = steps = 0
    batch_loop = []  # per chunk and step: the largest fallback count in the chunk (the while loop's trips)
    t0 = time.perf_counter()
    for a in range(0, n, chunk):
        scs = jax.tree_util.tree_map(lambda x, a=a: x[a : a + chunk], scs_all)
        r = sp.plan_batch(scs, max_steps=max_steps)
        jax.block_until_ready(r.q)
        radius, mask = jax.vmap(obstacles.radius_and_mask)(scs)
        fbs = np.asarray(r.fallbacks)
        its = np.asarray(r.iterations)
        batch_loop.append(fbs[:, 1:].max(axis=0))
        for b in range(scs.q0.shape[0]):
            sc = jax.tree_util.tree_map(lambda x, b=b: x[b], scs)
            it = int(its[b])
            m = np.asarray(mask[b])
            d_full = np.asarray(full_distances(sc, r.q[b]))[: it + 1][:, m]
            d_warm = (np.asarray(r.clearance[b])[: it + 1] + np.asarray(radius[b]))[:, m]
            diff = d_warm - d_full
            worst = max(worst, float(diff.max()))
            misses += int((diff > MISS).sum())
            better += int((diff < -MISS).sum())
            compared += diff.size
            n_pairs = int(m.sum()) * sc.q0.shape[0]
            fb_pairs += int(fbs[b, 1 : it + 1].sum())
            pair_steps += it * n_pairs
            steps_with_fb += int((fbs[b, 1 : it + 1] > 0).sum())
            steps += it
        log(f"  exactness: {min(a + chunk, n)}/{n} scenes, {misses} misses of {compared}, "
            f"{time.perf_counter() - t0:.0f} s")
    loop = np.concatenate(batch_loop)
    return dict(
        seed=seed, scenes=n, max_steps=max_steps, chunk=chunk, distances_compared=compared, misses=misses,
        worst_excess=worst, warm_lower_than_full=better,
        fallback_pairs=fb_pairs, pair_steps=pair_steps, fallback_rate_pairs=fb_pairs / max(pair_steps, 1),
        steps=steps, fallback_rate_steps=steps_with_fb / max(steps, 1),
        chunk_max_fallbacks_mean=float(loop.mean()), chunk_max_fallbacks_max=int(loop.max()),
    )


def paper_scenes(names=("sim1", "sim2", "tree")):
    """Warm start on vs off on the paper's scenes ``names``, default options and PAPER_STEP."""
    rows = []
    for name in names:
        sc = sp.paper_scenario(name)
        for label, extra in (("default", {}), ("PAPER_STEP", sp.PAPER_STEP)):
            off = sp.plan(sc, warm_start=False, **extra)
            on = sp.plan(sc, warm_start=True, **extra)
            k = min(len(on.q), len(off.q))
            rows.append(dict(
                scene=name, options=label, status_off=off.status, status_on=on.status,
                iterations_off=off.iterations, iterations_on=on.iterations,
                max_dq=float(np.abs(on.q[:k] - off.q[:k]).max()) if on.q.shape == off.q.shape else float("inf"),
                min_clearance_off=off.min_clearance, min_clearance_on=on.min_clearance,
            ))
            log(f"  {name} {label}: off {off.status} {off.iterations}, on {on.status} {on.iterations}, "
                f"max |dq| {rows[-1]['max_dq']:.2g}")
    return rows


def speed(batch_size: int, steps: int, rounds: int, seed: int):
    """Per-step time of planning-only rollouts: tree single and a random batch; warm, full, 10 points."""
    g = sp.default_gains()
    variants = {
        "warm": make_options("curve", check_collisions=False),
        "full": make_options("curve", check_collisions=False, warm_start=False),
        "points10": make_options("points", 10, check_collisions=False),
    }
    tree = sp.paper_scenario("tree")
    batch = sp.random_scenarios(seed, batch_size)

    single, batched = rollout_wrappers(rollout)

    compiled, compile_s = {}, {}
    for where, fn, sc in (("tree", single, tree), ("batch", batched, batch)):
        for name, o in variants.items():
            t0 = time.perf_counter()
            c = jax.jit(fn, static_argnames=("options", "max_steps")).lower(sc, g, options=o, max_steps=steps).compile()
            compile_s[(where, name)] = time.perf_counter() - t0
            jax.block_until_ready(c(sc, g))  # warm-up
            compiled[(where, name)] = (c, sc)
            log(f"  compiled {where}/{name} in {compile_s[(where, name)]:.1f} s")
    times = {key: [] for key in compiled}
    for k in range(rounds):
        for key, (c, sc) in compiled.items():
            t0 = time.perf_counter()
            jax.block_until_ready(c(sc, g))
            times[key].append(time.perf_counter() - t0)
        log(f"  round {k + 1}/{rounds}")
    out = {}
    for (where, name), ts in times.items():
        per = (steps + 1) * (batch_size if where == "batch" else 1)
        out[f"{where}/{name}"] = dict(
            compile_s=compile_s[(where, name)], min_step_s=min(ts) / per, median_step_s=statistics.median(ts) / per,
            rounds=len(ts),
        )
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="8 scenes, the tree, batch 16, 3 rounds, into results/quick/")
    ap.add_argument("--scenes", type=int, default=None, help="random scenes for the exactness check (default 200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-steps", type=int, default=600, help="rollout length of the exactness check")
    ap.add_argument("--chunk", type=int, default=50, help="scenes per plan_batch call in the exactness check")
    ap.add_argument("--batch", type=int, default=None, help="batch size of the speed test (default 256)")
    ap.add_argument("--steps", type=int, default=200, help="rollout length of the speed test")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 7)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: exactness,paper,speed")
    ap.add_argument("--out", default=None, help="output prefix (default benchmarks/results/warm_start)")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    scenes = args.scenes or (8 if args.quick else 200)
    batch = args.batch or (16 if args.quick else 256)
    rounds = args.rounds or (3 if args.quick else 7)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    if args.out is None:
        args.out = os.path.join(RESULTS_DIR, "quick" if args.quick else "", "warm_start")
    machine = machine_info("float64")
    t_start = time.perf_counter()
    report = dict(machine=machine)
    if "exactness" not in skip:
        log(f"exactness: {scenes} random scenes (seed {args.seed}), max_steps {args.max_steps} ...")
        report["exactness"] = exactness(args.seed, scenes, args.max_steps, min(args.chunk, scenes))
    if "paper" not in skip:
        log("paper scenes, warm start on vs off ...")
        report["paper"] = paper_scenes(("tree",) if args.quick else ("sim1", "sim2", "tree"))
    if "speed" not in skip:
        log(f"speed: tree single and a batch of {batch} random scenes, {args.steps} steps, {rounds} rounds ...")
        report["speed"] = speed(batch, args.steps, rounds, args.seed)
    finish_machine(machine)
    args_used = sys.argv[1:] if argv is None else list(argv)
    cmd = "python benchmarks/warm_start.py" + (" " + " ".join(args_used) if args_used else "")
    lines = [
        "# Warm-started, certified closest points",
        "",
        f"- generated by `{cmd}` in {time.perf_counter() - t_start:.0f} s",
        *machine_lines(machine),
        "",
    ]
    if "exactness" in report:
        e = report["exactness"]
        lines += [
            f"## Exactness: {e['scenes']} random scenes (seed {e['seed']}), every step",
            "",
            "Warm-started distances (the rollout's clearance records, `plan_batch` default options) against "
            "the full solver's at the same q, every step of every scene.",
            "",
            "| quantity | value |",
            "|---|---|",
            f"| distances compared | {e['distances_compared']:,} |",
            f"| misses (warm > full + 1e-9) | **{e['misses']}** |",
            f"| largest warm - full | {e['worst_excess']:.3g} |",
            f"| warm < full - 1e-9 (the full solver's misses) | {e['warm_lower_than_full']} |",
            f"| fallback rate, pair-steps (k >= 1) | {e['fallback_rate_pairs']:.4f} "
            f"({e['fallback_pairs']:,} of {e['pair_steps']:,}) |",
            f"| steps with any fallback (k >= 1) | {e['fallback_rate_steps']:.4f} |",
            f"| largest fallback count per step in a chunk of {e['chunk']} (while-loop trips), mean / max | "
            f"{e['chunk_max_fallbacks_mean']:.2f} / {e['chunk_max_fallbacks_max']} |",
            "",
        ]
    if "paper" in report:
        lines += [
            "## The paper scenes: warm start on vs off",
            "",
            "| scene | options | status off / on | iterations off / on | max abs(q_on - q_off) |",
            "|---|---|---|---|---|",
        ]
        for r in report["paper"]:
            lines.append(f"| {r['scene']} | {r['options']} | {r['status_off']} / {r['status_on']} | "
                         f"{r['iterations_off']} / {r['iterations_on']} | {r['max_dq']:.2g} |")
        lines.append("")
    if "speed" in report:
        s = report["speed"]
        lines += [
            f"## Speed: planning-only rollouts ({args.steps} steps), per step; {rounds} interleaved rounds",
            "",
            f"Batch: {batch} random scenes (seed {args.seed}, 8 curve slots), time per scenario-step.",
            "",
            "| case | min | median | compile |",
            "|---|---|---|---|",
        ]
        for key, v in s.items():
            lines.append(f"| {key} | {fmt_s(v['min_step_s'])} | {fmt_s(v['median_step_s'])} | "
                         f"{v['compile_s']:.1f} s |")
        for where in ("tree", "batch"):
            w, f, p = (s[f"{where}/{k}"]["median_step_s"] for k in ("warm", "full", "points10"))
            lines.append(f"\n{where}: warm / full = {w / f:.2f}, warm / 10 points = {w / p:.2f} (medians)")
        lines.append("")
    md = "\n".join(lines) + "\n"
    write_results(args.out, report, md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
