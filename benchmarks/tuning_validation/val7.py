# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 17: a step guard for the benchmark's gradient recipe (val6.py's config N: d0, dt with
# stable_dt, sigma 0.4, step 1.0): projection onto the grid's box (bounds) or per-update clipping
# (max_step). Judged on the VALIDATION seed (2) with tuner seeds 5-9; the held-out seed (1) and the
# tuner seeds 0-4 that benchmarks/tuning_seeds.py reports are not used here.
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.smoothing import GainSpace, tune_smoothed

m = sys.argv[1]
configs = sys.argv[2].split(",") if len(sys.argv) > 2 else ["N", "P", "Q"]
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7, 8, 9]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
train = sp.random_scenarios(0, 64)
val = sp.random_scenarios(2, 256)


def ev(g):
    r = sp.plan_batch(val, gains=g, max_steps=150, chunk=64, **kw)
    return round((np.asarray(r.reached) & ~np.asarray(r.collided)).mean(), 3)


c = sp.default_gains()._replace(
    d0=jnp.asarray(math.sqrt(0.07 * 0.4)), dt=jnp.asarray(math.sqrt(0.1 * 0.8)), eta=jnp.asarray(0.002)
)
BOX = dict(d0=(0.07, 0.4), dt=(0.1, 0.8))  # the grid's box (benchmarks/tuning.py --grid-d0 / --grid-dt)
CONFIGS = dict(  # every one spends 768 rollouts (24 updates x 2 x 16 pairs)
    N=dict(),  # the benchmark's recipe since session 16 (val6.py config N)
    P=dict(bounds=BOX),
    Q=dict(max_step=0.3),
    R=dict(bounds=BOX, max_step=0.3),
    S=dict(max_step=0.15),
)
for name in configs:
    for seed in seeds:
        t = tune_smoothed(train, GainSpace(("d0", "dt"), stable_dt=True), c, sigma=0.4, pairs=16, updates=24,
                          learning_rate=1.0, seed=seed, progress=False, **CONFIGS[name], **kw)
        print(m, name, CONFIGS[name] or "(the recipe)", f"seed={seed}", ev(t.gains),
              {k: round(float(getattr(t.gains, k)), 4) for k in ("d0", "dt")}, flush=True)
