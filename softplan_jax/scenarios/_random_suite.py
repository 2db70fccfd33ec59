"""Seeded suites of random scenarios for batch benchmarking (:func:`random_scenarios`; the
paper evaluates on its three scenes only, section 3): goals drawn on the host in NumPy,
curves placed across the path and redrawn until certainly clear of the start arm and the
goal, and the stack assembled at once, every scene bit for bit what
:func:`~softplan_jax.scenarios.make_scenario` and
:func:`~softplan_jax.scenarios.stack_scenarios` build of it."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._memory import check_memory
from ..base._validation import check_configuration
from ..geometry._curves import PolynomialCurve
from ..geometry._kinematics import backbone_points, tip_position
from ._scenario import Scenario, default_start, make_scenario, stack_scenarios

__all__ = ["random_scenarios"]



def seed_sequence(key_or_seed) -> np.random.SeedSequence:
    """A NumPy SeedSequence from an int seed or a JAX PRNG key (raw or typed)."""
    if isinstance(key_or_seed, (int, np.integer)) and not isinstance(key_or_seed, bool):
        if int(key_or_seed) < 0:
            raise ValueError(f"seed must be >= 0, got {key_or_seed}")
        return np.random.SeedSequence(int(key_or_seed))
    try:
        key = key_or_seed
        if jnp.issubdtype(jnp.asarray(key).dtype, jax.dtypes.prng_key):
            key = jax.random.key_data(key)
        words = np.asarray(key)
    except (TypeError, ValueError):
        words = None
    if words is None or words.dtype.kind not in "ui" or words.size == 0:
        raise ValueError(f"key_or_seed must be an int seed or a JAX PRNG key, got {key_or_seed!r}")
    return np.random.SeedSequence([int(w) for w in words.astype(np.uint64).ravel()])


@functools.cache
def _batched_tips():
    """jit(vmap(tip position)), built once (a new jit per call would recompile)."""
    return package_jit(jax.vmap(tip_position), None)


@functools.cache
def _backbone():
    """jit(backbone points), built once."""
    return package_jit(backbone_points, None, static_argnums=1)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_perpendicular(rng, e):
    """Unit vectors (..., 3) perpendicular to the unit vectors e (..., 3), uniform in angle."""
    helper = np.where(np.abs(e[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    b1 = _unit(np.cross(e, helper))
    b2 = np.cross(e, b1)
    ang = rng.uniform(0.0, 2.0 * np.pi, e.shape[:-1])[..., None]
    return np.cos(ang) * b1 + np.sin(ang) * b2


def _sampled_min_distance(curve_pts, cloud, chunk: int = 128):
    """min over samples of |curve point - cloud point|: curve_pts (M, S, 3), cloud (A, 3) -> (M,)."""
    out = np.empty(curve_pts.shape[0])
    c2 = np.sum(cloud * cloud, axis=-1)
    for a in range(0, curve_pts.shape[0], chunk):
        p = curve_pts[a : a + chunk]
        cross = (p.reshape(-1, 3) @ cloud.T).reshape(*p.shape[:2], -1)
        d2 = np.sum(p * p, axis=-1)[..., None] + c2 - 2.0 * cross
        out[a : a + chunk] = np.sqrt(np.maximum(np.min(d2, axis=(1, 2)), 0.0))
    return out


def _quadratic_points(coeffs, n_samples: int):
    """(M, n_samples, 3) points of quadratics coeffs (M, 3, 3) at u evenly spaced in [0, 1], and the
    largest arc length between consecutive samples (M,) (the speed |k1 + 2 k2 u| is convex in u,
    so its maximum is at an end)."""
    u = np.linspace(0.0, 1.0, n_samples)
    k0, k1, k2 = coeffs[:, None, :, 0], coeffs[:, None, :, 1], coeffs[:, None, :, 2]
    pts = k0 + u[None, :, None] * k1 + (u**2)[None, :, None] * k2
    speed = np.maximum(np.linalg.norm(coeffs[..., 1], axis=-1),
                       np.linalg.norm(coeffs[..., 1] + 2.0 * coeffs[..., 2], axis=-1))
    return pts, speed / (n_samples - 1)


# Candidate curves whose samples are held at once (a multiple of _sampled_min_distance's chunk,
# so the arithmetic groups the same rows as on the whole array: the same bits, in bounded memory).
_CANDIDATE_BLOCK = 8 * 1024


def _clear_of(coeffs, arm_fine, h_fine, arm_coarse, h_coarse, goal, start_clearance, goal_clearance):
    """Whether each quadratic curve (M, 3, 3) is certainly at least start_clearance from the arm
    and goal_clearance from its goal (M, 3). Sampled distances minus the sampling error bound
    (half the sample spacing on each side), coarse first, fine only where the coarse answer is
    undecided; conservative: a curve within the error bound of a threshold is rejected."""
    m = coeffs.shape[0]
    d, hc_c, d_goal, hc_g = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for a in range(0, m, _CANDIDATE_BLOCK):
        block = slice(a, a + _CANDIDATE_BLOCK)
        pts_c, hc_c[block] = _quadratic_points(coeffs[block], 16)
        d[block] = _sampled_min_distance(pts_c, arm_coarse)
        pts_g, hc_g[block] = _quadratic_points(coeffs[block], 64)
        d_goal[block] = np.min(np.linalg.norm(pts_g - goal[block, None, :], axis=-1), axis=1)
    sure = d - 0.5 * (hc_c + h_coarse) >= start_clearance
    undecided = np.nonzero(~sure & (d >= start_clearance))[0]
    if undecided.size:
        pts_f, hc_f = _quadratic_points(coeffs[undecided], 64)
        d_f = _sampled_min_distance(pts_f, arm_fine)
        sure[undecided] = d_f - 0.5 * (hc_f + h_fine) >= start_clearance
    return sure & (d_goal - 0.5 * hc_g >= goal_clearance)


def random_scenarios(
    key_or_seed,
    n: int,
    *,
    obstacles=(1, 8),
    degrees=(1, 2),
    curve_slots: int = 8,
    degree: int = 2,
    theta_max: float = 1.6,
    length: float = 1.0,
    q0=None,
    min_goal_distance: float = 0.5,
    path_fraction=(0.3, 0.7),
    path_offset: float = 0.1,
    curve_length=(0.6, 1.6),
    bend: float = 0.5,
    start_clearance: float = 0.15,
    goal_clearance: float = 0.15,
    max_rounds: int = 200,
    dtype=None,
) -> Scenario:
    """A seeded suite of ``n`` random scenarios, padded to one shape and stacked.

    The generator (host side, NumPy, deterministic for a given seed/key and
    arguments):

    * **Start**: ``q0`` (default :func:`default_start`: the straight vertical
      arm, tip at (0, 0, 3)), the same for every scenario.
    * **Goal** (reachable by construction): the tip of a random configuration
      with every ``L_i = length``, ``theta_i ~ U[0, theta_max]``,
      ``phi_i ~ U[-pi, pi]``; redrawn until it lies at least
      ``min_goal_distance`` from the start tip.
    * **Obstacles**: ``k ~ U{obstacles[0] .. obstacles[1]}`` polynomial curves,
      each of degree ``d ~ U{degrees}``, u in [0, 1], placed to BLOCK the direct
      path: with ``p0`` the start tip, ``g`` the goal and ``e`` the unit vector
      from ``p0`` to ``g``, the curve's midpoint ``c`` lies on the straight
      segment ``p0 -> g`` at a fraction ``t ~ U[path_fraction]``, moved
      sideways (perpendicular to ``e``) by a uniform offset in a disc of
      radius ``path_offset``; the curve runs through ``c`` along a random
      direction ``a`` perpendicular to ``e`` (so it crosses the path), with
      length ``l ~ U[curve_length]``; a degree-2 curve also bends by
      ``beta ~ U[-bend, bend]`` towards a random direction ``b`` perpendicular
      to ``a``::

          F(u) = c + l (u - 1/2) a + beta l (u - 1/2)^2 b,   u in [0, 1].

      An obstacle is redrawn (new t, offset, direction, length, bend) until it
      is certainly at least ``start_clearance`` from the start arm and
      ``goal_clearance`` from the goal: sampled distances (curve at up to 64
      points, arm at 40 points per segment) minus the sampling error bound
      (half the sample spacing on each side) must clear the thresholds, so the
      exact clearances are never smaller. If one obstacle finds no place in
      ``max_rounds`` draws (the goal leaves no room, e.g. a path hugging the
      arm), that scenario's goal and obstacles are drawn anew. Obstacles may
      cross each other.
    * Radii are 0 (arm and obstacles), length limits the defaults of
      :func:`make_scenario`.

    Args:
      key_or_seed: an int seed or a JAX PRNG key.
      n: number of scenarios.
      obstacles: (min, max) obstacle count, 1 <= min <= max <= curve_slots.
      degrees: the curve degrees to draw from (each 1 or 2, <= ``degree``).
      curve_slots, degree: the padded shape (every scenario has the same).
      theta_max, length: the goal configurations' bending range and segment length.
      q0: (n_seg, 3) start, or None for :func:`default_start`.
      min_goal_distance, path_fraction, path_offset, curve_length, bend,
      start_clearance, goal_clearance: see above.
      max_rounds: redraw rounds before giving up (ValueError: the constraints
        are too tight).
      dtype: float dtype of the result; default JAX's default float.

    Returns:
      A batched :class:`Scenario` (leading axis n): q0 (n, n_seg, 3), goal
      (n, 3), curves.coeffs (n, curve_slots, 3, degree + 1), curve_mask
      (n, curve_slots), no point sets; each entry equals ``make_scenario(goal,
      curves, q0, curve_slots=curve_slots, degree=degree)``.
    """
    n = _check_suite_args(n, obstacles, degrees, curve_slots, degree, theta_max, length, path_fraction,
                          curve_length, dict(path_offset=path_offset, bend=bend, min_goal_distance=min_goal_distance,
                                             start_clearance=start_clearance, goal_clearance=goal_clearance))
    lo, hi = (int(v) for v in obstacles)
    degrees = [int(d) for d in degrees]
    dtype = dtype or jnp.result_type(float)
    q0 = check_configuration(default_start() if q0 is None else q0)
    _check_suite_memory(n, curve_slots, degree)
    q0_np = np.asarray(q0, np.float64)
    rng = np.random.default_rng(seed_sequence(key_or_seed))
    arm = _StartArm(q0_np, q0.dtype)
    goals = _GoalDraw(rng, n, q0_np.shape[0], length, theta_max, arm.tip, min_goal_distance, max_rounds)
    goal = np.zeros((n, 3))
    goals.fill(goal, np.arange(n))
    counts = rng.integers(lo, hi + 1, n)
    real = np.arange(curve_slots)[None, :] < counts[:, None]  # (n, slots)
    deg = rng.choice(degrees, (n, curve_slots))
    coeffs = np.zeros((n, curve_slots, 3, int(degree) + 1))
    placement = dict(path_fraction=path_fraction, path_offset=path_offset, curve_length=curve_length, bend=bend,
                     start_clearance=start_clearance, goal_clearance=goal_clearance)
    _place_obstacles(rng, goals, arm, goal, real, deg, coeffs, placement, max_rounds)
    return _assemble(q0_np, goal, real, coeffs, curve_slots, degree, goal_clearance, dtype)


def _check_suite_args(n, obstacles, degrees, curve_slots, degree, theta_max, length, path_fraction, curve_length,
                      nonneg: dict) -> int:
    """random_scenarios' arguments checked (ValueError naming the argument); n as an int."""
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be an int >= 1, got {n!r}")
    lo, hi = (int(v) for v in obstacles)
    if not 1 <= lo <= hi <= int(curve_slots):
        raise ValueError(
            f"need 1 <= obstacles[0] <= obstacles[1] <= curve_slots; "
            f"got {obstacles}, curve_slots {curve_slots}"
        )
    degrees = [int(d) for d in degrees]
    if not degrees or any(d not in (1, 2) or d > int(degree) for d in degrees):
        raise ValueError(
            f"degrees must be a non-empty list of 1 and/or 2, each <= degree = {degree}; got {degrees}"
        )
    if not 0.0 <= path_fraction[0] <= path_fraction[1] <= 1.0:
        raise ValueError(f"path_fraction must satisfy 0 <= a <= b <= 1, got {path_fraction}")
    if not 0.0 < curve_length[0] <= curve_length[1]:
        raise ValueError(f"curve_length must satisfy 0 < a <= b, got {curve_length}")
    for name, v in (("theta_max", theta_max), ("length", length)):
        if not v > 0:
            raise ValueError(f"{name} must be > 0, got {v}")
    for name, v in nonneg.items():
        if not v >= 0:
            raise ValueError(f"{name} must be >= 0, got {v}")
    return int(n)


