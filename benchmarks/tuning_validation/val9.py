# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 18: narrowing the seed spread of the benchmark's recipe (val7.py config Q: d0, dt with
# stable_dt, sigma 0.4, step 1.0, clip 0.3) at the same 768 rollouts. Judged on the VALIDATION seed
# (2) with tuner seeds 5-9, as val7.py; config Q's rows are val7.py's (the same code and seeds).
import sys

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
from _recipe import CENTRE, tune_recipe, validation_success

from softplan_jax.tuning.smoothing import ScoreWeights

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
configs = sys.argv[2].split(",") if len(sys.argv) > 2 else ["T", "C", "R"]
seeds = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 6, 7, 8, 9]
# the grid box's centre in the tuner's own coordinates: log d0 as CENTRE, logit(dt k_att / 2) halfway
# between the box's dt ends 0.1 and 0.8 at k_att = 2, i.e. dt = 0.4 (CENTRE's dt is the log-centre 0.283)
LOGIT_CENTRE = CENTRE._replace(dt=jnp.asarray(0.4))
CONFIGS = dict(  # all but B spend 768 rollouts (24 updates x 2 x 16 pairs)
    Q=dict(max_step=0.3),  # the benchmark's recipe (val7.py config Q)
    T=dict(max_step=0.3, sigma=0.6),  # wider smoothing: a flip-driven estimate's variance falls as 1 / sigma
    C=dict(max_step=0.3, start=LOGIT_CENTRE),  # start at the box centre in the tuner's coordinates
    R=dict(max_step=0.3, reshuffle=True),  # scenes drawn epoch by epoch (random reshuffling)
    W=dict(max_step=0.3, weights=ScoreWeights(progress=3.0)),  # the smooth progress term weighted 3 (less flip noise)
    B=dict(max_step=0.3, pairs=32),  # twice the budget (1,536 rollouts, 2/5 of the grid's): half the noise
)
for name in configs:
    for seed in seeds:
        t = tune_recipe(m, seed, **CONFIGS[name])
        shown = {k: (v if k == "weights" else round(float(v), 4) if k != "start" else "dt 0.4")
                 for k, v in CONFIGS[name].items()}
        print(m, name, shown, f"seed={seed}", validation_success(t.gains, m),
              {k: round(float(getattr(t.gains, k)), 4) for k in ("d0", "dt")}, flush=True)
