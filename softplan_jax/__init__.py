"""softplan_jax: a JAX-accelerated, differentiable path planner for soft continuum arms around
curve-like obstacles (branches, pipes, wires). The top level holds what a planning script uses
(``__all__``); the rest is in sub-namespaces, one per layer of the package, read top-down:
:mod:`softplan_jax.cli` (the ``softplan`` command), :mod:`softplan_jax.viewer` (the
interactive 3-D view in the browser, the optional extra ``viewer``), :mod:`softplan_jax.plotting` (matplotlib),
:mod:`softplan_jax.tuning` (tuning the gains, gains files), :mod:`softplan_jax.trajectories`
(timed trajectories of the actuators, TOPP-RA, their files), :mod:`softplan_jax.sweeps` (a seeded
random suite of any size, planned in chunks in constant memory, resumable),
:mod:`softplan_jax.search` (reachability and the certified global fallback),
:mod:`softplan_jax.planning` (the planner of paper eq. 9, its rollout engine, planning and
tracking), :mod:`softplan_jax.clouds` (obstacles fitted to point clouds),
:mod:`softplan_jax.scenarios` (static and moving scenes, the paper's, random suites, the JSON
format), :mod:`softplan_jax.actuators` (tendon and chamber lengths, their limits),
:mod:`softplan_jax.rod` (the loaded arm: a rod under gravity and a tip load, its shape as
constant-curvature pieces, its motion bound),
:mod:`softplan_jax.geometry` (kinematics, curves, exact closest points, clearance) and
:mod:`softplan_jax.base` (numerics, input checks, status codes, the compilation cache);
:mod:`softplan_jax.moving` gathers what moving scenes and tracking need."""

import importlib as _importlib
from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

from . import actuators as actuators
from . import geometry as geometry
from . import moving as moving
from . import planning as planning
from . import rod as rod
from . import scenarios as scenarios
from . import search as search
from . import sweeps as sweeps
from . import trajectories as trajectories
from . import tuning as tuning
from . import viewer as viewer
from .base._compilation_cache import disable_compilation_cache, enable_compilation_cache
from .base._compilation_cache import enable_default_cache as _enable_default_cache
from .base._status import Status
from .geometry._closest import closest_point
from .geometry._curves import ParametricCurve, PolynomialCurve, line_segment
from .geometry._kinematics import point_jacobian, segment_point, tip_position
from .geometry._point_sets import closest_point_to_points
from .planning._gains import GainFunction, Gains, default_gains
from .planning._options import PAPER_STEP, PlanOptions, make_options
from .planning._planner import PlanResult, plan, plan_batch
from .planning._presets import apply_preset
from .planning._tracking import track, track_batch
from .rod import RodModel, loaded_backbone
from .scenarios import Scenario, load_scenario, make_scenario, paper_scenario, random_scenarios, save_scenario
from .scenarios._motion import make_moving_scenario
from .scenarios._moving import moving_scenario
from .search._fallback import plan_fallback
from .search._tracking import track_fallback
from .trajectories import Trajectory, load_trajectory, save_trajectory, time_parametrize
from .tuning._gains_file import load_gains, save_gains
from .viewer._launch import view

# jax's persistent compilation cache on for the planner's programs, unless the user set one or
# opted out (SOFTPLAN_JAX_NO_CACHE=1; see softplan_jax.base._compilation_cache).
_enable_default_cache()

try:
    __version__ = _version("softplan_jax")
except _PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = [
    # scenes
    "Scenario",
    "make_scenario",
    "paper_scenario",
    "random_scenarios",
    "load_scenario",
    "save_scenario",
    # obstacles and the arm
    "PolynomialCurve",
    "ParametricCurve",
    "line_segment",
    "segment_point",
    "tip_position",
    "point_jacobian",
    "closest_point",
    "closest_point_to_points",
    # the loaded arm (gravity and a tip load)
    "RodModel",
    "loaded_backbone",
    # planning (paper eq. 9)
    "Gains",
    "GainFunction",
    "default_gains",
    "PAPER_STEP",
    "PlanOptions",
    "make_options",
    "PlanResult",
    "Status",
    "plan",
    "plan_batch",
    "plan_fallback",
    # moving goals and obstacles
    "moving_scenario",
    "make_moving_scenario",
    "track",
    "track_batch",
    "track_fallback",
    # actuators over time
    "Trajectory",
    "time_parametrize",
    "save_trajectory",
    "load_trajectory",
    # gains
    "apply_preset",
    "save_gains",
    "load_gains",
    # the interactive view in the browser (needs the extra "viewer")
    "view",
    "enable_compilation_cache",
    "disable_compilation_cache",
    "__version__",
]

_LAZY_MODULES = ("plotting", "cli", "clouds")  # imported on first use: matplotlib, argparse, scipy


def __getattr__(name):
    if name in _LAZY_MODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_MODULES))
