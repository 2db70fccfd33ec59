"""The clearance-bounded step, the escapes, NaN handling and the sanity
warnings. References: dense sampling of the motion with the NumPy oracle's
kinematics (the motion bound), an independent brute-force distance to the
curves (collisions), the paper's plain step on the same scenes (the contrast)."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planning import apply_collision_checks
from softplan_jax.planning._planner import make_options, result_from_rollout
from softplan_jax.planning._programs import rollout_batch, rollout_jit
from softplan_jax.testing import oracle

PAD = dict(curve_slots=5, degree=2)

# The scenes of random_scenarios(0, 256) in which the paper's plain step collides
# with the default gains (issue "collision-free by construction").
COLLIDING = [23, 26, 45, 117, 118, 149, 156, 166, 219, 238, 240]


def _observed_motion(q_a, q_b, substeps=60, arm_samples=60):
    """Largest displacement (per segment, cumulative) of any sampled arm point
    from its start over the straight-line motion q_a -> q_b, with the oracle's
    kinematics. Sampling can only under-estimate it."""
    s = np.linspace(0.0, 1.0, arm_samples)
    n = q_a.shape[0]
    start = [oracle.segment_points(q_a, i, s) for i in range(n)]
    worst = np.zeros(n)
    for t in np.linspace(0.0, 1.0, substeps + 1)[1:]:
        q = q_a + t * (q_b - q_a)
        for i in range(n):
            worst[i] = max(worst[i], np.max(np.linalg.norm(oracle.segment_points(q, i, s) - start[i], axis=1)))
    return np.maximum.accumulate(worst)


def test_motion_bound_is_sound_on_random_motions():
    rng = np.random.default_rng(0)
    for k in range(150):
        n = int(rng.integers(1, 5))
        theta = rng.uniform(-3.0, 3.0, n) * (rng.random(n) > 0.25)  # a quarter straight segments
        q_a = np.stack([rng.uniform(0.2, 1.5, n), theta, rng.uniform(-np.pi, np.pi, n)], 1)
        dq = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-3, 0)
        q_b = q_a + dq
        q_b[:, 0] = np.maximum(q_b[:, 0], 0.05)
        bound = np.asarray(sp.geometry.motion_bound(q_a, q_b))
        seen = _observed_motion(q_a, q_b, substeps=20, arm_samples=30)
        assert bound.shape == (n,)
        assert np.all(bound >= seen - 1e-12), (k, bound, seen)
    # At theta = 0 and with no motion: finite, and zero.
    q = np.asarray(sp.scenarios.default_start())
    assert np.all(np.asarray(sp.geometry.motion_bound(q, q)) == 0)
    with pytest.raises(ValueError, match="same shape"):
        sp.geometry.motion_bound(q, q[:2])


def test_motion_bound_is_sound_and_tight_on_planner_steps():
    """Planner steps of the tree (plain step, so every step is full size): the
    bound holds, and is a few times the observed motion, not orders more."""
    sc = sp.paper_scenario("tree", **PAD)
    r = sp.plan(sc, max_steps=200, **sp.PAPER_STEP)  # the rollout test_planner compiles too
    ratios = []
    for k in range(0, r.iterations, 5):
        bound = np.asarray(sp.geometry.motion_bound(r.q[k], r.q[k + 1]))
        seen = _observed_motion(r.q[k], r.q[k + 1])
        assert np.all(bound >= seen - 1e-12), k
        ratios.append(bound[-1] / seen[-1])
    # Measured: 1.5-2.2, median 2.0.
    assert np.median(ratios) < 3.0 and np.max(ratios) < 5.0, ratios


def test_motion_bound_gradient_is_finite_at_theta_zero():
    q = sp.scenarios.default_start()
    g = jax.grad(lambda d: sp.geometry.motion_bound(q, q + d)[-1])(jnp.full((3, 3), 1e-3))
    assert np.isfinite(np.asarray(g)).all()


def _brute_clearance(q_a, q_b, coeffs, substeps=8, arm_samples=60, curve_samples=600):
    """Independent brute force: the oracle's kinematics, each polynomial curve
    (u in [0, 1]) sampled densely; smallest sampled distance over the motion."""
    s = np.linspace(0.0, 1.0, arm_samples)
    u = np.linspace(0.0, 1.0, curve_samples)
    curves = np.stack([np.einsum("ak,uk->ua", c, u[:, None] ** np.arange(c.shape[1])) for c in coeffs])
    pts_c = curves.reshape(-1, 3)
    t = np.linspace(0.0, 1.0, substeps + 1)
    q_a, q_b = np.asarray(q_a), np.asarray(q_b)
    best = np.inf
    for arm in oracle.arm_points_many(q_a + t[:, None, None] * (q_b - q_a), s):
        best = min(best, float(np.sqrt(((arm[:, None, :] - pts_c[None, :, :]) ** 2).sum(-1).min())))
    return best


@pytest.fixture(scope="module")
def colliding_scenes():
    suite = sp.random_scenarios(0, 256)
    idx = np.asarray(COLLIDING)
    return jax.tree_util.tree_map(lambda x: x[idx], suite)


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_safe_step_removes_the_collisions_of_the_plain_step(colliding_scenes, dtype):
    """The eleven scenes where the paper's step passes through a curve: the
    safe step (the default) has no collision, by the exact checks and by an
    independent brute force over the motion of every near step; the plain step
    really collides there (the same brute force confirms it)."""
    dt = jnp.float32 if dtype == "float32" else jnp.float64
    scenes = jax.tree_util.tree_map(lambda x: x.astype(dt) if x.dtype == jnp.float64 else x, colliding_scenes)
    gains = sp.default_gains(dt)
    safe = jax.device_get(rollout_batch(scenes, gains, make_options("curve"), 300))
    assert not np.any(safe.collided), safe.status
    assert np.all(np.isfinite(safe.min_clearance)) and np.all(safe.min_clearance > 0)
    assert np.all(safe.status != sp.Status.NONFINITE)
    if dtype == "float32":
        return
    # The paper's step with the stall test of the sweep (60 steps, 1e-4).
    paper_step = make_options("curve", step="plain", escapes=0, stall_window=60, stall_tolerance=1e-4)
    plain = jax.device_get(rollout_batch(scenes, gains, paper_step, 300))
    assert np.all(plain.collided), plain.status
    coeffs = np.asarray(scenes.curves.coeffs)
    mask = np.asarray(scenes.curve_mask)
    for b in range(len(COLLIDING)):
        c = coeffs[b][mask[b]]
        it = int(safe.iterations[b])
        # The three nearest motions of the safe rollout, by the brute force.
        nearest = np.argsort(np.min(safe.clearance[b, :it], axis=1))[:3]
        for k in nearest:
            assert _brute_clearance(safe.q[b, k], safe.q[b, k + 1], c) > 0, (b, k)
    for b in range(3):
        # The plain step's last motion really passes through (or touches) a curve.
        c = coeffs[b][mask[b]]
        k = int(plain.iterations[b]) - 1
        assert _brute_clearance(plain.q[b, k], plain.q[b, k + 1], c, substeps=40, arm_samples=200,
                                curve_samples=1000) < 1e-2, b


def test_safe_step_keeps_the_clearance_above_the_floor(colliding_scenes):
    """Conservative advancement: no step moves any point farther than the
    fraction f of the clearance, so the clearance never falls below (1 - f)
    times its previous value."""
    scenes = colliding_scenes
    opts = make_options("curve")
    f = opts.safe_fraction
    r = jax.device_get(rollout_batch(scenes, sp.default_gains(), opts, 300))
    for b in range(len(COLLIDING)):
        it = int(r.iterations[b])
        c = np.min(r.clearance[b, : it + 1], axis=1)
        assert np.all(c[1:] >= (1 - f) * c[:-1] - 1e-12)
        for k in range(0, it, 7):
            bound = float(sp.geometry.motion_bound(r.q[b, k], r.q[b, k + 1])[-1])
            assert bound <= f * c[k] + 1e-12, (b, k, bound, c[k])
        assert np.all((r.step_scale[b, :it] > 0) & (r.step_scale[b, :it] <= 1))


@pytest.mark.slow
def test_points_method_with_safe_step_still_passes_between_points(colliding_scenes):
    """The N-point model with the same safe step bounds the motion against its
    sampled points only: with N = 1 it still collides with the real curves."""
    opts = make_options("points", 1, check_collisions=False)
    r = rollout_batch(colliding_scenes, sp.default_gains(), opts, 300)
    checked = jax.device_get(jax.jit(jax.vmap(apply_collision_checks, in_axes=(0, 0, None)), static_argnums=2)(
        r, colliding_scenes, opts))
    assert np.any(checked.collided)


def test_escapes_are_reproducible_and_reach_more():
    """Scene 4 of random_scenarios(0, 256) (a local minimum for the field): the
    random walks are a function of the seed, and the default (with escapes)
    reaches it where the safe step without escapes does not. Its four curves padded to
    PAD and 200 steps: the default rollout is the one test_nan_clearance (and
    test_planner) compile."""
    scene = jax.tree_util.tree_map(lambda x: x[4], sp.random_scenarios(0, 8))
    n = int(np.sum(np.asarray(scene.curve_mask)))
    curves = [sp.PolynomialCurve(scene.curves.coeffs[j], scene.curves.u_range[j]) for j in range(n)]
    sc = sp.make_scenario(scene.goal, curves, scene.q0, **PAD)
    a = sp.plan(sc, max_steps=200, seed=1)
    b = sp.plan(sc, max_steps=200, seed=1)
    np.testing.assert_array_equal(a.q, b.q)
    none = sp.plan(sc, max_steps=200, escapes=0)
    assert not none.reached
    assert a.reached or sp.plan(sc, max_steps=200, seed=2).reached


def test_nan_clearance_is_a_failure_not_clear():
    """A curve whose points are NaN (built past the constructor's, make_scenario's and plan's
    checks, straight into the rollout): the clearance is NaN, and the rollout ends non-finite,
    never reached or clear."""
    good = sp.line_segment([0.5, -1.0, 1.5], [0.5, 1.0, 1.5])
    bad = sp.PolynomialCurve.tree_unflatten(None, [good.coeffs * jnp.nan, good.u_range, good.radius])
    with pytest.raises(ValueError, match="not finite"):
        sp.make_scenario([1.0, 0.0, 2.0], [bad], **PAD)
    sc = sp.make_scenario([1.0, 0.0, 2.0], [good], **PAD)
    sc = sc._replace(curves=sp.PolynomialCurve.tree_unflatten(
        None, [sc.curves.coeffs.at[0].multiply(jnp.nan), sc.curves.u_range, sc.curves.radius]))
    with pytest.raises(ValueError, match="scenario.curves"):
        sp.plan(sc, max_steps=200)
    for step, extra in (("safe", {}), ("plain", sp.PAPER_STEP)):
        r = result_from_rollout(rollout_jit(sc, sp.default_gains(), sp.make_options(**extra), 200), sc)
        assert r.status == "non_finite", (step, r.status)
        assert not r.reached and not r.collided
        assert np.isnan(r.min_clearance)  # never reported as a finite (clear) clearance


def _float32_paper_scene_reached(name, step, extra):
    sc = sp.paper_scenario(name, dtype=jnp.float32, **PAD)
    assert sc.q0.dtype == jnp.float32
    r = sp.plan(sc, max_steps=200, **extra)
    assert r.q.dtype == np.float32 and r.clearance.dtype == np.float32
    assert np.isfinite(r.clearance).all() and np.isfinite(r.min_clearance), (name, step)
    assert r.reached and not r.collided, (name, step, r.status)


@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_float32_paper_scenes_have_finite_clearance(name):
    """float32 end to end with the default planner (the float32 smoke test)."""
    _float32_paper_scene_reached(name, "safe", {})


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_float32_paper_scenes_with_the_papers_step(name):
    """float32 end to end with the paper's step (a program of its own: in the slow step)."""
    _float32_paper_scene_reached(name, "plain", sp.PAPER_STEP)


