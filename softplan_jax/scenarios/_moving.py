"""Moving scenes: the presets people would try (:func:`moving_scenario`: ``tree_sway``,
``tree_fruit``, ``wire_sweep``, on the paper's arm) and a seeded random suite
(:func:`random_moving_scenarios`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..geometry._curves import line_segment
from ._motion import CurveMotion, GoalPath, MovingScenario, curve_motion, goal_path, make_moving_scenario
from ._paper import paper_scenario
from ._random_suite import random_scenarios, seed_sequence
from ._scenario import default_start, make_scenario

__all__ = ["MOVING_SCENARIOS", "MOVING_OPTIONS", "moving_scenario", "random_moving_scenarios"]

MOVING_SCENARIOS = {
    "tree_sway": "the paper's tree, branches swaying (0.06 rad at 1.5 rad/s); the paper's goal",
    "tree_fruit": "the swaying tree; the goal hangs 0.12 below branch 2 and moves with it",
    "wire_sweep": "a wire moving up and down (1.2 +- 0.8 m at 0.3 rad/s) through the arm's pose at the goal",
}

# The tracking options each preset is played with by `softplan run` (TrackOptions fields).
MOVING_OPTIONS = {"tree_sway": {}, "tree_fruit": {}, "wire_sweep": {"anticipation": 0.5}}


def _tree_motions(coeffs: np.ndarray, amplitude: float, omega: float, dtype):
    motions = []
    for k in range(4):
        along = coeffs[k][:, 1].copy()
        along[2] = 0.0
        along /= np.linalg.norm(along)
        motions.append(curve_motion(pivot=coeffs[k][:, 0], axis=(-along[1], along[0], 0.0), amplitude=amplitude,
                                    omega=omega, phase=1.3 * k, dtype=dtype))
    return motions + [None]


def moving_scenario(name: str, *, dtype=None) -> MovingScenario:
    """One of the :data:`MOVING_SCENARIOS` presets, on the paper's arm (3 segments of length 1,
    the default start).

    * ``"tree_sway"``: the paper's tree (Table 4's four legible branches and the trunk,
      DESIGN.md); each branch sways about its base on the trunk, about the horizontal axis
      across it (bobbing up and down), amplitude 0.06 rad at 1.5 rad/s, phases 1.3 rad
      apart; the trunk stands still; the goal is the paper's, fixed.
    * ``"tree_fruit"``: the same swaying tree; the goal is a fruit hanging 0.12 below
      branch 2 at u = 1 and moving with the branch (:class:`GoalPath` ``attach``).
    * ``"wire_sweep"``: a horizontal wire across the goal's side of the workspace (x = 0.9,
      y from 0.4 to 2.0) moves up and down through the arm's pose at the goal (1.2, 0.9,
      1.4): height 1.2 + 0.8 sin(0.3 t). The arm gives way and comes back; it is played with
      a look-ahead of 0.5 s (:data:`MOVING_OPTIONS`; without it the safe step stops it
      ``too_fast``).
    """
    if name not in MOVING_SCENARIOS:
        raise ValueError(f"unknown moving scenario {name!r}; choose one of {sorted(MOVING_SCENARIOS)}")
    dtype = dtype or jnp.result_type(float)
    if name in ("tree_sway", "tree_fruit"):
        tree = paper_scenario("tree", dtype=dtype)
        coeffs = np.asarray(tree.curves.coeffs, np.float64)
        motions = _tree_motions(coeffs, 0.06, 1.5, dtype)
        goal = None
        if name == "tree_fruit":
            on_branch = coeffs[1] @ np.ones(coeffs.shape[-1])  # branch 2 at u = 1
            goal = goal_path([0.0], (on_branch + [0.0, 0.0, -0.12])[None], attach=1, dtype=dtype)
        return make_moving_scenario(tree, motions, goal)
    wire = line_segment([0.9, 0.4, 1.2], [0.9, 2.0, 1.2])
    scene = make_scenario(jnp.asarray([1.2, 0.9, 1.4], dtype), [wire], default_start(dtype=dtype))
    return make_moving_scenario(scene, [curve_motion(shift=(0.0, 0.0, 0.8), omega=0.3, dtype=dtype)])


def random_moving_scenarios(key_or_seed, n: int, *, amplitude: float = 0.08, shift: float = 0.06,
                            omega=(0.5, 1.5), attach_fraction: float = 0.5, dtype=None,
                            **suite) -> MovingScenario:
    """A seeded suite of ``n`` random moving scenes, stacked (one compiled shape).

    The scenes at rest are :func:`~softplan_jax.scenarios.random_scenarios`
    (``key_or_seed`` and ``**suite``: its arguments); every curve then sways
    about its start point F_o(0) about a random unit axis, amplitude
    ``~ U[0, amplitude]`` rad, and translates by ``sin(omega t + phase)`` times
    a random vector of length ``~ U[0, shift]``, ``omega ~ U[omega]``, phase
    ``~ U[-pi, pi]``. With probability ``attach_fraction`` the goal moves with
    the nearest curve (at rest), else it is fixed.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    for label, v in (("amplitude", amplitude), ("shift", shift)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{label} must be a finite number >= 0, got {v}")
    lo, hi = (float(v) for v in omega)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi):
        raise ValueError(f"omega must be a range 0 <= lo <= hi, got {omega}")
    if not 0.0 <= float(attach_fraction) <= 1.0:
        raise ValueError(f"attach_fraction must be in [0, 1], got {attach_fraction}")
    dtype = dtype or jnp.result_type(float)
    scenes = random_scenarios(key_or_seed, n, dtype=dtype, **suite)
    rng = np.random.default_rng(seed_sequence(key_or_seed).spawn(1)[0])  # apart from the scenes' stream
    coeffs = np.asarray(scenes.curves.coeffs, np.float64)  # (n, m_c, 3, K)
    mask = np.asarray(scenes.curve_mask)
    goals = np.asarray(scenes.goal, np.float64)
    shape = mask.shape

    def unit(size):
        v = rng.normal(size=(*size, 3))
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    real = mask.astype(float)
    motion = CurveMotion(
        pivot=coeffs[..., 0] * real[..., None],
        axis=unit(shape) * real[..., None],
        amplitude=rng.uniform(0.0, amplitude, shape) * real,
        omega=rng.uniform(lo, hi, shape) * real,
        phase=rng.uniform(-np.pi, np.pi, shape) * real,
        shift=unit(shape) * rng.uniform(0.0, shift, shape)[..., None] * real[..., None],
        velocity=np.zeros((*shape, 3)),
    )
    # The nearest real curve (at rest) carries the goal in a share of the scenes.
    u = np.linspace(0.0, 1.0, 65)
    pts = np.einsum("bjdk,uk->bjud", coeffs, u[:, None] ** np.arange(coeffs.shape[-1]))
    dist = np.where(mask, np.linalg.norm(pts - goals[:, None, None], axis=-1).min(axis=-1), np.inf)
    attach = np.where(rng.uniform(size=n) < attach_fraction, np.argmin(dist, axis=1), -1)
    path = GoalPath(times=np.zeros((n, 1)), points=goals[:, None], attach=attach.astype(np.int32))
    to_jax = lambda x: jnp.asarray(x, jnp.int32 if x.dtype.kind in "iu" else dtype)  # noqa: E731
    return MovingScenario(scenes, CurveMotion(*map(to_jax, motion)), GoalPath(*map(to_jax, path)))
