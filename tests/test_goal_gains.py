"""Gains that depend on the distance to the goal (GainFunction.goal_profile), the
objective's time and path terms (ScoreWeights), and tune_smoothed's recipe defaults.

References: a hand-computed piecewise-linear interpolation; central differences of one
planner step; the rollout's own arrays for the score; the constant gains themselves for a
zero profile (the same arrays, bit for bit, from the single-scene program).
"""

import math
import warnings
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planning import planner_step
from softplan_jax.planning._planner import make_options
from softplan_jax.planning._step import GOAL_GAINS, goal_scaled
from softplan_jax.tuning import GainSpace, ScoreWeights, estimate_objective, rollout_score, smoothing_sample
from softplan_jax.tuning._tuner import (
    RECIPE_SPACE,
    RECIPE_WEIGHTS,
    recipe_sigma,
    recipe_start,
    tune_smoothed,
)


def _profile(K=4, seed=0):
    return jnp.asarray(np.random.default_rng(seed).normal(0, 0.5, (len(GOAL_GAINS), K)))


def test_zero_goal_profile_plans_exactly_as_the_constant_gains():
    """sp.plan with a zero goal profile (and zero repulsion profile and weights) gives
    the constant gains' arrays bit for bit (exp(0) = 1 exactly); a non-zero one changes them."""
    tree = sp.paper_scenario("tree", curve_slots=5, degree=2)  # the constant gains: test_planner's program
    g = sp.default_gains()
    gf = sp.GainFunction.from_gains(g, 2, tree.q0.shape[0], goal_knots=6)
    a, b = sp.plan(tree, gains=g, max_steps=200), sp.plan(tree, gains=gf, max_steps=200)
    assert a.status == "reached"
    for name in ("q", "tip", "clearance", "iterations", "final_error"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)), err_msg=name)
    c = sp.plan(tree, gains=gf._replace(goal_profile=_profile(6)), max_steps=200)
    assert not np.array_equal(np.asarray(a.q), np.asarray(c.q))


def test_goal_scaled_interpolates_the_knots_and_is_finite_at_the_goal():
    g = sp.GainFunction.from_gains(sp.default_gains(), 2, 3)._replace(goal_profile=_profile())
    r = float(g.v_max / g.k_att)  # the linear zone's radius: u = rho / (rho + r)
    P = np.asarray(g.goal_profile)
    K = P.shape[1]
    for u in (0.0, 1 / 3, 0.5, 0.9):
        rho = u * r / (1 - u)
        s = goal_scaled(g, jnp.array([rho, 0.0, 0.0]))
        x = u * (K - 1)
        i = min(int(math.floor(x)), K - 2)
        t = x - i
        for row, k in enumerate(GOAL_GAINS):
            want = float(getattr(g, k)) * math.exp((1 - t) * P[row, i] + t * P[row, i + 1])
            assert float(getattr(s, k)) == pytest.approx(want, rel=1e-12), (u, k)
        assert float(s.dt) == float(g.dt) and float(s.damping) == float(g.damping)
    # At the goal (V_e = 0, where |V_e| has no derivative) values and gradients stay finite.
    def total(profile, v):
        s = goal_scaled(g._replace(goal_profile=profile), v)
        return sum(getattr(s, k) for k in GOAL_GAINS)

    gp, gv = jax.grad(total, argnums=(0, 1))(g.goal_profile, jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(gp))) and np.all(np.isfinite(np.asarray(gv)))
    assert goal_scaled(sp.default_gains(), jnp.ones(3)) == sp.default_gains()  # constant gains: unchanged


def test_one_step_gradient_in_the_goal_profile_matches_central_differences():
    """jax.jacfwd of one planner step in the goal profile against central differences; the
    repulsion rows (eta, d0) act on the tree's start, where d0 = 0.3 reaches the branches.
    (The padded tree, default options and this GainFunction's structure: the central
    differences step with test_smoothing's compiled planner_step.)"""
    tree = sp.paper_scenario("tree", curve_slots=5, degree=2)
    g = sp.GainFunction.from_gains(sp.default_gains()._replace(d0=jnp.asarray(0.3, jnp.float64)), 5, 3, goal_knots=3)
    P0 = _profile(3, seed=1)
    opts = make_options("curve")

    def step(P):
        return planner_step(tree.q0, tree, g._replace(goal_profile=P), opts)

    jac = np.asarray(jax.jacfwd(step)(P0))  # (n, 3, G, K)
    h = 1e-6
    fd = np.zeros_like(jac)
    for i in range(P0.shape[0]):
        for j in range(P0.shape[1]):
            e = jnp.zeros_like(P0).at[i, j].set(h)
            fd[..., i, j] = (np.asarray(step(P0 + e)) - np.asarray(step(P0 - e))) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-8)
    for row in (GOAL_GAINS.index("eta"), GOAL_GAINS.index("d0")):
        assert np.abs(jac[..., row, :]).max() > 1e-6, GOAL_GAINS[row]


def test_gain_space_with_goal_knots_round_trips():
    space = GainSpace(("d0", "dt"), stable_dt=True, goal_knots=3).check(3)
    assert space.size == 2 + 4 * 3 and space.is_function
    base = space.base(sp.default_gains(), 3)
    assert base.goal_profile.shape == (4, 3) and not np.any(np.asarray(base.goal_profile))
    theta0 = space.encode(base)
    np.testing.assert_array_equal(np.asarray(theta0[2:]), 0.0)
    theta = theta0.at[2:].set(jnp.arange(12.0) / 8)  # exact binary fractions
    g = space.decode(theta, base)
    np.testing.assert_array_equal(np.asarray(g.goal_profile), np.arange(12.0).reshape(4, 3) / 8)
    np.testing.assert_allclose(np.asarray(space.encode(g)), np.asarray(theta), rtol=1e-12)


