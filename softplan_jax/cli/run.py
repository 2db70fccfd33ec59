"""``softplan run``: plan one scenario and print a summary.

A static scene (a paper scenario or a JSON scenario file) is planned with the
compiled rollout (the paper's eq. 9 step; :func:`~softplan_jax.planning._programs.rollout_jit`),
then, where the local planner stalls or runs out of steps, rescued by the
reachability test and the global search (unless ``--no-fallback``). A moving
scene (a moving preset, or a JSON file with motion fields) is tracked among its
moving obstacles (:mod:`softplan_jax.planning._tracking`), and where the goal is
never reached, tracked again along the global search's path at rest
(:func:`~softplan_jax.search._tracking.track_fallback`; unless ``--no-fallback``). Both write the same
figures, the same ``--out`` trajectory file and the same report.

jax is imported inside :func:`cmd_run`, after the arguments are parsed, so that
float64 (``jax_enable_x64``) can be switched on before any array exists.
"""

from __future__ import annotations

import math
import os
import sys
import time

from .actuation import check_actuator_args, constrain, summary_rows, time_run, write_outputs
from .common import (
    InputError,
    fmt_gain_values,
    fmt_seconds,
    gains_report,
    moving_names,
    package_version,
    paper_names,
    report,
    resolve_gains,
    warn,
    write_figures,
)
from .gravity import model_report, model_rows, resolve_model
from .parser import check_run_args
from .trajectory import TRAJECTORY_FORMAT, trajectory_record, write_trajectory

__all__ = ["cmd_run"]


