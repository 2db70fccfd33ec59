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
    softplan sweep --n N --out DIR [--chunk C] [--seed S] [--method curve|points]
                   [--max-steps N] [--gains PRESET|FILE] [--fallback] [--trajectories K|all]
                   [--force] [--json] [--no-progress] [--float32]
    softplan view SCENE [--method curve|points] [--n-points N] [--gains PRESET|FILE]
                        [--max-steps N] [--seed S] [--host HOST] [--port PORT] [--share]

SCENARIO is a paper scenario name (``sim1``, ``sim2``, ``tree``) or the path of
a JSON scenario file (a file literally named like a paper scenario: write
``./sim1``).

``--gains`` (``run`` and ``batch``) is a gain preset (``default``, ``paper``:
gains, step options and start pose, :mod:`softplan_jax.planning.presets`) or the path of
a gains file (format ``softplan-gains/1``, :mod:`softplan_jax.tuning.gains_file`,
written by :func:`softplan_jax.save_gains`): the file's gains with the default
preset's start pose and step options. A file tuned for another ``--method`` or
``--n-points`` is bad input. The summary (and ``run --out``) records the gains
used: ``gains`` (the preset name or the path as given), ``gains_file`` (its
absolute path, or null for a preset) and ``gain_values``.

``run --out FILE`` saves the whole trajectory: ``q`` (iterations + 1, n, 3),
``tip`` (iterations + 1, 3) and ``clearance`` (iterations + 1, obstacles), the
true clearance to every obstacle at every step, start first, plus the status,
iterations and the run's metadata (format ``softplan-trajectory/1``, see
:func:`~softplan_jax.cli.trajectory.trajectory_record`). The format follows the extension: ``.json`` (arrays
as nested lists, non-finite numbers as null) or ``.npz`` (``numpy.load``; one
array per field, strings and numbers as 0-d arrays, no pickles). Any other
extension is bad input. An existing FILE is never replaced unless ``--force``
is given (then the summary says it was overwritten).

Exit codes: 0 success (for ``run``: planning finished, whatever its status —
reached, stalled, collided or max_steps; the status is in the summary);
2 bad input (unknown scenario, missing or malformed file, bad option value,
output path that cannot be written, a size too large for memory), with one
line ``softplan: error: ...`` on stderr; 3 ``run --require-reached`` and the
run did not succeed (any status but "reached", or "held" for a moving goal);
130 interrupted (Ctrl-C: one line ``softplan: interrupted`` on stderr, no
partial output file left behind: an output is written whole under its name or
not at all). A Ctrl-C that comes after the command finished, while the process
exits, is ignored: the exit code is the command's.

``run`` keeps compiled rollouts in jax's persistent compilation cache
(``~/.cache/softplan_jax/jax``; see :mod:`softplan_jax.base.compilation_cache`;
``SOFTPLAN_JAX_NO_CACHE=1`` or ``SOFTPLAN_COMPILATION_CACHE=0`` turns it off), so a
second run of the same scenario shape does not compile again.

jax is imported inside the commands, after :func:`main` has parsed the
arguments, so ``--help`` is fast and float64 (``jax_enable_x64``) can be
switched on before any array exists.

The command is one module per subcommand: :mod:`.run`, :mod:`.batch`, :mod:`.sweep`,
:mod:`.fit`, :mod:`.scenario_list` (``softplan scenarios``), :mod:`.export` and :mod:`.view`;
:mod:`.parser` holds the argument parser and the checks of the arguments,
:mod:`.trajectory` the ``run --out`` file format and :mod:`.common` what the
commands share. This module dispatches and turns errors into exit codes.
"""

from __future__ import annotations

import sys

from .batch import cmd_batch
from .common import EXIT_BAD_INPUT, InputError
from .export import cmd_export
from .fit import cmd_fit
from .interrupt import EXIT_INTERRUPTED, interrupt_guard
from .parser import build_parser
from .run import cmd_run
from .scenario_list import cmd_scenarios
from .sweep import cmd_sweep
from .view import cmd_view

__all__ = ["main", "console_main"]


def main(argv=None) -> int:
    """The ``softplan`` command called in-process (``argv`` as on the command line, default
    ``sys.argv[1:]``); returns the exit code (Ctrl-C: the process ends with 130, see
    :mod:`.interrupt`). Python's SIGINT handler is as it was afterwards."""
    with interrupt_guard():
        return _main(argv)


def console_main() -> int:
    """The ``softplan`` process's entry point (the console script, ``python -m
    softplan_jax.cli``): :func:`main` on ``sys.argv[1:]``, after which SIGINT stays ignored
    while the process exits (see :mod:`.interrupt`)."""
    with interrupt_guard(restore=False):
        rc = _main(None)
    return rc


def _main(argv) -> int:
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
            return cmd_run(args)
        if args.command == "scenarios":
            return cmd_scenarios(args)
        if args.command == "fit":
            return cmd_fit(args)
        if args.command == "batch":
            return cmd_batch(args)
        if args.command == "sweep":
            return cmd_sweep(args)
        if args.command == "view":
            return cmd_view(args)
        return cmd_export(args)
    except (InputError, ValueError) as err:
        # A ValueError is the library's answer to bad input (a size that cannot fit, a bad seed, ...).
        msg = " ".join(str(err).split())  # one line
        print(f"softplan: error: {msg}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # outside the guard's reach (not the main thread): one line all the same
        print("softplan: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    raise SystemExit(main())