def _check_suite_memory(n: int, curve_slots: int, degree: int) -> None:
    """ValueError (naming n) when the generator's arrays would not fit in memory: per scene its
    curve slots' coefficients and sampled points and distances (an estimate, bytes)."""
    per_scene = 8 * int(curve_slots) * (3 * (int(degree) + 1) + 16 * 30 + 64 * 8) + 1024
    check_memory(n * per_scene, "n", f"a suite of {n} random scenes with {curve_slots} curve slots",
                 "draw fewer scenes (or plan a large suite in parts: softplan sweep streams one of any size)",
                 on_device=False)


class _StartArm:
    """The start arm as the placement test sees it: its tip ``p0``, its backbone at 40 (fine)
    and 8 (coarse) points per segment with the base, and their sample spacings."""

    def __init__(self, q0_np, dtype):
        q0_j = jnp.asarray(q0_np, dtype)
        self.tip = np.asarray(_batched_tips()(q0_j[None]), np.float64)[0]
        self.fine = np.concatenate([np.zeros((1, 3)), np.asarray(_backbone()(q0_j, 40), np.float64)])
        self.coarse = np.concatenate([np.zeros((1, 3)), np.asarray(_backbone()(q0_j, 8), np.float64)])
        self.h_fine, self.h_coarse = q0_np[:, 0].max() / 40, q0_np[:, 0].max() / 8


