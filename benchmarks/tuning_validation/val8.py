# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 17: the gain-function stage of benchmarks/tuning.py (20 parameters: log d0, dt, eta, a 14-knot
# repulsion profile, 3 segment weights; 24 updates of 32 pairs, sigma 0.2, step 0.1) starts from the
# gradient's result, near dt = 0.6-0.9, where sigma 0.2 in log dt straddles the Euler cliff at dt = 1
# (landscape.py). F0: as the benchmark runs it; F1: the same with stable_dt. Judged on the VALIDATION
# seed (2), tuner seeds 5-7 (argv[3]); the start is the recipe's result with argv[2]'s guard.
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.smoothing import GainSpace, tune_smoothed

m = sys.argv[1]
guard = sys.argv[2] if len(sys.argv) > 2 else "clip"
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
train = sp.random_scenarios(0, 64)
val = sp.random_scenarios(2, 256)


def ev(g):
    r = sp.plan_batch(val, gains=g, max_steps=150, chunk=64, **kw)
    return round((np.asarray(r.reached) & ~np.asarray(r.collided)).mean(), 3)


c = sp.default_gains()._replace(
    d0=jnp.asarray(math.sqrt(0.07 * 0.4)), dt=jnp.asarray(math.sqrt(0.1 * 0.8)), eta=jnp.asarray(0.002)
)
GUARDS = dict(box=dict(bounds=dict(d0=(0.07, 0.4), dt=(0.1, 0.8))), clip=dict(max_step=0.3), none=dict())
for seed in seeds:
    t = tune_smoothed(train, GainSpace(("d0", "dt"), stable_dt=True), c, sigma=0.4, pairs=16, updates=24,
                      learning_rate=1.0, seed=seed, progress=False, **GUARDS[guard], **kw)
    print(m, "start", guard, f"seed={seed}", ev(t.gains), flush=True)
    for name, stable in (("F0", False), ("F1", True)):
        f = tune_smoothed(train, GainSpace(("d0", "dt", "eta"), knots=14, segments=3, stable_dt=stable), t.gains,
                          updates=24, pairs=32, sigma=0.2, learning_rate=0.1, seed=seed + 1, progress=False, **kw)
        print(m, name, f"stable_dt={stable}", f"seed={seed}", ev(f.gains),
              {k: round(float(getattr(f.gains, k)), 4) for k in ("d0", "dt", "eta")}, flush=True)
