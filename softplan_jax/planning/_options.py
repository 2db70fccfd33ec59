"""The planner's static options: :class:`PlanOptions` (a planning rollout: stop at the goal)
and :class:`TrackOptions` (a tracking rollout: hold a moving goal to the horizon), their
checks, and the one rule that tells a rollout's mode from its options."""

from __future__ import annotations

from typing import NamedTuple

from ..base._compilation_cache import compiler_options, one_shot_options
from ..base._validation import check_bool, check_int, check_number
from ..geometry._closest import DEFAULT_OPTIONS, SolverOptions
from ..geometry._closest_grid import GridSolverOptions

__all__ = ["PlanOptions", "PAPER_STEP", "check_options", "make_options", "TrackOptions", "check_track_options",
           "make_track_options", "tracks", "plan_options", "PROGRAM_KIND", "rollout_compiler_options"]


class PlanOptions(NamedTuple):
    """Static planner settings (hashable: changing one recompiles).

    Attributes:
      method: "curve" (exact closest points) or "points" (N-point model).
      n_points: N of the N-point model of each curve (method "points").
      points_per_segment: arm samples per segment for the N-point method (paper: 10).
      repulsion: "khatib" or "exponential".
      goal_tolerance: reached when |V_e| < goal_tolerance.
      stall_window: stalled after this many steps without improving the best
        |V_e| by more than stall_tolerance (then an escape starts while any
        is left; else the rollout ends "stalled").
      stall_tolerance: see stall_window. The defaults (30 steps, 0.02) call
        creeping along an obstacle at under ~1e-3 per step a stall: it would
        not reach the goal within the step budget (docs: Collision-free steps).
      check_collisions: compute the true clearance and the between-step
        check inside the rollout (default). False gives a planning-only
        rollout (clearance records NaN, never "collided"), for timing the
        planner alone; :func:`~softplan_jax.planning._checks.apply_collision_checks` adds the checks after.
      contact_tolerance: a clearance at or below this counts as a collision
        (zero-radius curves that cross meet at a single point, which a
        solver reaches only to rounding). The rollout uses
        ``max(contact_tolerance, 10 sqrt(eps))``: 1e-6 in float64, 3.5e-3 in float32.
      solver: the exact closest-point solver: SolverOptions (default) or
        GridSolverOptions (the paper's 2-D solver).
      step: "safe" (default): the clearance-bounded step
        (:func:`~softplan_jax.planning._step.safe_scale`); "plain": the paper's step ``q + dt qdot`` (paper eq. 9).
      safe_fraction: the safe step keeps the motion bound of every step below
        this fraction of ``(clearance - floor)``, in (0, 1]; floor is twice the
        contact tolerance, so the clearance never falls to the contact tolerance.
      escapes: random-walk escapes from stalls allowed per rollout (0: none;
        a stall then ends the rollout, as in the paper).
      escape_steps: steps of one random walk.
      warm_start: in a rollout, carry each (segment, curve) pair's closest
        point from step to step, polish it and certify it the global minimum
        (:mod:`softplan_jax.geometry._warm_start`); only pairs whose certificate fails
        take the full solve. Same closest points as the full solver, fewer
        solves. Applies to the default solver (SolverOptions) only; False:
        the full solve at every step. :func:`planner_step` and the post-hoc
        checks always use the full solve.
      swept_proof: run the between-step search only for the (step, obstacle)
        motions that the motion bound does not prove clear
        (:func:`softplan_jax.geometry._clearance.swept_clear`: the clearance at the start
        of the motion minus :func:`~softplan_jax.geometry._kinematics.motion_bound`
        stays above the contact tolerance); the statuses are the same, the
        search is skipped where it cannot find a collision (see
        ``Rollout.between``). False: search every motion (for
        comparison).
      far_margin: with the warm start and the Khatib repulsion, solve only the (segment,
        curve) pairs whose certified lower bound on the clearance is below ``d0 +
        far_margin`` (:mod:`softplan_jax.geometry._near_pairs`; a moving scene adds the
        field's look-ahead to d0): the others exert no force and keep their bound (the exact
        clearance less the arm's motion, and a moving obstacle's travel, since it was
        solved). The clearances a rollout records above ``d0 + far_margin`` are then such
        lower bounds, and a safe step bounded by one is shorter than with the exact value.
        None: every pair exact at every step (the results of the full solver). The default's
        measurement: docs, "How the planner works inside".
      step_chunk: steps between two checks of "done" by the rollout engine
        (:mod:`softplan_jax.planning._engine`): a rollout stops computing within this many
        steps after it finished. Changes the cost, never the results.
    """

    method: str = "curve"
    n_points: int = 10
    points_per_segment: int = 10
    repulsion: str = "khatib"
    goal_tolerance: float = 1e-2
    stall_window: int = 30
    stall_tolerance: float = 0.02
    check_collisions: bool = True
    contact_tolerance: float = 1e-6
    solver: SolverOptions = DEFAULT_OPTIONS
    step: str = "safe"
    safe_fraction: float = 0.8
    escapes: int = 20
    escape_steps: int = 15
    warm_start: bool = True
    swept_proof: bool = True
    step_chunk: int = 8
    far_margin: float | None = 0.2


