"""The smoothed tuning objective (softplan_jax.tuning._objective, .tuner): its gradient
against central finite differences of the same objective, against re-run
differences of the smoothed objective (common random numbers), the GainFunction
against the Gains it generalises, tune_smoothed's history and budget, bad input.

One compiled program of rollout scores is shared by the float64 tests (4 pairs,
20 steps, the default GainSpace); the float32 smoke test and the slow re-run
check compile their own.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planning._planner import make_options
from softplan_jax.tuning import (
    GainSpace,
    ScoreWeights,
    estimate_objective,
    smoothed_objective,
    smoothing_sample,
    tune_smoothed,
)

PAIRS, STEPS, SIGMA = 4, 20, 0.2
SIGMA_EACH = (0.15, 0.4, 0.25)  # one smoothing scale per coordinate of the default GainSpace
SETTINGS = [dict(), dict(d0=0.2, dt=0.4, eta=0.002), dict(d0=0.3, dt=0.6, eta=0.004)]
# The plain SGD of the checks below (tune_smoothed's defaults are the recipe: natural gradient,
# clip, recipe start and objective).
PLAIN = dict(gains=sp.default_gains(), natural=False, max_step=None, weights=ScoreWeights())


@pytest.fixture(scope="module")
def suite():
    return sp.random_scenarios(0, 8)


def _base(setting):
    return sp.default_gains()._replace(**{k: jnp.asarray(v, jnp.float64) for k, v in setting.items()})


@pytest.mark.parametrize("sigma", [SIGMA, SIGMA_EACH], ids=["one-sigma", "sigma-per-coordinate"])
@pytest.mark.parametrize("setting", SETTINGS, ids=["defaults", "mid", "large"])
def test_gradient_matches_central_differences_of_the_objective(suite, setting, sigma):
    """jax.grad of smoothed_objective against central differences of smoothed_objective
    itself (the same sample of rollouts), every component within 10 %, at the default gains
    and two other settings, with one smoothing scale and with one per coordinate; and
    equal to the antithetic score-function formula."""
    space = GainSpace()
    base = _base(setting)
    theta = space.encode(base)
    sample = smoothing_sample(theta, space, base, suite, jax.random.PRNGKey(3), pairs=PAIRS, sigma=sigma,
                              max_steps=STEPS)
    sig = np.asarray(sigma)
    assert np.asarray(sample.sigma).shape == sig.shape
    grad = np.asarray(jax.grad(smoothed_objective)(theta, sample))
    assert np.all(np.isfinite(grad))
    # Scores differ between rollouts (else the gradient would be identically zero).
    assert np.ptp(np.asarray(sample.scores)) > 1e-3
    for h in (1e-2, 1e-3):
        fd = np.array([(float(smoothed_objective(theta.at[j].add(h), sample))
                        - float(smoothed_objective(theta.at[j].add(-h), sample))) / (2 * h)
                       for j in range(space.size)])
        rel = np.abs(fd - grad) / np.abs(fd)
        assert np.all(rel <= 0.1), (h, grad, fd, rel)
    # The value at the centre is the mean score; the gradient the antithetic formula.
    L = np.asarray(sample.scores)
    eps = (np.asarray(sample.x[:PAIRS]) - np.asarray(theta)) / sig
    np.testing.assert_allclose(np.asarray(sample.x[PAIRS:]), np.asarray(theta) - sig * eps, rtol=1e-12)
    formula = (((L[:PAIRS] - L[PAIRS:]) / 2)[:, None] * eps / sig).mean(0)
    np.testing.assert_allclose(grad, formula, rtol=1e-9, atol=1e-12)
    est = estimate_objective(sample)
    assert est.value == pytest.approx(L.mean(), rel=1e-12)
    # The same mean summed in another order: a component that cancels keeps fewer digits.
    np.testing.assert_allclose(est.grad, grad, rtol=1e-9, atol=1e-12)
    assert est.rollouts == 2 * PAIRS and np.all(est.grad_se > 0)


@pytest.mark.slow
@pytest.mark.parametrize("sigma", [SIGMA, SIGMA_EACH], ids=["one-sigma", "sigma-per-coordinate"])
def test_gradient_agrees_with_rerun_differences_of_the_smoothed_objective(sigma):
    """The gradient estimate predicts FINITE steps of the smoothed objective: central
    differences from fresh rollouts at theta +- h e_j (the same scenes, perturbations
    and escape keys: common random numbers), every component within 3 combined
    standard errors, and every component whose difference is clearly nonzero (beyond 3
    standard errors) has the difference's sign; with one sigma and with one per coordinate."""
    suite = sp.random_scenarios(0, 128)
    space = GainSpace()
    base = _base({})
    theta = space.encode(base)
    key = jax.random.PRNGKey(11)
    n, h = 128, 0.1
    kw = dict(pairs=n, sigma=sigma, max_steps=60)
    centre = smoothing_sample(theta, space, base, suite, key, **kw)
    est = estimate_objective(centre)
    for j in range(space.size):
        up = smoothing_sample(theta.at[j].add(h), space, base, suite, key, **kw)
        down = smoothing_sample(theta.at[j].add(-h), space, base, suite, key, **kw)
        per_pair = ((np.asarray(up.scores).reshape(2, n).mean(0) - np.asarray(down.scores).reshape(2, n).mean(0))
                    / (2 * h))
        fd, fd_se = per_pair.mean(), per_pair.std(ddof=1) / math.sqrt(n)
        z = (est.grad[j] - fd) / math.hypot(est.grad_se[j], fd_se)
        assert abs(z) <= 3.0, (j, est.grad[j], est.grad_se[j], fd, fd_se)
        if abs(fd) > 3 * fd_se:  # a clearly nonzero slope: the gradient has its sign
            assert np.sign(est.grad[j]) == np.sign(fd), (j, est.grad[j], fd)


