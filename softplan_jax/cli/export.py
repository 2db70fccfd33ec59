"""``softplan export``: write a paper scenario as a JSON scenario file (format
``softplan-scenario/1``) to edit and run with ``softplan run``."""

from __future__ import annotations

import os

from .common import EXIT_OK, InputError, paper_names
from .parser import check_output_path

__all__ = ["cmd_export"]


def cmd_export(args) -> int:
    """``softplan export``: write a paper scenario as a JSON file; the exit code."""
    import jax

    jax.config.update("jax_enable_x64", True)  # write the paper's numbers exactly
    from ..scenarios import paper_scenario, save_scenario

    names = paper_names()
    if args.name not in names:
        raise InputError(f"unknown paper scenario {args.name!r}; choose one of {', '.join(names)}")
    if os.path.exists(args.path) and not args.force:
        raise InputError(f"{args.path} exists; pass --force to overwrite it")
    check_output_path(args.path, "PATH")
    try:
        save_scenario(paper_scenario(args.name), args.path, name=args.name, overwrite=args.force)
    except (OSError, ValueError) as err:
        raise InputError(f"cannot write {args.path}: {err}") from None
    print(f"wrote {args.name} to {args.path}")
    return EXIT_OK
