"""The ``softplan`` command: the paper's simulations (section 3) and the user's
own scenes from the shell.

::

    softplan run SCENARIO [--method curve|points] [--n-points N] [--max-steps N]
                          [--gains paper|default|FILE] [--step safe|plain]
                          [--goal-tolerance TOL] [--repulsion khatib|exponential]
                          [--plot PNG] [--gif GIF] [--out FILE.json|FILE.npz [--force]]
                          [--json] [--float32] [--require-reached]
    softplan scenarios [--json]
    softplan export NAME PATH [--force]
    softplan fit CLOUD [--out JSON] [--goal X Y Z] [--degree D] [--max-degree D]
                       [--max-residual R] [--radius R] [--inflate] [--single]
                       [--plot PNG] [--force] [--json]

SCENARIO is a paper scenario name (``sim1``, ``sim2``, ``tree``) or the path of
a JSON scenario file (a file literally named like a paper scenario: write
``./sim1``).

``--gains`` (``run`` and ``batch``) is a gain preset (``default``, ``paper``:
gains, step options and start pose, :mod:`softplan_jax.presets`) or the path of
a gains file (format ``softplan-gains/1``, :mod:`softplan_jax.gains_file`,
written by :func:`softplan_jax.save_gains`): the file's gains with the default
preset's start pose and step options. A file tuned for another ``--method`` or
``--n-points`` is bad input. The summary (and ``run --out``) records the gains
used: ``gains`` (the preset name or the path as given), ``gains_file`` (its
absolute path, or null for a preset) and ``gain_values``.

``run --out FILE`` saves the whole trajectory: ``q`` (iterations + 1, n, 3),
``tip`` (iterations + 1, 3) and ``clearance`` (iterations + 1, obstacles), the
true clearance to every obstacle at every step, start first, plus the status,
iterations and the run's metadata (format ``softplan-trajectory/1``, see
:func:`trajectory_record`). The format follows the extension: ``.json`` (arrays
as nested lists, non-finite numbers as null) or ``.npz`` (``numpy.load``; one
array per field, strings and numbers as 0-d arrays, no pickles). Any other
extension is bad input. An existing FILE is never replaced unless ``--force``
is given (then the summary says it was overwritten).

Exit codes: 0 success (for ``run``: planning finished, whatever its status —
reached, stalled, collided or max_steps; the status is in the summary);
2 bad input (unknown scenario, missing or malformed file, bad option value,
output path that cannot be written), with one line ``softplan: error: ...`` on
stderr; 3 ``run --require-reached`` and the goal was not reached.

``run`` keeps compiled rollouts in jax's persistent compilation cache
(``~/.cache/softplan_jax/jax``; see :mod:`softplan_jax.compilation_cache`;
``SOFTPLAN_COMPILATION_CACHE=0`` turns it off), so a second run of the same
scenario shape does not compile again.

jax is imported inside :func:`main`, after the arguments are parsed, so
``--help`` is fast and float64 (``jax_enable_x64``) can be switched on before
any array exists.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_REACHED = 3

PAPER_DESCRIPTIONS = {
    "sim1": "paper Table 2: line X = 1, Y = u, Z = 0.5 - u, u in [-2, 2]; goal [1.1, -0.8, 0.9]",
    "sim2": "paper Table 3: parabola X = 0.5, Y = u, Z = 5u^2, u in [-2, 2]; goal [1, 1, 1]",
    "tree": "paper Table 4: four branches + trunk X = 1, Y = 1, Z = u, u in [0, 3] "
    "(the table is garbled after its 4th row); goal [1, 0.7, 1.45]",
}


class InputError(Exception):
    """Bad user input: reported as one line on stderr, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line ``softplan: error: ...`` (exit 2)."""

    def error(self, message):
        raise InputError(f"{message} (see '{self.prog} --help')")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("softplan_jax")
    except PackageNotFoundError:
        return "0.0.0+unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="softplan",
        description="Plan paths of a soft continuum arm around curve-like obstacles (softplan_jax).",
        epilog="Exit codes: 0 success, 2 bad input, 3 goal not reached with --require-reached.",
    )
    parser.add_argument("--version", action="version", version=f"softplan {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    run = sub.add_parser(
        "run",
        help="plan one scenario and print a summary",
        description="Plan one scenario (paper name or JSON file) and print a summary: status, "
        "iterations, collisions, minimum true clearance, final tip error, compile time and time "
        "per step.",
        epilog="Exit codes: 0 planning finished, whatever the status (use --require-reached to "
        "exit 3 when the goal was not reached); 2 bad input.",
    )
    run.add_argument("scenario", metavar="SCENARIO",
                     help="paper scenario (sim1, sim2, tree), moving scene (tree_sway, tree_fruit, wire_sweep: "
                     "tracked among moving obstacles, see softplan_jax.track) or path to a JSON scenario file "
                     "(with 'motion'/'goal_path' fields: a moving scene)")
    run.add_argument("--method", choices=("curve", "points"), default="curve",
                     help="curve: exact closest points (the paper's method); points: each curve "
                     "modelled by N points (default: curve)")
    run.add_argument("--n-points", type=int, default=None, metavar="N",
                     help="N of the N-point model, >= 1 (method points only; default 10)")
    run.add_argument("--gains", default="default", metavar="PRESET|FILE",
                     help="gain preset (gains, step options and start pose; softplan_jax.presets): paper: "
                     "the calibration that reproduces the paper's findings (plain step, start theta 0.1); "
                     "default: the library's (default); or a gains file (JSON, format softplan-gains/1, "
                     "from softplan_jax.save_gains): its gains with the default preset's start pose and "
                     "step options, refused if tuned for another --method/--n-points")
    run.add_argument("--step", choices=("safe", "plain"), default=None,
                     help="safe: the clearance-bounded step, no step can pass through an obstacle the "
                     "planner models exactly (default); plain: the paper's step (default of --gains paper)")
    run.add_argument("--escapes", type=int, default=None, metavar="K",
                     help="random-walk escapes from local minima, >= 0 (default: the planner's)")
    run.add_argument("--seed", type=int, default=0, help="seed of the escapes' random walks (default 0)")
    run.add_argument("--max-steps", type=int, default=600, metavar="N",
                     help="most planner steps, >= 1 (default 600)")
    run.add_argument("--goal-tolerance", type=float, default=None, metavar="TOL",
                     help="reached when |goal - tip| < TOL (default: the planner's, 0.01)")
    run.add_argument("--repulsion", choices=("khatib", "exponential"), default="khatib",
                     help="repulsion gain function (default: khatib)")
    run.add_argument("--no-fallback", action="store_true",
                     help="the local planner only: no reachability test and no global search where it stalls or "
                          "runs out of steps (default: both; see plan_fallback)")
    run.add_argument("--anticipation", type=float, default=None, metavar="S",
                     help="moving scenes: seconds of look-ahead of the repulsion, >= 0 (the field sees each "
                     "moving obstacle inflated by its speed bound times S; default: the preset's, else 0)")
    run.add_argument("--hold-tolerance", type=float, default=None, metavar="TOL",
                     help="moving scenes: the goal counts as held while |goal - tip| <= TOL (default 0.02)")
    run.add_argument("--plot", metavar="PATH", help="write the snapshot figure (PNG, PDF, SVG, ...)")
    run.add_argument("--gif", metavar="PATH", help="write an animated GIF of the motion (needs pillow)")
    run.add_argument("--out", metavar="FILE",
                     help="save the trajectory (q, tip, clearance per step, status, iterations, metadata) "
                     "as JSON (FILE.json) or NumPy (FILE.npz), chosen by the extension")
    run.add_argument("--force", action="store_true", help="let --out replace an existing FILE")
    run.add_argument("--json", action="store_true", help="print the summary as JSON")
    run.add_argument("--float32", action="store_true",
                     help="plan in float32 (default float64)")
    run.add_argument("--require-reached", action="store_true",
                     help="exit with code 3 unless the status is 'reached' (a moving goal: reached and "
                     "held to the end; 'lost' fails)")

    scen = sub.add_parser("scenarios", help="list the paper scenarios",
                          description="List the paper's scenarios (names for 'softplan run').")
    scen.add_argument("--json", action="store_true", help="print the list as JSON")

    export = sub.add_parser("export", help="write a paper scenario as a JSON scenario file",
                            description="Write a paper scenario as a JSON scenario file "
                            "(format softplan-scenario/1) to edit and run with 'softplan run'.")
    export.add_argument("name", metavar="NAME", help="paper scenario (sim1, sim2, tree)")
    export.add_argument("path", metavar="PATH", help="output .json file")
    export.add_argument("--force", action="store_true", help="overwrite PATH if it exists")
    _add_fit_parser(sub)
    _add_batch_parser(sub)
    return parser


def _add_batch_parser(sub) -> None:
    batch = sub.add_parser(
        "batch",
        help="plan a seeded suite of random scenarios, sharded over the devices, with progress",
        description="Plan random_scenarios(SEED, N) (reachable goals, 1-8 curves across the path, one "
        "padded shape) with plan_batch: in chunks of one shape (one compilation), every chunk split over "
        "the local devices, one progress line per chunk on stderr. Prints the outcome counts and the "
        "speed (scenario-steps per second, compile apart).",
        epilog="Exit codes: 0 planning finished; 2 bad input. On a CPU, --host-devices K splits the "
        "host into K devices (XLA_FLAGS=--xla_force_host_platform_device_count=K, set before jax starts).",
    )
    batch.add_argument("--n", type=int, default=1000, help="number of scenarios, >= 1 (default 1000)")
    batch.add_argument("--seed", type=int, default=0,
                       help="seed of the suite and of the escapes' random walks (default 0)")
    batch.add_argument("--obstacles", type=int, nargs=2, default=(1, 8), metavar=("LO", "HI"),
                       help="curves per scenario, drawn from LO..HI (default 1 8)")
    batch.add_argument("--slots", type=int, default=8, metavar="K",
                       help="curve slots every scenario is padded to, >= HI (default 8)")
    batch.add_argument("--method", choices=("curve", "points"), default="curve",
                       help="curve (the paper's method) or points (default: curve)")
    batch.add_argument("--n-points", type=int, default=None, metavar="N",
                       help="N of the N-point model, >= 1 (method points only; default 10)")
    batch.add_argument("--max-steps", type=int, default=600, metavar="N",
                       help="most planner steps, >= 1 (default 600)")
    batch.add_argument("--gains", default="default", metavar="PRESET|FILE",
                       help="gain preset (default, paper; as for 'softplan run') or a gains file (JSON, format "
                       "softplan-gains/1): its gains with the default preset's start pose and step options")
    batch.add_argument("--chunk", type=int, default=512, metavar="C",
                       help="scenarios per call, >= 1, rounded up to a multiple of the device count (default 512)")
    batch.add_argument("--devices", type=int, default=None, metavar="K",
                       help="use the first K local devices (default: all)")
    batch.add_argument("--host-devices", type=int, default=None, metavar="K",
                       help="split the CPU into K XLA devices (default: jax's, 1)")
    batch.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                       help="run as one of several processes (jax.distributed): the address of process 0's "
                       "coordinator; with --num-processes and --process-id, the same command on every host")
    batch.add_argument("--num-processes", type=int, default=None, metavar="P",
                       help="processes of a --coordinator run, >= 1")
    batch.add_argument("--process-id", type=int, default=None, metavar="I",
                       help="this process's index in a --coordinator run, 0..P-1 (process 0 prints and "
                       "writes --out)")
    batch.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    batch.add_argument("--out", metavar="FILE.npz",
                       help="save per-scenario status, iterations, min clearance, final error, escapes (NumPy)")
    batch.add_argument("--force", action="store_true", help="let --out replace an existing FILE")
    batch.add_argument("--json", action="store_true", help="print the summary as JSON")
    batch.add_argument("--float32", action="store_true", help="plan in float32 (default float64)")


def _add_fit_parser(sub) -> None:
    fit = sub.add_parser(
        "fit",
        help="fit obstacle curves to a point cloud and write a JSON scenario",
        description="Fit polynomial curves to an unordered, noisy point cloud (one or several curve-like "
        "obstacles: a trunk with branches, crossing wires) and write a JSON scenario of them, with the "
        "fit's residuals as metadata, for 'softplan run'. CLOUD is .npy (an (N, 3) array), .csv "
        "(x,y,z per line, optional header) or .xyz (x y z per line).",
        epilog="Exit codes: 0 written (a poor fit prints a warning); 2 bad input, or the maximum "
        "residual is above --max-residual.",
    )
    fit.add_argument("cloud", metavar="CLOUD", help="point cloud file: .npy, .csv or .xyz")
    fit.add_argument("--out", metavar="JSON", default=None,
                     help="scenario file to write (default: CLOUD with the extension .json)")
    fit.add_argument("--goal", type=float, nargs=3, metavar=("X", "Y", "Z"), default=None,
                     help="goal of the arm's tip (default: the straight arm's tip [0, 0, 3]; edit the JSON later)")
    fit.add_argument("--degree", type=int, default=None, metavar="D",
                     help="degree of every curve (default: chosen per curve by BIC)")
    fit.add_argument("--max-degree", type=int, default=8, metavar="D",
                     help="highest degree tried when --degree is not given (default 8)")
    fit.add_argument("--max-residual", type=float, default=None, metavar="R",
                     help="fail (exit 2) when some cloud point is farther than R from every fitted curve")
    fit.add_argument("--radius", type=float, default=0.0, metavar="R", help="obstacle radius of the curves (default 0)")
    fit.add_argument("--inflate", action="store_true",
                     help="add each curve's maximum residual to its radius (planning stays clear of the raw points)")
    fit.add_argument("--single", action="store_true",
                     help="fit exactly one curve to the whole cloud (default: split it into its curves)")
    fit.add_argument("--plot", metavar="PATH", help="write a figure of the cloud with the fitted curves (PNG, PDF, ...)")
    fit.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
    fit.add_argument("--json", action="store_true", help="print the summary as JSON")


# ----------------------------------------------------------------------------
# Checks on the host, before any planning.


def _check_output_path(path: str, option: str, inputs=()) -> str:
    """An output path whose directory exists and is writable, that is not a
    directory, and that is none of the input files."""
    if not path:
        raise InputError(f"{option}: empty path")
    if os.path.isdir(path):
        raise InputError(f"{option}: {path} is a directory")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise InputError(f"{option}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise InputError(f"{option}: {path} is not writable")
    for inp in inputs:
        if inp and os.path.exists(path) and os.path.exists(inp) and os.path.samefile(path, inp):
            raise InputError(f"{option}: {path} is an input file (scenario, gains or point cloud); "
                             "refusing to overwrite it")
    return path


def _check_plot_format(path: str) -> None:
    from matplotlib.figure import Figure

    ext = os.path.splitext(path)[1].lower().lstrip(".")
    supported = Figure().canvas.get_supported_filetypes()
    if ext not in supported:
        raise InputError(
            f"--plot: cannot tell the image format of {path!r}; use one of the extensions "
            f"{', '.join('.' + e for e in sorted(supported))}"
        )


def _check_gains_arg(value: str) -> str | None:
    """The path of ``--gains`` when it names a gains file; None for a preset name."""
    from ..planning.presets import PRESETS

    if value in PRESETS:
        return None
    if not os.path.exists(value):
        raise InputError(f"--gains: {value!r} is neither a gain preset ({', '.join(sorted(PRESETS))}) "
                         "nor an existing gains file")
    if os.path.isdir(value):
        raise InputError(f"--gains: {value} is a directory, not a gains file")
    return value


def _resolve_gains(args, scenario, method: str, n_points: int):
    """``(scenario, gains, options, gain_values)`` for ``--gains``: a preset's start pose,
    gains and step options, or a gains file's gains with the default preset's start pose
    and options (ValueError for a bad or mismatched file). ``gain_values`` is the JSON
    form of the gains (:func:`~softplan_jax.gains_file.gains_to_dict`; ``rep_max`` null
    = no cap)."""
    from ..tuning.gains_file import gains_to_dict, load_gains
    from ..planning.planner import check_gains
    from ..planning.presets import apply_preset

    scenario, gains, extra = apply_preset("default" if args.gains_file else args.gains, scenario)
    if args.gains_file:
        dtype = scenario.q0.dtype
        gains = load_gains(args.gains_file, method=method, n_points=n_points, dtype=dtype)
        gains = check_gains(gains, dtype, scenario.q0.shape[-2])  # seg_weights against the arm's segments
    return scenario, gains, extra, gains_to_dict(gains, method, n_points)["gains"]


def _gains_report(args, gain_values: dict) -> dict:
    """The summary's record of the gains used."""
    return {"gains": args.gains,
            "gains_file": os.path.abspath(args.gains_file) if args.gains_file else None,
            "gain_values": gain_values}


