"""``softplan fit``: fit polynomial curves to a point cloud (:mod:`softplan_jax.clouds`: ``.npy``,
``.csv``, ``.xyz``, ``.ply`` or ``.pcd``) and write them as a JSON scenario, with the fit's
residuals as metadata, and optionally a figure of the cloud with the curves.
"""

from __future__ import annotations

import json
import math
import os
import sys

from .common import EXIT_OK, InputError
from .parser import check_output_path, check_plot_format

__all__ = ["cmd_fit"]


def cmd_fit(args) -> int:
    """``softplan fit``: fit the cloud, write the scenario (and figure), print a summary; the exit code."""
    import jax

    jax.config.update("jax_enable_x64", True)  # fit and write the coefficients in float64
    from ..clouds import CloudFit, save_fit_scenario

    out = _check_args(args)
    cloud = args.cloud
    points, fit = _fit(args)
    meta = {"source": {"cloud": os.path.abspath(cloud), "command": "softplan fit", "single": bool(args.single),
                       "inflate": bool(args.inflate)}}
    replaced = os.path.exists(out)
    try:
        save_fit_scenario(fit, out, args.goal if args.goal is not None else [0.0, 0.0, 3.0],
                          name=os.path.splitext(os.path.basename(cloud))[0], metadata=meta, overwrite=args.force)
    except (OSError, ValueError) as err:
        raise InputError(f"cannot write {out}: {err}") from None
    if replaced:  # allowed by --force; never silently
        print(f"softplan: overwrote {out} (--force)", file=sys.stderr)
    cf = CloudFit.from_fit(fit)
    plot_path = _plot(args, points, fit, cf) if args.plot is not None else None
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
        "goal": list(args.goal if args.goal is not None else [0.0, 0.0, 3.0]),
        "scenario": os.path.abspath(out),
        "plot": plot_path,
    }
    print(json.dumps(summary, indent=2) if args.json else _text(args, summary, out))
    return EXIT_OK


def _check_args(args) -> str:
    """Check the flags (InputError); the scenario file to write."""
    from ..clouds import CLOUD_EXTENSIONS

    cloud = args.cloud
    if os.path.splitext(cloud)[1].lower() not in CLOUD_EXTENSIONS:
        raise InputError(f"cannot read point cloud {cloud!r}: use a file ending in {', '.join(CLOUD_EXTENSIONS)}")
    out = args.out if args.out is not None else os.path.splitext(cloud)[0] + ".json"
    if os.path.exists(out) and not args.force:
        raise InputError(f"{out} exists; pass --force to overwrite it (or choose --out)")
    check_output_path(out, "--out", (cloud,))
    if args.plot is not None:
        check_output_path(args.plot, "--plot", (cloud,))
        check_plot_format(args.plot)
        if os.path.abspath(args.plot) == os.path.abspath(out):
            raise InputError("--plot and --out name the same file")
        if os.path.exists(args.plot) and not args.force:
            raise InputError(f"--plot: {args.plot} exists; pass --force to overwrite it (or choose another path)")
    for opt, value in (("--max-residual", args.max_residual), ("--radius", args.radius)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{opt} must be a finite number >= 0, got {value}")
    if args.goal is not None and not all(math.isfinite(g) for g in args.goal):
        raise InputError(f"--goal must be three finite numbers, got {args.goal}")
    return out


def _fit(args):
    """``(points, fit)``: the cloud read and fitted; the reader's and the fit's warnings printed
    as ``softplan: warning:`` lines."""
    import warnings

    from ..clouds import FitWarning, fit_curve, fit_curves, load_cloud

    kwargs = dict(degree=args.degree, max_degree=args.max_degree, max_residual=args.max_residual,
                  radius=args.radius, inflate=args.inflate)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            points = load_cloud(args.cloud)
            fit = fit_curve(points, **kwargs) if args.single else fit_curves(points, **kwargs)
    except ValueError as err:
        raise InputError(str(err)) from None
    for w in caught:
        if issubclass(w.category, (FitWarning, UserWarning)):
            print(f"softplan: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
    return points, fit


def _plot(args, points, fit, cf) -> str:
    """Write ``--plot`` (whole or not at all, also on Ctrl-C); its absolute path."""
    if "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        matplotlib.use("Agg")  # the command never opens a window
    import matplotlib.pyplot as plt

    from ..plotting import plot_cloud_fit
    from .interrupt import atomic_output

    replaced = os.path.exists(args.plot)
    fig = plot_cloud_fit(points, fit, title=f"{os.path.basename(args.cloud)}: {len(cf.fits)} curve(s), "
                         f"max residual {cf.max_residual:.3g}")
    try:
        with atomic_output(args.plot) as tmp:
            fig.savefig(tmp, dpi=120, bbox_inches="tight")
    except OSError as err:
        raise InputError(f"cannot write output: {err}") from None
    finally:
        plt.close(fig)
    if replaced:
        print(f"softplan: overwrote {args.plot} (--force)", file=sys.stderr)
    return os.path.abspath(args.plot)


def _text(args, summary: dict, out: str) -> str:
    """The summary as the command's text."""
    noise = "" if summary["noise"] is None else f", estimated noise level {summary['noise']:.4g}"
    lines = [f"{args.cloud}: {summary['points']} points{noise}",
             f"{len(summary['curves'])} curve(s); max residual {summary['max_residual']:.4g}, "
             f"rms {summary['rms_residual']:.4g}"]
    for k, c in enumerate(summary["curves"]):
        lines.append(f"  curve {k}: degree {c['degree']}, {c['points']} points, rms {c['rms_residual']:.4g}, "
                     f"max {c['max_residual']:.4g}, radius {c['radius']:.4g}")
    if args.goal is None:
        lines.append("goal [0, 0, 3] (the straight arm's tip): pass --goal X Y Z or edit the JSON")
    lines.append(f"wrote {out}" + (f" and {args.plot}" if summary["plot"] else "") + f"; plan with: softplan run {out}")
    return "\n".join(lines)
