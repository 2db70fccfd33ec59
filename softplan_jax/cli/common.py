"""What the ``softplan`` subcommands share: the exit codes, :class:`InputError` (bad user input:
one line ``softplan: error: ...`` on stderr, exit code 2), the package version, warnings on
stderr, the scenes named on the command line (:func:`load_world`), ``--gains`` resolved and
recorded, the ``--plot`` / ``--gif`` figures, number formats and the printed summary; jax, numpy
and matplotlib are imported inside the functions that need them, so that ``softplan --help`` is
fast."""

from __future__ import annotations

import json
import math
import os
import sys

__all__ = [
    "EXIT_OK", "EXIT_BAD_INPUT", "EXIT_NOT_REACHED", "InputError", "package_version", "warn", "paper_names",
    "fmt_seconds", "fmt_gain_values", "resolve_gains", "gains_report", "write_figures", "report", "check_points_args",
    "moving_names", "load_world",
]

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_REACHED = 3


class InputError(Exception):
    """Bad user input: reported as one line on stderr, exit code 2."""


def package_version() -> str:
    """The installed softplan_jax version (``0.0.0+unknown`` when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("softplan_jax")
    except PackageNotFoundError:
        return "0.0.0+unknown"


def warn(msg: str) -> None:
    """One line ``softplan: warning: ...`` on stderr."""
    print(f"softplan: warning: {msg}", file=sys.stderr, flush=True)


def paper_names():
    """The paper scenarios' names, sorted."""
    from ..scenarios import PAPER_SCENARIOS

    return sorted(PAPER_SCENARIOS)


def fmt_seconds(t: float) -> str:
    """A duration in s, ms or us."""
    if t >= 1.0:
        return f"{t:.2f} s"
    if t >= 1e-3:
        return f"{t * 1e3:.2f} ms"
    return f"{t * 1e6:.1f} us"


def fmt_gain_values(values: dict) -> str:
    """The summary's ``gain_values`` as one line of text."""
    def fmt(k, v):
        if v is None:
            return f"{k} none (no cap)"
        if isinstance(v, list):
            def row(r):
                return f"[{', '.join(f'{x:.4g}' for x in r)}]"

            return f"{k} [{', '.join(row(x) for x in v)}]" if v and isinstance(v[0], list) else f"{k} {row(v)}"
        return f"{k} {v:.4g}"

    return ", ".join(fmt(k, v) for k, v in values.items())


def resolve_gains(args, scenario, method: str, n_points: int):
    """``(scenario, gains, options, gain_values)`` for ``--gains``: a preset's start pose,
    gains and step options, or a gains file's gains with the default preset's start pose
    and options (ValueError for a bad or mismatched file). ``gain_values`` is the JSON
    form of the gains (:func:`~softplan_jax.tuning._gains_file.gains_to_dict`; ``rep_max`` null
    = no cap)."""
    import warnings

    from ..planning._planner import check_gains
    from ..planning._presets import apply_preset
    from ..tuning._gains_file import gains_to_dict, load_gains

    scenario, gains, extra = apply_preset("default" if args.gains_file else args.gains, scenario)
    with warnings.catch_warnings(record=True) as caught:  # the gains' soundness warnings, as warning lines
        warnings.simplefilter("always")
        if args.gains_file:
            dtype = scenario.q0.dtype
            gains = load_gains(args.gains_file, method=method, n_points=n_points, dtype=dtype)
        # seg_weights against the arm's segments; damping 0 against the start pose (one scene)
        q0 = scenario.q0 if scenario.q0.ndim == 2 else None
        gains = check_gains(gains, scenario.q0.dtype, scenario.q0.shape[-2], q0)
        values = gains_to_dict(gains, method, n_points)["gains"]
    for w in {str(w.message): w for w in caught if issubclass(w.category, UserWarning)}:  # each once
        warn(" ".join(w.split()))
    return scenario, gains, extra, values


def gains_report(args, gain_values: dict) -> dict:
    """The summary's record of the gains used."""
    return {"gains": args.gains,
            "gains_file": os.path.abspath(args.gains_file) if args.gains_file else None,
            "gain_values": gain_values}


