"""Planning: the potential-field planner of paper eq. (9) on one rollout engine. The gains and gain
functions (:mod:`.gains`) and static options (:mod:`.options`); the field, the safe step and one
planner step (:mod:`.step`); the loop that plans to a goal or tracks a moving one and refills a
batch's lanes (:mod:`.engine`, its world :mod:`.world`, its records :mod:`.records`); the pure
:func:`rollout` and its compiled programs :data:`rollout_jit` and :data:`rollout_batch`
(:mod:`.programs`); the entry points :func:`plan` and :func:`plan_batch` (:mod:`.planner`), and
:func:`track` and :func:`track_batch` for moving goals and obstacles (:mod:`.tracking`, its
evasive step :mod:`.evasion`); named calibrations (:mod:`.presets`), post-hoc collision checks
(:mod:`.checks`) and host-side helpers of batch runs (:mod:`.batching`)."""

from ..base.status import STATUS_NAMES, Status, status_name
from .checks import apply_collision_checks
from .gains import GainFunction, Gains, default_gains
from .options import PAPER_STEP, PlanOptions, TrackOptions, make_options, make_track_options
from .planner import PlanResult, plan, plan_batch, result_from_rollout
from .presets import PRESETS, Preset, apply_preset, preset
from .programs import rollout, rollout_batch, rollout_jit
from .records import Rollout
from .step import attraction, planner_step, repulsion
from .tracking import Track, TrackResult, track, track_batch

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