def test_tune_smoothed_history_budget_progress_and_file(suite, tmp_path, capsys):
    space = GainSpace()
    res = tune_smoothed(suite, space, **PLAIN, updates=3, pairs=PAIRS, sigma=SIGMA, max_steps=STEPS, learning_rate=0.2,
                        average=1.0)
    err = capsys.readouterr().err
    assert err.count("[tune ") == 3 and "rollouts" in err
    assert res.rollouts == 3 * 2 * PAIRS
    assert res.history["theta"].shape == (4, space.size)
    assert res.history["objective"].shape == (3,) and np.all(np.isfinite(res.history["objective"]))
    np.testing.assert_array_equal(res.history["rollouts"], [8, 16, 24])
    assert np.any(np.abs(np.diff(res.history["theta"], axis=0)) > 0)
    # average=1: the mean of the three iterates after the updates (Polyak-Ruppert).
    np.testing.assert_allclose(res.theta, res.history["theta"][1:].mean(0), rtol=1e-12)
    for i, k in enumerate(space.names):
        assert float(getattr(res.gains, k)) == pytest.approx(math.exp(res.theta[i]))
    assert isinstance(res.gains, sp.Gains)
    # The first update is plain SGD (no momentum yet): theta_1 = theta_0 - lr * grad_0, with
    # grad_0 the gradient of the first update's sample (same key: the same draw).
    first = estimate_objective(smoothing_sample(res.history["theta"][0], space, sp.default_gains(), suite,
                                                jax.random.fold_in(jax.random.PRNGKey(0), 0), pairs=PAIRS,
                                                sigma=SIGMA, max_steps=STEPS))
    np.testing.assert_allclose(res.history["theta"][1], res.history["theta"][0] - 0.2 * first.grad, rtol=1e-10)
    assert res.history["objective"][0] == pytest.approx(first.value, rel=1e-12)
    path = tmp_path / "tuned.json"
    sp.save_gains(res.gains, path, method="curve")
    back = sp.load_gains(path, method="curve")
    for k in sp.Gains._fields:
        assert float(getattr(back, k)) == pytest.approx(float(getattr(res.gains, k)), rel=1e-15)