def write_figures(args, summary: dict, make_plot, write_gif) -> None:
    """``run --plot`` / ``--gif``: the figure from ``make_plot(plotting)`` saved to args.plot,
    ``write_gif(plotting, path)`` for args.gif (written to a temporary path, then renamed);
    their absolute paths into the summary; a replaced file (``--force``) said on stderr."""
    if args.plot is None and args.gif is None:
        return
    if "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        matplotlib.use("Agg")  # the command never opens a window
    import matplotlib.pyplot as plt

    import softplan_jax.plotting as plotting

    from .interrupt import atomic_output  # each figure whole or not at all, also on Ctrl-C

    replaced = [p for p in (args.plot, args.gif) if p is not None and os.path.exists(p)]  # with --force
    try:
        if args.plot is not None:
            fig = make_plot(plotting)
            try:
                with atomic_output(args.plot) as tmp:
                    fig.savefig(tmp, dpi=120, bbox_inches="tight", pad_inches=0.2)
            finally:
                plt.close(fig)
            summary["plot"] = os.path.abspath(args.plot)
        if args.gif is not None:
            print(f"softplan: rendering {args.gif} (up to 200 frames; tens of seconds) ...", file=sys.stderr,
                  flush=True)
            with atomic_output(args.gif) as tmp:
                write_gif(plotting, tmp)
            summary["gif"] = os.path.abspath(args.gif)
    except OSError as err:
        raise InputError(f"cannot write output: {err}") from None
    for path in replaced:  # allowed by --force; never silently
        print(f"softplan: overwrote {path} (--force)", file=sys.stderr)


def report(args, summary: dict, text, reached: bool) -> int:
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


def check_points_args(args) -> None:
    """``--method`` / ``--n-points`` of ``batch`` and ``sweep``: ``--n-points`` (default 10)
    with the N-point method only, at least 1 (sets ``args.n_points``)."""
    if args.method == "points":
        args.n_points = 10 if args.n_points is None else args.n_points
        if args.n_points < 1:
            raise InputError(f"--n-points must be >= 1, got {args.n_points}")
    elif args.n_points is not None:
        raise InputError("--n-points applies to --method points only")



# glibc's mallopt parameter M_MMAP_THRESHOLD, and the size from which an allocation gets its own
# mapping (returned to the system when freed) once it is set.
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD_BYTES = 4 << 20


def return_freed_chunks() -> None:
    """Let the batch commands' memory stay flat over their chunks: a fixed glibc mmap threshold,
    so that every buffer of 4 MiB or more (a chunk's rollout, its host copies) is mapped on its
    own and returned to the system when freed. glibc's default threshold grows with the largest
    buffer freed, after which such buffers come from the heap, which fragments and grows chunk
    by chunk (the documentation's Performance page, "Sweeps at scale"). Skipped outside glibc."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
    except (OSError, AttributeError):  # not glibc (macOS, musl without mallopt, Windows)
        pass


def moving_names():
    """The moving presets' names, sorted."""
    from ..scenarios._moving import MOVING_SCENARIOS

    return sorted(MOVING_SCENARIOS)


def load_world(spec: str, dtype) -> tuple:
    """A scene named on the command line: a paper scenario, a moving preset, or a JSON scenario
    file (static, or moving where it has motion fields); its warnings as warning lines.

    Returns:
      ``(world, preset_options)``: a Scenario or MovingScenario, and the tracking options a
      moving preset is played with (``MOVING_OPTIONS``; else empty).

    Raises:
      InputError: an unknown name, a missing, unreadable or malformed file (naming the field).
    """
    import warnings

    from ..scenarios import load_moving_scenario, load_scenario, paper_scenario
    from ..scenarios._json_format import is_moving_dict, read_json_file
    from ..scenarios._moving import MOVING_OPTIONS, moving_scenario

    if spec in paper_names():
        return paper_scenario(spec, dtype=dtype), {}
    if spec in moving_names():
        return moving_scenario(spec, dtype=dtype), dict(MOVING_OPTIONS[spec])
    if not os.path.exists(spec):
        raise InputError(f"unknown scenario {spec!r}: not a paper scenario or moving scene "
                         f"({', '.join(paper_names() + moving_names())}) and no such file")
    if os.path.isdir(spec):
        raise InputError(f"scenario {spec} is a directory, not a JSON file")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            moving = is_moving_dict(read_json_file(spec, "scenario"))
            world = (load_moving_scenario if moving else load_scenario)(spec, dtype=dtype)
    except ValueError as err:
        raise InputError(str(err)) from None
    for w in caught:
        warn(str(w.message))
    return world, {}
