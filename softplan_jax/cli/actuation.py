"""``softplan run``'s actuators: the checks of the options of an actuator layout and its limits
(``--tendons 3 --tendon-radius 0.03 --max-actuator-speed 0.02 ...``), the scene's
segment length limits that follow from them, the timed trajectory of the plan
(:func:`softplan_jax.time_parametrize`) written with ``--export`` (CSV and JSON)
and drawn with ``--plot-actuators``, and the summary's rows: the duration, the
tightest limit, and the arm's extension (unbounded without actuator limits).
"""

from __future__ import annotations

import math
import os
import sys

from .common import InputError, warn

__all__ = ["check_actuator_args", "constrain", "time_run", "write_outputs", "summary_rows"]

_LIMIT_FLAGS = (("min_actuator_length", "--min-actuator-length"), ("max_actuator_length", "--max-actuator-length"),
                ("max_actuator_speed", "--max-actuator-speed"),
                ("max_actuator_acceleration", "--max-actuator-acceleration"), ("max_tip_speed", "--max-tip-speed"))


def _layout_args(args):
    """``(kind, count, radius)`` from the flags, or None (InputError for a bad combination)."""
    if args.tendons is not None and args.chambers is not None:
        raise InputError("--tendons and --chambers exclude each other: one kind of actuator per arm")
    for flag, kind in (("--tendon-radius", "tendons"), ("--chamber-radius", "chambers")):
        value = getattr(args, flag[2:].replace("-", "_"))
        if value is not None and getattr(args, kind) is None:
            raise InputError(f"{flag} needs --{kind} K")
    if args.tendons is None and args.chambers is None:
        return None
    kind = "tendon" if args.tendons is not None else "chamber"
    count = args.tendons if kind == "tendon" else args.chambers
    radius = args.tendon_radius if kind == "tendon" else args.chamber_radius
    if count < 3:
        raise InputError(f"--{kind}s must be >= 3 (a segment needs 3 actuators to bend every way), got {count}")
    if radius is None:
        raise InputError(f"--{kind}s needs --{kind}-radius R, the actuators' distance from the backbone")
    if not (math.isfinite(radius) and radius > 0):
        raise InputError(f"--{kind}-radius must be a finite number > 0, got {radius}")
    return kind, count, radius


def export_paths(path: str) -> tuple[str, str]:
    """The CSV and JSON files of ``--export PATH`` (PATH ends in .csv or .json; the other beside it)."""
    stem, ext = os.path.splitext(path)
    if ext.lower() not in (".csv", ".json"):
        raise InputError(f"--export: the path must end in .csv or .json (both are written), got {path!r}")
    return stem + ".csv", stem + ".json"


def check_actuator_args(args) -> None:
    """The actuator options of ``softplan run``, checked before planning (after
    :func:`~.parser.check_run_args`): sets ``args.actuators`` (``(kind, count, radius)`` or None)."""
    from .parser import check_output_path, check_plot_format

    inputs = [p for p in (args.scenario, getattr(args, "gains_file", None)) if p and os.path.isfile(p)]
    outputs = [args.plot, args.gif, args.out]

    args.actuators = _layout_args(args)
    for name, flag in _LIMIT_FLAGS:
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"{flag} must be a finite number > 0, got {value}")
        if value is not None and args.actuators is None and name != "max_tip_speed":
            raise InputError(f"{flag} needs an actuator layout: --tendons K --tendon-radius R "
                             "(or --chambers K --chamber-radius R)")
    lo, hi = args.min_actuator_length, args.max_actuator_length
    if lo is not None and hi is not None and lo >= hi:
        raise InputError(f"--min-actuator-length {lo} must be below --max-actuator-length {hi}")
    if not (math.isfinite(args.sample_rate) and args.sample_rate > 0):
        raise InputError(f"--sample-rate must be a finite number > 0, got {args.sample_rate}")
    timed = args.export is not None or args.plot_actuators is not None
    if not timed:
        unused = [flag for name, flag in _LIMIT_FLAGS[2:] if getattr(args, name) is not None]
        if unused:
            warn(f"{', '.join(unused)} time the plan for --export or --plot-actuators; without either, ignored")
    if timed and args.actuators is None:
        raise InputError("--export and --plot-actuators need an actuator layout: --tendons K --tendon-radius R "
                         "(or --chambers K --chamber-radius R)")
    if timed and args.max_actuator_speed is None and args.max_tip_speed is None:
        raise InputError("--export and --plot-actuators need a speed limit: --max-actuator-speed V "
                         "(or --max-tip-speed V); without one the motion would take no time")
    taken = {os.path.abspath(p) for p in outputs if p}
    files = list(export_paths(args.export)) if args.export is not None else []
    for path in files + ([args.plot_actuators] if args.plot_actuators else []):
        flag = "--export" if path in files else "--plot-actuators"
        if os.path.abspath(path) in taken:
            raise InputError(f"{flag}: {path} is also another output of this run")
        taken.add(os.path.abspath(path))
        check_output_path(path, flag, inputs)
        if os.path.exists(path) and not args.force:
            raise InputError(f"{flag}: {path} exists; pass --force to overwrite it")
    if args.plot_actuators is not None:
        check_plot_format(args.plot_actuators, "--plot-actuators")


def _layout_and_limits(args, n: int, dtype):
    from ..actuators import actuator_layout, actuator_limits

    kind, count, radius = args.actuators
    layout = actuator_layout(kind, n, count, radius=radius, dtype=dtype)
    limits = actuator_limits(args.min_actuator_length, args.max_actuator_length, args.max_actuator_speed,
                             args.max_actuator_acceleration)
    return layout, limits