class _GoalDraw:
    """Goals: tips of random configurations (every ``L_i = length``, ``theta_i ~ U[0, theta_max]``,
    ``phi_i ~ U[-pi, pi]``) at least ``min_goal_distance`` from the start tip."""

    def __init__(self, rng, n, n_seg, length, theta_max, p0, min_goal_distance, max_rounds):
        self.rng, self.n, self.n_seg, self.length, self.theta_max = rng, n, n_seg, length, theta_max
        self.p0, self.min_goal_distance, self.max_rounds = p0, min_goal_distance, max_rounds

    def fill(self, goal, idx) -> None:
        """Draw the goals of scenarios ``idx`` into ``goal`` (n, 3), in order."""
        todo = np.asarray(idx)
        n, rng = self.n, self.rng
        for _ in range(self.max_rounds):
            # Always n candidates (one compiled shape); the accepted ones fill todo in order.
            qs = np.stack(
                [np.full((n, self.n_seg), float(self.length)), rng.uniform(0.0, self.theta_max, (n, self.n_seg)),
                 rng.uniform(-np.pi, np.pi, (n, self.n_seg))], axis=-1)
            g = np.asarray(_batched_tips()(jnp.asarray(qs)), np.float64)
            g = g[np.linalg.norm(g - self.p0, axis=-1) >= self.min_goal_distance]
            take = min(todo.size, g.shape[0])
            goal[todo[:take]] = g[:take]
            todo = todo[take:]
            if todo.size == 0:
                return
        raise ValueError(f"no goal at least {self.min_goal_distance} from the start tip after {self.max_rounds} "
                         "rounds")