def test_tune_smoothed_guards_bound_and_clip_the_steps(suite):
    """bounds: every iterate is the projection of the SGD step onto the box (the first
    one exactly clip(theta_0 - lr grad_0, lo, hi)); max_step: the first update is
    -lr grad_0 clipped per coordinate. A large step makes both guards act."""
    space = GainSpace()
    box = dict(d0=(0.05, 0.1), dt=(0.05, 0.2), eta=(0.0005, 0.002))
    lo, hi = (np.log([box[k][i] for k in space.names]) for i in (0, 1))
    kw = dict(PLAIN, updates=2, pairs=PAIRS, sigma=SIGMA, max_steps=STEPS, learning_rate=50.0, progress=False)
    first = estimate_objective(smoothing_sample(space.encode(sp.default_gains()), space, sp.default_gains(), suite,
                                                jax.random.fold_in(jax.random.PRNGKey(0), 0), pairs=PAIRS,
                                                sigma=SIGMA, max_steps=STEPS))
    step = -50.0 * first.grad
    free = tune_smoothed(suite, space, **kw)
    boxed = tune_smoothed(suite, space, bounds=box, **kw)
    clipped = tune_smoothed(suite, space, **dict(kw, max_step=0.05))
    t0 = free.history["theta"][0]
    np.testing.assert_allclose(free.history["theta"][1], t0 + step, rtol=1e-10)
    assert np.any((t0 + step < lo) | (t0 + step > hi))  # unguarded, the step leaves the box
    np.testing.assert_allclose(boxed.history["theta"][1], np.clip(t0 + step, lo, hi), rtol=1e-10)
    assert np.all(boxed.history["theta"] >= lo - 1e-12) and np.all(boxed.history["theta"] <= hi + 1e-12)
    for k in space.names:  # the averaged result stays in the box too
        assert box[k][0] * (1 - 1e-9) <= float(getattr(boxed.gains, k)) <= box[k][1] * (1 + 1e-9)
    assert np.any(np.abs(step) > 0.05)
    np.testing.assert_allclose(clipped.history["theta"][1], t0 + np.clip(step, -0.05, 0.05), rtol=1e-10)
    assert np.all(np.abs(np.diff(clipped.history["theta"], axis=0)) <= 0.05 + 1e-12)


def test_tune_smoothed_natural_gradient_steps(suite):
    """natural=True: the first update is theta_0 - lr sigma^2 grad_0, coordinate by
    coordinate (the natural gradient of the smoothing distribution's mean), with grad_0
    recomputed from the update's key; with one sigma for every coordinate the whole run
    equals the plain one with the learning rate times sigma^2."""
    space = GainSpace()
    kw = dict(PLAIN, updates=2, pairs=PAIRS, max_steps=STEPS, progress=False)
    nat = tune_smoothed(suite, space, **dict(kw, sigma=SIGMA_EACH, learning_rate=2.0, natural=True))
    t0 = nat.history["theta"][0]
    first = estimate_objective(smoothing_sample(t0, space, sp.default_gains(), suite,
                                                jax.random.fold_in(jax.random.PRNGKey(0), 0), pairs=PAIRS,
                                                sigma=SIGMA_EACH, max_steps=STEPS))
    step = -2.0 * np.square(SIGMA_EACH) * first.grad
    assert np.all(step != 0)
    np.testing.assert_allclose(nat.history["theta"][1], t0 + step, rtol=1e-10)
    one = tune_smoothed(suite, space, **dict(kw, sigma=SIGMA, learning_rate=2.0, natural=True))
    plain = tune_smoothed(suite, space, sigma=SIGMA, learning_rate=2.0 * SIGMA**2, **kw)
    np.testing.assert_allclose(one.history["theta"], plain.history["theta"], rtol=1e-10)
    np.testing.assert_allclose(one.theta, plain.theta, rtol=1e-10)


