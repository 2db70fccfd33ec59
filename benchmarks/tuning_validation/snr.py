# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 16: signal against noise of the smoothed gradient (training seed 0, 64 scenes, 100 steps) at three
# points, log dt or stable_dt, sigma 0.2 / 0.4, the score's progress weight 1 / 3: the gradient from 512 antithetic
# pairs, its standard error, and the noise of one 16-pair update (se x sqrt(512 / 16)).
# python benchmarks/tuning_validation/snr.py curve > snr_curve.log
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
from softplan_jax.planning.planner import make_options
from softplan_jax.tuning.smoothing import GainSpace, ScoreWeights, estimate_objective, smoothing_sample

m = sys.argv[1]
kw = dict(method="curve", n_points=10) if m == "curve" else dict(method="points", n_points=int(m))
opts = make_options(**kw)
train = sp.random_scenarios(0, 64)
base = sp.default_gains(jnp.float64)
for stable in (False, True):
    space = GainSpace(stable_dt=stable)
    for sigma in (0.2, 0.4):
        for pt in [(0.167, 0.283, 0.002), (0.25, 0.5, 0.002), (0.35, 0.75, 0.003)]:
            g = base._replace(d0=jnp.asarray(pt[0]), dt=jnp.asarray(pt[1]), eta=jnp.asarray(pt[2]))
            th = space.encode(g)
            for w in (ScoreWeights(), ScoreWeights(progress=3.0)):
                s = smoothing_sample(th, space, base, train, jax.random.PRNGKey(3), pairs=512, sigma=sigma,
                                     max_steps=100, options=opts, weights=w)
                e = estimate_objective(s)
                noise = e.grad_se * math.sqrt(512 / 16)
                print(m, f"stable={stable} sigma={sigma} pt={pt} w.progress={w.progress}: J {e.value:.3f} grad "
                      f"{np.round(e.grad, 3)} se(512) {np.round(e.grad_se, 3)}  -> per-16-pair noise "
                      f"{np.round(noise, 2)}  snr {np.round(np.abs(e.grad) / noise, 2)}", flush=True)
