# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 17: the gain-function stage of benchmarks/tuning.py (20 parameters: log d0, dt, eta, a 14-knot
# repulsion profile, 3 segment weights; 24 updates of 32 pairs, sigma 0.2, step 0.1) starts from the
# gradient's result, near dt = 0.6-0.9, where sigma 0.2 in log dt straddles the Euler cliff at dt = 1
# (landscape.py). F0: as the benchmark runs it; F1: the same with stable_dt. Judged on the VALIDATION
# seed (2), tuner seeds 5-7 (argv[3]); the start is the recipe's result with argv[2]'s guard.
import sys

import jax

jax.config.update("jax_enable_x64", True)
from _recipe import BOX, TRAIN, plan_kw, tune_recipe, validation_success

from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
guard = sys.argv[2] if len(sys.argv) > 2 else "clip"
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7]
GUARDS = dict(box=dict(bounds=BOX), clip=dict(max_step=0.3), none=dict())
for seed in seeds:
    t = tune_recipe(m, seed, **GUARDS[guard])
    print(m, "start", guard, f"seed={seed}", validation_success(t.gains, m), flush=True)
    for name, stable in (("F0", False), ("F1", True)):
        f = tune_smoothed(TRAIN, GainSpace(("d0", "dt", "eta"), knots=14, segments=3, stable_dt=stable), t.gains,
                          updates=24, pairs=32, sigma=0.2, learning_rate=0.1, seed=seed + 1, progress=False,
                          **plan_kw(m))
        print(m, name, f"stable_dt={stable}", f"seed={seed}", validation_success(f.gains, m),
              {k: round(float(getattr(f.gains, k)), 4) for k in ("d0", "dt", "eta")}, flush=True)
