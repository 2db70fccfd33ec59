"""Tuning the gains of eq. (9) on a suite of scenes, and gains files (docs: Tuning the gains): what
is tuned (:mod:`._space`, :class:`GainSpace`); the objective (:mod:`._objective`: Gaussian smoothing
of the rollout score and its unbiased gradient estimate); the tuner :func:`tune_smoothed`
(:mod:`._tuner`: stochastic gradient descent with optax, whose defaults are the recommended recipe);
tuned gains as JSON, with the obstacle model they were tuned for (:mod:`._gains_file`); and the
pathwise-gradient tuner ``tune_gains`` (:mod:`.pathwise`), kept as the baseline of the tuning
comparisons: it differentiates through the rollout, whose score is piecewise constant in the
gains, so its gradient sees little of what the smoothed tuner optimises."""

from . import pathwise as pathwise
from ._gains_file import gains_from_dict, gains_to_dict, load_gains, save_gains
from ._objective import (
    ObjectiveEstimate,
    ScoreWeights,
    SmoothingSample,
    estimate_objective,
    rollout_score,
    score_batch,
    smoothed_objective,
    smoothing_sample,
)
from ._space import GainSpace
from ._tuner import RECIPE_SPACE, RECIPE_WEIGHTS, TuneResult, recipe_sigma, recipe_start, tune_smoothed

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
