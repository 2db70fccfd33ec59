"""softplan_jax: a JAX-accelerated, differentiable path planner for soft
continuum arms around curve-like obstacles (branches, pipes, wires)."""

from importlib.metadata import PackageNotFoundError, version

from .closest import ClosestPoint as ClosestPoint
from .closest import SolverOptions as SolverOptions
from .closest import closest_point as closest_point
from .closest import closest_point_to_points as closest_point_to_points
from .closest import point_distance as point_distance
from .curves import ParametricCurve as ParametricCurve
from .curves import PolynomialCurve as PolynomialCurve
from .curves import curve_points as curve_points
from .curves import fit_polynomial_curve as fit_polynomial_curve
from .curves import line_segment as line_segment
from .curves import stack_curves as stack_curves
from .fitting import CloudFit as CloudFit
from .fitting import CurveFit as CurveFit
from .fitting import FitWarning as FitWarning
from .fitting import curve_distance as curve_distance
from .fitting import fit_curve as fit_curve
from .fitting import fit_curves as fit_curves
from .fitting import load_cloud as load_cloud
from .fitting import save_fit_scenario as save_fit_scenario
from .kinematics import backbone_points as backbone_points
from .kinematics import motion_bound as motion_bound
from .kinematics import point_jacobian as point_jacobian
from .kinematics import segment_frames as segment_frames
from .kinematics import segment_point as segment_point
from .kinematics import segment_transform as segment_transform
from .kinematics import tip_jacobian as tip_jacobian
from .kinematics import tip_position as tip_position
from .metrics import dense_trajectory_clearance as dense_trajectory_clearance
from .metrics import true_closest as true_closest
from .planner import PAPER_STEP as PAPER_STEP
from .planner import STATUS_NAMES as STATUS_NAMES
from .planner import Gains as Gains
from .planner import PlanOptions as PlanOptions
from .planner import PlanResult as PlanResult
from .planner import Rollout as Rollout
from .planner import Status as Status
from .planner import attraction as attraction
from .planner import default_gains as default_gains
from .planner import plan as plan
from .planner import plan_batch as plan_batch
from .planner import planner_step as planner_step
from .planner import repulsion as repulsion
from .planner import rollout as rollout
from .planner import stack_scenarios as stack_scenarios
from .presets import apply_preset as apply_preset
from .scenarios import Scenario as Scenario
from .scenarios import default_start as default_start
from .scenarios import load_scenario as load_scenario
from .scenarios import make_scenario as make_scenario
from .scenarios import paper_scenario as paper_scenario
from .scenarios import random_scenarios as random_scenarios
from .scenarios import save_scenario as save_scenario
from .scenarios import scenario_warnings as scenario_warnings

try:
    __version__ = version("softplan_jax")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
