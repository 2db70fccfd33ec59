"""The ``softplan`` command line: :func:`build_parser` (the subcommands ``run``,
``scenarios``, ``export``, ``fit``, ``batch``, ``sweep`` and ``view`` with their options and help),
and the checks of the arguments made on the host before any planning (output
paths, figure formats, ``--gains``, the options of ``run`` and of a
multi-process ``batch``). A bad argument raises :class:`~.common.InputError`.
"""

from __future__ import annotations

import argparse
import math
import os

from .common import InputError, package_version, warn
from .gravity import add_gravity_options
from .trajectory import TRAJECTORY_FORMATS

__all__ = ["build_parser", "check_output_path", "check_plot_format", "check_gains_arg", "check_run_args",
           "check_distributed_args", "initialize_distributed"]


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line ``softplan: error: ...`` (exit 2)."""

    def error(self, message):
        raise InputError(f"{message} (see '{self.prog} --help')")


def build_parser() -> argparse.ArgumentParser:
    """The ``softplan`` argument parser: one subparser per command; a bad argument raises InputError."""
    parser = _Parser(
        prog="softplan",
        description="Plan paths of a soft continuum arm around curve-like obstacles (softplan_jax).",
        epilog="Exit codes: 0 success, 2 bad input, 3 goal not reached with --require-reached.",
    )
    parser.add_argument("--version", action="version", version=f"softplan {package_version()}")
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
                     help="gain preset (gains, step options and start pose; softplan_jax.planning._presets): paper: "
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
    run.add_argument("--exact-clearances", action="store_true",
                     help="solve every closest pair at every step, so that every recorded clearance is exact "
                          "(default: a pair whose certified lower bound is beyond d0 + 0.2 keeps that bound; "
                          "PlanOptions.far_margin)")
    run.add_argument("--no-fallback", action="store_true",
                     help="the local planner only: no reachability test and no global search where it stalls or "
                          "runs out of steps (default: both; see plan_fallback; a moving scene: track_fallback)")
    run.add_argument("--anticipation", type=float, default=None, metavar="S",
                     help="moving scenes: seconds of look-ahead of the repulsion, >= 0 (the field sees each "
                     "moving obstacle inflated by its speed bound times S; default: the preset's, else 0)")
    run.add_argument("--hold-tolerance", type=float, default=None, metavar="TOL",
                     help="moving scenes: the goal counts as held while |goal - tip| <= TOL (default 0.02)")
    run.add_argument("--no-evasion", action="store_true",
                     help="moving scenes: end 'too_fast' where the field's step is not proven safe, instead of "
                     "trying the certified evasive step (default: evade)")
    run.add_argument("--evasion-speed", type=float, default=None, metavar="V",
                     help="moving scenes: the actuators' limit for the evasive step, > 0 m/s (default 1.0)")
    run.add_argument("--barrier-gain", type=float, default=None, metavar="G",
                     help="moving scenes: the evasive step's barrier gain gamma, finite, >= 0 1/s (default 5.0)")
    run.add_argument("--plot", metavar="PATH", help="write the snapshot figure (PNG, PDF, SVG, ...)")
    run.add_argument("--gif", metavar="PATH", help="write an animated GIF of the motion (needs pillow)")
    run.add_argument("--out", metavar="FILE",
                     help="save the trajectory (q, tip, clearance per step, status, iterations, metadata) "
                     "as JSON (FILE.json) or NumPy (FILE.npz), chosen by the extension")
    run.add_argument("--force", action="store_true",
                     help="let --out, --plot, --gif, --export and --plot-actuators replace existing files")
    run.add_argument("--json", action="store_true", help="print the summary as JSON")
    run.add_argument("--float32", action="store_true",
                     help="plan in float32 (default float64)")
    run.add_argument("--require-reached", action="store_true",
                     help="exit with code 3 unless the run succeeded: status 'reached' (a moving goal: "
                     "also 'held', the tip back on the goal at the end); every other status fails, "
                     "'lost', 'max_steps', 'stalled', 'collided', 'unreachable' included")
    _add_actuator_options(run)
    add_gravity_options(run)

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
    _add_sweep_parser(sub)
    _add_view_parser(sub)
    return parser


def _add_actuator_options(run) -> None:
    """The options of ``softplan run`` for actuators and timed trajectories (one argument group)."""
    g = run.add_argument_group("actuators and timed trajectories (see the documentation's Actuators page)")
    g.add_argument("--tendons", type=int, default=None, metavar="K",
                   help="K >= 3 tendons per segment, evenly spaced, each from the base to its segment's tip")
    g.add_argument("--chambers", type=int, default=None, metavar="K",
                   help="K >= 3 extensible chambers per segment, evenly spaced (pneumatic or hydraulic)")
    g.add_argument("--tendon-radius", type=float, default=None, metavar="R",
                   help="the tendons' distance from the backbone, > 0 (the scene's length unit, m)")
    g.add_argument("--chamber-radius", type=float, default=None, metavar="R",
                   help="the chambers' distance from the backbone, > 0")
    g.add_argument("--min-actuator-length", type=float, default=None, metavar="M",
                   help="shortest actuator length, > 0 (the planner's segment length limits follow from it)")
    g.add_argument("--max-actuator-length", type=float, default=None, metavar="M",
                   help="longest actuator length, > 0 (the planner's segment length limits follow from it)")
    g.add_argument("--max-actuator-speed", type=float, default=None, metavar="V",
                   help="largest actuator speed, > 0 m/s: the timed trajectory is as fast as this allows")
    g.add_argument("--max-actuator-acceleration", type=float, default=None, metavar="A",
                   help="largest actuator acceleration, > 0 m/s^2 (default: none)")
    g.add_argument("--max-tip-speed", type=float, default=None, metavar="V",
                   help="largest tip speed, > 0 m/s (default: none)")
    g.add_argument("--timing", choices=("smooth", "linear"), default="smooth",
                   help="smooth: the spline through the plan's steps where the swept check proves it clear, the "
                   "plan's straight motions elsewhere (default); linear: the straight motions, stopping at every step")
    g.add_argument("--sample-rate", type=float, default=100.0, metavar="HZ",
                   help="samples per second of the timed trajectory, > 0 (default 100; every step is a sample too)")
    g.add_argument("--export", default=None, metavar="FILE.csv",
                   help="write the timed trajectory as FILE.csv (one row per sample: t, q, actuator lengths and "
                   "speeds, tip) and FILE.json (the same with units, arm, layout, limits, status); needs a layout "
                   "and --max-actuator-speed or --max-tip-speed")
    g.add_argument("--plot-actuators", default=None, metavar="PATH",
                   help="write a figure of the actuator lengths, speeds and accelerations against time, with the limits")


def _add_view_parser(sub) -> None:
    """The ``view`` subcommand's arguments."""
    view = sub.add_parser(
        "view", help="an interactive 3-D view in the browser: drag the goal, watch the arm replan",
        description="Serve an interactive 3-D view of a scene in the browser (viser; pip install "
        "'softplan_jax[viewer]') and print its address: the arm, the obstacles, the goal as a handle to drag "
        "(every move replans), a time slider, the closest points and clearance, the global fallback.",
        epilog="Exit codes: 130 stopped by Ctrl-C; 2 bad input (nothing served).")
    view.add_argument("scene", metavar="SCENE",
                      help="paper scenario (sim1, sim2, tree), moving scene (tree_sway, tree_fruit, wire_sweep), "
                      "JSON scenario file, or a trajectory saved by 'softplan run --out' (.json or .npz)")
    view.add_argument("--method", choices=("curve", "points"), default=None,
                      help="obstacle model of the plans (default: the trajectory's, else curve)")
    view.add_argument("--n-points", type=int, default=None, metavar="N", help="N of the N-point model (default 10)")
    view.add_argument("--gains", default="default", metavar="PRESET|FILE",
                      help="gain preset (default, paper) or gains file, as for 'softplan run'")
    view.add_argument("--max-steps", type=int, default=600, metavar="N", help="most planner steps (default 600)")
    view.add_argument("--seed", type=int, default=0, help="seed of the escapes' random walks (default 0)")
    view.add_argument("--host", default="127.0.0.1",
                      help="address to serve on (default 127.0.0.1: this machine only; 0.0.0.0: every interface)")
    view.add_argument("--port", type=int, default=8080,
                      help="port, 0..65535 (default 8080; if in use, the next free one, and the command says so)")
    view.add_argument("--share", action="store_true",
                      help="also print a public URL through viser's relay (for a remote machine or Colab)")


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
    batch.add_argument("--fallback", action="store_true",
                       help="run the global fallback (reachability, certified search) on the scenarios the local "
                       "planner leaves stalled or at max steps; the summary reports local and global shares")
    _add_distributed_args(batch, "process 0 prints and writes --out")
    batch.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    batch.add_argument("--out", metavar="FILE.npz",
                       help="save per-scenario status, iterations, min clearance, final error, escapes, reached, "
                       "collided and planner (NumPy)")
    batch.add_argument("--force", action="store_true", help="let --out replace an existing FILE")
    batch.add_argument("--json", action="store_true", help="print the summary as JSON")
    batch.add_argument("--float32", action="store_true", help="plan in float32 (default float64)")


