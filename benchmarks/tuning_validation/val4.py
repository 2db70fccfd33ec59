# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Gradient-tuner settings judged on a VALIDATION seed (2), never the held-out seed (1).
import math
import sys

import jax
import jax.numpy as jnp
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


c = sp.default_gains()._replace(
    d0=jnp.asarray(math.sqrt(0.07 * 0.4)), dt=jnp.asarray(math.sqrt(0.1 * 0.8)), eta=jnp.asarray(0.002)
)
d = sp.default_gains()
U = 24
for name, start, opt, avg in [
    ("D1 centre adam.2cos avg1/3", c, lambda: optax.adam(optax.cosine_decay_schedule(0.2, U, alpha=0.1)), 1 / 3),
    (
        "D2 centre sgd.1cos m.5 avg1/3",
        c,
        lambda: optax.sgd(optax.cosine_decay_schedule(0.1, U, alpha=0.1), momentum=0.5),
        1 / 3,
    ),
    ("D3 default adam.3cos avg1/3", d, lambda: optax.adam(optax.cosine_decay_schedule(0.3, U, alpha=0.1)), 1 / 3),
    (
        "D4 default sgd.2cos m.5 avg1/3",
        d,
        lambda: optax.sgd(optax.cosine_decay_schedule(0.2, U, alpha=0.1), momentum=0.5),
        1 / 3,
    ),
]:
    res = []
    for seed in (0, 1):
        r = tune_smoothed(
            train,
            GainSpace(),
            start,
            updates=U,
            pairs=16,
            max_steps=100,
            progress=False,
            seed=seed,
            optimizer=opt(),
            average=avg,
            **kw,
        )
        res.append((round(ev(r.gains), 3), {k: round(float(getattr(r.gains, k)), 4) for k in ("eta", "d0", "dt")}))
    print(m, name, res, flush=True)
