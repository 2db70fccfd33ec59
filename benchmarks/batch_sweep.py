"""Batched sweep: the curve method vs N-point obstacle models over thousands of
seeded random scenarios, one vmapped, sharded call per chunk.

The suite is ``softplan_jax.random_scenarios(seed, n)``: reachable goals (tips of
random configurations), 1-8 polynomial curves (degree 1-2) placed across the
straight path from the start tip to the goal, all padded to one shape (8 curve
slots, degree 2) so that ONE compilation per method serves every scenario.

For each method (``curve`` and N points, N in 1, 5, 10, 20, 50, 100, 200):

1. **plan**: :func:`softplan_jax.plan_batch` with a planning-only option set
   (``check_collisions=False``), in chunks of one padded shape (``--chunk``),
   sharded over every device, with progress on stderr; compiled ahead
   (``rollout_batch.lower(...).compile()`` on one chunk: compile time reported
   apart);
2. **check**: ``apply_collision_checks`` vmapped over the batch (one
   compilation shared by every method) — the true clearance to the real curves
   at every step and during the motion between steps; the rollout is cut at
   the first contact, exactly as the checked rollout would be;
3. **report**: success rate (reached without collision), collision rate,
   stalled / max-steps rates, mean iterations over successes, collisions the
   planner did not notice (planning-only "reached" that the check turns into
   "collided"), per-scenario-step time of planning (wall time of the chunked
   plan_batch / (scenarios x scan steps), padding included in the work but
   not in the count) and of checking, compile apart.

Devices: plan_batch splits every chunk over ``jax.devices()`` (``jax.shard_map``,
no cross-device communication; the chunk is rounded up to a multiple of the
device count, padding dropped from every statistic). The checks run sharded the
same way (their own ``shard_map``: apply_collision_checks has no batched entry
point in the library). On a CPU, ``--host-devices K`` (or
``XLA_FLAGS=--xla_force_host_platform_device_count=K``) splits the host into K
devices so that the shards run on K cores. (Sharded runs on 2 host devices used
to hang: jaxlib's batched LAPACK solve waited on XLA's intra-op thread pool that
the devices' programs occupied; the library's 3x3 solves no longer call LAPACK,
see ``softplan_jax.base.numerics.solve_small``.)

Writes ``benchmarks/results/batch_sweep.{md,json}`` and the figure
``benchmarks/results/figures/sweep_collision_vs_cost.png`` (collision rate
against per-step cost, one point per method). ``--quick``: a few dozen
scenarios, the curve and 10-point methods, 60 steps (a smoke test).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

DEFAULT_METHODS = "curve,1,5,10,20,50,100,200"
QUICK = dict(n=30, chunk=16, max_steps=60, methods="curve,10", check_buckets=2)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=None, help="number of random scenarios (default 10000; quick 30)")
    ap.add_argument(
        "--chunk",
        type=int,
        default=None,
        help="scenarios per vmapped call (default 500; quick 16); rounded up to a multiple of the device count",
    )
    ap.add_argument("--max-steps", type=int, default=None, help="planner steps per rollout (default 200; quick 60)")
    ap.add_argument(
        "--methods",
        default=None,
        help=f"comma list of 'curve' and point counts N (default {DEFAULT_METHODS}; quick curve,10)",
    )
    ap.add_argument("--seed", type=int, default=0, help="seed of random_scenarios (default 0)")
    ap.add_argument(
        "--check-buckets",
        type=int,
        default=None,
        help="time lengths the collision checks are compiled for (default 4; quick 2; 1 = always the full "
        "rollout): a group of finished rollouts is checked only up to its longest run",
    )
    ap.add_argument("--float32", action="store_true", help="float32 throughout (default float64)")
    ap.add_argument("--quick", action="store_true", help="30 scenarios, curve and N=10, 60 steps (< ~90 s)")
    ap.add_argument(
        "--host-devices",
        type=int,
        default=None,
        help="split the CPU into this many XLA devices (sets XLA_FLAGS before jax starts)",
    )
    ap.add_argument(
        "--out",
        default=None,
        help="output prefix (default benchmarks/results/batch_sweep; quick: results/quick/batch_sweep)",
    )
    ap.add_argument(
        "--figure",
        default=None,
        help="figure path (default benchmarks/results/figures/sweep_collision_vs_cost.png; '' = none)",
    )
    ap.add_argument(
        "--dump",
        default=None,
        help="also save per-scenario statuses, iterations and checked q of every method to this .npz",
    )
    args = ap.parse_args(argv)
    for key, val in QUICK.items():
        if getattr(args, key) is None:
            default = dict(n=10000, chunk=500, max_steps=200, methods=DEFAULT_METHODS, check_buckets=4)[key]
            setattr(args, key, val if args.quick else default)
    if args.n < 1 or args.chunk < 1 or args.max_steps < 1 or args.check_buckets < 1:
        ap.error("--n, --chunk, --max-steps and --check-buckets must be >= 1")
    try:
        args.method_list = [m if m == "curve" else int(m) for m in args.methods.split(",")]
    except ValueError:
        ap.error(f"--methods: use 'curve' and integers, got {args.methods!r}")
    if any(m != "curve" and m < 1 for m in args.method_list):
        ap.error("--methods: N must be >= 1")
    return args


def check_lengths(scan_steps: int, buckets: int) -> list[int]:
    """The time lengths the checks are compiled for: ``buckets`` evenly spaced
    lengths up to ``scan_steps`` (the last is the full rollout)."""
    buckets = max(1, min(int(buckets), scan_steps))
    return sorted({math.ceil(scan_steps * k / buckets) for k in range(1, buckets + 1)})


def check_groups(iterations, chunk: int, lengths):
    """Group scenarios for ``apply_collision_checks``: sorted by iterations, cut into
    groups of ``chunk``, each checked over the shortest length in ``lengths`` that
    holds its longest rollout (``iterations + 1`` entries).

    Exact: the check only looks at the steps up to a rollout's ``iterations``
    (the rest is frozen: a finished rollout repeats its last state), so cutting
    the time axis after them changes no status, iteration count, clearance or
    configuration; it only skips the frozen tail's closest-point solves.

    Returns a list of (indices (chunk,), length).
    """
    iterations = np.asarray(iterations)
    if iterations.size % chunk:
        raise ValueError(f"{iterations.size} scenarios are not a multiple of the chunk {chunk}")
    order = np.argsort(iterations, kind="stable")
    groups = []
    for a in range(0, order.size, chunk):
        idx = order[a : a + chunk]
        need = int(iterations[idx].max()) + 1
        groups.append((idx, min(L for L in lengths if L >= need)))
    return groups


def method_label(m) -> str:
    return "curve" if m == "curve" else f"N={m}"


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.host_devices:
        flag = f"--xla_force_host_platform_device_count={int(args.host_devices)}"
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + flag).strip()

    import jax

    jax.config.update("jax_enable_x64", not args.float32)
    import jax.numpy as jnp
    from _common import (
        FIGURES_DIR,
        RESULTS_DIR,
        ProgressBar,
        compile_timed,
        finish_machine,
        fmt_s,
        log,
        machine_info,
        timed,
        write_results,
    )
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    import softplan_jax as sp
    from softplan_jax.base.status import Status
    from softplan_jax.planning import apply_collision_checks
    from softplan_jax.planning.batching import pad_batch, round_chunk
    from softplan_jax.planning.planner import make_options
    from softplan_jax.planning.programs import rollout

    t_start = time.perf_counter()
    dtype = jnp.float32 if args.float32 else jnp.float64
    machine = machine_info("float32" if args.float32 else "float64")
    base = os.path.join(RESULTS_DIR, "quick") if args.quick else RESULTS_DIR
    out = args.out or os.path.join(base, "batch_sweep")
    figures_dir = os.path.join(base, "figures") if args.quick else FIGURES_DIR
    figure = os.path.join(figures_dir, "sweep_collision_vs_cost.png") if args.figure is None else args.figure

    # The suite, on the host.
    log(f"random_scenarios(seed={args.seed}, n={args.n}) ...")
    suite, gen_s = timed(lambda: sp.random_scenarios(args.seed, args.n, dtype=dtype))
    host = jax.tree_util.tree_map(np.asarray, suite)
    n_obstacles = host.curve_mask.sum(axis=1)

    # Chunks: a multiple of the device count; the suite padded to whole chunks for the checks
    # (plan_batch pads its own last chunk the same way: copies of the last scenario).
    devices = jax.devices()
    n_dev = len(devices)
    mesh = Mesh(np.array(devices), ("batch",))
    batch_sharding = NamedSharding(mesh, PartitionSpec("batch"))
    chunk = round_chunk(args.chunk, args.n, n_dev)
    n_chunks = math.ceil(args.n / chunk)
    n_pad = n_chunks * chunk
    pad = n_pad - args.n
    padded = pad_batch(host, n_pad)
    first = jax.tree_util.tree_map(lambda x: x[:chunk], padded)
    gains = sp.default_gains(dtype)
    T = int(args.max_steps)
    scan_steps = T + 1
    log(
        f"{args.n} scenarios (+{pad} padding) in {n_chunks} chunk(s) of {chunk} over {n_dev} device(s); "
        f"{T} steps; dtype {machine['dtype']}"
    )

    check_opts = make_options("curve", check_collisions=True)
    batch = PartitionSpec("batch")
    # The checks, sharded like plan_batch's rollouts: every device checks its own shard.
    check_jit = jax.jit(
        jax.shard_map(
            lambda r, s: jax.vmap(lambda r1, s1: apply_collision_checks(r1, s1, check_opts))(r, s),
            mesh=mesh,
            in_specs=(batch, batch),
            out_specs=batch,
            check_vma=False,
        )
    )
    lengths = check_lengths(scan_steps, args.check_buckets)
    check_exes, check_compile = {}, {}

    def check_exe_for(length, r_shapes):
        """The compiled check for rollouts cut to ``length`` time steps (one compile per length)."""
        if length not in check_exes:
            shapes = jax.tree_util.tree_map(
                lambda x: jax.ShapeDtypeStruct(
                    (x.shape[0], length, *x.shape[2:]) if x.ndim >= 2 else x.shape, x.dtype, sharding=batch_sharding
                ),
                r_shapes,
            )
            check_exes[length], check_compile[length] = compile_timed(
                check_jit, shapes, jax.device_put(first, batch_sharding)
            )
        return check_exes[length]

    rows, dump = [], {}
    for method in args.method_list:
        label = method_label(method)
        opts = (
            make_options("curve", 10, check_collisions=False)
            if method == "curve"
            else make_options("points", method, check_collisions=False)
        )
        log(f"{label}: compiling the planning-only batch rollout ...")
        first_j = jax.tree_util.tree_map(jnp.asarray, first)
        _, plan_compile = compile_timed(sp.planning.rollout_batch, first_j, gains, opts, T)
        r_shapes = jax.eval_shape(lambda s, o=opts: jax.vmap(lambda s1: rollout(s1, gains, o, T))(s), first_j)
        # 1. Plan: plan_batch, chunk by chunk (compiled above: no compilation inside the timing).
        t0 = time.perf_counter()
        planned = sp.plan_batch(suite, gains=gains, max_steps=T, seed=0, chunk=chunk, progress=True, **opts._asdict())
        planned = jax.tree_util.tree_map(np.asarray, planned)
        plan_s = time.perf_counter() - t0
        planned = pad_batch(planned, n_pad)
        bar = ProgressBar(len(check_groups(planned.iterations, chunk, lengths)), label=f"{label:>6s} check")
        # 2. Check, in groups of similar length (see check_groups).
        check_times, check_steps = [], 0
        res = dict(
            status=np.empty(n_pad, planned.status.dtype),
            iterations=np.empty(n_pad, planned.iterations.dtype),
            min_clearance=np.empty(n_pad, planned.min_clearance.dtype),
            final_error=np.empty(n_pad, planned.final_error.dtype),
        )
        if args.dump:
            res["q"] = np.empty_like(planned.q)
        for idx, length in check_groups(planned.iterations, chunk, lengths):
            exe = check_exe_for(length, r_shapes)
            cut = jax.tree_util.tree_map(lambda x, idx=idx, L=length: x[idx][:, :L] if x.ndim >= 2 else x[idx], planned)
            sc = jax.tree_util.tree_map(lambda x, idx=idx: x[idx], padded)
            cut, sc = jax.device_put((cut, sc), batch_sharding)
            rc, dt = timed(exe, cut, sc)
            check_times.append(dt)
            check_steps += chunk * length
            for k in ("status", "iterations", "min_clearance", "final_error"):
                res[k][idx] = np.asarray(getattr(rc, k))
            if args.dump:
                q = np.asarray(rc.q)  # frozen after the end: repeat the last entry up to T + 1
                res["q"][idx] = np.concatenate([q, np.repeat(q[:, -1:], scan_steps - length, axis=1)], axis=1)
            bar.update(1, f"check {length} steps: {fmt_s(dt)}")
        res = {k: v[: args.n] for k, v in res.items()}
        res["plan_status"] = planned.status[: args.n]
        status = res["status"]
        success = status == Status.REACHED
        collided = status == Status.COLLIDED
        row = dict(
            method="curve" if method == "curve" else "points",
            n_points=None if method == "curve" else method,
            label=label,
            scenarios=args.n,
            success_rate=float(success.mean()),
            collision_rate=float(collided.mean()),
            stalled_rate=float((status == Status.STALLED).mean()),
            max_steps_rate=float((status == Status.MAX_STEPS).mean()),
            nonfinite_rate=float((status == Status.NONFINITE).mean()),
            mean_iterations_success=float(res["iterations"][success].mean()) if success.any() else None,
            median_iterations_success=float(np.median(res["iterations"][success])) if success.any() else None,
            unnoticed_collisions=int(((res["plan_status"] == Status.REACHED) & collided).sum()),
            collision_rate_by_obstacles={
                int(k): float(collided[n_obstacles == k].mean()) for k in np.unique(n_obstacles)
            },
            min_clearance_median=float(np.median(res["min_clearance"])),
            plan_per_step_s=plan_s / (args.n * scan_steps),
            plan_total_s=plan_s,
            check_total_s=float(sum(check_times)),
            check_per_step_s=float(sum(check_times) / check_steps),
            check_steps_fraction=check_steps / (n_pad * scan_steps),
            check_chunk_times_s=check_times,
            compile_plan_s=plan_compile,
        )
        rows.append(row)
        log(
            f"{label}: success {100 * row['success_rate']:.1f}%, "
            f"collided {100 * row['collision_rate']:.1f}%, "
            f"per scenario-step {fmt_s(row['plan_per_step_s'])} (check {fmt_s(row['check_per_step_s'])} per "
            f"checked step, {100 * row['check_steps_fraction']:.0f}% of the steps checked)"
        )
        if args.dump:
            for k, v in res.items():
                dump[f"{label}/{k}"] = v

    report = dict(
        quick=args.quick,
        n=args.n,
        seed=args.seed,
        chunk=chunk,
        chunks=n_chunks,
        padding=pad,
        max_steps=T,
        scan_steps=scan_steps,
        devices=n_dev,
        methods=[method_label(m) for m in args.method_list],
        generation_s=gen_s,
        check_lengths=lengths,
        check_compile_s={str(k): v for k, v in sorted(check_compile.items())},
        machine=machine,
        rows=rows,
        obstacle_count_histogram={int(k): int((n_obstacles == k).sum()) for k in np.unique(n_obstacles)},
        gains={k: float(v) for k, v in sp.default_gains(dtype)._asdict().items()},
        contact_tolerance=max(check_opts.contact_tolerance, 10.0 * float(np.sqrt(np.finfo(dtype).eps))),
        out=out,
        command="python benchmarks/batch_sweep.py " + " ".join(argv if argv is not None else sys.argv[1:]),
    )
    if figure:
        report["figure"] = _figure(rows, figure, report)
    finish_machine(machine)
    report["wall_time_s"] = time.perf_counter() - t_start
    text = markdown(report)
    write_results(out, report, text)
    if args.dump:
        np.savez_compressed(args.dump, **dump)
    log(f"wrote {out}.md and .json ({report['wall_time_s']:.0f} s)")
    print(text)
    return report


def _figure(rows, path, report):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softplan_jax.plotting import plot_benchmark

    fig = plot_benchmark(
        [r["label"] for r in rows],
        [r["plan_per_step_s"] for r in rows],
        [r["collision_rate"] for r in rows],
        success_rate=[r["success_rate"] for r in rows],
        title=f"{report['n']} random scenarios (seed {report['seed']}), {report['max_steps']} steps, "
        f"{report['machine']['dtype']}: collisions vs planner cost",
        xlabel="planning time per scenario-step (vmapped batch)",
    )
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def markdown(report: dict) -> str:
    from _common import fmt_s, machine_lines

    m = report["machine"]
    lines = [
        "# Batched sweep: curve vs N-point obstacle models over random scenarios",
        "",
        f"- generated by `{report['command'].strip()}` in {report['wall_time_s']:.0f} s"
        + (" (QUICK MODE: a smoke test, not a result)" if report["quick"] else ""),
        *machine_lines(m),
        f"- suite: `random_scenarios(seed={report['seed']}, n={report['n']})`, 8 curve slots of degree 2; "
        f"obstacle counts {report['obstacle_count_histogram']} (generated in {report['generation_s']:.1f} s)",
        f"- {report['chunks']} chunk(s) of {report['chunk']} scenarios "
        f"(+{report['padding']} padding, dropped "
        f"from the statistics), batch axis sharded over {report['devices']} device(s) (plan_batch; the checks "
        f"by their own shard_map); max_steps "
        f"{report['max_steps']} ({report['scan_steps']} scan steps); gains `default_gains()`; contact "
        f"tolerance {report['contact_tolerance']:.2g}",
        "- compile: `apply_collision_checks` (vmapped, shared by every method) for time lengths "
        + ", ".join(f"{k}: {fmt_s(v)}" for k, v in report["check_compile_s"].items())
        + "; each method's planning rollout in the table. Compile is excluded from every per-step figure.",
        "",
        "*plan / scenario-step* = wall time of the chunked, sharded `plan_batch` (planning only, compiled "
        "ahead, results copied to the host) / (scenarios x scan steps). *check*: the vmapped `apply_collision_checks` on "
        "its output; finished rollouts are grouped by length and checked only up to their last step (exact: "
        "the tail is frozen), so its figure is per CHECKED scenario-step, with the fraction of the scan's "
        "steps that were checked. Success = reached the goal without collision; collided = true clearance "
        "<= contact tolerance at a step or between two steps; *unnoticed* = planning-only rollouts that "
        '"reached" the goal through a collision. Mean iterations over successes.',
        "",
        "| method | success | collided | stalled | max steps | mean its (success) | unnoticed "
        "| plan / scenario-step | x curve | check / checked step | steps checked | plan compile |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    curve = next((r for r in report["rows"] if r["method"] == "curve"), None)
    for r in report["rows"]:
        ratio = f"{r['plan_per_step_s'] / curve['plan_per_step_s']:.3g}x" if curve else "—"
        its = "—" if r["mean_iterations_success"] is None else f"{r['mean_iterations_success']:.1f}"
        lines.append(
            f"| {r['label']} | {100 * r['success_rate']:.1f}% | {100 * r['collision_rate']:.1f}% "
            f"| {100 * r['stalled_rate']:.1f}% | {100 * r['max_steps_rate']:.1f}% | {its} "
            f"| {r['unnoticed_collisions']} | {fmt_s(r['plan_per_step_s'])} | {ratio} "
            f"| {fmt_s(r['check_per_step_s'])} | {100 * r['check_steps_fraction']:.0f}% "
            f"| {fmt_s(r['compile_plan_s'])} |"
        )
    counts = sorted(report["obstacle_count_histogram"])
    lines += [
        "",
        "Collision rate by number of obstacles:",
        "",
        "| method | " + " | ".join(str(k) for k in counts) + " |",
        "|---|" + "---|" * len(counts),
    ]
    for r in report["rows"]:
        by = r["collision_rate_by_obstacles"]
        lines.append(
            f"| {r['label']} | "
            + " | ".join(f"{100 * by.get(k, by.get(str(k), float('nan'))):.1f}%" for k in counts)
            + " |"
        )
    if report.get("figure"):
        rel = os.path.relpath(report["figure"], os.path.dirname(os.path.abspath(report["out"])))
        lines += ["", f"![collision rate vs per-step cost]({rel})"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
