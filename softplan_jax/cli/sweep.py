"""``softplan sweep``: plan ``--n`` scenes of the sweep suite in chunks with
:func:`~softplan_jax.sweeps.sweep`: one summary row per scene streamed to
``--out`` (CSV per chunk, written atomically), constant memory, resumable (the
same command again continues where it stopped), optionally with the global
fallback; prints the outcome shares with 95 % Wilson intervals and the speed.
"""

from __future__ import annotations

import json
import os

from .common import EXIT_OK, InputError, check_points_args, fmt_seconds, return_freed_chunks
from .interrupt import interrupted_say
from .parser import check_distributed_args, check_gains_arg, initialize_distributed

__all__ = ["cmd_sweep"]


def _check_args(args) -> bool:
    """Check the flags (InputError); whether this is a --coordinator run."""
    for flag, value in (("--n", args.n), ("--chunk", args.chunk), ("--max-steps", args.max_steps),
                        ("--slots", args.slots)):
        if value < 1:
            raise InputError(f"{flag} must be >= 1, got {value}")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    lo, hi = args.obstacles
    if not 1 <= lo <= hi <= args.slots:
        raise InputError(f"--obstacles: need 1 <= LO <= HI <= --slots ({args.slots}), got {lo} {hi}")
    check_points_args(args)
    if args.trajectories is not None and args.trajectories != "all":
        try:
            args.trajectories = int(args.trajectories)
        except ValueError:
            raise InputError(f"--trajectories: use 'all' or a number of scenes >= 1, got {args.trajectories!r}") \
                from None
        if args.trajectories < 1:
            raise InputError(f"--trajectories must be 'all' or >= 1, got {args.trajectories}")
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise InputError(f"--out: {args.out} exists and is not a folder")
    return check_distributed_args(args, local_devices=True)


def cmd_sweep(args) -> int:
    """``softplan sweep``: run (or resume) the sweep and print its summary; the exit code."""
    distributed = _check_args(args)
    return_freed_chunks()
    gains_file = check_gains_arg(args.gains)
    interrupted_say(f"the same command again resumes the sweep in {args.out} after its last complete chunk")
    import jax

    from ..base._compilation_cache import enable_compilation_cache

    if distributed:
        initialize_distributed(args)
    enable_compilation_cache()
    if not args.float32:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from ..sweeps import sweep

    dtype = jnp.float32 if args.float32 else jnp.float64
    n_points = args.n_points or 10
    gains = args.gains
    try:
        if gains_file is not None:
            from ..tuning._gains_file import load_gains

            gains = load_gains(gains_file, method=args.method, n_points=n_points, dtype=dtype)
        summary = sweep(args.n, args.out, args.seed, chunk=args.chunk, method=args.method, n_points=n_points,
                        gains=gains, max_steps=args.max_steps, fallback=args.fallback, obstacles=tuple(args.obstacles),
                        slots=args.slots, dtype=dtype, devices=args.devices, trajectories=args.trajectories,
                        progress=not args.no_progress, overwrite=args.force)
    except ValueError as err:
        raise InputError(str(err)) from None
    summary["gains_file"] = os.path.abspath(gains_file) if gains_file else None
    if distributed and args.process_id != 0:  # process 0 reports the merged sweep
        jax.distributed.shutdown()
        return EXIT_OK
    if args.json:
        from ..sweeps._store import finite_json

        print(json.dumps(finite_json(summary), indent=2))  # non-finite numbers as null
        return EXIT_OK
    print(_text(summary))
    return EXIT_OK


def _pct(s, name) -> str:
    lo, hi = s[f"{name}_ci95"]
    return f"{100 * s[f'{name}_rate']:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def _text(s: dict) -> str:
    method = s["method"] + (f" (N = {s['n_points']} points per curve)" if s["method"] == "points" else "")
    rate = "-" if s["scenes_per_s"] is None else f"{s['scenes_per_s']:,.1f} scenes/s"
    steps = "-" if s["steps_per_s"] is None else f"{s['steps_per_s']:,.0f} steps taken/s"
    rows = [
        ("scenes", f"{s['n']:,} (sweep suite, seed {s['seed']}, {s['dtype']}), chunks of {s['chunk']}"
         + (f", {s['resumed_chunks']} of {s['chunks']} chunks resumed" if s["resumed_chunks"] else "")
         + (f", on {s['processes']} processes" if s.get("processes", 1) > 1 else "")),
        ("method", method + (" + global fallback" if s["fallback"] else "")),
        ("gains", s["gains"] + (" (gains file)" if s.get("gains_file") else "")),
        ("outcomes", ", ".join(f"{k} {v:,}" for k, v in s["status_counts"].items())),
        ("reached [95 % CI]", _pct(s, "success")),
        ("  by the local planner", _pct(s, "local")),
        ("  by the global fallback", _pct(s, "global") if s["fallback"] else "- (no --fallback)"),
        ("collided", _pct(s, "collision")),
        ("mean iterations (reached)", "-" if s["mean_iterations_reached"] is None
         else f"{s['mean_iterations_reached']:.1f} (max steps {s['max_steps']})"),
        ("compile time", fmt_seconds(s["compile_s"])),
        ("run time" + (" (summed over processes)" if s.get("processes", 1) > 1 else ""),
         f"{fmt_seconds(s['run_s'])}: {rate}, {steps}"
         + (f" (fallback {fmt_seconds(s['fallback_s'])})" if s["fallback"] else "")),
        ("results", os.path.join(s["out"], "scenes.csv")),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