def _add_distributed_args(parser, lead: str) -> None:
    """--coordinator, --num-processes and --process-id (jax.distributed); ``lead``: what process 0 does."""
    parser.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                        help="run as one of several processes (jax.distributed): the address of process 0's "
                        "coordinator; with --num-processes and --process-id, the same command on every host")
    parser.add_argument("--num-processes", type=int, default=None, metavar="P",
                        help="processes of a --coordinator run, >= 1")
    parser.add_argument("--process-id", type=int, default=None, metavar="I",
                        help=f"this process's index in a --coordinator run, 0..P-1 ({lead})")


def _add_sweep_parser(sub) -> None:
    sweep = sub.add_parser(
        "sweep",
        help="plan a seeded random suite of any size in constant memory, streamed to a folder, resumable",
        description="Plan N scenes of the sweep suite (softplan_jax.sweeps: random_scenarios drawn in blocks of 64, "
        "scene i the same in every sweep with the same seed) in chunks of one shape; one summary row per scene "
        "(status, iterations, clearance, path length, final error, planner) written to OUT per chunk, atomically, "
        "as CSV, merged into OUT/scenes.csv at the end, with OUT/sweep.json (seed, versions, options) and "
        "OUT/summary.json. The same command again continues a killed sweep where it stopped.",
        epilog="Exit codes: 0 planning finished; 2 bad input (also: OUT holds a sweep with other arguments, "
        "or files that are not a sweep's, unless --force). The scenes differ from 'softplan batch' (whose "
        "scene i depends on --n).",
    )
    sweep.add_argument("--n", type=int, required=True, help="number of scenes, >= 1")
    sweep.add_argument("--out", required=True, metavar="DIR", help="the sweep folder (new, empty, or this sweep's)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the scenes, the escapes and the fallback (default 0)")
    sweep.add_argument("--chunk", type=int, default=256, metavar="C", help="scenes per planner call, >= 1 (default 256)")
    sweep.add_argument("--obstacles", type=int, nargs=2, default=(1, 8), metavar=("LO", "HI"),
                       help="curves per scene, drawn from LO..HI (default 1 8)")
    sweep.add_argument("--slots", type=int, default=8, metavar="K", help="curve slots, >= HI (default 8)")
    sweep.add_argument("--method", choices=("curve", "points"), default="curve", help="default: curve")
    sweep.add_argument("--n-points", type=int, default=None, metavar="N",
                       help="N of the N-point model, >= 1 (method points only; default 10)")
    sweep.add_argument("--max-steps", type=int, default=600, metavar="N", help="most planner steps, >= 1 (default 600)")
    sweep.add_argument("--gains", default="default", metavar="PRESET|FILE",
                       help="gain preset (default, paper) or a gains file, as for 'softplan batch'")
    sweep.add_argument("--fallback", action="store_true",
                       help="run the global fallback (reachability, certified search) on the scenes the local "
                       "planner leaves stalled or at max steps; the summary reports local and global shares")
    sweep.add_argument("--trajectories", default=None, metavar="K|all",
                       help="keep the paths of scenes 0..K-1 (or all) in DIR/trajectories/*.npz (default: none)")
    sweep.add_argument("--devices", type=int, default=None, metavar="K",
                       help="use the first K local devices (default: all)")
    _add_distributed_args(sweep, "each process plans the chunks c with c %% P == I into DIR, which every "
                          "process must see; process 0 merges the tables and prints the summary")
    sweep.add_argument("--force", action="store_true",
                       help="remove the sweep already in DIR (or write beside other files) and start anew")
    sweep.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    sweep.add_argument("--json", action="store_true", help="print the summary as JSON")
    sweep.add_argument("--float32", action="store_true", help="plan in float32 (default float64)")


