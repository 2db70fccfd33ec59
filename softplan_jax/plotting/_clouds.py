"""A point cloud with the curves fitted to it (matplotlib, host side): :func:`plot_cloud_fit` draws
the raw cloud and every curve of a :class:`~softplan_jax.clouds.CloudFit` or
:class:`~softplan_jax.clouds.CurveFit` over it, each labelled with its degree and residuals."""

from __future__ import annotations

import numpy as np

from ._scene import CURVE_SAMPLES, pyplot

__all__ = ["plot_cloud_fit"]


def plot_cloud_fit(points, fit, ax=None, title=None, max_points: int = 6000, figsize=(8, 6.5)):
    """The raw cloud (grey dots) with the fitted curves over it, one colour per
    curve, each labelled with its degree and residuals.

    Args:
      points: (N, 3) the cloud that was fitted.
      fit: a :class:`~softplan_jax.clouds.CloudFit` or
        :class:`~softplan_jax.clouds.CurveFit`.
      ax: a 3D Axes to draw on; None = a new figure.
      title: figure title; None = a summary of the fit.
      max_points: draw at most this many cloud points (a seeded random subset).

    Returns:
      The matplotlib Figure.
    """
    from ..base._validation import check_cloud
    from ..clouds import CloudFit

    P = check_cloud(points)
    cf = CloudFit.from_fit(fit)
    plt = pyplot()
    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d", computed_zorder=False)  # curves drawn over the cloud
    else:
        fig = ax.figure
    shown = P
    if P.shape[0] > max_points:
        shown = P[np.random.default_rng(0).choice(P.shape[0], max_points, replace=False)]
    ax.scatter(shown[:, 0], shown[:, 1], shown[:, 2], s=2, color="0.5", alpha=0.3, depthshade=False,
               label=f"cloud ({P.shape[0]} points)", zorder=1)
    colors = plt.get_cmap("tab10")
    for k, f in enumerate(cf.fits):
        coeffs = np.asarray(f.curve.coeffs, dtype=float)
        lo, hi = (float(x) for x in np.asarray(f.curve.u_range))
        u = np.linspace(lo, hi, CURVE_SAMPLES)
        pts = np.stack([np.polynomial.polynomial.polyval(u, coeffs[a]) for a in range(3)], axis=-1)
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=colors(k % 10), lw=2.0, zorder=2 + k,
                label=f"curve {k}: degree {f.degree}, rms {f.rms_residual:.3g}, max {f.max_residual:.3g}")
    lo, hi = P.min(axis=0), P.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1e-9) * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_xlabel("X")
    ax.set_ylabel("Y")
    ax.set_zlabel("Z")
    if title is None:
        title = f"{len(cf.fits)} curve(s) fitted; max residual {cf.max_residual:.3g}, rms {cf.rms_residual:.3g}"
        if np.isfinite(cf.noise):
            title += f"\nestimated noise level {cf.noise:.3g} (poor fit above {cf.tolerance:.3g})"
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", fontsize=8)
    return fig