def _fmt_gain_values(values: dict) -> str:
    def fmt(k, v):
        if v is None:
            return f"{k} none (no cap)"
        if isinstance(v, list):
            return f"{k} [{', '.join(f'{x:.4g}' for x in v)}]"
        return f"{k} {v:.4g}"

    return ", ".join(fmt(k, v) for k, v in values.items())


def _check_run_args(args, paper_names) -> None:
    n_points_given = args.n_points is not None
    if not n_points_given:
        args.n_points = 10
    if args.escapes is not None and args.escapes < 0:
        raise InputError(f"--escapes must be >= 0, got {args.escapes}")
    if args.n_points < 1:
        raise InputError(f"--n-points must be >= 1, got {args.n_points}")
    if args.max_steps < 1:
        raise InputError(f"--max-steps must be >= 1, got {args.max_steps}")
    tol = args.goal_tolerance
    if tol is not None and not (math.isfinite(tol) and tol > 0):
        raise InputError(f"--goal-tolerance must be a finite number > 0, got {args.goal_tolerance}")
    if args.anticipation is not None and not (math.isfinite(args.anticipation) and args.anticipation >= 0):
        raise InputError(f"--anticipation must be a finite number >= 0, got {args.anticipation}")
    if args.hold_tolerance is not None and not (math.isfinite(args.hold_tolerance) and args.hold_tolerance > 0):
        raise InputError(f"--hold-tolerance must be a finite number > 0, got {args.hold_tolerance}")
    is_file = args.scenario not in paper_names
    if is_file:
        if not os.path.exists(args.scenario):
            raise InputError(
                f"unknown scenario {args.scenario!r}: not a paper scenario or moving scene "
                f"({', '.join(paper_names)}) and no such file"
            )
        if os.path.isdir(args.scenario):
            raise InputError(f"scenario {args.scenario} is a directory, not a JSON file")
    inputs = (args.scenario,) if is_file else ()
    args.gains_file = _check_gains_arg(args.gains)
    if args.gains_file is not None:
        inputs += (args.gains_file,)
    if args.plot is not None and args.gif is not None and os.path.abspath(args.plot) == os.path.abspath(
        args.gif
    ):
        raise InputError("--plot and --gif name the same file")
    if args.plot is not None:
        _check_output_path(args.plot, "--plot", inputs)
        _check_plot_format(args.plot)
    if args.gif is not None:
        _check_output_path(args.gif, "--gif", inputs)
        if not args.gif.lower().endswith(".gif"):
            raise InputError(f"--gif: the path must end in .gif, got {args.gif!r}")
        try:
            import PIL  # noqa: F401
        except ImportError:
            raise InputError("--gif needs pillow: pip install pillow") from None
    if args.out is not None:
        outputs = [p for p in (args.plot, args.gif) if p is not None]
        if any(os.path.abspath(args.out) == os.path.abspath(p) for p in outputs):
            raise InputError("--out names the same file as --plot or --gif")
        _check_output_path(args.out, "--out", inputs)
        ext = os.path.splitext(args.out)[1].lower()
        if ext not in TRAJECTORY_FORMATS:
            raise InputError(
                f"--out: unknown extension {ext or '(none)'!r} in {args.out!r}; use .json or .npz"
            )
        if os.path.exists(args.out) and not args.force:
            raise InputError(f"--out: {args.out} exists; pass --force to overwrite it")
    elif args.force:
        raise InputError("--force only applies to --out")
    # Last, so that a bad argument is one error line, not a warning and an error.
    if n_points_given and args.method == "curve":
        _warn("--n-points applies to --method points only; the curve method ignores it")


