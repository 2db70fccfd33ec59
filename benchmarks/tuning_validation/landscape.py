# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 16: the landscape of the 3 gains. Per setting: the training mean score L (seed 0, 64 scenes,
# 100 steps: what the tuners see) and the validation success (seed 2, 256 scenes, 150 steps).
# python benchmarks/tuning_validation/landscape.py curve > landscape_curve.log  (writes landscape_curve.json)
import itertools
import json
import os
import sys
import time

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.planning.planner import make_options
from softplan_jax.tuning.smoothing import GainSpace, score_batch

m = sys.argv[1]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
opts = make_options(**kw)
base = sp.default_gains(jnp.float64)
space = GainSpace(("d0", "dt", "eta"))
train = sp.random_scenarios(0, 64)
val = sp.random_scenarios(2, 256)
keys_t = jax.random.split(jax.random.PRNGKey(5), 64)
keys_v = jax.random.split(jax.random.PRNGKey(6), 256)
rows = []
t0 = time.time()
grid = itertools.product([0.1, 0.15, 0.2, 0.3, 0.4, 0.55], [0.2, 0.4, 0.6, 0.8, 1.1], [0.001, 0.002, 0.004])
for d0, dt, eta in grid:
    th = jnp.log(jnp.array([d0, dt, eta]))
    Lt, rt, ct = score_batch(jnp.tile(th, (64, 1)), space, base, train, keys_t, opts, 100)
    Lv, rv, cv = score_batch(jnp.tile(th, (256, 1)), space, base, val, keys_v, opts, 150)
    row = dict(d0=d0, dt=dt, eta=eta, Lt=float(Lt.mean()), st=float((rt & ~ct).mean()), Lv=float(Lv.mean()),
               sv=float((rv & ~cv).mean()))
    rows.append(row)
    print(f"{d0:5.2f} {dt:4.1f} {eta:.3f}  train L {row['Lt']:.3f} succ {row['st']:.3f}   val L {row['Lv']:.3f} "
          f"succ {row['sv']:.3f}  ({time.time() - t0:.0f}s)", flush=True)
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), f"landscape_{m}.json"), "w") as fh:
    json.dump(rows, fh)
