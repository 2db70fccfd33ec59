"""``softplan batch``: plan a seeded suite of random scenarios
(:func:`~softplan_jax.scenarios.random_scenarios`) with
:func:`~softplan_jax.planning.planner.plan_batch`, in chunks of one padded shape
split over the local devices (or over the devices of several processes with
``--coordinator``), and print the outcome counts and the speed.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

from .common import EXIT_OK, InputError, check_points_args, fmt_gain_values, fmt_seconds, gains_report, resolve_gains
from .parser import check_distributed_args, check_gains_arg, check_output_path, initialize_distributed

__all__ = ["cmd_batch"]


def cmd_batch(args) -> int:
    """``softplan batch``: plan the random suite and print its summary; the exit code."""
    if args.n < 1:
        raise InputError(f"--n must be >= 1, got {args.n}")
    if args.max_steps < 1:
        raise InputError(f"--max-steps must be >= 1, got {args.max_steps}")
    if args.chunk < 1:
        raise InputError(f"--chunk must be >= 1, got {args.chunk}")
    distributed = check_distributed_args(args)
    if distributed and args.fallback:
        raise InputError("--fallback does not combine with --coordinator; use 'softplan sweep --fallback "
                         "--coordinator ...', which runs the fallback on each process's own chunks")
    if args.host_devices is not None:
        if args.host_devices < 1:
            raise InputError(f"--host-devices must be >= 1, got {args.host_devices}")
        if "jax" in sys.modules:  # main() called in a process that already started jax
            import jax

            if jax.local_device_count() != args.host_devices:
                raise InputError("--host-devices: jax is already running in this process (set XLA_FLAGS="
                                 f"--xla_force_host_platform_device_count={args.host_devices} before it starts)")
        else:
            flags = [f for f in os.environ.get("XLA_FLAGS", "").split()
                     if "xla_force_host_platform_device_count" not in f]
            flags.append(f"--xla_force_host_platform_device_count={args.host_devices}")
            os.environ["XLA_FLAGS"] = " ".join(flags)
    check_points_args(args)
    if args.out is not None:
        if not args.out.endswith(".npz"):
            raise InputError(f"--out: use a .npz file, got {args.out!r}")
        if os.path.exists(args.out) and not args.force:
            raise InputError(f"--out: {args.out} exists (use --force to replace it)")
        check_output_path(args.out, "--out")
    import jax

    from ..base.compilation_cache import enable_compilation_cache

    if distributed:
        initialize_distributed(args)
        args.devices = "global"
        args.no_progress = args.no_progress or args.process_id != 0
    enable_compilation_cache()
    if not args.float32:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from ..base.status import STATUS_NAMES, Status
    from ..planning.batching import pad_batch, round_chunk
    from ..planning.planner import make_options, plan_batch
    from ..planning.programs import rollout_batch
    from ..scenarios import random_scenarios
    from ..sweeps.store import wilson_interval

    dtype = jnp.float32 if args.float32 else jnp.float64
    args.gains_file = check_gains_arg(args.gains)
    try:
        n_dev = (len(jax.local_devices()) if args.devices is None else len(jax.devices())
                 if args.devices == "global" else int(args.devices))
        t0 = time.perf_counter()
        suite = random_scenarios(args.seed, args.n, obstacles=tuple(args.obstacles), curve_slots=args.slots,
                                 dtype=dtype)
        generation_time = time.perf_counter() - t0
        suite, gains, extra, gain_values = resolve_gains(args, suite, args.method, args.n_points or 10)
        options = make_options(args.method, args.n_points or 10, **extra)
        size = round_chunk(args.chunk, args.n, max(n_dev, 1))
        first = pad_batch(jax.tree_util.tree_map(lambda x: x[:size], suite), size)
        t0 = time.perf_counter()
        rollout_batch.lower(first, gains, options, args.max_steps, args.seed, devices=args.devices).compile()
        compile_time = time.perf_counter() - t0
    except ValueError as err:
        raise InputError(str(err)) from None
    t0 = time.perf_counter()
    r = plan_batch(suite, gains=gains, max_steps=args.max_steps, seed=args.seed, chunk=args.chunk,
                   devices=args.devices, progress=not args.no_progress, **options._asdict())
    r = jax.tree_util.tree_map(np.asarray, r)
    run_time = time.perf_counter() - t0
    out = {k: np.array(getattr(r, k)) for k in ("status", "iterations", "min_clearance", "final_error", "escapes",
                                                 "reached", "collided")}  # writable copies: the fallback updates
    out["planner"] = np.where(r.reached, "local", "none").astype("<U6")
    fallback_time = _fallback(args, suite, r, options, out) if args.fallback else 0.0
    status = out["status"]
    reached = status == Status.REACHED
    summary = {
        "scenarios": args.n,
        "seed": args.seed,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "max_steps": args.max_steps,
        **gains_report(args, gain_values),
        "devices": n_dev,
        "chunk": size,
        "dtype": str(jnp.dtype(dtype)),
        "status_counts": {STATUS_NAMES[int(k)]: int((status == k).sum()) for k in np.unique(status)},
        "success_rate": float(reached.mean()),
        "success_ci95": list(wilson_interval(int(reached.sum()), args.n)),
        "fallback": bool(args.fallback),
        "reached_local": int((out["planner"] == "local").sum()),
        "reached_global": int((out["planner"] == "global").sum()),
        "collision_rate": float(np.isin(status, (Status.COLLIDED, Status.START_COLLIDED)).mean()),
        "mean_iterations_reached": float(out["iterations"][reached].mean()) if reached.any() else None,
        "min_clearance": float(np.min(out["min_clearance"])),
        "generation_time_s": generation_time,
        "compile_time_s": compile_time,
        "run_time_s": run_time,  # the local planner's
        "fallback_time_s": fallback_time,  # the fallback's (its compilation included)
        # Steps taken: the engine's lanes stop computing a scene when it finishes.
        "scenes_per_s": args.n / (run_time + fallback_time),
        "steps_per_s": float(np.sum(r.iterations)) / run_time,
        "processes": args.num_processes if distributed else 1,
        "out": None,
    }
    if distributed and args.process_id != 0:  # every process holds the whole result; process 0 reports it
        jax.distributed.shutdown()
        return EXIT_OK
    if args.out is not None:
        try:
            np.savez_compressed(args.out, **out)
        except OSError as err:
            raise InputError(f"cannot write output: {err}") from None
        summary["out"] = os.path.abspath(args.out)
    if args.json:
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in summary.items()}
        print(json.dumps(clean, indent=2))
    else:
        s = summary
        method = s["method"] + (f" (N = {s['n_points']} points per curve)" if s["method"] == "points" else "")
        rows = [
            ("scenarios", f"{s['scenarios']:,} (random_scenarios(seed={s['seed']}), {s['dtype']})"),
            ("method", method),
            ("gains", s["gains"] + (" (gains file)" if s["gains_file"] else " (preset)")),
            ("gain values", fmt_gain_values(s["gain_values"])),
            ("devices", f"{s['devices']}" + (f" on {s['processes']} processes" if s["processes"] > 1 else "")
             + f", chunks of {s['chunk']}"),
            ("outcomes", ", ".join(f"{k} {v:,}" for k, v in s["status_counts"].items())),
            ("success [95 % CI]", f"{100 * s['success_rate']:.1f} % [{100 * s['success_ci95'][0]:.1f}, "
             f"{100 * s['success_ci95'][1]:.1f}]" + (f": local {s['reached_local']:,}, global fallback "
                                                      f"{s['reached_global']:,}" if s["fallback"] else "")),
            ("collided", f"{100 * s['collision_rate']:.1f} %"),
            ("mean iterations (reached)", "-" if s["mean_iterations_reached"] is None
             else f"{s['mean_iterations_reached']:.1f} (max steps {s['max_steps']})"),
            ("min true clearance", f"{s['min_clearance']:.4f}"),
            ("compile time", fmt_seconds(s["compile_time_s"])),
            ("run time", f"{fmt_seconds(s['run_time_s'])}: {s['steps_per_s']:,.0f} steps taken/s"
             + (f"; fallback {fmt_seconds(s['fallback_time_s'])}" if s["fallback"] else "")
             + f"; {s['scenes_per_s']:,.1f} scenes/s"),
        ]
        if s["out"]:
            rows.append(("results", s["out"]))
        width = max(len(k) for k, _ in rows)
        print("\n".join(f"{k:<{width}}  {v}" for k, v in rows))
    return EXIT_OK


def _fallback(args, suite, r, options, out) -> float:
    """The global fallback on the scenes the local planner left stalled or at max steps
    (:func:`~softplan_jax.search.fallback.rescue_batch`): ``out``'s per-scene arrays updated
    in place, ``planner`` "global" where the search reached; returns its seconds."""
    from ..base.status import Status
    from ..search.fallback import rescue_batch

    t0 = time.perf_counter()
    idx, results = rescue_batch(suite, r, options, seed=args.seed, progress=not args.no_progress)
    for k, res in zip(idx, results, strict=True):
        out["status"][k], out["reached"][k] = int(Status.from_label(res.status)), res.reached
        out["iterations"][k] = res.iterations
        out["min_clearance"][k], out["final_error"][k] = res.min_clearance, res.final_error
        out["planner"][k] = ("global" if res.planner == "global" else "local") if res.reached else "none"
    return time.perf_counter() - t0
