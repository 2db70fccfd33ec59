"""The ``softplan`` command (the documentation's "The softplan command"): one module per
subcommand (:mod:`.run`, :mod:`.batch`, :mod:`.sweep`, :mod:`.fit`, :mod:`.scenario_list`,
:mod:`.export`, :mod:`.view`), the argument parser and checks in :mod:`.parser`, the ``run --out`` format in
:mod:`.trajectory`, what the commands share in :mod:`.common`; this module dispatches and turns
errors into exit codes (0 done, 2 bad input with one line ``softplan: error: ...``, 3
``run --require-reached`` not met, 130 interrupted). jax is imported inside the commands, after
the arguments are parsed, so ``--help`` is fast and float64 can be switched on before any array
exists."""

from __future__ import annotations

import sys

from .batch import cmd_batch
from .common import EXIT_BAD_INPUT, InputError
from .export import cmd_export
from .fit import cmd_fit
from .interrupt import EXIT_INTERRUPTED, interrupt_guard, interrupted_next_step, interrupted_say
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
    interrupted_say("")  # a command of its own: nothing said after "interrupted" unless it says so
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
    except KeyboardInterrupt:  # outside the guard's reach (not the main thread): the same lines all the same
        print("softplan: interrupted", file=sys.stderr)
        print(interrupted_next_step(), file=sys.stderr, end="")
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    raise SystemExit(main())