# ----------------------------------------------------------------------------
# The trajectory file of ``run --out``.

TRAJECTORY_FORMAT = "softplan-trajectory/1"
TRAJECTORY_FORMATS = (".json", ".npz")


def trajectory_record(result, scenario, summary: dict) -> dict:
    """The content of a ``run --out`` file: arrays and metadata of one run.

    Args:
      result: the run's PlanResult (trimmed to the steps taken).
      scenario: the planned Scenario (for the goal).
      summary: the run's summary (scenario label, method, options, times).

    Returns:
      dict with ``q`` (T, n, 3), ``tip`` (T, 3), ``clearance`` (T, m) (float
      arrays, T = iterations + 1, m = the scenario's obstacles, the true
      clearance at every step), ``goal`` (3,), and the scalars ``format``,
      ``status``, ``iterations``, ``reached``, ``collided``, ``min_clearance``,
      ``final_error``, ``planner`` ("local" or "global"), ``reason`` ("" or why the
      goal was not reached), ``global_start`` (the step where the global search's
      path leaves the local one, or None), ``best_error`` (the reachability IK's best
      tip distance, or None) and the summary's metadata (``scenario``, ``method``,
      ``n_points``, ``repulsion``, ``dtype``, ``max_steps``,
      ``goal_tolerance``, ``compile_time_s``, ``run_time_s``, ``gains``: the
      preset name or the gains file as given, ``gains_file``: its absolute
      path or None), plus ``softplan_jax_version`` and ``gain_values``: the
      gains used, a dict of floats (``rep_max`` inf: no cap) and, for a gain
      function, lists (``rep_profile``, ``seg_weights``). In an NPZ file it is
      flattened to ``gain_values.k_att``, ... arrays; in JSON inf is null.
    """
    import numpy as np

    record = {
        "format": TRAJECTORY_FORMAT,
        "softplan_jax_version": _version(),
        "q": np.asarray(result.q),
        "tip": np.asarray(result.tip),
        "clearance": np.asarray(result.clearance),
        "goal": np.asarray(scenario.goal),
        "status": result.status,
        "iterations": int(result.iterations),
        "reached": bool(result.reached),
        "collided": bool(result.collided),
        "min_clearance": float(result.min_clearance),
        "final_error": float(result.final_error),
        "planner": result.planner,
        "reason": result.reason,
        "global_start": result.global_start,
        "best_error": result.best_error,
    }
    for key in ("scenario", "method", "n_points", "repulsion", "dtype", "max_steps", "goal_tolerance",
                "compile_time_s", "run_time_s", "gains", "gains_file"):
        record[key] = summary[key]
    record["gain_values"] = {k: (math.inf if v is None else v) for k, v in summary["gain_values"].items()}
    return record


