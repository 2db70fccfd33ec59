# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 19: the seed spread of the benchmark's recipe (val7.py config Q: d0 and dt with stable_dt,
# sigma 0.4, step 1.0, clip 0.3). Why it spreads (measured at three points with 512 pairs): the two
# coordinates differ. log d0's landscape is steep and lopsided (a small d0 loses many scenes), and its
# per-pair gradient noise is large; dt's logit sees a broad ridge below the Euler bound, with a
# weak, consistent slope whose per-pair signal to noise is about 0.1 at sigma 0.4, so from the box's
# centre dt creeps up and many runs end below dt 0.6. One sigma for both cannot suit both. Here:
# one smoothing scale per coordinate (sigma=(s_d0, s_dt)), and the natural-gradient step
# (natural=True: theta <- theta - lr sigma^2 grad J, so each coordinate moves in units of its own
# scale). Judged on the VALIDATION seed (2) with tuner seeds 5-14 (a second run: 15-24); the
# held-out seed (1) and the tuner seeds 0-4 that the benchmarks report are not used.
#   python val10.py {curve,10,50} CONFIGS [SEEDS]
import math
import sys

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np
import optax
from _recipe import CENTRE, tune_recipe, validation_success

from softplan_jax.tuning.smoothing import ScoreWeights

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
configs = sys.argv[2].split(",")
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else list(range(5, 15))


def scaled_sgd(scale, lr, updates=24):
    """The default optimiser of tune_smoothed with the gradient multiplied by ``scale`` per coordinate."""
    v = jnp.asarray(scale, jnp.float64)
    pre = optax.GradientTransformation(lambda p: optax.EmptyState(), lambda u, s, p=None: (u * v, s))
    return optax.chain(pre, optax.sgd(optax.cosine_decay_schedule(lr, updates, alpha=0.1), momentum=0.5))


PROGRESS_ONLY = ScoreWeights(progress=1.0, unreached=0.0, collided=2.0)
CONFIGS = dict(  # every one spends 768 rollouts (24 updates x 2 x 16 pairs) and clips each update to 0.3
    Q=dict(),  # the benchmark's recipe of sessions 17-18 (val7.py config Q)
    P=dict(weights=PROGRESS_ONLY),  # the smooth progress term alone (no failure indicator)
    S7=dict(sigma=0.7),  # wider smoothing for both coordinates
    PS7=dict(sigma=0.7, weights=PROGRESS_ONLY),
    V37=dict(sigma=(0.3, 0.7)),  # one scale per coordinate: narrow in log d0, wide in dt's logit
    V47=dict(sigma=(0.4, 0.7)),
    V26=dict(sigma=(0.25, 0.6)),
    V49=dict(sigma=(0.4, 0.9)),
    L37=dict(sigma=(0.3, 0.7), optimizer=scaled_sgd([1.0, 2.0], 1.0)),  # dt's step doubled by hand
    # the natural gradient: step lr sigma^2 grad J; lr 1 / 0.4^2 = 6.25 is the old step 1.0 for a
    # coordinate at the old sigma 0.4; 3.75 and 2.5 are 0.6 and 0.4 of it
    N37a=dict(sigma=(0.3, 0.7), natural=True, learning_rate=6.25),
    N37b=dict(sigma=(0.3, 0.7), natural=True, learning_rate=3.75),
    N37c=dict(sigma=(0.3, 0.7), natural=True, learning_rate=2.5),
)


# the grid's choice on the training scenes (benchmarks/results/tuning.md), for reference
GRID = {"curve": (0.4, 0.8, 0.004), 10: (0.3, 0.6, 0.004), 50: (0.4, 0.8, 0.004)}


def shown(cfg):
    return {k: ("scaled sgd" if k == "optimizer" else v) for k, v in cfg.items()}


for name in configs:
    if name == "GRID":
        d0, dt, eta = GRID[m]
        g = CENTRE._replace(d0=jnp.asarray(d0), dt=jnp.asarray(dt), eta=jnp.asarray(eta))
        print(m, "GRID", (d0, dt, eta), validation_success(g, m), flush=True)
        continue
    succ = []
    for seed in seeds:
        t = tune_recipe(m, seed, max_step=0.3, **CONFIGS[name])
        succ.append(validation_success(t.gains, m))
        print(m, name, shown(CONFIGS[name]) or "(the recipe)", f"seed={seed}", succ[-1],
              {k: round(float(getattr(t.gains, k)), 4) for k in ("d0", "dt")}, flush=True)
    s = np.asarray(succ)
    print(f"{m} {name} SUMMARY seeds {seeds[0]}-{seeds[-1]}: mean {s.mean():.3f} min {s.min():.3f} max {s.max():.3f} "
          f"(sd {s.std(ddof=1) if len(s) > 1 else math.nan:.3f})", flush=True)
