"""Tuning the gains by stochastic gradient descent on the smoothed objective of
:mod:`softplan_jax.tuning._objective`: :func:`tune_smoothed` runs optax on its antithetic
score-function gradients (SGD with momentum, a decaying step and iterate averaging by default;
optionally along the natural gradient ``sigma^2 grad J``), a fresh draw of scenes and
perturbations per update, with progress, the training history and the rollout budget accounted
for. Its defaults are the recommended recipe (docs: Tuning the gains, with the recipe's choices
and its comparison with a grid, random search, Optuna's TPE and CMA-ES)."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..base._validation import check_bool, check_int, check_number
from ..planning._gains import GOAL_GAINS, Gains, default_gains
from ..planning._options import make_options
from ..planning._planner import check_gains
from ..scenarios import Scenario
from ._objective import ScoreWeights, check_sigma, check_weights, estimate_objective, scores_jit, smoothing_sample
from ._space import GainSpace

__all__ = ["TuneResult", "tune_smoothed", "RECIPE_SPACE", "RECIPE_WEIGHTS", "recipe_start", "recipe_sigma"]

RECIPE_SPACE = GainSpace(("d0", "dt"), stable_dt=True, goal_knots=6)
"""The recommended space, :func:`tune_smoothed`'s default: log d0, dt as the logit of its
fraction of the Euler bound, and a 6-knot goal-distance profile of k_att, v_max, eta and d0
(26 parameters; zeros: the constant gains)."""

RECIPE_WEIGHTS = ScoreWeights(steps=1.0)
"""The recommended objective, :func:`tune_smoothed`'s default: the failure and progress terms
of :class:`ScoreWeights`, plus the time to a plan (steps / max_steps where the goal is
reached, 1 otherwise). ``fallback`` stays 0: ``unreached`` already charges a failure, and
the fallback's time made the score's differences, and with them the natural gradient's
steps, larger and the tuned function worse (docs: Tuning the gains, "What a plan costs").
With larger weights, lower ``learning_rate`` alike."""


def recipe_start(dtype=None) -> Gains:
    """The recommended start, :func:`tune_smoothed`'s default: the default gains with d0,
    dt and eta at the geometric centre of the grid's box of ``benchmarks/science.py``
    (d0 0.07-0.4, dt 0.1-0.8, eta 0.001-0.004): d0 0.167, dt 0.283, eta 0.002."""
    g = default_gains(dtype)
    centre = dict(d0=math.sqrt(0.07 * 0.4), dt=math.sqrt(0.1 * 0.8), eta=math.sqrt(0.001 * 0.004))
    return g._replace(**{k: jnp.asarray(v, g.k_att.dtype) for k, v in centre.items()})


def recipe_sigma(space: GainSpace) -> tuple:
    """The recommended smoothing scales of ``space``'s coordinates: 0.7 for dt's logit
    (``stable_dt``: a broad ridge below the Euler bound), 0.3 for the other log-gains and
    for a repulsion profile's and segment weights' log-multipliers, 0.5 for the
    goal-distance profile's, chosen on the validation seed ``random_scenarios(2, 256)``
    (docs: Tuning the gains, "How the rest of the recipe was chosen")."""
    wide = {"dt"} if space.stable_dt else set()
    scalars = tuple(0.7 if k in wide else 0.3 for k in space.names)
    return scalars + (0.3,) * (space.knots + space.segments) + (0.5,) * (len(GOAL_GAINS) * space.goal_knots)


class TuneResult(NamedTuple):
    """Outcome of :func:`tune_smoothed` (host-side).

    Attributes:
      gains: the tuned gains (Gains, or a GainFunction for a space with a profile
        or segment weights); pass to ``sp.plan(..., gains=...)`` or
        :func:`~softplan_jax.tuning._gains_file.save_gains`.
      theta: (P,) their parameters.
      space: the GainSpace.
      history: dict of arrays, one row per update: ``objective`` and
        ``objective_se`` (the estimate of J at that update's theta, before the
        update), ``grad_norm``, ``success`` (fraction of that update's rollouts
        that reached without collision), ``scenes`` (updates, pairs: the suite's
        scenes each update used), ``theta`` (updates + 1, P: the start and after
        each update), ``rollouts`` (cumulative).
      rollouts: rollouts spent in all.
      compile_seconds: compile time of the estimate's program (0 when cached).
      seconds: wall time of the updates, compile excluded.
    """

    gains: object
    theta: np.ndarray
    space: GainSpace
    history: dict
    rollouts: int
    compile_seconds: float
    seconds: float


def _theta_box(space: GainSpace, base, bounds, theta):
    """``bounds`` ({name: (lo, hi)} in gains units) as theta-space arrays (lo, hi),
    or (None, None) without bounds. Checks the names, the numbers and that the
    start ``theta`` lies in the box."""
    if bounds is None:
        return None, None
    if not isinstance(bounds, dict) or not bounds:
        raise ValueError(f"bounds must be a non-empty dict {{name: (lo, hi)}}, got {bounds!r}")
    lo = np.full(space.size, -np.inf)
    hi = np.full(space.size, np.inf)
    for k, pair in bounds.items():
        if k not in space.names:
            raise ValueError(f"bounds names {k!r}, which this GainSpace does not tune ({list(space.names)})")
        try:
            a, b = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ValueError(f"bounds[{k!r}] must be a pair of numbers (lo, hi), got {pair!r}") from None
        if not (math.isfinite(a) and math.isfinite(b) and 0 < a < b):
            raise ValueError(f"bounds[{k!r}] must satisfy 0 < lo < hi (finite), got {pair!r}")
        i = space.names.index(k)
        ends = [float(space.encode(base._replace(**{k: jnp.asarray(v, base.k_att.dtype)}))[i]) for v in (a, b)]
        if not all(math.isfinite(e) for e in ends):
            raise ValueError(f"bounds[{k!r}] = {pair!r} has no finite parameters in this GainSpace "
                             "(with stable_dt, dt must be below 2 / k_att)")
        lo[i], hi[i] = ends
    t = np.asarray(theta, float)
    outside = [space.names[i] for i in range(len(space.names)) if not lo[i] - 1e-9 <= t[i] <= hi[i] + 1e-9]
    if outside:
        raise ValueError(f"the start gains lie outside bounds for {outside}")
    dtype = jnp.result_type(theta)
    return jnp.asarray(lo, dtype), jnp.asarray(hi, dtype)


def _reshuffled(key, n_suite: int, length: int) -> np.ndarray:
    """The first ``length`` scenes of the random-reshuffling stream: suite permutations
    one after another, epoch e's drawn from ``key`` folded with 2**30 + e (update keys
    fold ``it`` < 2**30). Update ``it`` takes positions ``it * pairs`` to ``(it + 1) * pairs - 1``."""
    perms = [np.asarray(jax.random.permutation(jax.random.fold_in(key, 2**30 + e), n_suite))
             for e in range(math.ceil(length / n_suite))]
    return np.concatenate(perms)[:length]


class _Setup(NamedTuple):
    """A tuning run's checked inputs."""

    scenarios: Scenario
    space: GainSpace
    base: object  # the start gains (Gains or GainFunction) in the space's form
    theta: jax.Array  # the start parameters
    box: tuple  # (lo, hi) of the projection, or (None, None)
    sigma: object
    options: object  # PlanOptions of the rollouts