# The paper's step (eq. 9, unscaled, no escapes) with the stall test of the paper's tables:
# ``make_options(method, N, **PAPER_STEP)``; the paper tables and the NumPy baseline use it.
PAPER_STEP = {"step": "plain", "escapes": 0, "stall_window": 60, "stall_tolerance": 1e-4}

_INT_OPTIONS = {"n_points": 1, "points_per_segment": 1, "stall_window": 1, "escapes": 0, "escape_steps": 1,
                "step_chunk": 1}  # name -> least value
_CHOICES = {"method": ("curve", "points"), "repulsion": ("khatib", "exponential"), "step": ("safe", "plain")}


def check_options(options: PlanOptions) -> PlanOptions:
    """``options`` when every field has its type and range; a ValueError naming the field
    otherwise (options are static arguments of the compiled rollouts)."""
    for name, least in _INT_OPTIONS.items():
        check_int(getattr(options, name), name, least)
    for name in ("check_collisions", "warm_start", "swept_proof"):
        check_bool(getattr(options, name), name)
    for name, choices in _CHOICES.items():
        v = getattr(options, name)
        if not isinstance(v, str) or v not in choices:
            raise ValueError(f"unknown {name} {v!r}; choose " + " or ".join(repr(c) for c in choices))
    check_number(options.goal_tolerance, "goal_tolerance", 0.0, strict=True)
    check_number(options.stall_tolerance, "stall_tolerance", 0.0)
    check_number(options.contact_tolerance, "contact_tolerance", 0.0)
    if not 0 < check_number(options.safe_fraction, "safe_fraction") <= 1:
        raise ValueError(f"safe_fraction must be in (0, 1], got {options.safe_fraction}")
    if options.far_margin is not None:
        check_number(options.far_margin, "far_margin", 0.0)
    if not isinstance(options.solver, (SolverOptions, GridSolverOptions)):
        raise ValueError(f"solver must be a SolverOptions or a GridSolverOptions, got {options.solver!r}")
    return options


def make_options(method="curve", n_points=10, **kwargs) -> PlanOptions:
    """PlanOptions from keyword arguments, validated."""
    unknown = set(kwargs) - set(PlanOptions._fields)
    if unknown:
        raise ValueError(f"unknown planner option(s) {sorted(unknown)}; known: {list(PlanOptions._fields)}")
    return check_options(PlanOptions(method=method, n_points=n_points, **kwargs))


