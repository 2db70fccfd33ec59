"""Planning: the potential-field planner of paper eq. (9) on one rollout engine.

* :mod:`.gains` -- the gains of eq. (9) and the gain functions beyond the paper;
* :mod:`.step` -- the field of eq. (9), the safe step, one planner step;
* :mod:`.engine` -- the rollout loop (plan to the goal or track a moving one),
  paid by the step, and the batch loop that refills its lanes;
* :mod:`.programs` -- :func:`rollout` (pure) and its compiled programs,
  :data:`rollout_jit` (one scene) and :data:`rollout_batch` (a batch);
* :mod:`.planner` -- the entry points :func:`plan` and :func:`plan_batch`
  and their results;
* :mod:`.tracking` -- :func:`track` and :func:`track_batch` for moving goals
  and obstacles; :mod:`.evasion` -- the evasive step among fast obstacles;
* :mod:`.presets` -- named calibrations (``"paper"``, ``"default"``);
* :mod:`.batching` -- host-side helpers of batch runs.
"""

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