def test_gains_file_keeps_the_goal_profile_and_rejects_a_bad_one(tmp_path):
    g = sp.GainFunction.from_gains(sp.default_gains(), 2, 3)._replace(goal_profile=_profile(5))
    path = tmp_path / "g.json"
    sp.save_gains(g, path, method="curve")
    back = sp.load_gains(path, method="curve")
    np.testing.assert_array_equal(np.asarray(back.goal_profile), np.asarray(g.goal_profile))
    base = sp.tuning.gains_to_dict(g)
    for bad, match in (([[0.0, 1.0]] * 3, "4 lists"), ([[0.0]] * 4, "K >= 2"),
                       ([[0.0, 1.0]] * 3 + [[0.0, 1.0, 2.0]], "one length"), ([[0.0, "x"]] * 4, "4 lists")):
        d = dict(base, gains=dict(base["gains"], goal_profile=bad))
        with pytest.raises(ValueError, match="gains.goal_profile"):
            sp.tuning.gains_from_dict(d)
        with pytest.raises(ValueError, match=match):
            sp.tuning.gains_from_dict(d)
    d = dict(base, gains={k: v for k, v in base["gains"].items() if k not in ("rep_profile", "seg_weights")})
    with pytest.raises(ValueError, match="needs rep_profile"):
        sp.tuning.gains_from_dict(d)
    with pytest.raises(ValueError, match="goal_profile"):
        sp.plan(sp.paper_scenario("tree"), gains=g._replace(goal_profile=jnp.zeros((3, 4))))


def test_score_weights_time_and_path_terms_against_the_rollout():
    tip = jnp.array([[0.0, 0, 0], [0.3, 0, 0], [0.3, 0.4, 0], [0.3, 0.4, 0]])
    scene = SimpleNamespace(goal=jnp.array([0.3, 0.4, 0.0]))
    err = np.linalg.norm(np.asarray(scene.goal) - np.asarray(tip), axis=-1)
    base = err.mean() / err[0]
    w = ScoreWeights(steps=2.0, fallback=5.0, path_length=0.5)
    reached = SimpleNamespace(tip=tip, reached=jnp.asarray(True), collided=jnp.asarray(False),
                              iterations=jnp.asarray(2))
    assert float(rollout_score(reached, scene, w)) == pytest.approx(base + 2.0 * 2 / 3 + 0.5 * 0.7 / 0.5)
    failed = SimpleNamespace(**{**vars(reached), "reached": jnp.asarray(False)})
    assert float(rollout_score(failed, scene, w)) == pytest.approx(base + 1.0 + 2.0 * (1 + 5.0) + 0.5 * 0.7 / 0.5)
    assert float(rollout_score(reached, scene)) == pytest.approx(base)  # the default weights: progress alone


def test_tune_smoothed_defaults_are_the_recipe():
    """tune_smoothed(suite) with no settings: RECIPE_SPACE from recipe_start, recipe_sigma,
    RECIPE_WEIGHTS, the natural gradient from step 3.75 clipped to 0.3 (the first update
    recomputed from the update's key), and a GainFunction with its goal profile."""
    suite = sp.random_scenarios(0, 4)
    res = tune_smoothed(suite, updates=1, pairs=2, max_steps=20, progress=False)
    assert res.space == RECIPE_SPACE and res.theta.shape == (RECIPE_SPACE.size,) and RECIPE_SPACE.size == 26
    assert isinstance(res.gains, sp.GainFunction) and res.gains.goal_profile.shape == (4, 6)
    base = RECIPE_SPACE.base(recipe_start(), 3)
    theta0 = RECIPE_SPACE.encode(base)
    np.testing.assert_allclose(res.history["theta"][0], np.asarray(theta0), rtol=1e-15)
    sigma = np.asarray(recipe_sigma(RECIPE_SPACE))
    assert sigma[1] == 0.7 and sigma[0] == 0.3 and np.all(sigma[2:] == 0.5)
    first = estimate_objective(smoothing_sample(theta0, RECIPE_SPACE, base, suite,
                                                jax.random.fold_in(jax.random.PRNGKey(0), 0), pairs=2,
                                                sigma=tuple(sigma), max_steps=20, weights=RECIPE_WEIGHTS))
    step = np.clip(-3.75 * sigma**2 * first.grad, -0.3, 0.3)
    assert np.any(step != 0)
    np.testing.assert_allclose(res.history["theta"][1], np.asarray(theta0) + step, rtol=1e-10, atol=1e-14)


def test_euler_warning_sees_the_goal_profile_and_the_space_its_knots():
    """k_att * dt below 2 for the constants, past it with a profile that doubles k_att near
    the goal (and not with one that doubles it only far away); a start whose goal profile
    has other knots than the space is refused."""
    g = sp.GainFunction.from_gains(sp.default_gains()._replace(dt=jnp.asarray(0.6)), 2, 3, goal_knots=3)
    near = g._replace(goal_profile=jnp.zeros((4, 3)).at[0, 0].set(math.log(2.0)))
    far = g._replace(goal_profile=jnp.zeros((4, 3)).at[0, 2].set(math.log(2.0)))
    with pytest.warns(UserWarning, match="goal profile"):
        sp.planning._planner.check_gains(near, jnp.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sp.planning._planner.check_gains(far, jnp.float64)
        sp.planning._planner.check_gains(g, jnp.float64)
    with pytest.raises(ValueError, match="goal_knots = 6"):
        tune_smoothed(sp.random_scenarios(0, 2), gains=g, updates=1, pairs=2, max_steps=5, progress=False)