class TrackOptions(NamedTuple):
    """Static settings of a tracking rollout (hashable: changing one recompiles).

    Attributes:
      plan: the PlanOptions of the step (method, N, safe step, escapes, goal
        tolerance, solver, warm start, ...). ``check_collisions`` must be on.
      hold_tolerance: the goal counts as held while |g(t) - tip| <= this, > 0.
      feedforward: add dg/dt to the attraction (:func:`~softplan_jax.planning._step.tracking_attraction`).
      search_substeps: instants of the between-step search, >= 1.
      anticipation: seconds of look-ahead of the repulsion, >= 0: eq. (9)'s
        field sees obstacle j inflated by ``S_j * anticipation`` (S_j its
        speed bound), so the arm gives way to a fast obstacle before the safe
        step has to stop it. 0: the static field. The safe step always uses
        the true clearance.
      evasion: where no scale of the field's step is proven safe (an obstacle
        could come further in one step than the clearance allows), take the
        evasive step of :mod:`softplan_jax.planning._evasion` (a barrier filter
        on the field's step, certified by conservative advancement in time)
        instead of ending ``too_fast``; it ends ``too_fast`` only where the
        evasive motion is not proven clear either. False: end there.
        Acts only where the rollout would otherwise end ``too_fast``.
      evasion_speed: the actuators' limit for the evasive step [m/s]: the
        arm's motion bound over a step at most ``evasion_speed * dt``, > 0.
      barrier_gain: gamma [1/s] of the barrier condition
        ``dh/dt >= -gamma h`` on the clearance's margin, finite, >= 0.
      evasion_pieces: the most pieces of the evasive step's proof in time, >= 1.
    """

    plan: PlanOptions = PlanOptions()
    hold_tolerance: float = 0.02
    feedforward: bool = True
    search_substeps: int = 8
    anticipation: float = 0.0
    evasion: bool = True
    evasion_speed: float = 1.0
    barrier_gain: float = 5.0
    evasion_pieces: int = 16


def check_track_options(options: TrackOptions) -> TrackOptions:
    """``options`` when every field has its type and range; a ValueError naming the field otherwise."""
    if not options.plan.check_collisions:
        raise ValueError("tracking needs check_collisions=True (the status depends on the clearance)")
    check_number(options.hold_tolerance, "hold_tolerance", 0.0, strict=True)
    check_int(options.search_substeps, "search_substeps", 1)
    check_number(options.anticipation, "anticipation", 0.0)
    check_bool(options.evasion, "evasion")
    check_number(options.evasion_speed, "evasion_speed", 0.0, strict=True)
    check_number(options.barrier_gain, "barrier_gain", 0.0)
    check_int(options.evasion_pieces, "evasion_pieces", 1)
    return options


def make_track_options(method="curve", n_points=10, *, hold_tolerance=0.02, feedforward=True, search_substeps=8,
                       anticipation=0.0, evasion=True, evasion_speed=1.0, barrier_gain=5.0, evasion_pieces=16,
                       **plan_options) -> TrackOptions:
    """TrackOptions from keyword arguments (PlanOptions fields go to ``plan``), validated."""
    for name, v in (("hold_tolerance", hold_tolerance), ("anticipation", anticipation),
                    ("evasion_speed", evasion_speed), ("barrier_gain", barrier_gain)):
        check_number(v, name)
    return check_track_options(TrackOptions(make_options(method, n_points, **plan_options), float(hold_tolerance),
                                            bool(feedforward), int(search_substeps), float(anticipation),
                                            evasion, float(evasion_speed), float(barrier_gain), evasion_pieces))


def tracks(options) -> bool:
    """The mode of a rollout: True for TrackOptions (hold the goal to the horizon), False for
    PlanOptions (stop at the goal or at a stall)."""
    return isinstance(options, TrackOptions)


def plan_options(options) -> PlanOptions:
    """The PlanOptions of a rollout's options (PlanOptions, or TrackOptions' ``plan``)."""
    return options.plan if tracks(options) else options


# The kind of XLA program of each obstacle model (base.compilation_cache.compiler_options).
PROGRAM_KIND = {"curve": "exact", "points": "samples"}


def rollout_compiler_options(method: str = "curve", one_shot: bool = False) -> dict | None:
    """The XLA options the rollouts of the planner's ``method`` ("curve" or "points") compile
    with (:func:`~softplan_jax.base._compilation_cache.compiler_options` of its
    :data:`PROGRAM_KIND`; ``one_shot``: a rollout compiled to run once,
    :func:`~softplan_jax.base._compilation_cache.one_shot_options`). ValueError for another
    method."""
    if method not in PROGRAM_KIND:
        raise ValueError(f"method must be 'curve' or 'points'; got {method!r}")
    return (one_shot_options if one_shot else compiler_options)(PROGRAM_KIND[method])
