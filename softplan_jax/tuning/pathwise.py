"""Gradient tuning of the gains through whole rollouts (optax), the pathwise baseline of the tuning
comparisons. :func:`rollout_loss` is differentiable in the gains (the planner step is smooth in
them, the closest points carry implicit derivatives, :mod:`softplan_jax.geometry._closest`, and the
status logic only freezes the state): ``w_path`` times the mean tip error |V_e| over the steps,
plus ``w_final`` times the final one, plus ``w_clearance`` times a soft penalty
``tau softplus((margin - clearance) / tau)`` on the true clearance of every obstacle at every
step. :func:`tune_gains` optimises the gains' logarithms with an optax optimiser over a batch of
scenarios."""

from __future__ import annotations

import sys
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..planning._options import PlanOptions, make_options, rollout_compiler_options
from ..planning._planner import check_gains
from ..planning._programs import rollout
from ..planning._step import Gains
from ..scenarios import Scenario

__all__ = ["LossWeights", "rollout_loss", "batch_loss", "tune_gains", "TuningResult"]


class LossWeights(NamedTuple):
    """Weights of :func:`rollout_loss` (a pytree of floats)."""

    w_path: float = 1.0
    w_final: float = 1.0
    w_clearance: float = 10.0
    margin: float = 0.03
    tau: float = 0.005


def rollout_loss(gains: Gains, scenario: Scenario, options: PlanOptions, max_steps: int,
                 weights: LossWeights = LossWeights()):
    """Scalar loss of one rollout (see the module docstring); differentiable in gains."""
    r = rollout(scenario, gains, options, max_steps)
    err = jnp.linalg.norm(scenario.goal - r.tip, axis=-1)
    finite_c = jnp.where(jnp.isfinite(r.clearance), r.clearance, 1e3)
    penalty = weights.tau * jax.nn.softplus((weights.margin - finite_c) / weights.tau)
    return (
        weights.w_path * jnp.mean(err)
        + weights.w_final * err[-1]
        + weights.w_clearance * jnp.sum(jnp.mean(penalty, axis=0))
    )


def batch_loss(gains: Gains, scenarios: Scenario, options: PlanOptions, max_steps: int,
               weights: LossWeights = LossWeights()):
    """Mean :func:`rollout_loss` over a batch of scenarios (leading axis)."""
    losses = jax.vmap(lambda sc: rollout_loss(gains, sc, options, max_steps, weights))(scenarios)
    return jnp.mean(losses)


class TuningResult(NamedTuple):
    """Outcome of :func:`tune_gains`.

    Attributes:
      gains: the tuned Gains.
      losses: (steps + 1,) loss before each update and after the last.
      history: list of Gains after each update.
      compile_seconds: time to compile the loss-and-gradient function (0 when
        an earlier call with the same shapes had compiled it).
    """

    gains: Gains
    losses: np.ndarray
    history: list
    compile_seconds: float


def _to_gains(params, fixed):
    """Gains from log-parameters ``params`` (tuned) and ``fixed`` values (the rest)."""
    return Gains(**{k: (jnp.exp(params[k]) if k in params else v) for k, v in fixed.items()})


# Loss and gradient in the gains: the very program of notebooks/tuning.ipynb and
# tests/test_planner.py (``jax.jit(jax.value_and_grad(batch_loss))`` with the
# scenes as an argument, compiled with rollout_compiler_options(method)), so that
# they share one compilation through jax's persistent cache. tune_gains applies
# the chain rule to the log-gains itself. The package's XLA options roughly halve
# the gradient's compile time at the same run time (docs: Performance, "Compilation").
_loss_and_grad = jax.jit(jax.value_and_grad(batch_loss), static_argnames=("options", "max_steps"))

# AOT-compiled _loss_and_grad, keyed by argument structure, shapes, dtypes and statics.
_COMPILED: dict = {}


