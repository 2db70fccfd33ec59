"""softplan_jax: a JAX-accelerated, differentiable path planner for soft
continuum arms around curve-like obstacles (branches, pipes, wires).

The public API is the names in ``__all__`` (see docs/api.md). Two host-side
submodules are public as modules: :mod:`softplan_jax.plotting` (matplotlib)
and :mod:`softplan_jax.cli` (the ``softplan`` command).
"""

from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

from .closest import ClosestPoint, SolverOptions, closest_point, closest_point_to_points, point_distance
from .closest_grid import GridSolverOptions
from .compilation_cache import compilation_cache_dir, enable_compilation_cache
from .curves import ParametricCurve, PolynomialCurve, curve_points, fit_polynomial_curve, line_segment, stack_curves
from .fallback import plan_fallback
from .fitting import CloudFit, CurveFit, FitWarning, curve_distance, fit_curve, fit_curves, load_cloud, save_fit_scenario
from .gains_file import gains_from_dict, gains_to_dict, load_gains, save_gains
from .kinematics import (
    backbone_points,
    motion_bound,
    point_jacobian,
    segment_frames,
    segment_point,
    segment_transform,
    tip_jacobian,
    tip_position,
)
from .metrics import apply_collision_checks, dense_trajectory_clearance, true_closest
from .motion import (
    CurveMotion,
    GoalPath,
    MovingScenario,
    curve_motion,
    goal_at,
    goal_path,
    make_moving_scenario,
    scenario_at,
    speed_bounds,
    stack_moving_scenarios,
)
from .planner import (
    PAPER_STEP,
    GainFunction,
    Gains,
    PlanOptions,
    PlanResult,
    Rollout,
    attraction,
    default_gains,
    make_options,
    plan,
    plan_batch,
    planner_step,
    repulsion,
    result_from_rollout,
    rollout,
    rollout_batch,
    rollout_jit,
)
from .presets import PRESETS, Preset, apply_preset, preset
from .reach import REACH_REASONS, Reachability, ReachOptions, reachability
from .scenarios import (
    Scenario,
    default_start,
    load_scenario,
    make_scenario,
    paper_scenario,
    random_scenarios,
    save_scenario,
    scenario_from_dict,
    scenario_to_dict,
    scenario_warnings,
    stack_scenarios,
)
from .scenarios.moving import MOVING_SCENARIOS, moving_scenario, random_moving_scenarios
from .smoothing import (
    GainSpace,
    ObjectiveEstimate,
    ScoreWeights,
    SmoothingSample,
    TuneResult,
    estimate_objective,
    rollout_score,
    score_batch,
    smoothed_objective,
    smoothing_sample,
    tune_smoothed,
)
from .status import STATUS_NAMES, Status, status_name
from .tracking import Track, TrackOptions, TrackResult, track, track_batch
from .tuning import LossWeights, TuningResult, batch_loss, rollout_loss, tune_gains

try:
    __version__ = _version("softplan_jax")
except _PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = [
    # kinematics (paper section 2.1)
    "segment_transform",
    "segment_frames",
    "segment_point",
    "tip_position",
    "point_jacobian",
    "tip_jacobian",
    "backbone_points",
    "motion_bound",
    # obstacle curves and point clouds
    "PolynomialCurve",
    "ParametricCurve",
    "line_segment",
    "stack_curves",
    "curve_points",
    "fit_polynomial_curve",
    "CurveFit",
    "CloudFit",
    "FitWarning",
    "fit_curve",
    "fit_curves",
    "curve_distance",
    "load_cloud",
    "save_fit_scenario",
    # closest points (paper section 2.3)
    "ClosestPoint",
    "SolverOptions",
    "GridSolverOptions",
    "closest_point",
    "closest_point_to_points",
    "point_distance",
    # scenarios
    "Scenario",
    "default_start",
    "make_scenario",
    "stack_scenarios",
    "scenario_warnings",
    "paper_scenario",
    "random_scenarios",
    "load_scenario",
    "save_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    # planner (paper eq. 9)
    "Gains",
    "GainFunction",
    "default_gains",
    "attraction",
    "repulsion",
    "PlanOptions",
    "make_options",
    "PAPER_STEP",
    "planner_step",
    "Status",
    "STATUS_NAMES",
    "status_name",
    "Rollout",
    "rollout",
    "rollout_jit",
    "rollout_batch",
    "PlanResult",
    "result_from_rollout",
    "plan",
    "plan_batch",
    # reachability and the global fallback (softplan_jax.reach, softplan_jax.global_planner)
    "ReachOptions",
    "Reachability",
    "REACH_REASONS",
    "reachability",
    "plan_fallback",
    # moving obstacles and moving goals (softplan_jax.motion, softplan_jax.tracking)
    "CurveMotion",
    "GoalPath",
    "MovingScenario",
    "curve_motion",
    "goal_path",
    "make_moving_scenario",
    "stack_moving_scenarios",
    "scenario_at",
    "goal_at",
    "speed_bounds",
    "MOVING_SCENARIOS",
    "moving_scenario",
    "random_moving_scenarios",
    "TrackOptions",
    "Track",
    "TrackResult",
    "track",
    "track_batch",
    # gain presets ("paper": the calibration that reproduces the paper; "default")
    "Preset",
    "PRESETS",
    "preset",
    "apply_preset",
    # gains files (tuned gains as JSON, with the obstacle model they were tuned for)
    "save_gains",
    "load_gains",
    "gains_to_dict",
    "gains_from_dict",
    # metrics
    "true_closest",
    "dense_trajectory_clearance",
    "apply_collision_checks",
    # tuning
    "LossWeights",
    "TuningResult",
    "rollout_loss",
    "batch_loss",
    "tune_gains",
    # tuning on the smoothed objective (softplan_jax.smoothing)
    "GainSpace",
    "ScoreWeights",
    "rollout_score",
    "score_batch",
    "SmoothingSample",
    "smoothing_sample",
    "smoothed_objective",
    "ObjectiveEstimate",
    "estimate_objective",
    "TuneResult",
    "tune_smoothed",
    # compiled programs kept on disk
    "enable_compilation_cache",
    "compilation_cache_dir",
    "__version__",
]