def _setup(scenarios, space, gains, sigma, method, n_points, bounds, max_step, weights, numbers) -> _Setup:
    """Check :func:`tune_smoothed`'s arguments (ValueError naming the field)."""
    if not isinstance(scenarios, Scenario):
        raise ValueError(f"scenarios must be a Scenario, got {type(scenarios).__name__}")
    if scenarios.q0.ndim == 2:
        scenarios = jax.tree_util.tree_map(lambda x: x[None], scenarios)
    if scenarios.q0.shape[0] < 1:
        raise ValueError("the training suite is empty")
    for name, v in numbers.items():
        check_int(v, name, 2 if name == "pairs" else 1)
    n_seg, dtype = scenarios.q0.shape[-2], scenarios.q0.dtype
    if not isinstance(space, GainSpace):
        raise ValueError(f"space must be a GainSpace, got {type(space).__name__}")
    space = space.check(n_seg)
    check_weights(weights)
    base = space.base(check_gains(recipe_start(dtype) if gains is None else gains, dtype, n_seg), n_seg)
    base = type(base)(*(v if v is None else jnp.asarray(v, dtype) for v in base))
    theta = space.encode(base).astype(dtype)
    if not np.all(np.isfinite(np.asarray(theta))):
        bound = " (with stable_dt, dt must be below 2 / k_att)" if space.stable_dt else ""
        raise ValueError(f"the start gains have no finite parameters in this GainSpace{bound}: {np.asarray(theta)}")
    box = _theta_box(space, base, bounds, theta)
    if max_step is not None:
        check_number(max_step, "max_step", 0.0, strict=True)
    sigma = check_sigma(recipe_sigma(space) if sigma is None else sigma, space.size)
    return _Setup(scenarios, space, base, theta, box, sigma, make_options(method, n_points))


