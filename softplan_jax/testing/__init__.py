"""The independent reference the tests (and ``benchmarks/closest.py``) check the library against,
written from the paper's formulas with NumPy and SciPy only, importing nothing else of
``softplan_jax`` (nor jax), so that the library is never compared with itself; not a layer of
the planner (``import softplan_jax`` does not load it): :mod:`.oracle` (the closest point by
dense sampling refined by SciPy, and the N-point model's nearest pair; it re-exports
:mod:`.oracle_geometry`'s kinematics, curves and moving-curve clearance),
:mod:`.oracle_actuators` (actuator lengths as polylines of each tendon's path offset in a
parallel-transported frame), :mod:`.case_makers` (closest-point case generators) and
:mod:`.closest_cases` (the case corpus and the oracle's cached answers);
``from softplan_jax.testing import closest_cases, oracle``."""

from . import case_makers, closest_cases, oracle, oracle_actuators, oracle_geometry

__all__ = ["case_makers", "closest_cases", "oracle", "oracle_geometry", "oracle_actuators"]
