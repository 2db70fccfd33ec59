# ruff: noqa: E402  (jax_enable_x64 before softplan_jax is imported)
# Session 19: the smoothed gradient's signal and noise per coordinate (log d0, dt's logit) at three
# points on the way from the grid box's centre to the ridge, with one smoothing scale (0.4, the
# recipe of sessions 16-18) and with one per coordinate (0.3, 0.7; val10.py). 512 antithetic pairs
# per point on the TRAINING suite (what the tuner sees), 100 steps. Per pair n the estimate is
# g_n = (L+ - L-) / 2 * eps_n / sigma; "signal" is the mean of g_n, "noise" their standard
# deviation (one 16-pair update has noise / 4), snr = signal / noise per pair.
#   python snr_coords.py {curve,10,50}
import sys

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np
from _recipe import CENTRE, TRAIN, plan_kw

from softplan_jax.planning.planner import make_options
from softplan_jax.tuning.smoothing import GainSpace, estimate_objective, smoothing_sample

m = sys.argv[1] if sys.argv[1] == "curve" else int(sys.argv[1])
space = GainSpace(("d0", "dt"), stable_dt=True)
opts = make_options(**plan_kw(m))
n = 512
for sigma in (0.4, (0.3, 0.7)):
    for d0, dt in ((0.167, 0.283), (0.3, 0.5), (0.3, 0.75)):
        start = CENTRE._replace(d0=jnp.asarray(d0), dt=jnp.asarray(dt))
        theta = space.encode(start)
        s = smoothing_sample(theta, space, start, TRAIN, jax.random.PRNGKey(3), pairs=n, sigma=sigma, options=opts,
                             max_steps=100)
        est = estimate_objective(s)  # grad: the mean of g_n; grad_se: their standard deviation / sqrt(n)
        mean, sd = est.grad, est.grad_se * np.sqrt(n)
        ok = np.asarray(s.reached) & ~np.asarray(s.collided)
        print(f"{m} sigma {sigma} at d0 {d0} dt {dt}: J {est.value:.3f} success {ok.mean():.3f} pairs that flip "
              f"{np.mean(ok[:n] != ok[n:]):.3f} | signal d0 {mean[0]:+.3f} dt {mean[1]:+.3f} | noise per pair "
              f"d0 {sd[0]:.3f} dt {sd[1]:.3f} | snr per pair d0 {mean[0] / sd[0]:+.3f} dt {mean[1] / sd[1]:+.3f}",
              flush=True)
