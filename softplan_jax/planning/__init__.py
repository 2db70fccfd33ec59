"""Planning: the potential-field planner of paper eq. (9) on one rollout engine. The gains and gain
functions (:mod:`._gains`) and static options (:mod:`._options`); the field, the safe step and one
planner step (:mod:`._step`); the loop that plans to a goal or tracks a moving one and refills a
batch's lanes (:mod:`._engine`, its world :mod:`._world`, its records :mod:`._records`); the pure
:func:`rollout` and its compiled programs :data:`rollout_jit` and :data:`rollout_batch`
(:mod:`._programs`); the entry points :func:`plan` and :func:`plan_batch` (:mod:`._planner`), and
:func:`track` and :func:`track_batch` for moving goals and obstacles (:mod:`._tracking`, its
evasive step :mod:`._evasion`); named calibrations (:mod:`._presets`), post-hoc collision checks
(:mod:`._checks`) and host-side helpers of batch runs (:mod:`._batching`)."""

from ..base._status import STATUS_NAMES, Status, status_name
from ._checks import apply_collision_checks
from ._gains import GainFunction, Gains, default_gains
from ._options import PAPER_STEP, PlanOptions, TrackOptions, make_options, make_track_options
from ._planner import PlanResult, plan, plan_batch, result_from_rollout
from ._presets import PRESETS, Preset, apply_preset, preset
from ._programs import rollout, rollout_batch, rollout_jit
from ._records import Rollout
from ._step import attraction, planner_step, repulsion
from ._tracking import Track, TrackResult, track, track_batch

__all__ = [
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
    "TrackOptions",
    "make_track_options",
    "Track",
    "TrackResult",
    "track",
    "track_batch",
    "apply_collision_checks",
    "Preset",
    "PRESETS",
    "preset",
    "apply_preset",
]