def _load(args, dtype):
    import warnings

    from ..scenarios import load_scenario, paper_scenario

    if args.scenario in paper_names():
        return paper_scenario(args.scenario, dtype=dtype), args.scenario
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scenario = load_scenario(args.scenario, dtype=dtype)
        for w in caught:
            warn(str(w.message))
        return scenario, args.scenario
    except OSError as err:  # unreadable file, permission denied, ...
        raise InputError(f"cannot read scenario file {args.scenario}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise InputError(f"scenario file {args.scenario} is not UTF-8 text (is it a JSON file?)") from None


def _is_moving_file(path: str) -> bool:
    """The scenario file has motion fields (read once more by _load_moving for the errors)."""
    from ..scenarios._json_format import is_moving_dict, read_json_file

    try:
        return is_moving_dict(read_json_file(path, "scenario"))
    except ValueError:
        return False  # the static loader reports the error


def _plan_extra(args, extra: dict) -> dict:
    """The planner options given on the command line (``softplan run``, static or moving), added
    to ``extra`` (the gains' own options)."""
    extra["repulsion"] = args.repulsion
    if args.exact_clearances:
        extra["far_margin"] = None
    for key in ("step", "escapes", "goal_tolerance"):
        if getattr(args, key) is not None:
            extra[key] = getattr(args, key)
    return extra


def _write_out(args, summary: dict, record: dict) -> None:
    """Write ``--out`` (replacing a file only with --force, and saying so)."""
    replaced = os.path.exists(args.out)
    try:
        write_trajectory(args.out, record)
    except OSError as err:
        raise InputError(f"cannot write output: {err}") from None
    summary["out"] = os.path.abspath(args.out)
    if replaced:  # allowed by --force; never silently
        print(f"softplan: overwrote {args.out} (--force)", file=sys.stderr)


def cmd_run(args) -> int:
    """``softplan run``: plan a static scene, or track a moving one; the exit code."""
    import jax

    from ..base._compilation_cache import enable_compilation_cache

    enable_compilation_cache()  # a second run loads the compiled rollout from disk
    if not args.float32:
        # float64 needs x64 on before any array is created.
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    static_names = paper_names()
    check_run_args(args, static_names + moving_names())
    check_actuator_args(args)
    dtype = jnp.float32 if args.float32 else jnp.float64
    if args.scenario in moving_names() or (args.scenario not in static_names and _is_moving_file(args.scenario)):
        return _cmd_track(args, dtype)
    for flag, value in (("--anticipation", args.anticipation), ("--hold-tolerance", args.hold_tolerance),
                        ("--no-evasion", args.no_evasion or None), ("--evasion-speed", args.evasion_speed),
                        ("--barrier-gain", args.barrier_gain)):
        if value is not None:
            warn(f"{flag} applies to moving scenes only; {args.scenario} does not move, it is ignored")
    return _cmd_plan(args, dtype)


def _compiled_run(world, gains, options, max_steps: int, seed) -> tuple:
    """The rollout of one scene through :data:`~softplan_jax.planning._programs.rollout_jit`'s
    cached program: ``(rollout, compile_time, run_time, loaded)`` (compiled ahead and timed apart;
    ``loaded``: the traced program came from the cache)."""
    import jax

    from ..planning._programs import rollout_jit

    t0 = time.perf_counter()
    # Traced program and XLA executable both cached on disk: a second run loads them. Compiled
    # to run once: the first result comes sooner (docs: Performance, "A first result from an empty cache").
    run, loaded = rollout_jit.cached(world, gains, options, max_steps, one_shot=True)
    compile_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    rollout = jax.block_until_ready(run(world, gains, seed))
    return rollout, compile_time, time.perf_counter() - t0, loaded


def _loaded_run(model):
    """:func:`_compiled_run` for the loaded arm (a :class:`~softplan_jax.rod.LoadedArm` of
    ``model``; static or moving ``world``): the first call compiles and runs, the second runs;
    compile time = their difference."""
    import jax

    from ..planning._planner import arm_model
    from ..planning._programs import rollout_jit

    def run(world, gains, options, max_steps: int, seed) -> tuple:
        arm = arm_model(model, getattr(world, "scene", world).q0.shape[0])
        t0 = time.perf_counter()
        jax.block_until_ready(rollout_jit(world, gains, options, max_steps, seed, arm=arm))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        rollout = jax.block_until_ready(rollout_jit(world, gains, options, max_steps, seed, arm=arm))
        run_time = time.perf_counter() - t0
        return rollout, max(first - run_time, 0.0), run_time, False

    return run


def _compiling_message(what: str = "") -> None:
    print(f"softplan: preparing the planner{what} (compiled the first time a scene shape and option set is "
          "planned, loaded from the cache after) ...", file=sys.stderr, flush=True)


def _static_inputs(args, dtype, actuator_summary: dict) -> tuple:
    """``(scenario, label, gains, options, gain_values, model)`` of a static scene (InputError: bad
    input; ``model``: None or the loaded arm's RodModel); the actuators' segment length limits
    applied, their rows added to ``actuator_summary``."""
    from ..planning._options import make_options
    from ..planning._programs import prng_key
    from ..planning._records import check_rollout_memory

    try:
        scenario, label = _load(args, dtype)
        scenario, gains, extra, gain_values = resolve_gains(args, scenario, args.method, args.n_points)
        scenario = constrain(args, scenario, actuator_summary)  # the actuators' segment length limits
        options = make_options(args.method, args.n_points, **_plan_extra(args, extra))
        check_rollout_memory(scenario, options, int(args.max_steps))  # before anything is allocated
        prng_key(args.seed)  # a seed out of range: bad input before anything compiles
    except ValueError as err:
        raise InputError(str(err)) from None
    model = _checked_model(args, None if args.scenario in paper_names() else args.scenario, scenario.q0)
    return scenario, label, gains, options, gain_values, model


def _checked_model(args, path, q0):
    """The run's arm model (:func:`~softplan_jax.cli.gravity.resolve_model`: None for the PCC
    arm), checked against the arm and to carry its load at the start pose q0 (InputError)."""
    model = resolve_model(args, path)
    if model is not None:
        from ..planning._planner import start_arm

        try:
            start_arm(model, q0)
        except ValueError as err:
            raise InputError(str(err)) from None
    return model


def _cmd_plan(args, dtype) -> int:
    """``softplan run`` on a static scene: plan it, rescue it with the global fallback."""
    from ..planning._planner import arm_model, result_from_rollout, unreachable_result
    from ..scenarios._scenario import unreachable_reason

    actuator_summary = {}
    scenario, label, gains, options, gain_values, model = _static_inputs(args, dtype, actuator_summary)
    times = dict(compile_time_s=0.0, run_time_s=0.0, fallback_time_s=0.0, program_from_cache=False)
    escapes = local_steps = 0
    reason = unreachable_reason(scenario)
    if reason:  # proven on the host: nothing to plan
        print(f"softplan: the goal is proven unreachable ({reason.replace('_', ' ')}); nothing to plan",
              file=sys.stderr, flush=True)
        result = unreachable_result(scenario, options, reason, arm_model(model, scenario.q0.shape[0]))
    else:
        _compiling_message("" if model is None else " for the loaded arm")
        run = _compiled_run if model is None else _loaded_run(model)
        rollout, times["compile_time_s"], times["run_time_s"], times["program_from_cache"] = run(
            scenario, gains, options, int(args.max_steps), args.seed)
        result = result_from_rollout(rollout, scenario)
        escapes, local_steps = int(rollout.escapes), int(rollout.iterations)
    from ..base._status import Status
    from ..search._fallback import RESCUED, rescue

    if not args.no_fallback and Status.from_label(result.status) in RESCUED:
        print(f"softplan: the local planner ended {result.status}; deciding reachability and searching globally "
              "(its programs compile once, about a minute; later runs load them from the cache) ...",
              file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        result = rescue(scenario, [result], options, seed=args.seed, model=model)[0]
        times["fallback_time_s"] = time.perf_counter() - t0
    summary = _plan_summary(args, label, scenario, options, gain_values, result, escapes, times)
    summary["arm_model"] = model_report(model)
    summary["time_per_step_s"] = times["run_time_s"] / max(local_steps, 1)
    summary.update(actuator_summary)
    traj = time_run(args, scenario, result, options, summary)  # before any output: nothing written if it fails
    title = (
        f"{label} — {args.method} method"
        + (f" (N = {args.n_points})" if args.method == "points" else "")
        + f" — {result.status} after {result.iterations} iterations"
        + (f" (global search from step {result.global_start})" if result.planner == "global" else "")
        + (f" ({result.reason})" if result.reason else "")
        + "\n"
        f"min true clearance {result.min_clearance:.3f}, final tip error {result.final_error:.3f}"
        + ("" if model is None else " (the loaded arm; drawn: the commanded PCC shapes)")
    )
    write_figures(args, summary, lambda plotting: plotting.plot_snapshots(scenario, result, title=title),
                  lambda plotting, path: plotting.animate(scenario, result, path, title=title.split("\n")[0]))
    if args.out is not None:
        _write_out(args, summary, trajectory_record(result, scenario, summary))
    write_outputs(args, traj, scenario, summary)
    return report(args, summary, lambda: _text_summary(summary), result.reached)


def _plan_summary(args, label, scenario, options, gain_values, result, escapes, times) -> dict:
    """The summary of a static scene's run (printed as text or JSON, written with ``--out``)."""
    import jax.numpy as jnp

    return {
        "scenario": label,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "repulsion": args.repulsion,
        **gains_report(args, gain_values),
        "step": options.step,
        "escapes": escapes,
        "dtype": str(jnp.dtype(scenario.q0.dtype)),
        "status": result.status,
        "planner": result.planner,
        "reason": result.reason,
        "global_start": result.global_start,
        "best_error": result.best_error,
        "fallback": not args.no_fallback,
        "fallback_time_s": times["fallback_time_s"],
        "iterations": result.iterations,
        "max_steps": int(args.max_steps),
        "reached": result.reached,
        "collided": result.collided,
        "min_clearance": result.min_clearance,
        "final_error": result.final_error,
        "goal_tolerance": options.goal_tolerance,
        "compile_time_s": times["compile_time_s"],
        "program_from_cache": times["program_from_cache"],
        "run_time_s": times["run_time_s"],
        # The engine stops within step_chunk steps of the end: the cost follows the steps taken.
        "time_per_step_s": 0.0,
        "plot": None,
        "gif": None,
        "out": None,
    }


def _moving_inputs(args, dtype, actuator_summary: dict) -> tuple:
    """``(moving, gains, options, preset, extra, gain_values)`` of a moving scene (InputError:
    bad input): the preset's tracking options, then those given on the command line; the
    actuators' segment length limits applied, their rows added to ``actuator_summary``."""
    from ..planning._options import make_track_options
    from ..planning._programs import prng_key
    from ..planning._records import check_rollout_memory
    from ..scenarios._json_format import load_moving_scenario
    from ..scenarios._moving import MOVING_OPTIONS, moving_scenario

    try:
        if args.scenario in moving_names():
            moving = moving_scenario(args.scenario, dtype=dtype)
            preset = dict(MOVING_OPTIONS[args.scenario])
        else:
            moving = load_moving_scenario(args.scenario, dtype=dtype)
            preset = {}
        scenario, gains, extra, gain_values = resolve_gains(args, moving.scene, args.method, args.n_points)
        scenario = constrain(args, scenario, actuator_summary)  # the actuators' segment length limits
        moving = moving._replace(scene=scenario)
        extra = _plan_extra(args, extra)
        for name in ("anticipation", "hold_tolerance", "evasion_speed", "barrier_gain"):
            if getattr(args, name) is not None:
                preset[name] = getattr(args, name)
        if args.no_evasion:
            preset["evasion"] = False
        options = make_track_options(args.method, args.n_points, **preset, **extra)
        check_rollout_memory(moving, options, int(args.max_steps))  # before anything is allocated
        prng_key(args.seed)
    except OSError as err:
        raise InputError(f"cannot read scenario file {args.scenario}: {err.strerror or err}") from None
    except ValueError as err:
        raise InputError(str(err)) from None
    return moving, gains, options, preset, extra, gain_values


def _cmd_track(args, dtype) -> int:
    """``softplan run`` on a moving scene: track its goal among its moving obstacles (softplan_jax.track)."""
    from ..planning._tracking import result_from_track

    actuator_summary = {}
    moving, gains, options, preset, extra, gain_values = _moving_inputs(args, dtype, actuator_summary)
    model = _checked_model(args, None if args.scenario in moving_names() else args.scenario, moving.scene.q0)
    max_steps = int(args.max_steps)
    _compiling_message(f" for a moving scene{'' if model is None else ' and the loaded arm'}, tracked for "
                       f"{max_steps} steps ({max_steps * float(gains.dt):g} s of the scene's own time, not the wait)")
    run = _compiled_run if model is None else _loaded_run(model)
    track, compile_time, run_time, loaded = run(moving, gains, options, max_steps, args.seed)
    result = result_from_track(track, moving, float(gains.dt))
    if result.status == "max_steps" and not args.no_fallback:
        from ..search._tracking import track_fallback

        print("softplan: the goal was never reached: planning the scene at rest with the global search, then "
              "tracking again along its path (--no-fallback: skip) ...", file=sys.stderr, flush=True)
        result = track_fallback(moving, args.method, args.n_points, gains, max_steps, args.seed, model=model,
                                **preset, **extra)
    summary = _track_summary(args, options, gain_values, result, float(gains.dt), dtype)
    summary.update(compile_time_s=compile_time, program_from_cache=loaded, run_time_s=run_time,
                   time_per_step_s=run_time / max(result.iterations, 1), arm_model=model_report(model),
                   **actuator_summary)
    summary["evasion"] = summary["evasion"] and model is None  # the loaded arm takes no evasive step
    traj = time_run(args, moving.scene, result, options.plan, summary)  # before any output
    title = (f"{args.scenario} (moving) — {args.method} method"
             + (f" (N = {args.n_points})" if args.method == "points" else "") + f" — {result.status}")
    write_figures(args, summary, lambda plotting: plotting.plot_tracking(result, title=title),
                  lambda plotting, path: plotting.animate_tracking(result, path, title=title))
    if args.out is not None:
        _write_out(args, summary, _track_record(result, summary))
    write_outputs(args, traj, moving.scene, summary)
    # --require-reached asks for success: the tip on the goal at the end, "reached" (held from the
    # first reach) or "held" (left and regained); "lost", "max_steps", "collided", ... are not.
    return report(args, summary, lambda: _track_text(summary, result, options),
                  result.status in ("reached", "held"))


def _track_summary(args, options, gain_values, result, dt: float, dtype) -> dict:
    """The summary of a moving scene's run (printed as text or JSON, written with ``--out``)."""
    import jax.numpy as jnp

    max_steps = int(args.max_steps)
    return {
        "scenario": args.scenario,
        "moving": True,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "repulsion": args.repulsion,
        **gains_report(args, gain_values),
        "step": options.plan.step,
        "anticipation_s": options.anticipation,
        "evasion": options.evasion,
        "evasive_steps": result.evasive_steps,
        "planner": result.planner,
        "reason": result.reason,
        "hold_tolerance": options.hold_tolerance,
        "dtype": str(jnp.dtype(dtype)),
        "status": result.status,
        "iterations": result.iterations,
        "max_steps": max_steps,
        "horizon_s": max_steps * dt,
        "reached": result.reached,
        "reached_at_s": None if result.reached_step is None else float(result.time[result.reached_step]),
        "held_s": result.held_time,
        "held_to_end": result.held_to_end,
        "collided": result.collided,
        "min_clearance": result.min_clearance,
        "final_error": result.final_error,
        "goal_tolerance": options.plan.goal_tolerance,
        "plot": None,
        "gif": None,
        "out": None,
    }


def _track_record(result, summary: dict) -> dict:
    """The ``--out`` trajectory file of a tracked run."""
    import numpy as np

    return {"format": TRAJECTORY_FORMAT, "softplan_jax_version": package_version(),
            **{k: np.asarray(getattr(result, k)) for k in ("q", "tip", "clearance", "goal", "time", "error")},
            **{k: v for k, v in summary.items() if k not in ("plot", "gif", "out", "gain_values")},
            "gain_values": {k: (math.inf if v is None else v) for k, v in summary["gain_values"].items()}}


def _track_text(summary: dict, result, options) -> str:
    """The summary of a tracked run as text."""
    method = summary["method"] + (f" (N = {summary['n_points']})" if summary["method"] == "points" else "")
    rows = [
        ("scenario", f"{summary['scenario']} (moving obstacles; tracked)"),
        ("method", method),
        ("gains", summary["gains"]),
        ("step", f"{summary['step']}, look-ahead {summary['anticipation_s']:g} s, "
                 + (f"{result.evasive_steps} evasive step(s)" if summary["evasion"] else
                    "no evasion" + (" (the loaded arm)" if summary["arm_model"]["kind"] == "loaded" else ""))),
        ("dtype", summary["dtype"]),
        ("status", result.status),
        ("steps", f"{result.iterations} of {summary['max_steps']} ({summary['horizon_s']:g} s of simulated time)"),
        ("planner", result.planner + ("" if result.reason is None else f" ({result.reason})")),
        ("reached", "no" if not result.reached else
         f"at t = {summary['reached_at_s']:.2f} s; held {result.held_time:.2f} s"
         + (" (to the end)" if result.held_to_end else f" (hold tolerance {options.hold_tolerance:g})")),
        ("collided", "yes" if result.collided else "no"),
        ("min true clearance", f"{result.min_clearance:.4f}"),
        ("final tip error", f"{result.final_error:.4f} (goal tolerance {options.plan.goal_tolerance:g})"),
        ("compile time", fmt_seconds(summary["compile_time_s"])
         + (" (traced program loaded from the cache)" if summary["program_from_cache"] else "")),
        ("run time", f"{fmt_seconds(summary['run_time_s'])} for {result.iterations} steps"),
    ]
    rows += model_rows(summary)
    rows += summary_rows(summary)
    rows += [(k, summary[k]) for k in ("plot", "gif", "out") if summary[k]]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def _text_summary(s: dict) -> str:
    method = s["method"] + (f" (N = {s['n_points']} points per curve)" if s["method"] == "points" else "")
    rows = [
        ("scenario", s["scenario"]),
        ("method", method),
        ("repulsion", s["repulsion"]),
        ("gains", s["gains"] + (" (gains file)" if s["gains_file"] else
                                " (preset: the paper calibration)" if s["gains"] == "paper" else " (preset)")),
        ("gain values", fmt_gain_values(s["gain_values"])),
        ("step", ("safe (clearance-bounded)" if s["step"] == "safe" else "plain (the paper's)")
         + f", {s['escapes']} escape(s) used"),
        ("dtype", s["dtype"]),
        ("status", s["status"] + (f" ({s['reason']})" if s["reason"] else "")),
        ("planner", ("local (potential field, paper eq. 9)" if s["planner"] == "local" else
                     f"global: the local path to step {s['global_start']}, then the certified global search")
         + ("" if s["fallback"] else "; fallback off (--no-fallback)")),
        ("iterations", f"{s['iterations']} (max steps {s['max_steps']} of the local planner)"),
        ("reached", "yes" if s["reached"] else "no"),
        ("collided", "yes" if s["collided"] else "no"),
        ("min true clearance", f"{s['min_clearance']:.4f}"),
        ("final tip error", f"{s['final_error']:.4f} (goal tolerance {s['goal_tolerance']:g})"
         + (f"; best tip error of a collision-free IK configuration {s['best_error']:.4g}"
            if s["best_error"] is not None else "")),
        ("compile time", fmt_seconds(s["compile_time_s"])
         + (" (traced program loaded from the cache)" if s["program_from_cache"] else "")),
        ("run time", f"{fmt_seconds(s['run_time_s'])}"
         + (f"; fallback {fmt_seconds(s['fallback_time_s'])}" if s["fallback_time_s"] else "")),
        ("time per step", f"{fmt_seconds(s['time_per_step_s'])} "
         "(run time / steps taken: the planner stops within a few steps of the end)"),
    ]
    rows += model_rows(s)
    rows += summary_rows(s)
    if s["plot"]:
        rows.append(("plot", s["plot"]))
    if s["gif"]:
        rows.append(("gif", s["gif"]))
    if s["out"]:
        rows.append(("trajectory", s["out"]))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