def _place_obstacles(rng, goals: _GoalDraw, arm: _StartArm, goal, real, deg, coeffs, placement: dict,
                     max_rounds: int) -> None:
    """Draw every real slot's curve (``real`` (n, slots), degrees ``deg``) into ``coeffs`` in
    place, redrawing a curve until it is clear of the start arm and of its goal, and a scenario's
    goal and curves where one curve finds no place in ``max_rounds`` draws (random_scenarios)."""
    todo_i, todo_j = np.nonzero(real)
    tries = np.zeros(todo_i.size, int)
    for _ in range(20 * max_rounds):
        # An obstacle that found no place in max_rounds draws: the goal leaves no room
        # (e.g. a path hugging the arm); draw a new goal and all obstacles of that scenario.
        stuck = np.unique(todo_i[tries >= max_rounds])
        if stuck.size:
            goals.fill(goal, stuck)
            coeffs[stuck] = 0.0
            keep = ~np.isin(todo_i, stuck)
            si, sj = np.nonzero(real[stuck])
            todo_i = np.concatenate([todo_i[keep], stuck[si]])
            todo_j = np.concatenate([todo_j[keep], sj])
            tries = np.concatenate([tries[keep], np.zeros(si.size, int)])
        gi = goal[todo_i]
        cand = _candidate_curves(rng, arm.tip, gi, deg[todo_i, todo_j] == 2, placement)
        ok = _clear_of(cand, arm.fine, arm.h_fine, arm.coarse, arm.h_coarse, gi, placement["start_clearance"],
                       placement["goal_clearance"])
        coeffs[todo_i[ok], todo_j[ok], :, :3] = cand[ok]
        todo_i, todo_j, tries = todo_i[~ok], todo_j[~ok], tries[~ok] + 1
        if todo_i.size == 0:
            return
    raise ValueError(
        f"{todo_i.size} obstacles could not be placed; loosen start_clearance, goal_clearance, "
        "path_offset or min_goal_distance"
    )


