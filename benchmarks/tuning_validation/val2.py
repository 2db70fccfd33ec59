# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Gradient-tuner settings judged on a VALIDATION seed (2), never the held-out seed (1).
import sys

import jax
import numpy as np
import optax

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

m = sys.argv[1]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
train = sp.random_scenarios(0, 64)
val = sp.random_scenarios(2, 256)


def ev(g):
    r = sp.plan_batch(val, gains=g, max_steps=150, chunk=64, **kw)
    return (np.asarray(r.reached) & ~np.asarray(r.collided)).mean()


for name, sigma, lr, ups, pairs in [
    ("V1 s.2 lr.3", 0.2, 0.3, 12, 32),
    ("V2 s.4 lr.3", 0.4, 0.3, 12, 32),
    ("V4 s.4 lr.4", 0.4, 0.4, 12, 32),
    ("V5 s.3 lr.4", 0.3, 0.4, 12, 32),
    ("V3 s.3 lr.3 24x16", 0.3, 0.3, 24, 16),
]:
    r = tune_smoothed(
        train,
        GainSpace(),
        updates=ups,
        pairs=pairs,
        sigma=sigma,
        optimizer=optax.adam(lr),
        average=0.0,
        max_steps=100,
        progress=False,
        **kw,
    )
    print(m, name, ev(r.gains), {k: round(float(getattr(r.gains, k)), 4) for k in ("eta", "d0", "dt")}, flush=True)
