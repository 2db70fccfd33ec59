# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Tuner variants judged on a VALIDATION seed (2), never the held-out seed (1).
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
    ok = np.asarray(r.reached) & ~np.asarray(r.collided)
    return ok.mean()


out = {}
t3 = tune_smoothed(
    train, GainSpace(), updates=12, pairs=32, max_steps=100, progress=False, optimizer=optax.adam(0.3), average=0.0, **kw
)
out["3 last"] = ev(t3.gains)
theta_avg = t3.history["theta"][-6:].mean(0)
g3avg = GainSpace().decode(jnp.asarray(theta_avg), sp.default_gains())
out["3 avg"] = ev(g3avg)
for name, space, avg, lr, pairs, ups in [
    ("A 22 adam.1", GainSpace(("k_att", "v_max", "eta", "d0", "dt"), 14, 3), 0.0, 0.1, 32, 24),
    ("A 22 adam.1 avg", GainSpace(("k_att", "v_max", "eta", "d0", "dt"), 14, 3), 0.5, 0.1, 32, 24),
    ("B 20 adam.1 avg", GainSpace(("eta", "d0", "dt"), 14, 3), 0.5, 0.1, 32, 24),
    ("B 20 adam.05 p64 avg", GainSpace(("eta", "d0", "dt"), 14, 3), 0.5, 0.05, 64, 12),
]:
    r = tune_smoothed(
        train,
        space,
        t3.gains,
        updates=ups,
        pairs=pairs,
        optimizer=optax.adam(lr),
        max_steps=100,
        seed=1,
        average=avg,
        progress=False,
        **kw,
    )
    out[name] = ev(r.gains)
    print(
        name,
        out[name],
        {k: round(float(getattr(r.gains, k)), 4) for k in ("k_att", "v_max", "eta", "d0", "dt")},
        np.round(np.asarray(r.gains.rep_profile), 2),
        np.round(np.asarray(r.gains.seg_weights), 2),
        flush=True,
    )
print(out)