def _candidate_curves(rng, p0, gi, quadratic, placement: dict):
    """One candidate curve (3, 3) per goal of ``gi`` (m, 3) across the path from the start tip
    ``p0`` to it; ``quadratic`` (m,) says which ones bend (random_scenarios' formula)."""
    m = gi.shape[0]
    ei = _unit(gi - p0)
    t = rng.uniform(placement["path_fraction"][0], placement["path_fraction"][1], m)
    r = placement["path_offset"] * np.sqrt(rng.uniform(0.0, 1.0, m))
    c = p0 + t[:, None] * (gi - p0) + r[:, None] * _random_perpendicular(rng, ei)
    a = _random_perpendicular(rng, ei)
    b = _random_perpendicular(rng, a)
    ell = rng.uniform(placement["curve_length"][0], placement["curve_length"][1], m)
    bend = placement["bend"]
    beta = np.where(quadratic, rng.uniform(-bend, bend, m), 0.0)
    # F(u) = c + l (u - 1/2) a + beta l (u - 1/2)^2 b in the power basis.
    k0 = c - 0.5 * ell[:, None] * a + 0.25 * (beta * ell)[:, None] * b
    k1 = ell[:, None] * a - (beta * ell)[:, None] * b
    k2 = (beta * ell)[:, None] * b
    return np.stack([k0, k1, k2], axis=-1)  # (m, 3, 3)


def _assemble(q0_np, goal, real, coeffs, curve_slots, degree, goal_clearance, dtype) -> Scenario:
    """The stacked Scenario of the drawn goals and curves (what make_scenario and
    stack_scenarios build of each scene, bit for bit)."""
    n = goal.shape[0]
    q0_d = jnp.asarray(q0_np, dtype)

    def one(i):
        curves = [PolynomialCurve(coeffs[i, j], (0.0, 1.0)) for j in np.nonzero(real[i])[0]]
        return make_scenario(goal[i], curves, q0_d, curve_slots=curve_slots, degree=degree)

    if goal_clearance <= 0:
        # Each scene through the public constructor (its checks and warnings: a goal on an
        # obstacle is possible here), then stacked.
        return stack_scenarios([one(i) for i in range(n)])
    # The goals are proven goal_clearance > 0 from every curve, so make_scenario would warn of
    # nothing: the first scene goes through it (its checks), and the others take its fields
    # with their own goal, coefficients and mask, assembled on the host at once.
    first = one(0)
    stacked = jax.tree_util.tree_map(lambda x: np.broadcast_to(np.asarray(x), (n, *np.shape(x))), first)
    curves = stacked.curves
    stacked = stacked._replace(goal=goal, curve_mask=real, curves=curves.tree_unflatten(
        None, [coeffs, *jax.tree_util.tree_leaves(curves)[1:]]))
    return jax.tree_util.tree_map(lambda x, ref: jnp.asarray(np.asarray(x).astype(ref.dtype)), stacked, first)
