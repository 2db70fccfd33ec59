"""Tuning the gains of eq. (9) on a suite of scenes, and gains files.

* :mod:`.space` -- what is tuned: :class:`GainSpace`, the parameters of the gains
  and of a gain function;
* :mod:`.objective` -- the objective: Gaussian smoothing of the rollout score
  over those parameters and its unbiased gradient estimate;
* :mod:`.tuner` -- the tuner, :func:`tune_smoothed` (stochastic gradient descent
  on that estimate, with optax), whose defaults are the recommended recipe
  (:data:`RECIPE_SPACE`, :data:`RECIPE_WEIGHTS`, :func:`recipe_start`, :func:`recipe_sigma`);
* :mod:`.gains_file` -- tuned gains as JSON, with the obstacle model they were
  tuned for;
* :mod:`.pathwise` -- the earlier pathwise-gradient tuner (``tune_gains``),
  deprecated: it differentiates through the rollout, whose score is piecewise
  constant in the gains (reached or not), so its gradient sees none of what the
  smoothed tuner optimises.
"""

import warnings as _warnings

from . import pathwise as pathwise
from .gains_file import gains_from_dict, gains_to_dict, load_gains, save_gains
from .objective import (
    ObjectiveEstimate,
    ScoreWeights,
    SmoothingSample,
    estimate_objective,
    rollout_score,
    score_batch,
    smoothed_objective,
    smoothing_sample,
)
from .space import GainSpace
from .tuner import RECIPE_SPACE, RECIPE_WEIGHTS, TuneResult, recipe_sigma, recipe_start, tune_smoothed

__all__ = [
    "GainSpace",
    "ScoreWeights",
    "rollout_score",
    "score_batch",
    "SmoothingSample",
    "smoothing_sample",
    "smoothed_objective",
    "ObjectiveEstimate",
    "estimate_objective",
    "TuneResult",
    "tune_smoothed",
    "RECIPE_SPACE",
    "RECIPE_WEIGHTS",
    "recipe_start",
    "recipe_sigma",
    "save_gains",
    "load_gains",
    "gains_to_dict",
    "gains_from_dict",
]

_PATHWISE = ("tune_gains", "TuningResult", "LossWeights", "rollout_loss", "batch_loss")


def __getattr__(name):
    if name in _PATHWISE:
        _warnings.warn(
            f"softplan_jax.tuning.{name} is deprecated (the pathwise-gradient tuner); use "
            f"softplan_jax.tuning.tune_smoothed, or import softplan_jax.tuning.pathwise.{name} to keep it",
            DeprecationWarning, stacklevel=2)
        from . import pathwise

        return getattr(pathwise, name)
    raise AttributeError(f"module 'softplan_jax.tuning' has no attribute {name!r}")