def tune_gains(scenarios: Scenario, gains: Gains | None = None, *, steps: int = 50,
               learning_rate: float = 0.05, max_steps: int = 150, method: str = "curve",
               n_points: int = 10, weights: LossWeights = LossWeights(),
               tune: tuple[str, ...] = ("k_att", "eta", "d0", "dt"), optimizer=None,
               progress: bool = True, **options) -> TuningResult:
    """Tune gains by gradient descent on :func:`batch_loss` with optax.

    Args:
      scenarios: a batched Scenario (``stack_scenarios`` / ``random_scenarios``)
        or a single one.
      gains: starting gains (default :func:`default_gains`).
      steps: optimiser updates.
      learning_rate: of the default optimiser ``optax.adam`` on log-gains.
      max_steps: rollout length.
      tune: names of the Gains fields to tune; the others stay fixed.
      optimizer: an optax GradientTransformation (overrides learning_rate).
      progress: print one line per update to stderr.

    Returns:
      :class:`TuningResult`.
    """
    if not isinstance(scenarios, Scenario):
        raise ValueError(f"scenarios must be a Scenario, got {type(scenarios).__name__}")
    if scenarios.q0.ndim == 2:
        scenarios = jax.tree_util.tree_map(lambda x: x[None], scenarios)
    unknown = set(tune) - set(Gains._fields)
    if unknown or not tune:
        raise ValueError(f"tune must name Gains fields {list(Gains._fields)}; got {list(tune)}")
    if int(steps) < 1 or int(max_steps) < 1:
        raise ValueError(f"steps and max_steps must be >= 1; got {steps}, {max_steps}")
    opts = make_options(method, n_points, **options)
    g0 = check_gains(gains, scenarios.q0.dtype)
    fixed = g0._asdict()
    params = {k: jnp.log(fixed[k]) for k in tune}

    def to_gains(p):
        return _to_gains(p, fixed)

    # The default weights stay out of the arguments (batch_loss's default, baked in as
    # constants), exactly as in the notebook's call: the same program.
    extra = () if weights == LossWeights() else (weights,)
    args = (g0, scenarios) + extra
    leaves, treedef = jax.tree_util.tree_flatten(args)
    # Weak typing is part of the key: a Python float and a float64 array compile differently.
    key = (treedef, tuple((jnp.shape(x), jnp.result_type(x), getattr(x, "weak_type", isinstance(x, float)))
                          for x in leaves), opts, int(max_steps))
    compiled = _COMPILED.get(key)
    compile_s = 0.0
    if compiled is None:
        t0 = time.perf_counter()
        lowered = _loss_and_grad.lower(g0, scenarios, opts, int(max_steps), *extra)
        compiled = lowered.compile(compiler_options=rollout_compiler_options(opts.method))
        compile_s = time.perf_counter() - t0
        _COMPILED[key] = compiled

    def value_and_grad(p):
        g = to_gains(p)
        loss, grad = compiled(g, scenarios, *extra)
        # Chain rule to the log-gains: d loss / d log g = g * d loss / d g.
        return loss, {k: getattr(grad, k) * getattr(g, k) for k in p}

    opt = optimizer or optax.adam(learning_rate)
    state = opt.init(params)
    losses, history = [], []
    for it in range(int(steps)):
        loss, grad = value_and_grad(params)
        if not np.isfinite(float(loss)) or not all(np.all(np.isfinite(np.asarray(v))) for v in grad.values()):
            raise FloatingPointError(f"non-finite loss or gradient at update {it}: loss = {float(loss)}")
        # optax mixes Python floats with its int32 step count (adam's bias correction),
        # which jax's "strict" dtype promotion rejects: the optimiser runs under the
        # standard rules whatever the caller chose.
        with jax.numpy_dtype_promotion("standard"):
            updates, state = opt.update(grad, state, params)
            params = optax.apply_updates(params, updates)
        losses.append(float(loss))
        history.append(to_gains(params))
        if progress:
            shown = " ".join(f"{k}={float(jnp.exp(params[k])):.4g}" for k in tune)
            print(f"[tune {it + 1:4d}/{steps}] loss {float(loss):.5f}  {shown}", file=sys.stderr, flush=True)
    losses.append(float(value_and_grad(params)[0]))
    return TuningResult(to_gains(params), np.asarray(losses), history, compile_s)
