"""Planner: eq. (9) step, lax.scan rollouts, statuses, collisions, batching,
gradients. References: a plain Python loop of steps, brute-force dense
clearance of whole trajectories, central finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planner import make_options, rollout_jit
from softplan_jax.tuning import rollout_loss

# All paper scenarios padded to one shape: one compilation serves the three.
PAD = dict(curve_slots=5, degree=2)


@pytest.fixture(scope="module")
def paper():
    return {name: sp.paper_scenario(name, **PAD) for name in ("sim1", "sim2", "tree")}


@pytest.fixture(scope="module")
def paper_plans(paper):
    return {name: sp.plan(sc, max_steps=200) for name, sc in paper.items()}


@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_paper_scenarios_reach_without_collision(paper, paper_plans, name):
    r = paper_plans[name]
    assert r.status == "reached", (name, r.status, r.final_error)
    assert r.reached and not r.collided
    assert r.final_error < 1e-2
    assert r.min_clearance > 0
    assert r.q.shape == (r.iterations + 1, 3, 3) and r.tip.shape == (r.iterations + 1, 3)
    np.testing.assert_allclose(r.tip[-1], np.asarray(sp.tip_position(r.q[-1])), atol=1e-12)
    # Independent check: brute-force clearance over the interpolated motion.
    dense = np.asarray(sp.dense_trajectory_clearance(jnp.asarray(r.q), paper[name], substeps=8, arm_samples=60,
                                                     curve_samples=1500))
    assert np.isfinite(dense[:, np.asarray(paper[name].curve_mask)]).all()
    assert dense.min() > 0, dense.min()
    # The recorded clearance is the exact one: never above the brute-force value
    # at the steps themselves, and close to it (dense sampling error only).
    step_dense = np.asarray(
        sp.dense_trajectory_clearance(jnp.asarray(np.stack([r.q, r.q], 1).reshape(-1, 3, 3)), paper[name],
                                      substeps=1, arm_samples=200, curve_samples=4000)
    )[::2]
    rec = r.clearance
    assert np.all(rec <= step_dense[:, : rec.shape[1]] + 1e-12)
    assert np.max(step_dense[:, : rec.shape[1]] - rec) < 5e-3


def test_scan_equals_python_loop(paper):
    sc = paper["tree"]
    gains = sp.default_gains()
    opts = make_options("curve")
    steps = 25
    r = rollout_jit(sc, gains, opts, steps)
    q = sc.q0
    for k in range(steps):
        np.testing.assert_allclose(np.asarray(r.q[k]), np.asarray(q), rtol=0, atol=1e-12, err_msg=f"step {k}")
        q = sp.planner_step(q, sc, gains, opts)
    np.testing.assert_allclose(np.asarray(r.q[steps]), np.asarray(q), rtol=0, atol=1e-12)
    # N-point method too.
    opts_p = make_options("points", 10)
    r = rollout_jit(sc, gains, opts_p, 10)
    q = sc.q0
    for _ in range(10):
        q = sp.planner_step(q, sc, gains, opts_p)
    np.testing.assert_allclose(np.asarray(r.q[10]), np.asarray(q), rtol=0, atol=1e-12)


def test_collision_between_steps_is_detected():
    """A short wire placed exactly where the tip passes between steps k and
    k+1 of a free rollout: both sampled configurations are clear, the motion
    between them is not."""
    q0 = sp.default_start()
    goal = jnp.array([1.2, -0.6, 1.4])
    far = sp.line_segment([-5.0, -5.0, 0.0], [-5.0, -4.0, 0.0])
    gains = sp.default_gains()._replace(eta=jnp.asarray(1e-12), v_max=jnp.asarray(1.0))
    free = sp.plan(sp.make_scenario(goal, [far], q0), gains=gains, max_steps=40)
    k = 10
    q_mid = 0.5 * (free.q[k] + free.q[k + 1])
    p_mid = np.asarray(sp.tip_position(q_mid))
    motion = free.tip[k + 1] - free.tip[k]
    tangent = np.asarray(sp.point_jacobian(q_mid, 2, 1.0)[:, 0])  # dP/dL_1 ~ along the arm
    axis = np.cross(motion, tangent)
    axis /= np.linalg.norm(axis)
    wire = sp.line_segment(p_mid - 0.1 * axis, p_mid + 0.1 * axis)
    sc = sp.make_scenario(goal, [wire], q0)
    r = sp.plan(sc, gains=gains, max_steps=40)
    assert r.collided and r.status == "collided"
    assert r.iterations == k + 1
    # Both configurations around the crossing are clear ...
    assert np.all(r.clearance[: k + 2] > 0.01), r.clearance[: k + 2]
    # ... and the brute-force check of the motion confirms the crossing.
    dense = np.asarray(sp.dense_trajectory_clearance(jnp.asarray(r.q[k : k + 2]), sc, substeps=200,
                                                     arm_samples=400))
    assert dense.min() < 2e-3


def test_collision_flag_agrees_with_dense_check_on_random_scenes():
    rng = np.random.default_rng(3)
    agree = 0
    n = 12
    for _ in range(n):
        goal = rng.uniform([0.5, -1.2, 0.6], [1.6, 1.2, 2.2])
        mid = 0.5 * (goal + np.array([0, 0, 2.0])) + rng.normal(0, 0.15, 3)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        wire = sp.line_segment(mid - 1.5 * d, mid + 1.5 * d)
        sc = sp.make_scenario(goal, [wire], curve_slots=5, degree=2)
        weak = sp.default_gains()._replace(eta=jnp.asarray(1e-5 * rng.uniform(0, 1) + 1e-9))
        r = sp.plan(sc, gains=weak, max_steps=120)
        # Pad the trajectory to one length (a frozen arm does not move): one compilation for all scenes.
        q_pad = np.concatenate([r.q, np.repeat(r.q[-1:], 121 - r.q.shape[0], axis=0)])
        dense = np.asarray(sp.dense_trajectory_clearance(jnp.asarray(q_pad), sc, substeps=20, arm_samples=150,
                                                         curve_samples=3000))
        # Brute force can only over-estimate the clearance; 2e-3 covers its sampling error.
        if r.collided:
            ok = dense.min() <= 2e-3
        else:
            ok = dense.min() > 0
        agree += ok
    assert agree == n


def test_unreachable_goal_ends_without_nan(paper):
    sc = sp.paper_scenario("sim1", L_max=1.05, **PAD)._replace(goal=jnp.array([0.0, 0.0, 10.0]))
    r = sp.plan(sc, max_steps=200)
    assert r.status in ("stalled", "max_steps")
    assert not r.reached
    assert np.isfinite(r.q).all() and np.isfinite(r.final_error)
    assert r.q[:, :, 0].max() <= 1.05 + 1e-12


def test_length_limits_respected(paper):
    sc = sp.paper_scenario("tree", L_min=0.9, L_max=1.1, **PAD)
    r = sp.plan(sc, max_steps=200)
    assert r.q[:, :, 0].min() >= 0.9 - 1e-12 and r.q[:, :, 0].max() <= 1.1 + 1e-12


def test_same_padded_shape_does_not_recompile(paper):
    gains = sp.default_gains()
    opts = make_options("curve")
    rollout_jit(paper["sim1"], gains, opts, 30)
    before = rollout_jit._cache_size()
    for name in ("sim2", "tree"):
        rollout_jit(paper[name], gains, opts, 30)
    moved = paper["tree"]._replace(goal=paper["tree"].goal + 0.1)
    rollout_jit(moved, gains._replace(eta=gains.eta * 2), opts, 30)
    assert rollout_jit._cache_size() == before


def test_plan_batch_matches_single(paper):
    batch = sp.stack_scenarios(list(paper.values()))
    rb = sp.plan_batch(batch, max_steps=200)
    for b, (name, sc) in enumerate(paper.items()):
        single = rollout_jit(sc, sp.default_gains(), make_options("curve"), 200)
        assert int(rb.status[b]) == int(single.status), name
        assert int(rb.iterations[b]) == int(single.iterations)
        np.testing.assert_allclose(np.asarray(rb.q[b]), np.asarray(single.q), atol=1e-10)


def test_mixed_obstacles_both_methods():
    helix = sp.ParametricCurve(lambda u: jnp.stack([0.3 * jnp.cos(u) + 1.4, 0.3 * jnp.sin(u), 0.15 * u]),
                               (0.0, 12.0))
    pts = np.stack([np.full(12, -0.6), np.linspace(-1, 1, 12), np.full(12, 1.6)], 1)
    line = sp.line_segment([0.8, -1.0, 2.2], [0.8, 1.0, 1.8])
    sc = sp.make_scenario([1.0, 0.5, 1.2], [line, pts, helix])
    for method in ("curve", "points"):
        r = sp.plan(sc, method=method, n_points=20, max_steps=250)
        assert np.isfinite(r.q).all()
        assert r.clearance.shape[1] == 3
        if method == "curve":
            assert r.reached and not r.collided, (r.status, r.min_clearance)


def test_gradient_through_rollout_matches_finite_differences(paper):
    sc = paper["tree"]
    opts = make_options("curve", goal_tolerance=1e-9, stall_window=10**6)
    g = sp.default_gains()
    steps = 30
    loss = jax.jit(lambda g: rollout_loss(g, sc, opts, steps))
    grad = jax.jit(jax.grad(lambda g: rollout_loss(g, sc, opts, steps)))(g)
    for k in ("k_att", "v_max", "eta", "d0", "dt"):
        h = 1e-6 * float(getattr(g, k))
        fp = float(loss(g._replace(**{k: getattr(g, k) + h})))
        fm = float(loss(g._replace(**{k: getattr(g, k) - h})))
        fd = (fp - fm) / (2 * h)
        ad = float(getattr(grad, k))
        assert np.isfinite(ad)
        assert abs(ad - fd) <= 1e-3 * abs(fd) + 1e-9, (k, ad, fd)
    # The repulsion gains matter in the tree (the arm passes within d0 of a branch).
    assert abs(float(grad.eta)) > 1e-3 and abs(float(grad.d0)) > 1e-3


def test_float32_smoke():
    sc = sp.paper_scenario("sim1", dtype=jnp.float32)
    assert sc.q0.dtype == jnp.float32
    r = sp.plan(sc, max_steps=150)
    assert r.q.dtype == np.float32
    assert r.reached and not r.collided


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(method="bogus"), "unknown method"),
        (dict(n_points=0), "n_points"),
        (dict(max_steps=0), "max_steps"),
        (dict(repulsion="nope"), "repulsion"),
        (dict(goal_tolerance=-1.0), "goal_tolerance"),
        (dict(nonsense=1), "unknown planner option"),
    ],
)
def test_plan_rejects_bad_options(paper, kwargs, match):
    with pytest.raises(ValueError, match=match):
        sp.plan(paper["sim1"], **kwargs)


def test_plan_rejects_bad_gains(paper):
    with pytest.raises(ValueError, match="gain dt"):
        sp.plan(paper["sim1"], gains=sp.default_gains()._replace(dt=jnp.asarray(-1.0)))
    with pytest.raises(ValueError, match="gain eta"):
        sp.plan(paper["sim1"], gains=sp.default_gains()._replace(eta=jnp.asarray(jnp.nan)))
    with pytest.raises(ValueError, match="Scenario"):
        sp.plan({"goal": [1, 2, 3]})


def test_post_hoc_collision_checks_equal_in_scan_checks():
    """apply_collision_checks on a planning-only rollout == the checked rollout,
    on a scene that collides (weak repulsion, a wire across the path) and one that does not."""
    from softplan_jax.planner import apply_collision_checks

    q0 = sp.default_start()
    wire = sp.line_segment([0.9, -1.5, 1.2], [0.9, 1.5, 1.9])
    for eta in (1e-12, 1e-3):
        sc = sp.make_scenario([1.4, 0.2, 0.9], [wire], q0, curve_slots=5, degree=2)
        g = sp.default_gains()._replace(eta=jnp.asarray(eta))
        checked = rollout_jit(sc, g, make_options("curve"), 150)
        opts = make_options("curve", check_collisions=False)
        free = rollout_jit(sc, g, opts, 150)
        assert np.isnan(np.asarray(free.clearance)).all() and int(free.status) != sp.Status.COLLIDED
        post = jax.jit(apply_collision_checks, static_argnums=2)(free, sc, opts)
        assert int(post.status) == int(checked.status), eta
        assert int(post.iterations) == int(checked.iterations)
        np.testing.assert_allclose(np.asarray(post.q), np.asarray(checked.q), atol=1e-12)
        np.testing.assert_allclose(float(post.min_clearance), float(checked.min_clearance), atol=1e-12)
        if eta == 1e-12:
            assert bool(checked.collided)
