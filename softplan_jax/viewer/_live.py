"""The viewer's model, without a browser: the scene on show (static or moving), its planner
reused warm for every new goal (:func:`~softplan_jax.plan` or :func:`~softplan_jax.track`: a
goal of the same shape runs the compiled rollout again), the global fallback, and what the view
draws of a plan at each step: the arm's backbone, the obstacles' poses of a moving scene and the
exact closest points with their clearance (DESIGN.md: the true clearance)."""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._status import Status
from ..geometry._closest import DEFAULT_OPTIONS
from ..geometry._curves import PolynomialCurve
from ..geometry._kinematics import backbone_points
from ..geometry._obstacles import clearance_of, obstacle_samples, radius_and_mask, true_closest
from ..planning._options import make_options, make_track_options
from ..planning._planner import check_gains, result_from_rollout, unreachable_result
from ..planning._programs import prng_key, rollout_jit, strong_gains
from ..planning._tracking import result_from_track
from ..scenarios import Scenario
from ..scenarios._motion import MovingScenario, goal_path, moved_curves, scenario_at
from ..scenarios._scenario import check_scenario, unreachable_reason
from ..search._fallback import RESCUED, rescue
from ..search._tracking import track_fallback

__all__ = ["ARM_SAMPLES", "ShownPlan", "LivePlanner", "shown_plan"]

ARM_SAMPLES = 16  # backbone points per segment drawn (a constant-curvature arc each)
SUCCESS = ("reached", "held")  # the statuses of a plan that did what was asked


@dataclasses.dataclass(frozen=True)
class ShownPlan:
    """A plan as the view shows it (host side, NumPy; T = iterations + 1 steps).

    Attributes:
      q: (T, n, 3) configurations. tip: (T, 3). goal: (T, 3) the goal at each step.
      time: (T,) seconds of a moving scene's steps, or None (a static plan: steps only).
      clearance: (T, m) true clearance to every real obstacle.
      status, iterations, min_clearance, final_error, collided: the outcome.
      planner: "local", "global" (plan_fallback's search) or "search" (track_fallback).
      global_start: the step where the global search's path leaves the local one (or None).
      reason: why the goal was not reached ("" if none given).
      source: where it came from ("plan", "fallback", or a file's path).
    """

    q: np.ndarray
    tip: np.ndarray
    goal: np.ndarray
    time: np.ndarray | None
    clearance: np.ndarray
    status: str
    iterations: int
    min_clearance: float
    final_error: float
    collided: bool
    planner: str = "local"
    global_start: int | None = None
    reason: str = ""
    source: str = "plan"

    @property
    def succeeded(self) -> bool:
        """The goal reached (held to the end, or regained, for a moving goal)."""
        return self.status in SUCCESS


def shown_plan(result, goal=None, source: str = "plan") -> ShownPlan:
    """A :class:`ShownPlan` of a :class:`~softplan_jax.PlanResult` (its ``goal`` (3,) given), a
    :class:`~softplan_jax.planning._tracking.TrackResult` or a trajectory record (the dict of
    :func:`softplan_jax.cli.trajectory.read_trajectory`: format ``softplan-trajectory/1``)."""
    get = result.get if isinstance(result, dict) else lambda k, d=None: getattr(result, k, d)
    q = np.asarray(get("q"), np.float64)
    T = q.shape[0]
    goal = np.asarray(get("goal") if goal is None else goal, np.float64)
    goal = np.broadcast_to(goal, (T, 3)).copy() if goal.shape == (3,) else goal[:T]
    time = get("time")
    gs = get("global_start")
    return ShownPlan(
        q=q, tip=np.asarray(get("tip"), np.float64), goal=goal,
        time=None if time is None else np.asarray(time, np.float64),
        clearance=np.asarray(get("clearance"), np.float64).reshape(T, -1),
        status=str(get("status")), iterations=int(get("iterations")),
        min_clearance=float(get("min_clearance", np.nan)), final_error=float(get("final_error", np.nan)),
        collided=bool(get("collided", False)), planner=str(get("planner", "local") or "local"),
        global_start=None if gs is None or int(gs) < 0 else int(gs), reason=str(get("reason", "") or ""),
        source=source)


@functools.cache
def _backbone_program(n_samples: int):
    """(n, 3) configuration -> (n * n_samples + 1, 3) backbone, the base first."""
    def backbone(q):
        return jnp.concatenate([jnp.zeros((1, 3), q.dtype), backbone_points(q, n_samples)])

    return package_jit(backbone, None)


