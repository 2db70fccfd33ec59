"""``softplan batch``: plan a seeded suite of random scenarios
(:func:`~softplan_jax.scenarios.random_scenarios`) chunk by chunk on the sweep's chunk loop
(:class:`~softplan_jax.sweeps._chunks.ChunkLoop`: each chunk planned by
:func:`~softplan_jax.planning._planner.plan_batch`, reduced to one summary row per scene and
dropped, the global fallback per chunk with ``--fallback``), split over the local devices (or
the devices of several processes with ``--coordinator``), and print the outcome counts and the
speed.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

from .common import (
    EXIT_OK,
    InputError,
    check_points_args,
    fmt_gain_values,
    fmt_seconds,
    gains_report,
    resolve_gains,
    return_freed_chunks,
)
from .parser import check_distributed_args, check_gains_arg, check_output_path, initialize_distributed

__all__ = ["cmd_batch"]

# The per-scene arrays of --out: (name, dtype; "float": the suite's float dtype).
_ARRAYS = (("status", "int32"), ("iterations", "int32"), ("min_clearance", "float"), ("final_error", "float"),
           ("escapes", "int32"), ("reached", "bool"), ("collided", "bool"), ("planner", "<U6"))


def cmd_batch(args) -> int:
    """``softplan batch``: plan the random suite and print its summary; the exit code."""
    distributed = _check_args(args)
    return_freed_chunks()
    import jax

    from ..base._compilation_cache import enable_compilation_cache

    if distributed:
        initialize_distributed(args)
        args.devices = "global"
        args.no_progress = args.no_progress or args.process_id != 0
    enable_compilation_cache()
    if not args.float32:
        jax.config.update("jax_enable_x64", True)
    args.gains_file = check_gains_arg(args.gains)
    try:
        setup = _prepare(args)
        arrays, times = _plan(args, setup)
    except ValueError as err:
        raise InputError(str(err)) from None
    summary = _summary(args, setup, arrays, times, distributed)
    import numpy as np

    if distributed and args.process_id != 0:  # every process holds the whole result; process 0 reports it
        jax.distributed.shutdown()
        return EXIT_OK
    if args.out is not None:
        try:
            np.savez_compressed(args.out, **arrays)
        except OSError as err:
            raise InputError(f"cannot write output: {err}") from None
        summary["out"] = os.path.abspath(args.out)
    if args.json:
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in summary.items()}
        print(json.dumps(clean, indent=2))
    else:
        print(_text(summary))
    return EXIT_OK


def _check_args(args) -> bool:
    """Check the flags (InputError) and set XLA_FLAGS for ``--host-devices``; whether this is a
    --coordinator run."""
    for flag, value in (("--n", args.n), ("--max-steps", args.max_steps), ("--chunk", args.chunk)):
        if value < 1:
            raise InputError(f"{flag} must be >= 1, got {value}")
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
    return distributed


def _prepare(args) -> dict:
    """The suite, its escape keys, the gains and options, the device count and the chunk size."""
    import jax.numpy as jnp
    import numpy as np

    from ..planning._batching import batch_mesh, round_chunk
    from ..planning._planner import make_options
    from ..planning._programs import batch_keys
    from ..scenarios import random_scenarios

    dtype = jnp.float32 if args.float32 else jnp.float64
    mesh = batch_mesh(args.devices)
    n_dev = 1 if mesh is None else mesh.size
    t0 = time.perf_counter()
    suite = random_scenarios(args.seed, args.n, obstacles=tuple(args.obstacles), curve_slots=args.slots, dtype=dtype)
    generation_s = time.perf_counter() - t0
    suite, gains, extra, gain_values = resolve_gains(args, suite, args.method, args.n_points or 10)
    keys = np.asarray(batch_keys(args.seed, args.n))  # raw keys: scene b's escapes, as plan_batch of the suite
    return dict(suite=suite, keys=keys, gains=gains, gain_values=gain_values, dtype=dtype, devices=n_dev,
                options=make_options(args.method, args.n_points or 10, **extra), generation_s=generation_s,
                size=round_chunk(args.chunk, args.n, n_dev))


def _plan(args, setup: dict):
    """Plan the suite chunk by chunk; ``(per-scene arrays, times)``. The fallback of chunk c is
    seeded ``seed + 2 c`` (its IK from that seed, its search from the next), so a suite of one
    chunk is rescued exactly as ``rescue_batch(suite, ..., seed=seed)`` rescues it."""
    import numpy as np

    from ..base._status import Status
    from ..sweeps._chunks import ChunkLoop, SuiteSource
    from ..sweeps._report import reporter

    n, size = args.n, setup["size"]
    reach = None
    if args.fallback:
        from ..search._reach import ReachOptions

        reach = ReachOptions()
    loop = ChunkLoop(SuiteSource(setup["suite"], setup["keys"]).take, n, size, setup["options"], setup["gains"],
                     args.max_steps, args.devices, reach=reach, fallback_seed=lambda c: args.seed + 2 * c)
    float_dtype = np.dtype(setup["dtype"])
    arrays = {k: np.zeros(n, float_dtype if t == "float" else t) for k, t in _ARRAYS}
    times = dict(run_s=0.0, fallback_s=0.0, local_steps=0)
    n_chunks = math.ceil(n / size)
    say = reporter(not args.no_progress, n, n_chunks, None, 0, args.fallback, "batch", resumable=False)

    def commit(rows, timing, paths, elapsed):
        a = timing["first"]
        for k, row in enumerate(rows):
            for name, _ in _ARRAYS:
                arrays[name][a + k] = int(Status.from_label(row["status"])) if name == "status" else row[name]
        times["run_s"] += timing["seconds"] - timing["fallback_s"]
        times["fallback_s"] += timing["fallback_s"]
        times["local_steps"] += timing["local_steps"]
        say(rows, timing, elapsed, loop.compile_s or 0.0)

    loop.run(list(range(n_chunks)), commit)
    times["compile_s"] = loop.compile_s
    return arrays, times


def _summary(args, setup: dict, arrays: dict, times: dict, distributed: bool) -> dict:
    """The summary (``--json``'s keys)."""
    import numpy as np

    from ..base._status import STATUS_NAMES, Status
    from ..sweeps._store import wilson_interval

    status = arrays["status"]
    reached = status == Status.REACHED
    run_s, fallback_s = times["run_s"], times["fallback_s"]
    return {
        "scenarios": args.n, "seed": args.seed, "method": args.method,
        "n_points": args.n_points if args.method == "points" else None, "max_steps": args.max_steps,
        **gains_report(args, setup["gain_values"]),
        "devices": setup["devices"], "chunk": setup["size"], "dtype": str(np.dtype(setup["dtype"])),
        "status_counts": {STATUS_NAMES[int(k)]: int((status == k).sum()) for k in np.unique(status)},
        "success_rate": float(reached.mean()),
        "success_ci95": list(wilson_interval(int(reached.sum()), args.n)),
        "fallback": bool(args.fallback),
        "reached_local": int((arrays["planner"] == "local").sum()),
        "reached_global": int((arrays["planner"] == "global").sum()),
        "collision_rate": float(np.isin(status, (Status.COLLIDED, Status.START_COLLIDED)).mean()),
        "mean_iterations_reached": float(arrays["iterations"][reached].mean()) if reached.any() else None,
        "min_clearance": float(np.min(arrays["min_clearance"])),
        "generation_time_s": setup["generation_s"],
        "compile_time_s": times["compile_s"],  # the first chunk's call: tracing and compiling
        "run_time_s": run_s,  # the local planner's, compile excluded
        "fallback_time_s": fallback_s,  # the fallback's (its compilation included)
        "scenes_per_s": args.n / (run_s + fallback_s),
        # Steps taken: the engine's lanes stop computing a scene when it finishes.
        "steps_per_s": times["local_steps"] / run_s,
        "processes": args.num_processes if distributed else 1,
        "out": None,
    }


def _text(s: dict) -> str:
    """The summary as the command's text table."""
    method = s["method"] + (f" (N = {s['n_points']} points per curve)" if s["method"] == "points" else "")
    lo, hi = s["success_ci95"]
    rows = [
        ("scenarios", f"{s['scenarios']:,} (random_scenarios(seed={s['seed']}), {s['dtype']})"),
        ("method", method),
        ("gains", s["gains"] + (" (gains file)" if s["gains_file"] else " (preset)")),
        ("gain values", fmt_gain_values(s["gain_values"])),
        ("devices", f"{s['devices']}" + (f" on {s['processes']} processes" if s["processes"] > 1 else "")
         + f", chunks of {s['chunk']}"),
        ("outcomes", ", ".join(f"{k} {v:,}" for k, v in s["status_counts"].items())),
        ("success [95 % CI]", f"{100 * s['success_rate']:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"
         + (f": local {s['reached_local']:,}, global fallback {s['reached_global']:,}" if s["fallback"] else "")),
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
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