def _add_fit_parser(sub) -> None:
    fit = sub.add_parser(
        "fit",
        help="fit obstacle curves to a point cloud and write a JSON scenario",
        description="Fit polynomial curves to an unordered, noisy point cloud (one or several curve-like "
        "obstacles: a trunk with branches, crossing wires) and write a JSON scenario of them, with the "
        "fit's residuals as metadata, for 'softplan run'. CLOUD is .npy (an (N, 3) array), .csv "
        "(x,y,z per line, optional header), .xyz (x y z per line), .ply (a PLY file's vertices, ASCII or "
        "binary) or .pcd (a PCL point cloud: ascii, binary or binary_compressed).",
        epilog="Exit codes: 0 written (a poor fit prints a warning); 2 bad input, or the maximum "
        "residual is above --max-residual.",
    )
    fit.add_argument("cloud", metavar="CLOUD", help="point cloud file: .npy, .csv, .xyz, .ply or .pcd")
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
    fit.add_argument("--force", action="store_true", help="let the scenario file and --plot replace existing files")
    fit.add_argument("--json", action="store_true", help="print the summary as JSON")


# ----------------------------------------------------------------------------
# Checks on the host, before any planning.


def check_output_path(path: str, option: str, inputs=()) -> str:
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


def check_plot_format(path: str, option: str = "--plot") -> None:
    """``--plot`` (or ``option``): the extension names an image format matplotlib can write."""
    from matplotlib.figure import Figure

    ext = os.path.splitext(path)[1].lower().lstrip(".")
    supported = Figure().canvas.get_supported_filetypes()
    if ext not in supported:
        raise InputError(
            f"{option}: cannot tell the image format of {path!r}; use one of the extensions "
            f"{', '.join('.' + e for e in sorted(supported))}"
        )