@functools.cache
def _closest_program(solver):
    """(q, world, t) -> (arm points (m, 3), obstacle points (m, 3), clearance (m,)) of the exact
    closest pairs (paper §2.3) at time t (a static scene: t ignored)."""
    def closest(q, world, t):
        scene = scenario_at(world, t) if isinstance(world, MovingScenario) else world
        pairs = true_closest(q, scene, solver)
        return pairs.arm_point, pairs.obstacle_point, clearance_of(pairs, scene)

    return package_jit(closest)


def _pose_program():
    """(motion, t) -> the rigid poses of every polynomial curve slot at time t: rotations
    (m_c, 3, 3) and translations (m_c, 3), ``x -> R x + p``. Read off :func:`moved_curves`
    applied to the curve whose coefficients are [0 | I] (constant term 0, the three linear terms
    the axes): its moved coefficients are [p | R]."""
    def poses(motion, t):
        m_c = motion.amplitude.shape[0]
        basis = jnp.concatenate([jnp.zeros((m_c, 3, 1), t.dtype), jnp.broadcast_to(jnp.eye(3, dtype=t.dtype),
                                                                                    (m_c, 3, 3))], axis=-1)
        unit = PolynomialCurve.tree_unflatten(None, [basis, jnp.zeros((m_c, 2), t.dtype), jnp.zeros((m_c,), t.dtype)])
        moved = moved_curves(unit, motion, t).coeffs
        return moved[..., 1:], moved[..., 0]

    return package_jit(poses, None)


_POSES = _pose_program()