def test_goal_inside_an_obstacle_warns():
    wire = sp.line_segment([1.0, -1.0, 1.0], [1.0, 1.0, 1.0], radius=0.05)
    with pytest.warns(UserWarning, match="inside obstacle"):
        sp.make_scenario([1.0, 0.0, 1.02], [wire])
    pts = np.array([[0.5, 0.5, 0.5]])
    with pytest.warns(UserWarning, match="inside obstacle"):
        sp.make_scenario([0.5, 0.5, 0.5], [pts])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sp.make_scenario([1.0, 0.0, 1.2], [wire])  # 0.2 away: no warning


def test_goal_warning_names_the_obstacle_slot():
    """The message names the slots of the clearance records (padding slots counted),
    for each kind of obstacle: curve, point set and parametric curve."""
    wire = sp.line_segment([1.0, -1.0, 1.0], [1.0, 1.0, 1.0], radius=0.05)
    pts = np.array([[0.5, 0.5, 0.5], [0.6, 0.5, 0.5]])
    ring = sp.ParametricCurve(lambda u: jnp.stack([jnp.cos(u), jnp.sin(u), jnp.full_like(u, 2.0)]), (0.0, 3.0))
    far = [0.0, 0.0, 1.5]
    for goal, slot in (([1.0, 0.0, 1.02], 0), ([0.5, 0.5, 0.5], 2), ([1.0, 0.0, 2.0], 3)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sc = sp.make_scenario(goal, [wire, pts, ring], curve_slots=2)
        msgs = sp.scenarios.scenario_warnings(sc)
        assert len(msgs) == 1 and f"obstacle(s) [{slot}]" in msgs[0], (goal, msgs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert sp.scenarios.scenario_warnings(sp.make_scenario(far, [wire, pts, ring], curve_slots=2)) == []


def test_goal_beyond_reach_warns():
    with pytest.warns(UserWarning, match="farther than the arm reaches"):
        sp.make_scenario([0.0, 0.0, 4.0], [], L_max=1.2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sp.make_scenario([0.0, 0.0, 3.5], [], L_max=1.2)


def test_degenerate_inputs_are_errors():
    with pytest.raises(ValueError, match="same point"):
        sp.line_segment([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    q = sp.scenarios.default_start()
    for s in (-0.1, 1.5):
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            sp.geometry.segment_point(q, 0, s)
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            sp.geometry.point_jacobian(q, 0, s)
    with pytest.raises(ValueError, match="not finite inside u_range"):
        sp.ParametricCurve(lambda u: jnp.stack([jnp.sqrt(u), u, u]), (-1.0, 1.0))
    with pytest.raises(ValueError, match="safe_fraction"):
        make_options("curve", safe_fraction=0.0)
    with pytest.raises(ValueError, match="unknown step"):
        make_options("curve", step="fast")
    with pytest.raises(ValueError, match="escapes"):
        make_options("curve", escapes=-1)


def test_plain_step_is_the_papers_step():
    """step="plain" is exactly q + dt qdot with lengths clipped (paper eq. 9),
    the step the paper tables use; the safe step never moves farther."""
    sc = sp.paper_scenario("tree", **PAD)
    g = sp.default_gains()
    plain = rollout_jit(sc, g, make_options("curve", **sp.PAPER_STEP), 200)
    safe = rollout_jit(sc, g, make_options("curve"), 200)
    assert np.all(np.asarray(plain.step_scale[: int(plain.iterations)]) == 1)
    a = np.asarray(safe.step_scale[: int(safe.iterations)])
    assert np.all((a > 0) & (a <= 1)) and np.any(a < 1)
