"""Point clouds: curve-like obstacles fitted to scanned points (one curve or many in one cloud).

The paper models a real branch, pipe or wire as a curve ``F_o(u)`` "derived from
a set of points ... using regression" (§2.3). A depth camera or a LiDAR returns
those points unordered, noisy, and often from several obstacles at once; the
modules here turn such a cloud into polynomial curves and say how well they fit:

* :mod:`.cloud_io` — :func:`load_cloud` reads an ``.npy``, ``.csv`` or ``.xyz`` cloud;
* :mod:`.distance` — :func:`curve_distance`, the exact distance from points to a curve;
* :mod:`.graph` — the cloud's noise level, neighbour graph, spanning tree and length scales;
* :mod:`.refine` — one curve from initial parameters (parameter correction, degree by BIC);
* :mod:`.one_curve` — :func:`fit_curve` (one curve, any order) and :func:`fit_polynomial_curve`
  (an ordered cloud), with :class:`CurveFit` and :class:`FitWarning`;
* :mod:`.skeleton` — the pruned spanning tree split at junctions and rejoined into curves;
* :mod:`.many_curves` — :func:`fit_curves`, several curves in one cloud (:class:`CloudFit`);
* :mod:`.output` — :func:`save_fit_scenario`, a JSON scenario with the residuals as metadata
  (what ``softplan fit`` writes).

Everything here runs on the host (NumPy/SciPy), not under ``jit``: fitting is a
one-off step before planning.
"""

from .cloud_io import CLOUD_EXTENSIONS, load_cloud
from .distance import curve_distance
from .many_curves import CloudFit, fit_curves
from .one_curve import CurveFit, FitWarning, fit_curve, fit_polynomial_curve
from .output import fit_scenario_dict, save_fit_scenario

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