def constrain(args, scenario, summary_extra: dict):
    """The scene with the segment length limits of the actuator layout (unchanged without one);
    the layout and limits recorded in ``summary_extra``. ValueError for limits the scene cannot meet."""
    if getattr(args, "actuators", None) is None:
        return scenario
    from ..trajectories import constrain_scenario

    layout, limits = _layout_and_limits(args, scenario.q0.shape[-2], scenario.q0.dtype)
    out = constrain_scenario(scenario, layout, limits)
    kind, count, radius = args.actuators
    summary_extra["actuators"] = {"kind": kind, "count": count, "radius": radius}
    summary_extra["actuator_limits"] = {k: v for k, v in limits.to_dict().items() if k != "units"}
    summary_extra["segment_length_limits"] = [[float(a), None if math.isinf(b) else float(b)]
                                              for a, b in zip(out.L_min.tolist(), out.L_max.tolist(), strict=True)]
    return out


def time_run(args, scenario, result, options, summary: dict):
    """The timed trajectory of the run (None unless --export or --plot-actuators), its figures of merit and
    the arm's extension added to ``summary``. InputError when the plan cannot be timed: nothing is written."""
    from ..trajectories import extension

    ext = extension(scenario, result.q)
    summary["extension"] = ext
    if ext["warn"]:
        warn(f"the plan stretches segment {ext['segment']} to {ext['stretch']:.2f}x its start length, and the arm's "
             "extension is unbounded (no length limit): give the actuators and their limits (--tendons K "
             "--tendon-radius R --max-actuator-length M) or the scene's arm.length_limits")
    if args.export is None and args.plot_actuators is None:
        return None
    from ..trajectories import time_parametrize

    layout, limits = _layout_and_limits(args, scenario.q0.shape[-2], scenario.q0.dtype)
    print("softplan: timing the plan under the actuator limits (TOPP-RA) ...", file=sys.stderr, flush=True)
    try:
        traj = time_parametrize(result, layout, limits, scenario, path=args.timing, rate=args.sample_rate,
                                max_tip_speed=args.max_tip_speed, options=options)
    except ValueError as err:
        raise InputError(f"cannot time the plan ({err}); nothing written") from None
    r = traj.report
    summary.update(duration_s=traj.duration, timing=traj.path, stops=len(traj.stops), samples=int(traj.t.shape[0]),
                   tightest_limit=r.describe() if r.tightest else None, within_limits=r.ok, limit_violation=r.first)
    if not r.ok:
        warn(f"the tracked motion exceeds the actuator limits: first {r.first} ({sum(r.violations.values())} "
             "sample(s) in all)")
    return traj


def write_outputs(args, traj, scenario, summary: dict) -> None:
    """Write --export (CSV and JSON) and --plot-actuators; their absolute paths into ``summary``."""
    if traj is None:
        return
    from ..trajectories import save_trajectory

    arm = {"radius": float(scenario.arm_radius), "scenario": summary.get("scenario"),
           "length_limits": summary.get("segment_length_limits")}
    try:
        if args.export is not None:
            csv, js = export_paths(args.export)
            save_trajectory(traj, csv, arm=arm, overwrite=args.force)
            save_trajectory(traj, js, arm=arm, overwrite=args.force)
            summary["export"] = [os.path.abspath(csv), os.path.abspath(js)]
        if args.plot_actuators is not None:
            if "matplotlib.pyplot" not in sys.modules:
                import matplotlib

                matplotlib.use("Agg")  # the command never opens a window
            import matplotlib.pyplot as plt

            from ..plotting import plot_actuators
            from .interrupt import atomic_output

            fig = plot_actuators(traj)
            try:
                with atomic_output(args.plot_actuators) as tmp:
                    fig.savefig(tmp, dpi=120, bbox_inches="tight")
            finally:
                plt.close(fig)
            summary["actuator_plot"] = os.path.abspath(args.plot_actuators)
    except (OSError, ValueError) as err:
        raise InputError(f"cannot write output: {err}") from None


def summary_rows(s: dict) -> list[tuple[str, str]]:
    """The summary's rows about the actuators, the timing and the arm's extension."""
    rows = []
    a = s.get("actuators")
    if a:
        limits = ", ".join(f"{k} {v:g}" for k, v in s["actuator_limits"].items() if isinstance(v, float)) or "none"
        rows.append(("actuators", f"{a['count']} {a['kind']}s per segment at radius {a['radius']:g}; limits: {limits}"))
    ext = s.get("extension")
    if ext is not None:
        if ext["bounded"]:
            text = f"bounded; longest segment {ext['stretch']:.2f}x its start length"
        else:
            text = (f"unbounded (no length limit); segment {ext['segment']} reaches {ext['stretch']:.2f}x its start "
                    "length" + (" (over 2x: see the warning)" if ext["warn"] else ""))
        rows.append(("extension", text))
    if "duration_s" in s:
        rows.append(("duration", f"{s['duration_s']:.3f} s ({s['timing']} path, {s['stops']} stop(s), "
                                 f"{s['samples']} samples)"))
        rows.append(("tightest limit", (s["tightest_limit"] or "none")
                     + ("" if s["within_limits"] else f"; EXCEEDED: {s['limit_violation']}")))
    if s.get("export"):
        rows.append(("export", ", ".join(s["export"])))
    if s.get("actuator_plot"):
        rows.append(("actuator plot", s["actuator_plot"]))
    return rows
