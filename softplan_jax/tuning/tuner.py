"""Tuning the gains by stochastic gradient descent on the smoothed objective of
:mod:`softplan_jax.tuning.objective` (its importance-weighted estimate and the
antithetic score-function gradient).

:func:`tune_smoothed` runs optax on these gradients (SGD with momentum, a
decaying step and iterate averaging by default; optionally along the natural
gradient ``sigma^2 grad J``), a fresh draw of scenes and perturbations per
update, with progress, the training history, and the rollout budget accounted
for. ``benchmarks/tuning.py`` compares it with a grid, random search and CMA-ES
at equal budgets on held-out scenes.
"""

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

from ..planning.gains import GOAL_GAINS, Gains, default_gains
from ..planning.options import make_options
from ..planning.planner import check_gains
from ..scenarios import Scenario
from .objective import ScoreWeights, check_sigma, check_weights, estimate_objective, scores_jit, smoothing_sample
from .space import GainSpace

__all__ = ["TuneResult", "tune_smoothed", "RECIPE_SPACE", "RECIPE_WEIGHTS", "recipe_start", "recipe_sigma"]

RECIPE_SPACE = GainSpace(("d0", "dt"), stable_dt=True, goal_knots=6)
"""The recommended space, :func:`tune_smoothed`'s default: log d0, dt as the logit of its
fraction of the Euler bound, and a 6-knot goal-distance profile of k_att, v_max, eta and d0
(26 parameters; zeros: the constant gains)."""

