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
* :mod:`.pathwise` -- the pathwise-gradient tuner (``tune_gains``), kept as the
  baseline of the tuning comparisons: it differentiates through the rollout, whose
  score is piecewise constant in the gains, so its gradient sees little of what
  the smoothed tuner optimises.
"""

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
