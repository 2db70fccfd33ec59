"""Point clouds: curve-like obstacles fitted to scanned points, one curve or many in one
cloud (the paper's ``F_o(u)`` "derived from a set of points ... using regression", §2.3):
:mod:`._cloud_io` reads a cloud, :mod:`._one_curve` and :mod:`._many_curves` fit it (on
:mod:`._graph`, :mod:`._skeleton`, :mod:`._refine` and :mod:`._distance`), :mod:`._output` writes
the scenario file ``softplan fit`` writes; everything runs on the host (NumPy/SciPy), not
under ``jit``: fitting is a one-off step before planning (the documentation's "Obstacles from
point clouds")."""

from ._cloud_io import CLOUD_EXTENSIONS, load_cloud
from ._distance import curve_distance
from ._many_curves import CloudFit, fit_curves
from ._one_curve import CurveFit, FitWarning, fit_curve, fit_polynomial_curve
from ._output import fit_scenario_dict, save_fit_scenario

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
