"""The Gaussian-smoothed rollout objective of gain tuning and its score-function gradient: a
gradient that predicts finite steps, where the pathwise gradient of a chaotic rollout does not
(docs: Tuning the gains). The parameters ``theta`` (a :class:`GainSpace`) are perturbed per
rollout, ``J(theta) = E_scene E_{eps ~ N(0, I)} [L(decode(theta + sigma eps), scene)]`` with ``L``
the score :func:`rollout_score`, and :func:`smoothed_objective` estimates J from one sample of
antithetic pairs (:func:`smoothing_sample`) with importance weights,
``1/2N sum_k L_k N(x_k; theta, diag(sigma^2)) / N(x_k; theta0, diag(sigma^2))``: unbiased near
theta0 and smooth in theta, so ``jax.grad`` of it is exact for it, and at theta0 that gradient is
the antithetic estimate ``1/N sum_n (L(theta0 + sigma eps_n) - L(theta0 - sigma eps_n)) eps_n /
(2 sigma)`` (Williams 1992; Salimans et al. 2017; Mohamed et al. 2020, section 5)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..planning._options import PlanOptions, make_options, rollout_compiler_options
from ..planning._programs import rollout
from ..scenarios import Scenario
from ._space import GainSpace

__all__ = [
    "ScoreWeights",
    "check_weights",
    "rollout_score",
    "score_batch",
    "scores_jit",
    "check_sigma",
    "SmoothingSample",
    "smoothing_sample",
    "smoothed_objective",
    "ObjectiveEstimate",
    "estimate_objective",
]

class ScoreWeights(NamedTuple):
    """Weights of :func:`rollout_score` (floats; the user's choice of what a plan costs).

    Attributes:
      progress: weight of the area under the tip-error curve, normalised by the
        start's error (1: the tip never moved closer; near 0: reached at once).
      unreached: added when the rollout did not reach the goal.
      collided: added (on top of ``unreached``) when it collided.
      steps: weight of the time to a plan, in units of the rollout's length
        ``max_steps``: the steps taken / max_steps for a rollout that reached its
        goal; for one that did not, 1 + ``fallback`` (it ran to its end, then the
        fallback plans).
      fallback: the fallback's time (:func:`softplan_jax.plan_fallback`), in
        rollouts of ``max_steps`` steps, charged by ``steps`` to a rollout that
        does not reach (docs: Tuning the gains, "What a plan costs").
      path_length: weight of the tip's path length, normalised by the start's
        tip error (1: a straight line to the goal).
    """

    progress: float = 1.0
    unreached: float = 1.0
    collided: float = 2.0
    steps: float = 0.0
    fallback: float = 0.0
    path_length: float = 0.0


def check_weights(weights) -> ScoreWeights:
    """``weights`` if it is a :class:`ScoreWeights` of finite numbers >= 0, else a ValueError."""
    if not isinstance(weights, ScoreWeights):
        raise ValueError(f"weights must be a ScoreWeights, got {type(weights).__name__}")
    for k, v in weights._asdict().items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                or not math.isfinite(v) or v < 0:
            raise ValueError(f"ScoreWeights.{k} must be a finite number >= 0, got {v!r}")
    return weights


def rollout_score(r, scenario: Scenario, weights: ScoreWeights = ScoreWeights()):
    """The per-rollout score L of the smoothed objective (lower is better): a
    failure indicator plus a progress term and, with their weights, the time to a
    plan (the fallback's included) and the tip's path length. Bounded (at most
    about ``progress + unreached + collided + steps (1 + fallback)`` plus the path
    term for an arm that never moves away from its goal by more than its start
    error). ``r``: one (unbatched) Rollout of ``max_steps + 1`` records."""
    err = jnp.linalg.norm(scenario.goal - r.tip, axis=-1)
    start = jnp.maximum(err[0], jnp.finfo(err.dtype).tiny)
    progress = jnp.mean(err) / start
    unreached = (~r.reached).astype(err.dtype)
    score = (weights.progress * progress + weights.unreached * unreached
             + weights.collided * r.collided.astype(err.dtype))
    # Terms with weight 0 stay out of the program (the default score, bit for bit).
    if weights.steps:
        max_steps = r.tip.shape[0] - 1
        taken = r.iterations.astype(err.dtype) / max_steps
        score = score + weights.steps * jnp.where(r.reached, taken, 1.0 + weights.fallback)
    if weights.path_length:
        travelled = jnp.sum(jnp.linalg.norm(jnp.diff(r.tip, axis=0), axis=-1))
        score = score + weights.path_length * travelled / start
    return score


def _scores(thetas, space: GainSpace, base, scenarios: Scenario, keys, options: PlanOptions, max_steps: int,
            weights: ScoreWeights):
    """L of rollout b: scene ``scenarios[b]`` with gains ``decode(thetas[b])`` and escape
    key ``keys[b]``; one vmapped batch."""

    def one(theta, sc, key):
        r = rollout(sc, space.decode(theta, base), options, max_steps, key)
        return rollout_score(r, sc, weights), r.reached, r.collided

    return jax.vmap(one)(thetas, scenarios, keys)


_SCORES_JIT: dict = {}


def score_batch(thetas, space: GainSpace, base, scenarios: Scenario, keys, options: PlanOptions, max_steps: int,
                weights: ScoreWeights = ScoreWeights()):
    """:func:`rollout_score` of a batch of rollouts, one per row: scene ``scenarios[b]`` (a
    batched Scenario) with gains ``space.decode(thetas[b], base)`` and escape key ``keys[b]``
    (one vmapped, jitted program per shape; the one :func:`smoothing_sample` runs).

    Returns:
      ``(scores (B,), reached (B,) bool, collided (B,) bool)``.
    """
    return scores_jit(options.method)(thetas, space, base, scenarios, keys, options, int(max_steps), weights)


def scores_jit(method: str):
    """``jax.jit(_scores)`` with the package's XLA options for the method (as the rollouts); the tuner
    reads its cache size to tell compile time from run time."""
    if method not in _SCORES_JIT:
        _SCORES_JIT[method] = jax.jit(_scores, static_argnames=("space", "options", "max_steps", "weights"),
                                      compiler_options=rollout_compiler_options(method))
    return _SCORES_JIT[method]


def check_sigma(sigma, size: int) -> np.ndarray:
    """``sigma`` as a float64 array: shape () (one scale for every coordinate of theta)
    or ``(size,)`` (one per coordinate), finite and > 0; else a ValueError."""
    try:
        s = np.asarray(sigma)
        bad_type = s.dtype.kind not in "iuf"  # bools, strings, objects
        s = s.astype(np.float64)
    except (TypeError, ValueError):
        bad_type = True
    if bad_type or s.ndim > 1 or (s.ndim == 1 and s.shape != (size,)):
        raise ValueError(f"sigma must be a number or {size} numbers (one per coordinate of theta), got {sigma!r}")
    if not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(f"sigma must be finite and > 0, got {sigma!r}")
    return s


def _draw(key, theta, scenarios: Scenario, pairs: int):
    """The scenes, perturbations and escape keys of one sample: ``pairs`` scenes drawn
    from the suite without replacement (the suite cycled in fresh permutations if it is
    smaller), one eps per scene, the scene and its escape key shared by the pair's two signs."""
    k_scene, k_eps, k_esc = jax.random.split(key, 3)
    n_suite = scenarios.q0.shape[0]
    reps = math.ceil(pairs / n_suite)
    order = jnp.concatenate([jax.random.permutation(jax.random.fold_in(k_scene, i), n_suite) for i in range(reps)])
    idx = order[:pairs]
    eps = jax.random.normal(k_eps, (pairs, theta.shape[0]), theta.dtype)
    esc = jax.random.split(k_esc, pairs)
    return idx, eps, esc


class SmoothingSample(NamedTuple):
    """One sample of rollouts around ``theta0`` (see :func:`smoothing_sample`); a pytree.

    Attributes:
      theta0: (P,) the centre of the sample.
      x: (2N, P) the perturbed parameters ``theta0 + sigma eps_n`` then
        ``theta0 - sigma eps_n`` (antithetic pairs: row n and row N + n).
      scores: (2N,) :func:`rollout_score` of each rollout.
      reached, collided: (2N,) bool outcomes of each rollout.
      sigma: () the smoothing scale, or (P,) one per coordinate of theta.
      scenes: (N,) the suite's scene of each pair (its two rollouts).
    """

    theta0: jax.Array
    x: jax.Array
    scores: jax.Array
    reached: jax.Array
    collided: jax.Array
    sigma: jax.Array
    scenes: jax.Array


def smoothing_sample(theta0, space: GainSpace, base, scenarios: Scenario, key, *, pairs: int = 32,
                     sigma: float | Sequence[float] = 0.2, method: str = "curve", n_points: int = 10,
                     max_steps: int = 100, weights: ScoreWeights = ScoreWeights(),
                     options: PlanOptions | None = None, eps=None, scene_index=None) -> SmoothingSample:
    """Roll out ``2 * pairs`` perturbed gain settings around ``theta0`` (one vmapped batch).

    Args:
      theta0: (P,) parameters of ``space`` (``space.encode(gains)``).
      space: the :class:`GainSpace`.
      base: the gains that theta modifies (``space.base(gains, n)``; fields not tuned
        are taken from it).
      scenarios: a batched Scenario, the training suite.
      key: PRNG key of the draw (scenes, perturbations, escapes): the same key gives
        the same draw (common random numbers: compare centres with one key).
      pairs: N, antithetic pairs (2N rollouts): scene n and its escape key are shared
        by ``theta0 + sigma eps_n`` and ``theta0 - sigma eps_n``.
      sigma: smoothing scale, in theta's units (log-gains; log-multipliers): one number,
        or P numbers, one per coordinate (the perturbations are ``sigma * eps``,
        ``eps ~ N(0, I)``: the smoothing distribution is ``N(theta0, diag(sigma^2))``).
      method, n_points, max_steps: the planner (``make_options(method, n_points)``: the
        library's default planner, with its collision checks) and the rollout length.
      weights: :class:`ScoreWeights`.
      options: PlanOptions, overriding method / n_points.
      eps: (N, P) perturbations to use instead of the key's (scenes and escape keys
        still come from the key).
      scene_index: (N,) ints, the suite's scenes to use instead of the key's draw
        (scene n for pair n; perturbations and escape keys still come from the key).

    Returns:
      :class:`SmoothingSample`.
    """
    opts = options if options is not None else make_options(method, n_points)
    dtype = scenarios.q0.dtype
    theta0 = jnp.asarray(theta0, dtype)
    if theta0.shape != (space.size,):
        raise ValueError(f"theta must have shape ({space.size},) for {space}, got {theta0.shape}")
    if not np.all(np.isfinite(np.asarray(theta0))):
        raise ValueError(f"theta must be finite, got {np.asarray(theta0)}")
    sigma = check_sigma(sigma, space.size)
    if isinstance(pairs, bool) or not isinstance(pairs, (int, np.integer)) or pairs < 2:
        raise ValueError(f"pairs must be an int >= 2 (standard errors need two pairs), got {pairs!r}")
    if scenarios.q0.ndim != 3 or scenarios.q0.shape[0] < 1:
        raise ValueError("scenarios must be a non-empty batched Scenario (random_scenarios, stack_scenarios)")
    idx, draw_eps, esc = _draw(key, theta0, scenarios, int(pairs))
    eps = draw_eps if eps is None else jnp.asarray(eps, dtype)
    if scene_index is not None:
        idx = np.asarray(scene_index)
        if idx.shape != (int(pairs),) or idx.dtype.kind not in "iu":
            raise ValueError(f"scene_index must be {pairs} ints, got {idx.dtype} of shape {idx.shape}")
        if idx.min() < 0 or idx.max() >= scenarios.q0.shape[0]:
            raise ValueError(f"scene_index must index the suite's {scenarios.q0.shape[0]} scenes, got "
                             f"{idx.min()}..{idx.max()}")
        idx = jnp.asarray(idx)
    if eps.shape != (int(pairs), space.size):
        raise ValueError(f"eps must have shape ({pairs}, {space.size}), got {eps.shape}")
    sigma = jnp.asarray(sigma, dtype)
    x = jnp.concatenate([theta0 + sigma * eps, theta0 - sigma * eps])
    scenes = jax.tree_util.tree_map(lambda a: jnp.concatenate([a[idx], a[idx]]), scenarios)
    keys = jnp.concatenate([esc, esc])
    L, reached, collided = scores_jit(opts.method)(x, space, base, scenes, keys, opts, int(max_steps), weights)
    return SmoothingSample(theta0, x, L, reached, collided, sigma, idx)


def smoothed_objective(theta, sample: SmoothingSample):
    """The smoothed objective J at ``theta``, estimated from one sample (pure, jittable,
    differentiable: THE tuning objective; see the module docstring).

    Importance-weighted (likelihood-ratio) estimate with the sample's fixed rollouts::

        J(theta) ~ 1/(2N) sum_k L_k N(x_k; theta, diag(sigma^2)) / N(x_k; theta0, diag(sigma^2))

    unbiased for the Gaussian-smoothed objective at every theta (the weights are the
    density ratio), smooth in theta, equal to the sample mean of the scores at
    ``theta0``; its gradient there (``jax.grad``) is the antithetic score-function
    estimate ``1/N sum_n (L(theta0 + sigma eps_n) - L(theta0 - sigma eps_n)) eps_n / (2 sigma)``
    (per coordinate, with one sigma per coordinate).
    Far from ``theta0`` (beyond about sigma) the weights degenerate: draw a new sample.

    Args:
      theta: (P,) parameters.
      sample: a :class:`SmoothingSample`.

    Returns:
      () the estimate of J(theta).
    """
    s2 = sample.sigma**2
    if jnp.ndim(sample.sigma) == 0:
        log_w = (jnp.sum((sample.x - sample.theta0) ** 2, -1) - jnp.sum((sample.x - theta) ** 2, -1)) / (2 * s2)
    else:  # one scale per coordinate: N(x; theta, diag(sigma^2))
        log_w = jnp.sum(((sample.x - sample.theta0) ** 2 - (sample.x - theta) ** 2) / (2 * s2), -1)
    return jnp.mean(sample.scores * jnp.exp(log_w))


class ObjectiveEstimate(NamedTuple):
    """The objective and its gradient at a sample's centre, with standard errors (NumPy).

    Attributes:
      value: the estimate of J(theta0) (mean of the 2N scores).
      grad: (P,) ``jax.grad(smoothed_objective)`` at theta0 (the antithetic
        score-function estimate).
      value_se, grad_se: standard errors over the N antithetic pairs.
      success: fraction of the 2N rollouts that reached without collision.
      collided: fraction that collided.
      rollouts: 2N.
    """

    value: float
    grad: np.ndarray
    value_se: float
    grad_se: np.ndarray
    success: float
    collided: float
    rollouts: int


_value_and_grad = package_jit(jax.value_and_grad(smoothed_objective), None)


def estimate_objective(sample: SmoothingSample) -> ObjectiveEstimate:
    """:class:`ObjectiveEstimate` of a sample: J and its gradient at the sample's centre."""
    value, grad = _value_and_grad(sample.theta0, sample)
    L = np.asarray(sample.scores, np.float64)
    n = L.shape[0] // 2
    sigma = np.asarray(sample.sigma, np.float64)  # () or (P,)
    e = (np.asarray(sample.x[:n], np.float64) - np.asarray(sample.theta0, np.float64)) / sigma
    per_value = 0.5 * (L[:n] + L[n:])
    per_grad = ((L[:n] - L[n:]) / 2.0)[:, None] * (e / sigma)
    ok = np.asarray(sample.reached) & ~np.asarray(sample.collided)
    return ObjectiveEstimate(
        value=float(value),
        grad=np.asarray(grad, np.float64),
        value_se=float(per_value.std(ddof=1) / math.sqrt(n)),
        grad_se=per_grad.std(0, ddof=1) / math.sqrt(n),
        success=float(ok.mean()),
        collided=float(np.asarray(sample.collided).mean()),
        rollouts=2 * n,
    )