def test_tune_smoothed_reshuffle_uses_every_scene_once_per_epoch(suite):
    """reshuffle: each block of len(suite) / pairs updates uses every scene of the suite
    exactly once, and the first update is the SGD step on the sample of those scenes
    (with the update's own key for perturbations and escapes). Without it, the recorded
    scenes are smoothing_sample's own draw."""
    space = GainSpace()
    kw = dict(PLAIN, updates=4, pairs=PAIRS, sigma=SIGMA, max_steps=STEPS, learning_rate=0.2, progress=False)
    res = tune_smoothed(suite, space, reshuffle=True, **kw)
    scenes = res.history["scenes"]
    assert scenes.shape == (4, PAIRS)
    n = suite.q0.shape[0]
    for epoch in (scenes[:2], scenes[2:]):
        np.testing.assert_array_equal(np.sort(epoch.ravel()), np.arange(n))
    assert not np.array_equal(scenes[:2], scenes[2:])  # a fresh permutation per epoch
    k0 = jax.random.fold_in(jax.random.PRNGKey(0), 0)
    first = estimate_objective(smoothing_sample(res.history["theta"][0], space, sp.default_gains(), suite, k0,
                                                pairs=PAIRS, sigma=SIGMA, max_steps=STEPS, scene_index=scenes[0]))
    np.testing.assert_allclose(res.history["theta"][1], res.history["theta"][0] - 0.2 * first.grad, rtol=1e-10)
    # Independent draws (the default) repeat scenes within an epoch's worth of updates.
    free = tune_smoothed(suite, space, **kw).history["scenes"]
    assert any(len(np.unique(free[i:i + 2])) < n for i in (0, 2))
    for bad, match in ((np.arange(PAIRS - 1), "scene_index"), (np.arange(PAIRS) + n - 1, "index the suite"),
                       (np.zeros(PAIRS), "ints")):
        with pytest.raises(ValueError, match=match):
            smoothing_sample(res.history["theta"][0], space, sp.default_gains(), suite, k0, pairs=PAIRS,
                             max_steps=STEPS, scene_index=bad)


def test_gain_function_generalises_gains():
    """A GainFunction with zero profiles and weights steps exactly as its Gains; a
    constant log-profile c (or constant segment weights c) steps as eta * exp(c).
    (The Gains' step is test_planner's compiled planner_step: the padded tree, default options.)"""
    sc = sp.paper_scenario("tree", curve_slots=5, degree=2)
    g = sp.default_gains()._replace(d0=jnp.asarray(3.0, jnp.float64))  # the branches within d0: the repulsion acts
    q = sc.q0.at[:, 1].set(0.3)
    opts = make_options("curve")
    ref = np.asarray(sp.planning.planner_step(q, sc, g, opts))
    fn = sp.GainFunction.from_gains(g, 5, 3, goal_knots=3)  # test_goal_gains' one-step structure: one program
    np.testing.assert_array_equal(np.asarray(sp.planning.planner_step(q, sc, fn, opts)), ref)
    c = 0.7
    scaled = np.asarray(sp.planning.planner_step(q, sc, g._replace(eta=g.eta * math.exp(c)), opts))
    assert np.abs(scaled - ref).max() > 1e-6  # the repulsion matters here
    # float64, not weakly typed: fn's program (a weak type would compile two more)
    for f in (fn._replace(rep_profile=jnp.full((5,), c, jnp.float64)),
              fn._replace(seg_weights=jnp.full((3,), c, jnp.float64))):
        np.testing.assert_allclose(np.asarray(sp.planning.planner_step(q, sc, f, opts)), scaled, rtol=1e-12, atol=1e-14)