class LivePlanner:
    """The scene on show and its planner, compiled once and reused warm for every goal.

    The rollout is the command line's (:meth:`~softplan_jax.planning._programs.RolloutProgram.cached`
    of :data:`~softplan_jax.planning._programs.rollout_jit`: the traced program kept on disk, so a
    second session loads it): one program per obstacle model, run again for every goal; the
    results are :func:`~softplan_jax.plan`'s and :func:`~softplan_jax.track`'s.

    Args:
      world: a :class:`~softplan_jax.Scenario` or a :class:`~softplan_jax.moving.MovingScenario`.
      method, n_points, gains, max_steps, seed: as :func:`~softplan_jax.plan` (a moving scene:
        :func:`~softplan_jax.track`, ``max_steps`` its horizon).
      options: further :class:`~softplan_jax.PlanOptions` (or TrackOptions) fields.

    Raises:
      ValueError: a world of another type, a batched one, bad gains, seed or planner options.
    """

    def __init__(self, world, method: str = "curve", n_points: int = 10, gains=None, max_steps: int = 600,
                 seed=0, **options):
        if not isinstance(world, (Scenario, MovingScenario)):
            raise ValueError(f"view a Scenario or a MovingScenario, got {type(world).__name__}")
        scene = world.scene if isinstance(world, MovingScenario) else world
        check_scenario(scene, batched=False)
        self.world, self.scene = world, scene
        self.moving = isinstance(world, MovingScenario)
        dtype = scene.q0.dtype
        self.gains = strong_gains(check_gains(gains, dtype, scene.q0.shape[0], scene.q0), dtype)
        self.max_steps, self.options = int(max_steps), dict(options)
        prng_key(seed)  # a bad seed: a ValueError now
        self.seed = seed
        self._programs = {}  # (method, n_points) -> (options, compiled run)
        self.set_method(method, n_points)
        self.obstacles = obstacle_samples(scene, 256)  # dict(kind, pts (N, 3), radius, slot), real ones only
        _, mask = radius_and_mask(scene)
        self.real_slots = np.nonzero(np.asarray(mask))[0]
        self.curve_slots = int(scene.curves.coeffs.shape[0])  # slots that move in a moving scene
        self._result = None  # the last local plan's PlanResult (what the fallback rescues)

    # --- the planner --------------------------------------------------------------------------

    def set_method(self, method: str, n_points: int = 10) -> None:
        """The obstacle model of the next plans: "curve" (exact closest points) or "points"
        (N points per curve). ValueError for an unknown method or N < 1."""
        make = make_track_options if self.moving else make_options
        self._options = make(method, n_points, **self.options)  # checks everything before it is used
        self.method, self.n_points = method, int(n_points)

    @property
    def goal(self) -> np.ndarray:
        """(3,) the goal of the next plan (a moving scene: at t = 0)."""
        if self.moving:
            return np.asarray(self.world.goal_path.points[0], np.float64)
        return np.asarray(self.scene.goal, np.float64)

    def set_goal(self, goal) -> None:
        """A new goal (3,) for the next plans; same shape and dtype, so the compiled rollout is
        reused. A moving scene's goal becomes fixed in space at ``goal`` (attached to no curve).
        ValueError for a goal that is not 3 finite numbers."""
        g = np.asarray(goal, np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"goal must be 3 finite numbers, got {goal!r}")
        dtype = self.scene.q0.dtype
        if self.moving:
            path = self.world.goal_path
            k = path.times.shape[0]
            new = goal_path(np.asarray(path.times), np.tile(g, (k, 1)), -1, dtype=dtype)
            self.world = self.world._replace(goal_path=new, scene=self.scene._replace(goal=jnp.asarray(g, dtype)))
            self.scene = self.world.scene
        else:
            self.world = self.scene = self.scene._replace(goal=jnp.asarray(g, dtype))

    @property
    def is_compiled(self) -> bool:
        """Whether the current obstacle model's rollout is compiled in this process already."""
        return (self.method, self.n_points) in self._programs

    def compiled(self) -> tuple:
        """``(options, run)``: the current obstacle model's options and compiled rollout
        (compiled, or loaded from the cache, on the first call for each model)."""
        key = (self.method, self.n_points)
        if key not in self._programs:
            run, _ = rollout_jit.cached(self.world, self.gains, self._options, self.max_steps)
            self._programs[key] = (self._options, run)
        return self._programs[key]

    def plan(self) -> ShownPlan:
        """Plan (or track) the current world with the local planner: :func:`~softplan_jax.plan`
        (a goal proven unreachable returns at once, status "unreachable") or
        :func:`~softplan_jax.track`, through the compiled rollout of :meth:`compiled`."""
        options, run = self.compiled()
        if self.moving:
            r = run(self.world, self.gains, self.seed)
            return shown_plan(result_from_track(r, self.world, float(self.gains.dt)))
        reason = unreachable_reason(self.scene)
        if reason:
            self._result = unreachable_result(self.scene, options, reason)
        else:
            self._result = result_from_rollout(run(self.world, self.gains, self.seed), self.scene)
        return shown_plan(self._result, self.goal)

    def can_fall_back(self, shown: ShownPlan) -> bool:
        """Whether the global fallback applies to a plan's ending: a static plan that stalled or
        ran out of steps (plan_fallback), a tracked goal never reached (track_fallback)."""
        if shown.source not in ("plan",):
            return False
        if self.moving:
            return shown.status == "max_steps"
        return self._result is not None and Status.from_label(shown.status) in RESCUED

    def fallback(self) -> ShownPlan:
        """The last plan with the global fallback: reachability and the certified search where
        the local planner stopped short (:func:`~softplan_jax.search._fallback.rescue`, as
        :func:`~softplan_jax.plan_fallback`), or for a moving scene
        :func:`~softplan_jax.track_fallback`; their programs compile on the first call."""
        if self.moving:
            moving = track_fallback(self.world, self.method, self.n_points, self.gains, self.max_steps, self.seed,
                                    **self.options)
            return shown_plan(moving, source="fallback")
        if self._result is None:
            self.plan()
        result = rescue(self.scene, [self._result], self._options, seed=self.seed)[0]
        return shown_plan(result, self.goal, source="fallback")

    # --- what the view draws ------------------------------------------------------------------

    def backbone(self, q) -> np.ndarray:
        """(n * ARM_SAMPLES + 1, 3) backbone of the configuration q (n, 3), the base first;
        segment i spans points i * ARM_SAMPLES .. (i + 1) * ARM_SAMPLES."""
        out = _backbone_program(ARM_SAMPLES)(jnp.asarray(q, self.scene.q0.dtype))
        return np.asarray(out, np.float64)

    def curve_poses(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Rigid poses of the polynomial curve slots at time t: rotations (m_c, 3, 3) and
        translations (m_c, 3), ``x -> R x + p`` (the identity for a static scene)."""
        m_c = self.curve_slots
        if not self.moving or m_c == 0:
            return np.broadcast_to(np.eye(3), (m_c, 3, 3)).copy(), np.zeros((m_c, 3))
        R, p = _POSES(self.world.motion, jnp.asarray(t, self.scene.q0.dtype))
        return np.asarray(R, np.float64), np.asarray(p, np.float64)

    def closest(self, q, t: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The exact closest pairs between the arm at q (n, 3) and every real obstacle at time t:
        ``(arm points (k, 3), obstacle points (k, 3), clearance (k,))`` (paper §2.3; the
        clearance less the arm's and obstacle's radii)."""
        solver = self.options.get("solver", DEFAULT_OPTIONS)
        dtype = self.scene.q0.dtype
        a, o, c = _closest_program(solver)(jnp.asarray(q, dtype), self.world, jnp.asarray(t, dtype))
        s = self.real_slots
        return np.asarray(a, np.float64)[s], np.asarray(o, np.float64)[s], np.asarray(c, np.float64)[s]