def _json_ready(x):
    """Arrays to nested lists, non-finite floats to None (strict JSON)."""
    import numpy as np

    if isinstance(x, np.ndarray):
        return _json_ready(x.tolist())
    if isinstance(x, dict):
        return {k: _json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_ready(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_trajectory(path: str, record: dict) -> None:
    """Write :func:`trajectory_record` as JSON or NPZ, by the extension of ``path``."""
    import numpy as np

    ext = os.path.splitext(path)[1].lower()
    if ext == ".json":
        with open(path, "w", encoding="utf-8") as fh:
            json.dump({k: _json_ready(v) for k, v in record.items()}, fh, allow_nan=False)
            fh.write("\n")
    elif ext == ".npz":
        # None (n_points of the curve method) has no array form: left out; a dict
        # (gain_values) becomes one array per entry, "name.key" (no pickles).
        flat = {}
        for k, v in record.items():
            if isinstance(v, dict):
                flat.update({f"{k}.{sub}": w for sub, w in v.items()})
            else:
                flat[k] = v
        arrays = {k: np.asarray(v) for k, v in flat.items() if v is not None}
        with open(path, "wb") as fh:  # np.savez would append .npz to a name without it
            np.savez(fh, **arrays)
    else:
        raise ValueError(f"unknown trajectory format {ext!r}; use .json or .npz")


# ----------------------------------------------------------------------------
# Commands.


def _warn(msg: str) -> None:
    print(f"softplan: warning: {msg}", file=sys.stderr, flush=True)


def _load(args, dtype):
    import warnings

    from ..scenarios import load_scenario, paper_scenario

    if args.scenario in _paper_names():
        return paper_scenario(args.scenario, dtype=dtype), args.scenario
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scenario = load_scenario(args.scenario, dtype=dtype)
        for w in caught:
            _warn(str(w.message))
        return scenario, args.scenario
    except OSError as err:  # unreadable file, permission denied, ...
        raise InputError(f"cannot read scenario file {args.scenario}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise InputError(f"scenario file {args.scenario} is not UTF-8 text (is it a JSON file?)") from None


def _paper_names():
    from ..scenarios import PAPER_SCENARIOS

    return sorted(PAPER_SCENARIOS)


def _moving_names():
    from ..scenarios.moving import MOVING_SCENARIOS

    return sorted(MOVING_SCENARIOS)


def _is_moving_file(path: str) -> bool:
    """The scenario file has motion fields (read once more by _load_moving for the errors)."""
    from ..scenarios.json_format import is_moving_dict, read_json_file

    try:
        return is_moving_dict(read_json_file(path, "scenario"))
    except ValueError:
        return False  # the static loader reports the error


def _fmt_seconds(t: float) -> str:
    if t >= 1.0:
        return f"{t:.2f} s"
    if t >= 1e-3:
        return f"{t * 1e3:.2f} ms"
    return f"{t * 1e6:.1f} us"


def _write_figures(args, summary: dict, make_plot, write_gif) -> None:
    """``run --plot`` / ``--gif``: the figure from ``make_plot(plotting)`` saved to args.plot,
    ``write_gif(plotting)`` for args.gif; their absolute paths into the summary."""
    if args.plot is None and args.gif is None:
        return
    if "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        matplotlib.use("Agg")  # the command never opens a window
    import matplotlib.pyplot as plt

    from ..plotting import figures as plotting

    try:
        if args.plot is not None:
            fig = make_plot(plotting)
            try:
                fig.savefig(args.plot, dpi=120, bbox_inches="tight", pad_inches=0.2)
            finally:
                plt.close(fig)
            summary["plot"] = os.path.abspath(args.plot)
        if args.gif is not None:
            write_gif(plotting)
            summary["gif"] = os.path.abspath(args.gif)
    except OSError as err:
        raise InputError(f"cannot write output: {err}") from None


def _plan_extra(args, extra: dict) -> dict:
    """The planner options given on the command line (``softplan run``, static or moving), added
    to ``extra`` (the gains' own options)."""
    extra["repulsion"] = args.repulsion
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


def _report(args, summary: dict, text, reached: bool) -> int:
    """Print the summary (JSON, non-finite numbers as null, or ``text()``); the exit code."""
    if args.json:
        # Non-finite numbers (min clearance without obstacles is inf) become null.
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in summary.items()}
        print(json.dumps(clean, indent=2))
    else:
        print(text())
    if args.require_reached and not reached:
        return EXIT_NOT_REACHED
    return EXIT_OK


def _cmd_run(args) -> int:
    import jax

    from ..base.compilation_cache import enable_compilation_cache

    enable_compilation_cache()  # a second run loads the compiled rollout from disk
    if not args.float32:
        # float64 needs x64 on before any array is created.
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from ..planning.planner import make_options, result_from_rollout, rollout_jit

    paper_names = _paper_names()
    _check_run_args(args, paper_names + _moving_names())
    dtype = jnp.float32 if args.float32 else jnp.float64
    if args.scenario in _moving_names() or (args.scenario not in paper_names and _is_moving_file(args.scenario)):
        return _cmd_track(args, dtype)
    for flag, value in (("--anticipation", args.anticipation), ("--hold-tolerance", args.hold_tolerance)):
        if value is not None:
            _warn(f"{flag} applies to moving scenes only; {args.scenario} does not move, it is ignored")
    try:
        scenario, label = _load(args, dtype)
        scenario, gains, extra, gain_values = _resolve_gains(args, scenario, args.method, args.n_points)
        options = make_options(args.method, args.n_points, **_plan_extra(args, extra))
    except ValueError as err:
        raise InputError(str(err)) from None
    max_steps = int(args.max_steps)

    if sys.stderr.isatty():
        print("softplan: compiling the planner (once per scenario shape and option set) ...",
              file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    # Traced program and XLA executable both cached on disk: a second run loads them.
    run, loaded = rollout_jit.cached(scenario, gains, options, max_steps)
    compile_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    rollout = jax.block_until_ready(run(scenario, gains, args.seed))
    run_time = time.perf_counter() - t0
    result = result_from_rollout(rollout, scenario)
    fallback_time = 0.0
    if not args.no_fallback and result.status in ("stalled", "max_steps"):
        from ..search.fallback import rescue

        print(f"softplan: the local planner ended {result.status}; deciding reachability and searching globally "
              "(the first time compiles for about a minute) ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        result = rescue(scenario, [result], options, seed=args.seed)[0]
        fallback_time = time.perf_counter() - t0

    summary = {
        "scenario": label,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "repulsion": args.repulsion,
        **_gains_report(args, gain_values),
        "step": options.step,
        "escapes": int(rollout.escapes),
        "dtype": str(jnp.dtype(scenario.q0.dtype)),
        "status": result.status,
        "planner": result.planner,
        "reason": result.reason,
        "global_start": result.global_start,
        "best_error": result.best_error,
        "fallback": not args.no_fallback,
        "fallback_time_s": fallback_time,
        "iterations": result.iterations,
        "max_steps": max_steps,
        "reached": result.reached,
        "collided": result.collided,
        "min_clearance": result.min_clearance,
        "final_error": result.final_error,
        "goal_tolerance": options.goal_tolerance,
        "compile_time_s": compile_time,
        "program_from_cache": loaded,
        "run_time_s": run_time,
        # The engine stops within step_chunk steps of the end: the cost follows the steps taken.
        "time_per_step_s": run_time / max(int(rollout.iterations), 1),
        "plot": None,
        "gif": None,
        "out": None,
    }

    title = (
        f"{label} — {args.method} method"
        + (f" (N = {args.n_points})" if args.method == "points" else "")
        + f" — {result.status} after {result.iterations} iterations"
        + (f" (global search from step {result.global_start})" if result.planner == "global" else "")
        + (f" ({result.reason})" if result.reason else "")
        + "\n"
        f"min true clearance {result.min_clearance:.3f}, final tip error {result.final_error:.3f}"
    )
    _write_figures(args, summary, lambda plotting: plotting.plot_snapshots(scenario, result, title=title),
                   lambda plotting: plotting.animate(scenario, result, args.gif, title=title.split("\n")[0]))

    if args.out is not None:
        _write_out(args, summary, trajectory_record(result, scenario, summary))
    return _report(args, summary, lambda: _text_summary(summary), result.reached)


def _cmd_track(args, dtype) -> int:
    """``softplan run`` on a moving scene: track its goal among its moving obstacles (softplan_jax.track)."""
    import jax

    from ..scenarios.json_format import load_moving_scenario
    from ..scenarios.moving import MOVING_OPTIONS, moving_scenario
    from ..planning.tracking import make_track_options, result_from_track, track_program

    label = args.scenario
    try:
        if args.scenario in _moving_names():
            moving = moving_scenario(args.scenario, dtype=dtype)
            preset = dict(MOVING_OPTIONS[args.scenario])
        else:
            moving = load_moving_scenario(args.scenario, dtype=dtype)
            preset = {}
        scenario, gains, extra, gain_values = _resolve_gains(args, moving.scene, args.method, args.n_points)
        moving = moving._replace(scene=scenario)
        extra = _plan_extra(args, extra)
        if args.anticipation is not None:
            preset["anticipation"] = args.anticipation
        if args.hold_tolerance is not None:
            preset["hold_tolerance"] = args.hold_tolerance
        options = make_track_options(args.method, args.n_points, **preset, **extra)
    except OSError as err:
        raise InputError(f"cannot read scenario file {args.scenario}: {err.strerror or err}") from None
    except ValueError as err:
        raise InputError(str(err)) from None
    max_steps = int(args.max_steps)
    from ..planning.planner import strong_gains

    gains = strong_gains(gains, dtype)
    print("softplan: a moving scene: tracking its goal for "
          f"{max_steps} steps ({max_steps * float(gains.dt):g} s; compiling once) ...", file=sys.stderr, flush=True)
    fn = track_program(options, max_steps, False)
    key = jax.random.PRNGKey(int(args.seed))
    # Twice: the first call compiles (or finds the program in jit's cache), the second is timed alone.
    t0 = time.perf_counter()
    jax.block_until_ready(fn(moving, gains, key))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    track = jax.block_until_ready(fn(moving, gains, key))
    run_time = time.perf_counter() - t0
    compile_time = max(first - run_time, 0.0)
    result = result_from_track(track, moving, float(gains.dt))
    summary = {
        "scenario": label,
        "moving": True,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "repulsion": args.repulsion,
        **_gains_report(args, gain_values),
        "step": options.plan.step,
        "anticipation_s": options.anticipation,
        "hold_tolerance": options.hold_tolerance,
        "dtype": str(jax.numpy.dtype(dtype)),
        "status": result.status,
        "iterations": result.iterations,
        "max_steps": max_steps,
        "horizon_s": max_steps * float(gains.dt),
        "reached": result.reached,
        "reached_at_s": None if result.reached_step is None else float(result.time[result.reached_step]),
        "held_s": result.held_time,
        "held_to_end": result.held_to_end,
        "collided": result.collided,
        "min_clearance": result.min_clearance,
        "final_error": result.final_error,
        "goal_tolerance": options.plan.goal_tolerance,
        "compile_time_s": compile_time,
        "run_time_s": run_time,
        "time_per_step_s": run_time / max(result.iterations, 1),
        "plot": None,
        "gif": None,
        "out": None,
    }
    title = (f"{label} (moving) — {args.method} method"
             + (f" (N = {args.n_points})" if args.method == "points" else "") + f" — {result.status}")
    _write_figures(args, summary, lambda plotting: plotting.plot_tracking(result, title=title),
                   lambda plotting: plotting.animate_tracking(result, args.gif, title=title))
    if args.out is not None:
        import numpy as np

        record = {"format": TRAJECTORY_FORMAT, "softplan_jax_version": _version(),
                  **{k: np.asarray(getattr(result, k)) for k in ("q", "tip", "clearance", "goal", "time", "error")},
                  **{k: v for k, v in summary.items() if k not in ("plot", "gif", "out", "gain_values")},
                  "gain_values": {k: (math.inf if v is None else v) for k, v in summary["gain_values"].items()}}
        _write_out(args, summary, record)

    def text():
        rows = [
            ("scenario", f"{label} (moving obstacles; tracked)"),
            ("method", args.method + (f" (N = {args.n_points})" if args.method == "points" else "")),
            ("gains", summary["gains"]),
            ("step", f"{summary['step']}, look-ahead {summary['anticipation_s']:g} s"),
            ("dtype", summary["dtype"]),
            ("status", result.status),
            ("steps", f"{result.iterations} of {max_steps} ({summary['horizon_s']:g} s horizon)"),
            ("reached", "no" if not result.reached else
             f"at t = {summary['reached_at_s']:.2f} s; held {result.held_time:.2f} s"
             + (" (to the end)" if result.held_to_end else f" (hold tolerance {options.hold_tolerance:g})")),
            ("collided", "yes" if result.collided else "no"),
            ("min true clearance", f"{result.min_clearance:.4f}"),
            ("final tip error", f"{result.final_error:.4f} (goal tolerance {options.plan.goal_tolerance:g})"),
            ("compile time", _fmt_seconds(compile_time)),
            ("run time", f"{_fmt_seconds(run_time)} for {result.iterations} steps"),
        ]
        rows += [(k, summary[k]) for k in ("plot", "gif", "out") if summary[k]]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)

    # --require-reached asks for success: reached and held to the end ("lost" is not).
    return _report(args, summary, text, result.status == "reached")


def _check_distributed_args(args) -> bool:
    """Whether this is a --coordinator run; its three flags come together, in range,
    and exclude --devices (the mesh is every device of every process)."""
    given = [args.coordinator is not None, args.num_processes is not None, args.process_id is not None]
    if not any(given):
        return False
    if not all(given):
        raise InputError("--coordinator, --num-processes and --process-id go together")
    if args.num_processes < 1:
        raise InputError(f"--num-processes must be >= 1, got {args.num_processes}")
    if not 0 <= args.process_id < args.num_processes:
        raise InputError(f"--process-id must be in 0..{args.num_processes - 1}, got {args.process_id}")
    host, _, port = args.coordinator.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"--coordinator: use HOST:PORT, got {args.coordinator!r}")
    if args.devices is not None:
        raise InputError("--devices does not combine with --coordinator (every process's devices are used)")
    return True


def _cmd_batch(args) -> int:
    if args.n < 1:
        raise InputError(f"--n must be >= 1, got {args.n}")
    if args.max_steps < 1:
        raise InputError(f"--max-steps must be >= 1, got {args.max_steps}")
    if args.chunk < 1:
        raise InputError(f"--chunk must be >= 1, got {args.chunk}")
    distributed = _check_distributed_args(args)
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
    if args.method == "points":
        args.n_points = 10 if args.n_points is None else args.n_points
        if args.n_points < 1:
            raise InputError(f"--n-points must be >= 1, got {args.n_points}")
    elif args.n_points is not None:
        raise InputError("--n-points applies to --method points only")
    if args.out is not None:
        if not args.out.endswith(".npz"):
            raise InputError(f"--out: use a .npz file, got {args.out!r}")
        if os.path.exists(args.out) and not args.force:
            raise InputError(f"--out: {args.out} exists (use --force to replace it)")
        _check_output_path(args.out, "--out")
    import jax

    from ..base.compilation_cache import enable_compilation_cache

    if distributed:
        try:
            jax.distributed.initialize(coordinator_address=args.coordinator, num_processes=args.num_processes,
                                       process_id=args.process_id)
        except (RuntimeError, ValueError) as err:
            raise InputError(f"--coordinator: jax.distributed.initialize failed: {err}") from None
        args.devices = "global"
        args.no_progress = args.no_progress or args.process_id != 0
    enable_compilation_cache()
    if not args.float32:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from ..planning.batching import pad_batch, round_chunk
    from ..planning.planner import make_options, plan_batch, rollout_batch
    from ..scenarios import random_scenarios
    from ..base.status import STATUS_NAMES, Status

    dtype = jnp.float32 if args.float32 else jnp.float64
    args.gains_file = _check_gains_arg(args.gains)
    try:
        n_dev = (len(jax.local_devices()) if args.devices is None else len(jax.devices())
                 if args.devices == "global" else int(args.devices))
        t0 = time.perf_counter()
        suite = random_scenarios(args.seed, args.n, obstacles=tuple(args.obstacles), curve_slots=args.slots,
                                 dtype=dtype)
        generation_time = time.perf_counter() - t0
        suite, gains, extra, gain_values = _resolve_gains(args, suite, args.method, args.n_points or 10)
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
    status = r.status
    reached = status == Status.REACHED
    summary = {
        "scenarios": args.n,
        "seed": args.seed,
        "method": args.method,
        "n_points": args.n_points if args.method == "points" else None,
        "max_steps": args.max_steps,
        **_gains_report(args, gain_values),
        "devices": n_dev,
        "chunk": size,
        "dtype": str(jnp.dtype(dtype)),
        "status_counts": {STATUS_NAMES[int(k)]: int((status == k).sum()) for k in np.unique(status)},
        "success_rate": float(reached.mean()),
        "collision_rate": float((status == Status.COLLIDED).mean()),
        "mean_iterations_reached": float(r.iterations[reached].mean()) if reached.any() else None,
        "min_clearance": float(np.min(r.min_clearance)),
        "generation_time_s": generation_time,
        "compile_time_s": compile_time,
        "run_time_s": run_time,
        # Steps taken: the engine's lanes stop computing a scene when it finishes.
        "scenes_per_s": args.n / run_time,
        "steps_per_s": float(np.sum(r.iterations)) / run_time,
        "processes": args.num_processes if distributed else 1,
        "out": None,
    }
    if distributed and args.process_id != 0:  # every process holds the whole result; process 0 reports it
        jax.distributed.shutdown()
        return EXIT_OK
    if args.out is not None:
        try:
            np.savez_compressed(args.out, status=status, iterations=r.iterations, min_clearance=r.min_clearance,
                                final_error=r.final_error, escapes=r.escapes, reached=r.reached,
                                collided=r.collided)
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
            ("gain values", _fmt_gain_values(s["gain_values"])),
            ("devices", f"{s['devices']}" + (f" on {s['processes']} processes" if s["processes"] > 1 else "")
             + f", chunks of {s['chunk']}"),
            ("outcomes", ", ".join(f"{k} {v:,}" for k, v in s["status_counts"].items())),
            ("success / collided", f"{100 * s['success_rate']:.1f} % / {100 * s['collision_rate']:.1f} %"),
            ("mean iterations (reached)", "-" if s["mean_iterations_reached"] is None
             else f"{s['mean_iterations_reached']:.1f} (max steps {s['max_steps']})"),
            ("min true clearance", f"{s['min_clearance']:.4f}"),
            ("compile time", _fmt_seconds(s["compile_time_s"])),
            ("run time", f"{_fmt_seconds(s['run_time_s'])}: {s['scenes_per_s']:,.1f} scenes/s, "
             f"{s['steps_per_s']:,.0f} steps taken/s"),
        ]
        if s["out"]:
            rows.append(("results", s["out"]))
        width = max(len(k) for k, _ in rows)
        print("\n".join(f"{k:<{width}}  {v}" for k, v in rows))
    return EXIT_OK


def _text_summary(s: dict) -> str:
    method = s["method"] + (f" (N = {s['n_points']} points per curve)" if s["method"] == "points" else "")
    rows = [
        ("scenario", s["scenario"]),
        ("method", method),
        ("repulsion", s["repulsion"]),
        ("gains", s["gains"] + (" (gains file)" if s["gains_file"] else
                                " (preset: the paper calibration)" if s["gains"] == "paper" else " (preset)")),
        ("gain values", _fmt_gain_values(s["gain_values"])),
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
        ("compile time", _fmt_seconds(s["compile_time_s"])
         + (" (traced program loaded from the cache)" if s["program_from_cache"] else "")),
        ("run time", f"{_fmt_seconds(s['run_time_s'])}"
         + (f"; fallback {_fmt_seconds(s['fallback_time_s'])}" if s["fallback_time_s"] else "")),
        ("time per step", f"{_fmt_seconds(s['time_per_step_s'])} "
         "(run time / steps taken: the planner stops within a few steps of the end)"),
    ]
    if s["plot"]:
        rows.append(("plot", s["plot"]))
    if s["gif"]:
        rows.append(("gif", s["gif"]))
    if s["out"]:
        rows.append(("trajectory", s["out"]))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def _cmd_scenarios(args) -> int:
    from ..scenarios import PAPER_SCENARIOS

    rows = []
    for name in sorted(PAPER_SCENARIOS):
        spec = PAPER_SCENARIOS[name]
        rows.append(
            {
                "name": name,
                "goal": list(spec["goal"]),
                "obstacles": len(spec["curves"]),
                "description": PAPER_DESCRIPTIONS.get(name, ""),
            }
        )
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['name']:<6} {r['obstacles']} obstacle curve(s)  {r['description']}")
    return EXIT_OK