def _optimizer(optimizer, learning_rate: float, updates: int, max_step):
    """The default optimiser: SGD with momentum 0.5 and a cosine decay of the step to a tenth
    (Robbins-Monro steps), clipped to ``max_step`` per coordinate (None: not clipped)."""
    opt = optimizer or optax.sgd(optax.cosine_decay_schedule(learning_rate, int(updates), alpha=0.1), momentum=0.5)
    return opt if max_step is None else optax.chain(opt, optax.clip(float(max_step)))


def _progress(it: int, updates: int, est, su: _Setup, theta, spent: int, dt: float) -> None:
    now = su.space.decode(theta, su.base)  # the gains themselves (dt decoded also with stable_dt)
    shown = " ".join(f"{k}={float(getattr(now, k)):.4g}" for k in su.space.names)
    print(f"[tune {it + 1:3d}/{updates}] J {est.value:.4f} +- {est.value_se:.4f}  success {est.success:.2f}"
          f"  |g| {float(np.linalg.norm(est.grad)):.3g}  {shown}  ({spent} rollouts, {dt:.1f} s)",
          file=sys.stderr, flush=True)


def tune_smoothed(scenarios: Scenario, space: GainSpace = RECIPE_SPACE, gains=None, *, updates: int = 48,
                  pairs: int = 32, sigma: float | Sequence[float] | None = None, learning_rate: float = 3.75,
                  method: str = "curve", n_points: int = 10, max_steps: int = 100,
                  weights: ScoreWeights = RECIPE_WEIGHTS, seed: int = 0,
                  average: float = 1 / 3, optimizer=None, bounds=None, max_step: float | None = 0.3,
                  reshuffle: bool = False, natural: bool = True, progress: bool = True) -> TuneResult:
    """Tune gains by stochastic gradient descent (optax) on the smoothed objective.

    Each update draws ``pairs`` training scenes and one perturbation each, estimates grad J
    with :func:`~softplan_jax.tuning.smoothing_sample` (2 x ``pairs`` rollouts, one vmapped
    batch) and takes an optax step on theta; budget ``updates * 2 * pairs`` rollouts of
    ``max_steps`` steps. The defaults are the recommended recipe (the documentation's
    "Tuning the gains" says how each was chosen).

    Args:
      scenarios: the training suite (a batched Scenario); a single Scenario is a suite of one.
      space: what to tune (:class:`GainSpace`; default :data:`RECIPE_SPACE`).
      gains: the start (Gains or GainFunction; default :func:`recipe_start`).
      updates: optimiser updates (>= 1).
      pairs, method, n_points, max_steps: as :func:`~softplan_jax.tuning.smoothing_sample`.
      sigma: the smoothing's scale per parameter; None: :func:`recipe_sigma` of ``space``.
      learning_rate: the default optimiser's first step (theta units; with ``natural``,
        sigma^2 units): SGD with momentum 0.5, cosine decay to a tenth.
      weights: the objective's :class:`ScoreWeights` (default :data:`RECIPE_WEIGHTS`).
      seed: seed of the draws.
      average: return the mean of the last ``ceil(average * updates)`` iterates
        (Polyak-Ruppert averaging); 0: the last.
      optimizer: an optax GradientTransformation (overrides learning_rate).
      bounds: ``{name: (lo, hi)}`` for scalar gains of ``space`` in their own units: theta is
        projected onto the box after every update (projected SGD); the start must lie in it.
      max_step: clip each coordinate of each update to ``[-max_step, max_step]``; None: no clip.
      reshuffle: draw the updates' scenes epoch by epoch (each scene once per epoch); False:
        independently per update.
      natural: step along the natural gradient ``sigma**2 * grad J``, the gradient with respect
        to the smoothing distribution's mean in its Fisher metric (natural evolution
        strategies; Amari 1998, Wierstra et al. 2014).
      progress: one line per update on stderr.

    Returns:
      :class:`TuneResult`. ValueError for bad arguments; FloatingPointError for a non-finite
      objective or gradient.
    """
    su = _setup(scenarios, space, gains, sigma, method, n_points, bounds, max_step, weights,
                dict(updates=updates, pairs=pairs, max_steps=max_steps))
    if isinstance(average, bool) or not isinstance(average, (int, float)) or not 0 <= average <= 1:
        raise ValueError(f"average must be a number in [0, 1], got {average!r}")
    check_number(learning_rate, "learning_rate", 0.0, strict=True)
    check_bool(reshuffle, "reshuffle")
    check_bool(natural, "natural")
    dtype, theta = su.theta.dtype, su.theta
    precondition = jnp.broadcast_to(jnp.asarray(su.sigma**2, dtype), theta.shape) if natural else None
    opt = _optimizer(optimizer, learning_rate, updates, max_step)
    state = opt.init(theta)
    hist = {k: [] for k in ("objective", "objective_se", "grad_norm", "success", "scenes")}
    thetas = [np.asarray(theta)]
    key = jax.random.PRNGKey(seed)
    stream = _reshuffled(key, su.scenarios.q0.shape[0], int(updates) * int(pairs)) if reshuffle else None
    times, spent = [0.0, 0.0], 0  # compile (first call of a new program, run included), run
    for it in range(int(updates)):
        t0 = time.perf_counter()
        before = scores_jit(su.options.method)._cache_size()
        scenes = None if stream is None else stream[it * int(pairs):(it + 1) * int(pairs)]
        sample = smoothing_sample(theta, su.space, su.base, su.scenarios, jax.random.fold_in(key, it), pairs=pairs,
                                  sigma=sigma if sigma is not None else recipe_sigma(su.space),
                                  max_steps=max_steps, weights=weights, options=su.options, scene_index=scenes)
        est = estimate_objective(sample)
        dt = time.perf_counter() - t0
        times[0 if scores_jit(su.options.method)._cache_size() > before else 1] += dt
        spent += est.rollouts
        if not (np.isfinite(est.value) and np.all(np.isfinite(est.grad))):
            raise FloatingPointError(f"non-finite objective or gradient at update {it}: {est.value}")
        grad = jnp.asarray(est.grad, dtype)
        grad = grad if precondition is None else precondition * grad
        with jax.numpy_dtype_promotion("standard"):  # optax mixes Python floats with int32 counts
            step, state = opt.update(grad, state, theta)
            theta = optax.apply_updates(theta, step)
        if su.box[0] is not None:
            theta = jnp.clip(theta, *su.box)  # projection onto the box (projected SGD)
        for k, v in (("objective", est.value), ("objective_se", est.value_se), ("success", est.success),
                     ("grad_norm", float(np.linalg.norm(est.grad))), ("scenes", np.asarray(sample.scenes))):
            hist[k].append(v)
        thetas.append(np.asarray(theta))
        if progress:
            _progress(it, updates, est, su, theta, spent, dt)
    history = {k: np.asarray(v) for k, v in hist.items()}
    history["theta"] = np.stack(thetas)
    history["rollouts"] = np.arange(1, int(updates) + 1) * 2 * int(pairs)
    if average > 0:
        tail = max(1, math.ceil(average * int(updates)))
        theta = jnp.asarray(history["theta"][-tail:].mean(0), dtype)
    return TuneResult(su.space.decode(theta, su.base), np.asarray(theta), su.space, history, spent, *times)