RECIPE_WEIGHTS = ScoreWeights(steps=1.0)
"""The recommended objective, :func:`tune_smoothed`'s default: the failure and progress terms
of :class:`ScoreWeights`, plus the time to a plan (steps / max_steps where the goal is
reached, 1 otherwise). ``fallback`` stays 0: ``unreached`` already charges a failure,
and on the validation seed the fallback's full time (``fallback=5``: its median 0.55 s
where it runs, ``benchmarks/results/reach.md``, is about five 100-step rollouts) made the
score's differences, and with them the natural gradient's steps, several times larger:
the tuned function was worse (91.0 % against 99.6 % of ``random_scenarios(2, 256)``
reached with the recipe's sigma, tuner seed 0; 92.6 % against 97.7 % with the profile's
sigma at 0.3). With larger weights, lower ``learning_rate`` alike."""


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
    goal-distance profile's. Chosen on the validation seed ``random_scenarios(2, 256)``
    with tuner seeds 0-2 (never the held-out seed): the goal profile at 0.3 / 0.5 / 0.7 /
    1.0 reached 95.7-97.7 / 98.8-99.6 / 99.2-100 / 94.9-97.7 % of its scenes in a mean of
    28.7-34.4 / 21.9-23.5 / 22.5-28.5 / 22.3-23.7 steps (issue 39's closing note)."""
    wide = {"dt"} if space.stable_dt else set()
    scalars = tuple(0.7 if k in wide else 0.3 for k in space.names)
    return scalars + (0.3,) * (space.knots + space.segments) + (0.5,) * (len(GOAL_GAINS) * space.goal_knots)


class TuneResult(NamedTuple):
    """Outcome of :func:`tune_smoothed` (host-side).

    Attributes:
      gains: the tuned gains (Gains, or a GainFunction for a space with a profile
        or segment weights); pass to ``sp.plan(..., gains=...)`` or
        :func:`~softplan_jax.tuning.gains_file.save_gains`.
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


def tune_smoothed(scenarios: Scenario, space: GainSpace = RECIPE_SPACE, gains=None, *, updates: int = 48,
                  pairs: int = 32, sigma: float | Sequence[float] | None = None, learning_rate: float = 3.75,
                  method: str = "curve", n_points: int = 10, max_steps: int = 100,
                  weights: ScoreWeights = RECIPE_WEIGHTS, seed: int = 0,
                  average: float = 1 / 3, optimizer=None, bounds=None, max_step: float | None = 0.3,
                  reshuffle: bool = False, natural: bool = True, progress: bool = True) -> TuneResult:
    """Tune gains by stochastic gradient descent (optax) on the smoothed objective.

    ``tune_smoothed(train)`` runs the recommended recipe: the 26-parameter gain
    function :data:`RECIPE_SPACE` (d0, dt, and k_att, v_max, eta, d0 as functions
    of the distance to the goal) from :func:`recipe_start`, the objective
    :data:`RECIPE_WEIGHTS` (failures, progress and the time to a plan), sigma
    :func:`recipe_sigma`, 48 updates of 32 antithetic pairs (3,072 rollouts of
    100 steps; about 15 s on a 2-core CPU after a compile of about 20 s) along the
    natural gradient from step 3.75, each update clipped to 0.3.
    ``benchmarks/tuners.py`` compares it with Optuna's TPE and CMA-ES at equal
    rollouts, on held-out scenes, over five tuner seeds.

    Each update draws ``pairs`` training scenes and one perturbation each
    (a fresh key per update), estimates grad J with :func:`smoothed_objective`
    (2 x ``pairs`` rollouts of the library's default planner, one vmapped
    batch) and takes an optax step on theta. Budget: ``updates * 2 * pairs``
    rollouts of ``max_steps`` steps.

    The default optimiser is stochastic gradient descent with momentum 0.5 and a
    cosine decay of the step from ``learning_rate`` to a tenth of it, and the
    result is the mean of the last third of the iterates (Robbins-Monro steps with
    Polyak-Ruppert averaging, the textbook recipe for noisy gradients). Not adam:
    its per-coordinate normalisation moves a coordinate whose gradient is pure
    noise by about the learning rate at every update, a random walk; on a
    validation seed (``random_scenarios(2, 256)``, never the held-out one) adam
    ended 10-20 points of success lower for N = 10
    (``benchmarks/tuning_validation/`` in git history at b850131).

    The scalar part of the recipe (``benchmarks/tuning.py``'s two-gain tuner),
    chosen on that validation seed (``benchmarks/tuning_validation/val10.py``,
    b850131), is ``space=GainSpace(("d0", "dt"), stable_dt=True), sigma=(0.3, 0.7),
    natural=True, learning_rate=3.75, max_step=0.3`` from the centre of the
    grid's box: log d0's landscape is steep and lopsided and its gradient noisy,
    so it is smoothed narrowly and, along the natural gradient, moves slowly;
    dt's logit sees a broad ridge below the Euler bound with a weak, steady
    slope, so it is smoothed widely and moves fast. With one sigma (0.4) and the
    plain step, dt crept up from the start and the result depended on ``seed``
    (validation success 77.7-94.1 % for N = 10 over tuner seeds 5-14, against
    86.7-93.8 % with the recipe; documentation, "Tuning the gains").

    Two guards keep a noisy step from running away (off by default): ``bounds``
    projects theta onto a box after every update (projected stochastic gradient
    descent; the averaged iterate stays in the box, which is convex), and
    ``max_step`` clips every coordinate of every update (``optax.clip`` chained
    after the optimiser). Without them one large noisy gradient can throw a
    gain so far out that every rollout fails and the objective is flat, with
    nothing to bring it back. On the validation seed the clip (0.3) was the
    better guard for the recipe above; the grid's box cost a point
    (``benchmarks/tuning_validation/val7.py``, b850131).

    Args:
      scenarios: the training suite (a batched Scenario, e.g.
        ``random_scenarios(seed, n)``); a single Scenario is taken as a suite of one.
      space: what to tune (:class:`GainSpace`; default :data:`RECIPE_SPACE`).
      gains: the start (Gains or GainFunction; default :func:`recipe_start`).
      updates: optimiser updates (>= 1).
      pairs, method, n_points, max_steps: as :func:`smoothing_sample`.
      sigma: as :func:`smoothing_sample`; None: :func:`recipe_sigma` of ``space``.
      weights: the objective's :class:`ScoreWeights` (default :data:`RECIPE_WEIGHTS`;
        ``ScoreWeights()``: failures and progress alone).
      learning_rate: the first step size of the default optimiser (theta in log units;
        with ``natural``, in units of sigma^2).
      seed: seed of the draws.
      average: return the mean of the last ``ceil(average * updates)`` iterates
        (Polyak-Ruppert averaging of the noisy steps) instead of the last one; 0: the last.
      optimizer: an optax GradientTransformation (overrides learning_rate).
      bounds: ``{name: (lo, hi)}`` for scalar gains in ``space.names``, in the
        gains' own units (``0 < lo < hi``; with ``stable_dt``, a dt bound below
        ``2 / k_att`` of the start): theta is projected onto the box after every
        update. The start must lie in it. With ``stable_dt`` and a tuned
        ``k_att``, the dt bound holds at the start's ``k_att`` (it bounds the
        fraction ``dt k_att / 2``).
      max_step: clip each coordinate of each update to ``[-max_step, max_step]``
        (theta units, > 0); None: no clipping.
      reshuffle: draw the updates' scenes epoch by epoch (random reshuffling): the
        suite in a fresh permutation per epoch, consecutive blocks of ``pairs``
        scenes per update, so that every scene is used once before any is used
        again. False: each update draws its ``pairs`` scenes independently
        (:func:`smoothing_sample`'s draw). Perturbations and escape keys are the
        same either way. For the recipe above it did not narrow the spread over
        tuner seeds on the validation seed (``benchmarks/tuning_validation/val9.py``, b850131).
      natural: step along the natural gradient ``sigma**2 * grad J`` (per coordinate)
        instead of ``grad J``: the gradient with respect to the mean of the smoothing
        distribution ``N(theta, diag(sigma^2))`` in the metric of its Fisher information
        ``diag(1 / sigma^2)`` (natural evolution strategies). A coordinate smoothed
        more widely then moves faster, in proportion to its own scale, and the
        learning rate is a number of sigma^2 units; with one sigma for every
        coordinate it only multiplies the learning rate by ``sigma**2``.
      progress: one line per update on stderr.

    Returns:
      :class:`TuneResult`.
    """
    if not isinstance(scenarios, Scenario):
        raise ValueError(f"scenarios must be a Scenario, got {type(scenarios).__name__}")
    if scenarios.q0.ndim == 2:
        scenarios = jax.tree_util.tree_map(lambda x: x[None], scenarios)
    if scenarios.q0.shape[0] < 1:
        raise ValueError("the training suite is empty")
    for name, v in (("updates", updates), ("pairs", pairs), ("max_steps", max_steps)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < (2 if name == "pairs" else 1):
            raise ValueError(f"{name} must be an int >= {2 if name == 'pairs' else 1}, got {v!r}")
    if isinstance(average, bool) or not isinstance(average, (int, float)) or not 0 <= average <= 1:
        raise ValueError(f"average must be a number in [0, 1], got {average!r}")
    if not (isinstance(learning_rate, (int, float)) and math.isfinite(learning_rate) and learning_rate > 0):
        raise ValueError(f"learning_rate must be a finite number > 0, got {learning_rate!r}")
    n_seg = scenarios.q0.shape[-2]
    if not isinstance(space, GainSpace):
        raise ValueError(f"space must be a GainSpace, got {type(space).__name__}")
    space = space.check(n_seg)
    dtype = scenarios.q0.dtype
    check_weights(weights)
    if sigma is None:
        sigma = recipe_sigma(space)
    base = space.base(check_gains(recipe_start(dtype) if gains is None else gains, dtype, n_seg), n_seg)
    base = type(base)(*(v if v is None else jnp.asarray(v, dtype) for v in base))
    opts = make_options(method, n_points)
    theta = space.encode(base).astype(dtype)
    if not np.all(np.isfinite(np.asarray(theta))):
        bound = " (with stable_dt, dt must be below 2 / k_att)" if space.stable_dt else ""
        raise ValueError(f"the start gains have no finite parameters in this GainSpace{bound}: {np.asarray(theta)}")
    lo, hi = _theta_box(space, base, bounds, theta)
    if max_step is not None and (isinstance(max_step, bool) or not isinstance(max_step, (int, float))
                                 or not math.isfinite(max_step) or max_step <= 0):
        raise ValueError(f"max_step must be None or a finite number > 0, got {max_step!r}")
    if not isinstance(reshuffle, (bool, np.bool_)):
        raise ValueError(f"reshuffle must be a bool, got {reshuffle!r}")
    if not isinstance(natural, (bool, np.bool_)):
        raise ValueError(f"natural must be a bool, got {natural!r}")
    sigma_arr = check_sigma(sigma, space.size)
    # The natural gradient with respect to the mean of the smoothing distribution
    # N(theta, diag(sigma^2)): its Fisher information is diag(1 / sigma^2), so the natural
    # gradient is sigma^2 * grad J (Amari 1998; natural evolution strategies, Wierstra et al.
    # 2014, JMLR 15).
    precondition = jnp.broadcast_to(jnp.asarray(sigma_arr**2, dtype), theta.shape) if natural else None
    opt = optimizer or optax.sgd(optax.cosine_decay_schedule(learning_rate, int(updates), alpha=0.1), momentum=0.5)
    if max_step is not None:
        opt = optax.chain(opt, optax.clip(float(max_step)))
    state = opt.init(theta)
    hist = {k: [] for k in ("objective", "objective_se", "grad_norm", "success", "scenes")}
    thetas = [np.asarray(theta)]
    key = jax.random.PRNGKey(seed)
    stream = _reshuffled(key, scenarios.q0.shape[0], int(updates) * int(pairs)) if reshuffle else None
    compile_s, t_run, spent = 0.0, 0.0, 0
    for it in range(int(updates)):
        t0 = time.perf_counter()
        before = scores_jit(opts.method)._cache_size()
        scenes = None if stream is None else stream[it * int(pairs):(it + 1) * int(pairs)]
        sample = smoothing_sample(theta, space, base, scenarios, jax.random.fold_in(key, it), pairs=pairs,
                                  sigma=sigma, max_steps=max_steps, weights=weights, options=opts, scene_index=scenes)
        est = estimate_objective(sample)
        dt = time.perf_counter() - t0
        if scores_jit(opts.method)._cache_size() > before:
            compile_s += dt  # this call compiled (and ran once: the run is counted as compile)
        else:
            t_run += dt
        spent += est.rollouts
        if not (np.isfinite(est.value) and np.all(np.isfinite(est.grad))):
            raise FloatingPointError(f"non-finite objective or gradient at update {it}: {est.value}")
        grad = jnp.asarray(est.grad, dtype)
        if precondition is not None:
            grad = precondition * grad
        with jax.numpy_dtype_promotion("standard"):  # optax mixes Python floats with int32 counts
            updates_, state = opt.update(grad, state, theta)
            theta = optax.apply_updates(theta, updates_)
        if lo is not None:
            theta = jnp.clip(theta, lo, hi)  # projection onto the box (projected SGD)
        hist["objective"].append(est.value)
        hist["objective_se"].append(est.value_se)
        hist["grad_norm"].append(float(np.linalg.norm(est.grad)))
        hist["success"].append(est.success)
        hist["scenes"].append(np.asarray(sample.scenes))
        thetas.append(np.asarray(theta))
        if progress:
            now = space.decode(theta, base)  # the gains themselves (dt decoded also with stable_dt)
            shown = " ".join(f"{k}={float(getattr(now, k)):.4g}" for k in space.names)
            print(f"[tune {it + 1:3d}/{updates}] J {est.value:.4f} +- {est.value_se:.4f}  success {est.success:.2f}"
                  f"  |g| {hist['grad_norm'][-1]:.3g}  {shown}  ({spent} rollouts, {dt:.1f} s)",
                  file=sys.stderr, flush=True)
    history = {k: np.asarray(v) for k, v in hist.items()}
    history["theta"] = np.stack(thetas)
    history["rollouts"] = np.arange(1, int(updates) + 1) * 2 * int(pairs)
    if average > 0:
        tail = max(1, math.ceil(average * int(updates)))
        theta = jnp.asarray(history["theta"][-tail:].mean(0), dtype)
    tuned = space.decode(theta, base)
    return TuneResult(tuned, np.asarray(theta), space, history, spent, compile_s, t_run)
