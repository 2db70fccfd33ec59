# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Function-stage settings judged on a VALIDATION seed (2), never the held-out seed (1).
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.tuning.smoothing import GainSpace, tune_smoothed

m = sys.argv[1]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
train = sp.random_scenarios(0, 64)
val = sp.random_scenarios(2, 256)


def ev(g):
    r = sp.plan_batch(val, gains=g, max_steps=150, chunk=64, **kw)
    return round((np.asarray(r.reached) & ~np.asarray(r.collided)).mean(), 3)


grid = dict(curve=(0.4, 0.8, 0.004), **{"10": (0.3, 0.6, 0.004)})[m]
print(
    m,
    "grid",
    ev(sp.default_gains()._replace(d0=jnp.asarray(grid[0]), dt=jnp.asarray(grid[1]), eta=jnp.asarray(grid[2]))),
    flush=True,
)
c = sp.default_gains()._replace(
    d0=jnp.asarray(math.sqrt(0.07 * 0.4)), dt=jnp.asarray(math.sqrt(0.1 * 0.8)), eta=jnp.asarray(0.002)
)
t3 = tune_smoothed(train, GainSpace(), c, progress=False, **kw)
print(
    m,
    "3 (new defaults)",
    ev(t3.gains),
    {k: round(float(getattr(t3.gains, k)), 4) for k in ("eta", "d0", "dt")},
    flush=True,
)
B = GainSpace(("eta", "d0", "dt"), knots=14, segments=3)
for name, ups, pairs, lr in [("F1 24x16", 24, 16, 0.1), ("F2 24x32", 24, 32, 0.1), ("F3 24x16 lr.05", 24, 16, 0.05)]:
    r = tune_smoothed(train, B, t3.gains, updates=ups, pairs=pairs, learning_rate=lr, seed=1, progress=False, **kw)
    print(
        m,
        name,
        ev(r.gains),
        {k: round(float(getattr(r.gains, k)), 4) for k in ("eta", "d0", "dt")},
        np.round(np.asarray(r.gains.rep_profile), 2),
        np.round(np.asarray(r.gains.seg_weights), 2),
        flush=True,
    )