def _cmd_export(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # write the paper's numbers exactly
    from ..scenarios import paper_scenario, save_scenario

    names = _paper_names()
    if args.name not in names:
        raise InputError(f"unknown paper scenario {args.name!r}; choose one of {', '.join(names)}")
    if os.path.exists(args.path) and not args.force:
        raise InputError(f"{args.path} exists; pass --force to overwrite it")
    _check_output_path(args.path, "PATH")
    try:
        save_scenario(paper_scenario(args.name), args.path, name=args.name, overwrite=args.force)
    except (OSError, ValueError) as err:
        raise InputError(f"cannot write {args.path}: {err}") from None
    print(f"wrote {args.name} to {args.path}")
    return EXIT_OK


def _cmd_fit(args) -> int:
    import warnings

    import jax

    jax.config.update("jax_enable_x64", True)  # fit and write the coefficients in float64
    from ..clouds import (
        CLOUD_EXTENSIONS,
        CloudFit,
        FitWarning,
        fit_curve,
        fit_curves,
        load_cloud,
        save_fit_scenario,
    )

    cloud = args.cloud
    if os.path.splitext(cloud)[1].lower() not in CLOUD_EXTENSIONS:
        raise InputError(f"cannot read point cloud {cloud!r}: use a file ending in {', '.join(CLOUD_EXTENSIONS)}")
    out = args.out if args.out is not None else os.path.splitext(cloud)[0] + ".json"
    if os.path.exists(out) and not args.force:
        raise InputError(f"{out} exists; pass --force to overwrite it (or choose --out)")
    _check_output_path(out, "--out", (cloud,))
    if args.plot is not None:
        _check_output_path(args.plot, "--plot", (cloud,))
        _check_plot_format(args.plot)
        if os.path.abspath(args.plot) == os.path.abspath(out):
            raise InputError("--plot and --out name the same file")
    for opt, value in (("--max-residual", args.max_residual), ("--radius", args.radius)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{opt} must be a finite number >= 0, got {value}")
    if args.goal is not None and not all(math.isfinite(g) for g in args.goal):
        raise InputError(f"--goal must be three finite numbers, got {args.goal}")
    goal = args.goal if args.goal is not None else [0.0, 0.0, 3.0]
    kwargs = dict(degree=args.degree, max_degree=args.max_degree, max_residual=args.max_residual,
                  radius=args.radius, inflate=args.inflate)
    try:
        points = load_cloud(cloud)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FitWarning)
            fit = fit_curve(points, **kwargs) if args.single else fit_curves(points, **kwargs)
    except ValueError as err:
        raise InputError(str(err)) from None
    for w in caught:
        if issubclass(w.category, FitWarning):
            print(f"softplan: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
    meta = {"source": {"cloud": os.path.abspath(cloud), "command": "softplan fit", "single": bool(args.single),
                       "inflate": bool(args.inflate)}}
    try:
        save_fit_scenario(fit, out, goal, name=os.path.splitext(os.path.basename(cloud))[0], metadata=meta,
                          overwrite=args.force)
    except (OSError, ValueError) as err:
        raise InputError(f"cannot write {out}: {err}") from None
    cf = CloudFit.from_fit(fit)
    plot_path = None
    if args.plot is not None:
        if "matplotlib.pyplot" not in sys.modules:
            import matplotlib

            matplotlib.use("Agg")  # the command never opens a window
        import matplotlib.pyplot as plt

        from ..plotting.figures import plot_cloud_fit

        fig = plot_cloud_fit(points, fit, title=f"{os.path.basename(cloud)}: {len(cf.fits)} curve(s), "
                             f"max residual {cf.max_residual:.3g}")
        try:
            fig.savefig(args.plot, dpi=120, bbox_inches="tight")
        except OSError as err:
            raise InputError(f"cannot write output: {err}") from None
        finally:
            plt.close(fig)
        plot_path = os.path.abspath(args.plot)
    summary = {
        "cloud": cloud,
        "points": int(points.shape[0]),
        "noise": cf.noise if math.isfinite(cf.noise) else None,
        "curves": [
            {"degree": f.degree, "points": int(f.indices.size), "rms_residual": f.rms_residual,
             "max_residual": f.max_residual, "radius": float(f.curve.radius)}
            for f in cf.fits
        ],
        "rms_residual": cf.rms_residual,
        "max_residual": cf.max_residual,
        "goal": list(goal),
        "scenario": os.path.abspath(out),
        "plot": plot_path,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        noise = "" if summary["noise"] is None else f", estimated noise level {summary['noise']:.4g}"
        lines = [f"{cloud}: {summary['points']} points{noise}",
                 f"{len(cf.fits)} curve(s); max residual {cf.max_residual:.4g}, rms {cf.rms_residual:.4g}"]
        for k, c in enumerate(summary["curves"]):
            lines.append(f"  curve {k}: degree {c['degree']}, {c['points']} points, rms {c['rms_residual']:.4g}, "
                         f"max {c['max_residual']:.4g}, radius {c['radius']:.4g}")
        if args.goal is None:
            lines.append("goal [0, 0, 3] (the straight arm's tip): pass --goal X Y Z or edit the JSON")
        lines.append(f"wrote {out}" + (f" and {args.plot}" if plot_path else "") + f"; plan with: softplan run {out}")
        print("\n".join(lines))
    return EXIT_OK


def main(argv=None) -> int:
    """Entry point of the ``softplan`` command; returns the exit code."""
    parser = build_parser()
    try:
        try:
            args = parser.parse_args(argv)
        except SystemExit as exit_:  # --help, --version
            return int(exit_.code or 0) if not isinstance(exit_.code, str) else EXIT_BAD_INPUT
        if args.command is None:
            parser.print_help(sys.stderr)
            return EXIT_BAD_INPUT
        if args.command == "run":
            return _cmd_run(args)
        if args.command == "scenarios":
            return _cmd_scenarios(args)
        if args.command == "fit":
            return _cmd_fit(args)
        if args.command == "batch":
            return _cmd_batch(args)
        return _cmd_export(args)
    except InputError as err:
        msg = " ".join(str(err).split())  # one line
        print(f"softplan: error: {msg}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("softplan: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