def check_gains_arg(value: str) -> str | None:
    """The path of ``--gains`` when it names a gains file; None for a preset name."""
    from ..planning._presets import PRESETS

    if value in PRESETS:
        return None
    if not os.path.exists(value):
        raise InputError(f"--gains: {value!r} is neither a gain preset ({', '.join(sorted(PRESETS))}) "
                         "nor an existing gains file")
    if os.path.isdir(value):
        raise InputError(f"--gains: {value} is a directory, not a gains file")
    return value


def check_run_args(args, paper_names) -> None:
    """The options of ``softplan run`` (``paper_names``: the scene names that are not files); sets
    ``args.n_points`` (default 10) and ``args.gains_file``."""
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
    if args.evasion_speed is not None and not (math.isfinite(args.evasion_speed) and args.evasion_speed > 0):
        raise InputError(f"--evasion-speed must be a finite number > 0, got {args.evasion_speed}")
    if args.barrier_gain is not None and not (math.isfinite(args.barrier_gain) and args.barrier_gain >= 0):
        raise InputError(f"--barrier-gain must be a finite number >= 0, got {args.barrier_gain}")
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
    args.gains_file = check_gains_arg(args.gains)
    if args.gains_file is not None:
        inputs += (args.gains_file,)
    if args.plot is not None and args.gif is not None and os.path.abspath(args.plot) == os.path.abspath(
        args.gif
    ):
        raise InputError("--plot and --gif name the same file")
    if args.plot is not None:
        check_output_path(args.plot, "--plot", inputs)
        check_plot_format(args.plot)
    if args.gif is not None:
        check_output_path(args.gif, "--gif", inputs)
        if not args.gif.lower().endswith(".gif"):
            raise InputError(f"--gif: the path must end in .gif, got {args.gif!r}")
        try:
            import PIL  # noqa: F401
        except ImportError:
            raise InputError("--gif needs pillow: pip install pillow") from None
    for opt, path in (("--plot", args.plot), ("--gif", args.gif)):
        if path is not None and os.path.exists(path) and not args.force:
            raise InputError(f"{opt}: {path} exists; pass --force to overwrite it (or choose another path)")
    if args.out is not None:
        outputs = [p for p in (args.plot, args.gif) if p is not None]
        if any(os.path.abspath(args.out) == os.path.abspath(p) for p in outputs):
            raise InputError("--out names the same file as --plot or --gif")
        check_output_path(args.out, "--out", inputs)
        ext = os.path.splitext(args.out)[1].lower()
        if ext not in TRAJECTORY_FORMATS:
            raise InputError(
                f"--out: unknown extension {ext or '(none)'!r} in {args.out!r}; use .json or .npz"
            )
        if os.path.exists(args.out) and not args.force:
            raise InputError(f"--out: {args.out} exists; pass --force to overwrite it")
    elif args.force and all(p is None for p in (args.plot, args.gif, args.export, args.plot_actuators)):
        raise InputError("--force only applies to --out, --plot, --gif, --export and --plot-actuators")
    # Last, so that a bad argument is one error line, not a warning and an error.
    if n_points_given and args.method == "curve":
        warn("--n-points applies to --method points only; the curve method ignores it")


def check_distributed_args(args, local_devices: bool = False) -> bool:
    """Whether this is a --coordinator run; its three flags come together, in range,
    and exclude --devices unless ``local_devices`` (batch: the mesh is every device of
    every process; sweep: each process runs on its own local devices)."""
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
    if args.devices is not None and not local_devices:
        raise InputError("--devices does not combine with --coordinator (every process's devices are used)")
    return True


def initialize_distributed(args) -> None:
    """``jax.distributed.initialize`` from the --coordinator flags (InputError if it fails)."""
    import jax

    try:
        jax.distributed.initialize(coordinator_address=args.coordinator, num_processes=args.num_processes,
                                   process_id=args.process_id)
    except (RuntimeError, ValueError) as err:
        raise InputError(f"--coordinator: jax.distributed.initialize failed: {err}") from None
