# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 19: the gain-function stage of benchmarks/tuning.py (20 parameters: d0, dt, eta, a 14-knot
# repulsion profile, 3 segment weights; 24 updates of 32 pairs) and its ablation on the three gains,
# from the new recipe's result (val10.py config N37b), which ends near dt 0.75: there the stage's
# old settings (log dt, sigma 0.2, step 0.1; F0 and its ablation G0) put perturbations past the
# Euler bound dt = 1 (dt * exp(2 * 0.2) = 1.1). FN, FN2, GN: dt with stable_dt, the natural gradient
# (step 3.75 sigma^2 grad J, as the recipe), sigma 0.3 / 0.7 / 0.3 for d0 / dt / eta, and 0.3 (FN)
# or 0.2 (FN2) for the profile and the segment weights; GN: the three gains alone with those settings (the ablation).
# Judged on the VALIDATION seed (2) with tuner seeds 5-9.
#   python val11.py {curve,10,50} [CONFIGS] [SEEDS]
import sys

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np
from _recipe import TRAIN, plan_kw, tune_recipe, validation_success

from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
configs = sys.argv[2].split(",") if len(sys.argv) > 2 else ["F0", "G0", "FN", "FN2", "GN"]
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7, 8, 9]
GAINS3 = ("d0", "dt", "eta")
NEW = dict(natural=True, learning_rate=3.75, max_step=0.3)
CONFIGS = dict(
    F0=(GainSpace(GAINS3, knots=14, segments=3), dict(sigma=0.2, learning_rate=0.1)),
    G0=(GainSpace(GAINS3), dict(sigma=0.2, learning_rate=0.1)),
    FN=(GainSpace(GAINS3, knots=14, segments=3, stable_dt=True), dict(sigma=(0.3, 0.7, 0.3) + (0.3,) * 17, **NEW)),
    FN2=(GainSpace(GAINS3, knots=14, segments=3, stable_dt=True), dict(sigma=(0.3, 0.7, 0.3) + (0.2,) * 17, **NEW)),
    GN=(GainSpace(GAINS3, stable_dt=True), dict(sigma=(0.3, 0.7, 0.3), **NEW)),
)
succ = {c: [] for c in ["start", *configs]}
for seed in seeds:
    t = tune_recipe(m, seed, max_step=0.3, sigma=(0.3, 0.7), natural=True, learning_rate=3.75)
    succ["start"].append(validation_success(t.gains, m))
    print(m, "start (val10 N37b)", f"seed={seed}", succ["start"][-1], flush=True)
    for name in configs:
        space, kw = CONFIGS[name]
        f = tune_smoothed(TRAIN, space, t.gains, updates=24, pairs=32, seed=seed + 1, progress=False, **kw,
                          **plan_kw(m))
        succ[name].append(validation_success(f.gains, m))
        print(m, name, f"seed={seed}", succ[name][-1], {k: round(float(getattr(f.gains, k)), 4) for k in GAINS3},
              flush=True)
for name, s in succ.items():
    s = np.asarray(s)
    print(f"{m} {name} SUMMARY seeds {seeds[0]}-{seeds[-1]}: mean {s.mean():.3f} min {s.min():.3f} max {s.max():.3f}",
          flush=True)