def test_gain_space_encode_decode_round_trip():
    g = sp.default_gains()
    space = GainSpace(("k_att", "v_max", "eta", "d0", "dt"), knots=14, segments=3)
    assert space.size == 22
    base = space.base(g, 3)
    assert isinstance(base, sp.GainFunction)
    theta = jnp.arange(22.0) * 0.01
    back = space.decode(theta, base)
    np.testing.assert_allclose(np.asarray(space.encode(back)), np.asarray(theta), rtol=1e-12, atol=1e-15)
    assert float(back.rep_max) == float(g.rep_max) and float(back.damping) == float(g.damping)


def test_stable_dt_keeps_dt_below_the_euler_bound():
    """GainSpace(stable_dt=True): dt = (2 / k_att) sigmoid(theta_dt), so every theta decodes
    below the bound 2 / k_att of the attraction's Euler step (e <- (1 - dt k_att) e);
    encode inverts decode; the other gains stay log-parametrised; a tuned k_att moves the
    bound with it; the Jacobian of decode is finite everywhere, also at saturation."""
    space = GainSpace(("d0", "dt", "eta"), stable_dt=True)
    base = sp.default_gains()
    for t in (-30.0, -2.0, 0.0, 1.5, 30.0):
        theta = jnp.array([math.log(0.2), t, math.log(0.002)])
        g = space.decode(theta, base)
        bound = 2.0 / float(base.k_att)
        assert 0.0 <= float(g.dt) <= bound
        assert float(g.dt) == pytest.approx(bound / (1.0 + math.exp(-t)), rel=1e-12)
        assert float(g.d0) == pytest.approx(0.2) and float(g.eta) == pytest.approx(0.002)
        if abs(t) < 20:
            np.testing.assert_allclose(np.asarray(space.encode(g)), np.asarray(theta), rtol=1e-10, atol=1e-12)
        jac = np.asarray(jax.jacfwd(lambda th: space.decode(th, base).dt)(theta))
        assert np.all(np.isfinite(jac))
    # The default dt = 0.1 with k_att = 2 is a tenth of the bound: theta = logit(0.1).
    assert float(space.encode(base)[1]) == pytest.approx(math.log(0.1 / 0.9), rel=1e-12)
    both = GainSpace(("k_att", "dt"), stable_dt=True)
    g = both.decode(jnp.array([math.log(4.0), 0.0]), base)
    assert float(g.k_att) == pytest.approx(4.0) and float(g.dt) == pytest.approx(0.25)
    # Without stable_dt nothing changes: dt = exp(theta_dt).
    assert float(GainSpace().decode(jnp.array([0.0, 0.0, 0.0]), base).dt) == 1.0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(updates=0), "updates"),
        (dict(updates=-3), "updates"),
        (dict(pairs=1), "pairs"),
        (dict(max_steps=0), "max_steps"),
        (dict(learning_rate=float("nan")), "learning_rate"),
        (dict(average=1.5), "average"),
        (dict(sigma=0.0), "sigma"),
        (dict(sigma=float("inf")), "sigma"),
        (dict(sigma=(0.1, 0.2)), "one per coordinate"),
        (dict(sigma=(0.1, -0.2, 0.1)), "finite and > 0"),
        (dict(sigma=[[0.1, 0.2, 0.3]]), "one per coordinate"),
        (dict(sigma="0.2"), "sigma"),
        (dict(sigma=True), "sigma"),
        (dict(natural="yes"), "natural"),
        (dict(space=GainSpace(("nope",))), "GainSpace.names"),
        (dict(space=GainSpace((), knots=1)), "knots"),
        (dict(space=GainSpace((), segments=2)), "segments"),
        (dict(space=GainSpace(())), "tunes nothing"),
        (dict(space=GainSpace(stable_dt="yes")), "stable_dt"),
        (dict(space=GainSpace(stable_dt=True), gains=sp.default_gains()._replace(dt=jnp.asarray(1.2))), "2 / k_att"),
        (dict(gains=sp.default_gains()._replace(dt=jnp.asarray(float("nan")))), "gain dt"),
        (dict(method="bogus"), "unknown method"),
        (dict(bounds={}), "non-empty dict"),
        (dict(bounds={"nope": (0.01, 0.2)}), "does not tune"),
        (dict(bounds={"d0": (0.2, 0.1)}), "0 < lo < hi"),
        (dict(bounds={"d0": (0.0, 0.1)}), "0 < lo < hi"),
        (dict(bounds={"d0": (0.01, float("inf"))}), "0 < lo < hi"),
        (dict(bounds={"d0": (0.1,)}), "pair of numbers"),
        (dict(bounds={"d0": (0.1, 0.2)}), "outside bounds"),  # the default d0 = 0.07 is outside
        (dict(space=GainSpace(stable_dt=True), bounds={"dt": (0.05, 1.5)}), "2 / k_att"),
        (dict(max_step=0.0), "max_step"),
        (dict(max_step=float("nan")), "max_step"),
        (dict(max_step=True), "max_step"),
        (dict(reshuffle="yes"), "reshuffle"),
        (dict(space=GainSpace(goal_knots=1)), "goal_knots"),
        (dict(space=GainSpace(goal_knots=2.0)), "goal_knots must be an int"),
        (dict(space="recipe"), "must be a GainSpace"),
        (dict(weights=ScoreWeights(steps=-1.0)), "ScoreWeights.steps"),
        (dict(weights=ScoreWeights(fallback=float("inf"))), "ScoreWeights.fallback"),
        (dict(weights=(1.0, 1.0, 2.0)), "must be a ScoreWeights"),
    ],
)
def test_tune_smoothed_rejects_bad_input(suite, kwargs, match):
    kw = dict(updates=1, pairs=PAIRS, max_steps=STEPS, progress=False, space=GainSpace(), gains=sp.default_gains())
    kw.update(kwargs)
    with pytest.raises(ValueError, match=match):
        tune_smoothed(suite, **kw)


