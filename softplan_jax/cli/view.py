"""``softplan view SCENE``: the interactive 3-D view in the browser (:func:`softplan_jax.view`).

SCENE is a paper scenario, a moving preset, a JSON scenario file (static or moving) or a
trajectory saved by ``softplan run --out`` (JSON or NPZ: shown first, on the scene named in its
``scenario`` field, a preset or a file found as written, from here or beside the trajectory).
Everything is checked before the server starts: a bad scene, file, option or a missing viser is
one error line and exit code 2. The command serves until Ctrl-C (exit 130, as every command).
Its arguments are declared in :mod:`.parser`.
"""

from __future__ import annotations

import os
import sys

from .common import InputError, load_world, moving_names, paper_names, resolve_gains
from .parser import check_gains_arg
from .trajectory import is_trajectory_file, read_trajectory

__all__ = ["cmd_view"]


def _trajectory_scene(record: dict, path: str) -> str:
    """The scene of a saved trajectory: its ``scenario`` field, a preset or a file (as written,
    from the working folder, else beside the trajectory)."""
    spec = record["scenario"]
    if spec in paper_names() + moving_names() or os.path.isfile(spec):
        return spec
    beside = os.path.join(os.path.dirname(os.path.abspath(path)), spec)
    if os.path.isfile(beside):
        return beside
    raise InputError(f"trajectory file {path}: its scene {spec!r} (field scenario) is neither a preset nor a "
                     "file found from here or beside the trajectory")


def _inputs(args, dtype) -> tuple:
    """``(world, label, record, planner settings)`` of the command line (InputError: bad input)."""
    record = None
    spec = args.scene
    if spec not in paper_names() + moving_names() and os.path.isfile(spec) and is_trajectory_file(spec):
        try:
            record = read_trajectory(spec)
        except ValueError as err:
            raise InputError(str(err)) from None
        spec = _trajectory_scene(record, args.scene)
    world, preset = load_world(spec, dtype)
    saved = record or {}
    args.method = args.method or saved.get("method") or "curve"
    args.n_points = args.n_points if args.n_points is not None else int(saved.get("n_points") or 10)
    if args.n_points < 1:
        raise InputError(f"--n-points must be >= 1, got {args.n_points}")
    if args.max_steps < 1:
        raise InputError(f"--max-steps must be >= 1, got {args.max_steps}")
    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be in 0..65535, got {args.port}")
    if not args.host.strip():
        raise InputError("--host: empty address")
    args.gains_file = check_gains_arg(args.gains)
    moving = hasattr(world, "motion")
    if record is not None and moving != (record.get("time") is not None):
        raise InputError(f"trajectory file {args.scene}: a {'tracked' if record.get('time') is not None else 'planned'}"
                         f" run, but its scene {spec!r} is {'moving' if moving else 'static'}")
    try:
        scene, gains, extra, _ = resolve_gains(args, world.scene if moving else world, args.method, args.n_points)
    except ValueError as err:
        raise InputError(str(err)) from None
    world = world._replace(scene=scene) if moving else scene
    label = os.path.basename(args.scene) if record is not None or spec not in paper_names() + moving_names() else spec
    return world, label, record, dict(gains=gains, **preset, **extra)


def cmd_view(args) -> int:
    """``softplan view``: check everything, serve the view, print its address, serve until Ctrl-C."""
    import jax

    from ..base._compilation_cache import enable_compilation_cache

    enable_compilation_cache()
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from ..viewer._launch import require_viser, view

    world, label, record, settings = _inputs(args, jnp.float64)
    try:
        require_viser()
    except ImportError as err:
        raise InputError(str(err)) from None
    try:
        viewer = view(world, record, method=args.method, n_points=args.n_points, max_steps=args.max_steps,
                      seed=args.seed, host=args.host, port=args.port, share=args.share, label=label, **settings)
    except OSError as err:  # the address cannot be served at all (an unknown host, a port refused)
        raise InputError(f"cannot serve on {args.host}:{args.port}: {err.strerror or err}") from None
    print("softplan: serving until Ctrl-C", file=sys.stderr, flush=True)
    viewer.wait()
    return 0
