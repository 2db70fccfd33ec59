"""Scenario files of fitted curves (what ``softplan fit`` writes): :func:`fit_scenario_dict`
builds the ``softplan-scenario/1`` JSON structure whose obstacles are the fitted curves, with
the residuals (whole cloud and per curve), the cloud's noise level and the degree criterion in
``metadata`` (which :func:`~softplan_jax.load_scenario` accepts and leaves out of the
Scenario); :func:`save_fit_scenario` writes it to a file."""

from __future__ import annotations

import math

from ..scenarios import write_json_file
from ._many_curves import CloudFit

__all__ = ["fit_scenario_dict", "save_fit_scenario"]


def fit_scenario_dict(fit, goal, q0=None, *, name: str | None = None, metadata: dict | None = None) -> dict:
    """The JSON structure of a scenario whose obstacles are fitted curves, with
    the fit's residuals as ``metadata`` (top level: the whole cloud; each
    obstacle: its own points). ``load_scenario`` reads it; metadata is not part
    of the Scenario.

    Args:
      fit: a :class:`CloudFit` (or a :class:`CurveFit`).
      goal: (3,) goal of the tip.
      q0: (n, 3) start; None = the default straight arm.
      name: optional scenario name.
      metadata: extra top-level metadata (JSON-serialisable), e.g. the cloud's path.

    Returns:
      dict in the ``softplan-scenario/1`` format.
    """
    from ..scenarios import make_scenario, scenario_to_dict

    cf = CloudFit.from_fit(fit)
    scenario = make_scenario(goal, [f.curve for f in cf.fits], q0)
    data = scenario_to_dict(scenario, name)
    for ob, f in zip(data["obstacles"], cf.fits, strict=True):
        ob["metadata"] = {
            "fit": {
                "degree": f.degree,
                "points": int(f.indices.size),
                "rms_residual": f.rms_residual,
                "max_residual": f.max_residual,
            }
        }
    top = {
        "points": int(cf.residuals.size),
        "curves": len(cf.fits),
        "rms_residual": cf.rms_residual,
        "max_residual": cf.max_residual,
        "degree_criterion": "BIC (Schwarz 1978) unless the degree was given",
        "residual": "exact distance from each cloud point to its nearest fitted curve (centre line)",
    }
    if math.isfinite(cf.noise):
        top["noise"] = cf.noise
        top["tolerance"] = cf.tolerance
    meta = {"fit": top}
    if metadata:
        meta.update(metadata)
    data["metadata"] = meta
    return data


def save_fit_scenario(fit, path, goal, q0=None, *, name: str | None = None, metadata: dict | None = None,
                      overwrite: bool = False) -> None:
    """Write :func:`fit_scenario_dict` as a JSON scenario file (whole or not at
    all); refuses to replace an existing file unless ``overwrite=True``."""
    write_json_file(path, fit_scenario_dict(fit, goal, q0, name=name, metadata=metadata), overwrite)
