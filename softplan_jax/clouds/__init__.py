"""Point clouds: curve-like obstacles fitted to scanned points (one curve or many in one cloud)."""

from .fitting import (
    CLOUD_EXTENSIONS,
    CloudFit,
    CurveFit,
    FitWarning,
    curve_distance,
    fit_curve,
    fit_curves,
    fit_scenario_dict,
    load_cloud,
    save_fit_scenario,
)
from ..geometry.curves import fit_polynomial_curve

__all__ = [
    "CurveFit",
    "CloudFit",
    "FitWarning",
    "fit_polynomial_curve",
    "fit_curve",
    "fit_curves",
    "curve_distance",
    "load_cloud",
    "fit_scenario_dict",
    "save_fit_scenario",
    "CLOUD_EXTENSIONS",
]
