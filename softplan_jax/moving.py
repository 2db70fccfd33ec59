"""Moving goals and moving obstacles, in one namespace (``sp.moving``).

The types and scenes live in :mod:`softplan_jax.scenarios` (:mod:`.scenarios.motion`,
:mod:`.scenarios.moving`), the tracker in :mod:`softplan_jax.planning._tracking` (its evasive step in
:mod:`softplan_jax.planning._evasion`), the tracker with the global search in
:mod:`softplan_jax.search._tracking`.
"""

from .planning._options import TrackOptions, make_track_options
from .planning._tracking import Track, TrackResult, track, track_batch
from .scenarios._json_format import load_moving_scenario, save_moving_scenario
from .scenarios._motion import (
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
from .scenarios._moving import MOVING_SCENARIOS, moving_scenario, random_moving_scenarios
from .search._tracking import track_fallback

__all__ = [
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
    "load_moving_scenario",
    "save_moving_scenario",
    "TrackOptions",
    "make_track_options",
    "Track",
    "TrackResult",
    "track",
    "track_batch",
    "track_fallback",
]
