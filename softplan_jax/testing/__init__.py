"""The independent reference the tests (and ``benchmarks/closest.py``) check the library against.

Not a layer of the planner, and imported by none of them: ``import softplan_jax``
does not load it. Its modules are written from the paper's formulas with NumPy
and SciPy only and import nothing else of ``softplan_jax`` (nor jax), so that
the library is never compared with itself:

* :mod:`.oracle`: the closest point of an arm to a curve by dense sampling
  refined by SciPy (paper section 2.3) and the N-point model's nearest pair;
  it re-exports :mod:`.oracle_geometry`'s names, so one namespace serves;
* :mod:`.oracle_geometry`: the kinematics (section 2.1, complex-step
  Jacobians), the obstacle curves, and the clearance to moving curves sampled
  in space and time;
* :mod:`.oracle_actuators`: actuator lengths as polylines of each tendon's path
  offset in a parallel-transported frame (a NumPy loop);
* :mod:`.case_makers`: the generators of closest-point cases (random, touching,
  crossing, parallel, boundary minima, long curves, the paper's obstacles);
* :mod:`.closest_cases`: the case corpus (~1,200 cases in four families) and
  the oracle's answers to it, cached on disk and keyed by the oracle's source.

    from softplan_jax.testing import closest_cases, oracle
"""

from . import case_makers, closest_cases, oracle, oracle_actuators, oracle_geometry

__all__ = ["case_makers", "closest_cases", "oracle", "oracle_geometry", "oracle_actuators"]
