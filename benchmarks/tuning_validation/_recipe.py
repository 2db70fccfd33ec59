"""What val7.py to val11.py and snr_coords.py share: the training and validation suites,
the validation score, the grid box's centre (the start) and the benchmark's gradient
recipe of sessions 16-18 (d0 and dt with stable_dt, sigma 0.4, first step 1.0, 24
updates of 16 pairs = 768 rollouts; val10.py's config Q), which tune_recipe's keywords
change (val10.py's N37b, sigma (0.3, 0.7) along the natural gradient from 3.75, is
benchmarks/tuning.py's recipe since session 19). The caller enables float64 before
importing this module. val5.py and val6.py keep their own copies: each is the record
of the logs beside it."""

import math
import os
import sys

import jax.numpy as jnp
import numpy as np

import softplan_jax as sp
from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tuning import plan_kw  # noqa: E402  (benchmarks/tuning.py: the method keywords of a model)

TRAIN = sp.random_scenarios(0, 64)
VAL = sp.random_scenarios(2, 256)  # the validation seed; never the held-out seed 1
BOX = dict(d0=(0.07, 0.4), dt=(0.1, 0.8))  # the grid's box (benchmarks/tuning.py --grid-d0 / --grid-dt)
CENTRE = sp.default_gains()._replace(
    d0=jnp.asarray(math.sqrt(0.07 * 0.4)), dt=jnp.asarray(math.sqrt(0.1 * 0.8)), eta=jnp.asarray(0.002)
)


def validation_success(gains, m) -> float:
    """Success (reached without collision) on the 256 validation scenes, 150 steps, rounded."""
    r = sp.plan_batch(VAL, gains=gains, max_steps=150, chunk=64, **plan_kw(m))
    return round((np.asarray(r.reached) & ~np.asarray(r.collided)).mean(), 3)


def tune_recipe(m, seed: int, start=CENTRE, **changes):
    """The benchmark's gradient recipe from ``start`` (CENTRE) on TRAIN, with ``changes`` to
    tune_smoothed's keywords (bounds= / max_step= / sigma= / ...)."""
    kw = dict(sigma=0.4, pairs=16, updates=24, learning_rate=1.0, seed=seed, progress=False) | changes
    return tune_smoothed(TRAIN, GainSpace(("d0", "dt"), stable_dt=True), start, **kw, **plan_kw(m))
