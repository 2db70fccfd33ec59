# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 17: a step guard for the benchmark's gradient recipe (val6.py's config N: d0, dt with
# stable_dt, sigma 0.4, step 1.0): projection onto the grid's box (bounds) or per-update clipping
# (max_step). Judged on the VALIDATION seed (2) with tuner seeds 5-9; the held-out seed (1) and the
# tuner seeds 0-4 that benchmarks/tuning_seeds.py reports are not used here.
import sys

import jax

jax.config.update("jax_enable_x64", True)
from _recipe import BOX, tune_recipe, validation_success

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
configs = sys.argv[2].split(",") if len(sys.argv) > 2 else ["N", "P", "Q"]
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7, 8, 9]
CONFIGS = dict(  # every one spends 768 rollouts (24 updates x 2 x 16 pairs)
    N=dict(),  # the benchmark's recipe since session 16 (val6.py config N)
    P=dict(bounds=BOX),
    Q=dict(max_step=0.3),
    R=dict(bounds=BOX, max_step=0.3),
    S=dict(max_step=0.15),
)
for name in configs:
    for seed in seeds:
        t = tune_recipe(m, seed, **CONFIGS[name])
        print(m, name, CONFIGS[name] or "(the recipe)", f"seed={seed}", validation_success(t.gains, m),
              {k: round(float(getattr(t.gains, k)), 4) for k in ("d0", "dt")}, flush=True)