def test_bad_suites_and_theta(suite):
    empty = jax.tree_util.tree_map(lambda x: x[:0], suite)
    with pytest.raises(ValueError, match="empty"):
        tune_smoothed(empty, updates=1, progress=False)
    with pytest.raises(ValueError, match="Scenario"):
        tune_smoothed({"goal": [1, 2, 3]}, updates=1, progress=False)
    space, base = GainSpace(), sp.default_gains()
    with pytest.raises(ValueError, match="shape"):
        smoothing_sample(jnp.zeros(2), space, base, suite, jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="finite"):
        smoothing_sample(jnp.array([0.0, jnp.nan, 0.0]), space, base, suite, jax.random.PRNGKey(0))


@pytest.mark.slow  # a float32 objective and gradient of their own (~20 s of compilation); CI's slow step
def test_float32_straight_arm_gradient_is_finite():
    """float32 smoke test: the default start is the straight arm (theta = 0 on every
    segment); the smoothed objective's value and gradient are finite."""
    suite = sp.random_scenarios(0, 4, dtype=jnp.float32) if "dtype" in sp.random_scenarios.__code__.co_varnames \
        else jax.tree_util.tree_map(lambda x: x.astype(jnp.float32) if x.dtype == jnp.float64 else x,
                                    sp.random_scenarios(0, 4))
    assert np.all(np.asarray(suite.q0)[:, :, 1] == 0)  # straight
    space = GainSpace()
    base = sp.default_gains(jnp.float32)
    theta = space.encode(base)
    with jax.numpy_dtype_promotion("standard"):
        sample = smoothing_sample(theta, space, base, suite, jax.random.PRNGKey(0), pairs=2, max_steps=10)
        value, grad = jax.value_and_grad(smoothed_objective)(theta, sample)
    assert sample.scores.dtype == jnp.float32
    assert np.isfinite(float(value)) and np.all(np.isfinite(np.asarray(grad)))
