"""Planner: eq. (9) step, lax.scan rollouts, statuses, collisions, batching,
gradients. References: a plain Python loop of steps, brute-force dense
clearance of whole trajectories, central finite differences."""

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planning._options import rollout_compiler_options
from softplan_jax.planning._planner import make_options, result_from_rollout
from softplan_jax.planning._programs import rollout_jit
from softplan_jax.testing import oracle

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
    dense = np.asarray(sp.geometry.dense_trajectory_clearance(jnp.asarray(r.q), paper[name], substeps=4, arm_samples=40,
                                                     curve_samples=1000))
    assert np.isfinite(dense[:, np.asarray(paper[name].curve_mask)]).all()
    assert dense.min() > 0, dense.min()
    # The recorded clearance is never above the brute-force value at the steps themselves,
    # and below d0 + far_margin it is the exact one: close to it (dense sampling error only).
    step_dense = np.asarray(
        sp.geometry.dense_trajectory_clearance(jnp.asarray(np.stack([r.q, r.q], 1).reshape(-1, 3, 3)), paper[name],
                                      substeps=1, arm_samples=100, curve_samples=2000)
    )[::2]
    rec = r.clearance
    assert np.all(rec <= step_dense[:, : rec.shape[1]] + 1e-12)
    near = rec < float(sp.default_gains().d0) + sp.PlanOptions().far_margin
    assert near.any() and np.max((step_dense[:, : rec.shape[1]] - rec)[near]) < 5e-3


def test_scan_equals_python_loop(paper):
    sc = paper["tree"]
    gains = sp.default_gains()
    opts = make_options("curve")
    r = rollout_jit(sc, gains, opts, 200)  # the compilation sp.plan made for the paper plans
    steps = int(r.iterations)
    assert r.status == sp.Status.REACHED and steps > 20
    # The exact solver converged on every real obstacle at every step (the flag the rollout carries).
    assert r.converged.shape == (201,) and r.converged.dtype == bool and bool(np.all(r.converged))
    q = sc.q0
    for k in range(steps):
        np.testing.assert_allclose(np.asarray(r.q[k]), np.asarray(q), rtol=0, atol=1e-12, err_msg=f"step {k}")
        q = sp.planning.planner_step(q, sc, gains, opts)
    np.testing.assert_allclose(np.asarray(r.q[steps]), np.asarray(q), rtol=0, atol=1e-12)
    # Frozen after the end: every later record repeats the last state.
    np.testing.assert_array_equal(np.asarray(r.q[steps:]), np.broadcast_to(np.asarray(r.q[steps]), r.q[steps:].shape))
    # N-point method too.
    opts_p = make_options("points", 10)
    r = rollout_jit(sc, gains, opts_p, 200)
    q = sc.q0
    for _ in range(10):
        q = sp.planning.planner_step(q, sc, gains, opts_p)
    np.testing.assert_allclose(np.asarray(r.q[10]), np.asarray(q), rtol=0, atol=1e-12)


def test_collision_between_steps_is_detected():
    """A short wire placed exactly where the tip passes between steps k and
    k+1 of a free rollout: both sampled configurations are clear, the motion
    between them is not."""
    q0 = sp.scenarios.default_start()
    goal = jnp.array([1.2, -0.6, 1.4])
    far = sp.line_segment([-5.0, -5.0, 0.0], [-5.0, -4.0, 0.0])
    gains = sp.default_gains()._replace(eta=jnp.asarray(1e-12), v_max=jnp.asarray(1.0))
    # The paper's step: the safe step (the default) would not let the arm reach the wire.
    free = sp.plan(sp.make_scenario(goal, [far], q0, **PAD), gains=gains, max_steps=200, **sp.PAPER_STEP)
    k = 10
    q_mid = 0.5 * (free.q[k] + free.q[k + 1])
    p_mid = np.asarray(sp.tip_position(q_mid))
    motion = free.tip[k + 1] - free.tip[k]
    tangent = np.asarray(sp.geometry.point_jacobian(q_mid, 2, 1.0)[:, 0])  # dP/dL_1 ~ along the arm
    axis = np.cross(motion, tangent)
    axis /= np.linalg.norm(axis)
    wire = sp.line_segment(p_mid - 0.1 * axis, p_mid + 0.1 * axis)
    sc = sp.make_scenario(goal, [wire], q0, **PAD)
    r = sp.plan(sc, gains=gains, max_steps=200, **sp.PAPER_STEP)
    assert r.collided and r.status == "collided"
    assert r.iterations == k + 1
    # Both configurations around the crossing are clear ...
    assert np.all(r.clearance[: k + 2] > 0.01), r.clearance[: k + 2]
    # ... and the brute-force check of the motion confirms the crossing.
    # (t = 1/2 is a sub-step and the tip, s = 1, a sample: the brute force sees p_mid itself.)
    dense = np.asarray(sp.geometry.dense_trajectory_clearance(jnp.asarray(r.q[k : k + 2]), sc, substeps=20,
                                                     arm_samples=50))
    assert dense.min() < 2e-3


def _wire_clearance(q_a, q_b, a, b, substeps, arm_samples):
    """Independent brute force (NumPy oracle kinematics, exact point-to-segment
    distance): min clearance between the arm moving linearly in q from q_a to
    q_b and the straight wire a-b, sampled at ``substeps`` sub-steps and
    ``arm_samples`` points per segment. Sampling can only over-estimate it."""
    s = np.linspace(0.0, 1.0, arm_samples)
    ab = b - a
    t = np.linspace(0.0, 1.0, substeps + 1)
    q_a, q_b = np.asarray(q_a), np.asarray(q_b)
    pts = oracle.arm_points_many(q_a + t[:, None, None] * (q_b - q_a), s).reshape(-1, 3)
    w = np.clip((pts - a) @ ab / (ab @ ab), 0.0, 1.0)
    return float(np.min(np.linalg.norm(pts - (a + w[:, None] * ab), axis=1)))


def test_collision_flag_agrees_with_dense_check_on_random_scenes(paper, paper_plans):
    """Random wires across the path, weak repulsion: the collision flag (exact
    solves at the steps plus the between-steps check) against an independent
    brute-force check of the whole motion. Collided: the motion of the last
    interval really comes within sampling error of the wire. Not collided:
    every interval that comes near the wire, re-sampled finely, stays clear."""
    rng = np.random.default_rng(3)
    outcomes = []
    for _ in range(10):
        goal = rng.uniform([0.5, -1.2, 0.6], [1.6, 1.2, 2.2])
        mid = 0.5 * (goal + np.array([0, 0, 2.0])) + rng.normal(0, 0.15, 3)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        a, b = mid - 1.5 * d, mid + 1.5 * d
        sc = sp.make_scenario(goal, [sp.line_segment(a, b)], **PAD)
        weak = sp.default_gains()._replace(eta=jnp.asarray(1e-5 * rng.uniform(0, 1) + 1e-9))
        r = sp.plan(sc, gains=weak, max_steps=200, **sp.PAPER_STEP)  # the paper's step: it can collide
        assert r.q.shape[0] == r.iterations + 1
        if r.collided:
            # The flag fires at the first step whose motion touches the wire.
            fine = _wire_clearance(r.q[-2], r.q[-1], a, b, substeps=200, arm_samples=1000)
            assert fine <= 1e-3, (fine, r.clearance[-3:])
            coarse = [_wire_clearance(r.q[k], r.q[k + 1], a, b, 4, 200) for k in range(r.iterations - 1)]
            assert min(coarse, default=np.inf) > 0
        else:
            coarse = np.array([_wire_clearance(r.q[k], r.q[k + 1], a, b, 4, 200) for k in range(r.iterations)])
            for k in np.flatnonzero(coarse < 0.02):
                assert _wire_clearance(r.q[k], r.q[k + 1], a, b, 100, 1000) > 0, k
        outcomes.append(bool(r.collided))
    # The suite is only a test if it holds both kinds of rollout.
    assert 0 < sum(outcomes) < len(outcomes), outcomes


def test_unreachable_goal_ends_without_nan(paper):
    sc = sp.paper_scenario("sim1", L_max=1.05, **PAD)._replace(goal=jnp.array([0.0, 0.0, 10.0]))
    r = sp.plan(sc, max_steps=200)  # proven beyond reach: returned before planning
    assert r.status == "unreachable" and r.reason == "beyond_reach" and r.iterations == 0
    # The rollout itself, run anyway: it ends without NaN, the lengths within their limits.
    r = result_from_rollout(rollout_jit(sc, sp.default_gains(), make_options("curve"), 200), sc)
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
    rollout_jit(paper["sim1"], gains, opts, 200)
    before = rollout_jit.cache_size()
    for name in ("sim2", "tree"):
        rollout_jit(paper[name], gains, opts, 200)
    moved = paper["tree"]._replace(goal=paper["tree"].goal + 0.1)
    rollout_jit(moved, gains._replace(eta=gains.eta * 2), opts, 200)
    # Gains given as a Python float or a weakly typed array do not recompile either.
    rollout_jit(moved, gains._replace(eta=2e-3, d0=jnp.asarray(0.08)), opts, 200)
    assert rollout_jit.cache_size() == before


def test_trimming_a_rollout_compiles_nothing(paper, caplog):
    """result_from_rollout trims the records to the steps taken on the host: a new step count
    compiles no slice program (it cost ~25 ms a field on a CPU, 75 ms for a plan that ended at
    a step count not seen before). The same records, to the bit, as the device arrays'."""
    sc = paper["tree"]
    r = rollout_jit(sc, sp.default_gains(), make_options("curve"), 200)  # test_planner's program
    m = int(np.sum(np.asarray(sc.curve_mask)))
    result_from_rollout(r._replace(iterations=np.int32(2)), sc)  # the scene's own small programs (mask, radii)
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        for k in (3, 7, 11):
            res = result_from_rollout(r._replace(iterations=np.int32(k)), sc)
            assert res.q.shape == (k + 1, 3, 3) and res.tip.shape == (k + 1, 3) and res.clearance.shape == (k + 1, m)
            np.testing.assert_array_equal(res.q, np.asarray(r.q)[: k + 1])
            np.testing.assert_array_equal(res.clearance, np.asarray(r.clearance)[: k + 1][:, np.asarray(sc.curve_mask)])
    compiled = [rec.getMessage() for rec in caplog.records if "ompil" in rec.getMessage()]
    assert not compiled, compiled


def test_plan_batch_matches_single(paper):
    batch = sp.scenarios.stack_scenarios(list(paper.values()))
    rb = sp.plan_batch(batch, max_steps=200)
    for b, (name, sc) in enumerate(paper.items()):
        single = rollout_jit(sc, sp.default_gains(), make_options("curve"), 200)
        assert int(rb.status[b]) == int(single.status), name
        assert int(rb.iterations[b]) == int(single.iterations)
        np.testing.assert_allclose(np.asarray(rb.q[b]), np.asarray(single.q), atol=1e-10)


def test_plan_batch_chunks_one_shape_one_compilation(paper, capsys):
    """plan_batch in chunks: every chunk has the same padded shape (the last one padded
    with copies of the last scenario), so chunks of 3 reuse the compilation of a batch
    of 3, and they give that batch's rollouts bit for bit (the same program on the
    same inputs; no escape starts, so the per-scenario keys do not matter)."""
    scenes = list(paper.values())
    rb = sp.plan_batch(sp.scenarios.stack_scenarios(scenes), max_steps=200, devices=1)
    assert np.all(np.asarray(rb.escapes) == 0) and np.all(np.asarray(rb.reached))
    before = sp.planning.rollout_batch.cache_size()
    # 5 scenarios in chunks of 3: sim1 sim2 tree | sim1 sim2 + a padding copy of sim2.
    five = sp.scenarios.stack_scenarios(scenes + scenes[:2])
    rc = sp.plan_batch(five, max_steps=200, chunk=3, devices=1, progress=True)
    assert sp.planning.rollout_batch.cache_size() == before
    assert rc.q.shape == (5, 201, 3, 3) and isinstance(rc.q, np.ndarray)
    for field, got in rc._asdict().items():
        if got is None:  # the tracking fields of a planning rollout
            continue
        ref = np.asarray(getattr(rb, field))
        np.testing.assert_array_equal(got, np.concatenate([ref, ref[:2]]), err_msg=field)
    err = capsys.readouterr().err
    assert "plan_batch: 1/2 chunks, 3/5 scenarios on 1 device" in err
    assert "plan_batch: 2/2 chunks, 5/5 scenarios on 1 device" in err
    # Off by default.
    sp.plan_batch(five, max_steps=200, chunk=3, devices=1)
    assert capsys.readouterr().err == ""
    assert sp.planning.rollout_batch.cache_size() == before


def test_mixed_obstacles_both_methods():
    helix = sp.ParametricCurve(lambda u: jnp.stack([0.3 * jnp.cos(u) + 1.4, 0.3 * jnp.sin(u), 0.15 * u]),
                               (0.0, 12.0))
    pts = np.stack([np.full(12, -0.6), np.linspace(-1, 1, 12), np.full(12, 1.6)], 1)
    line = sp.line_segment([0.8, -1.0, 2.2], [0.8, 1.0, 1.8], radius=0.03)
    sc = sp.make_scenario([1.0, 0.5, 1.2], [line, pts, helix], arm_radius=0.02)
    # The N-point model plans only (its collision checks are the curve method's: the exact
    # closest points of test_obstacles' mixed scene); the curve method runs checked.
    for method in ("curve", "points"):
        r = sp.plan(sc, method=method, n_points=20, max_steps=200, check_collisions=method == "curve")
        assert np.isfinite(r.q).all()
        assert r.clearance.shape[1] == 3
        if method == "curve":
            # Radii (arm 0.02, wire 0.03) included: the safe step keeps the surfaces apart.
            assert r.reached and not r.collided, (r.status, r.min_clearance)
            assert r.min_clearance > 0
            # The motion up to the goal (the frozen steps after it do not move).
            dense = np.asarray(sp.geometry.dense_trajectory_clearance(
                jnp.asarray(r.q[: r.iterations + 1]), sc, substeps=4, arm_samples=40, curve_samples=1000))
            assert dense.min() > 0, dense.min()


@pytest.mark.slow  # the deprecated pathwise tuner: its loss-and-gradient program (~30 s compile)
def test_gradient_through_rollout_matches_finite_differences(paper):
    """jax.grad through whole rollouts (the batch loss of notebooks/tuning.ipynb, the same
    compiled program: the notebook's test run and this test share it through the persistent
    cache) against central finite differences of the same loss."""
    batch = sp.scenarios.stack_scenarios([paper["sim1"], paper["tree"]])
    opts = sp.PlanOptions(method="curve")
    # A wider influence distance than the default, so that the repulsion acts
    # within the short horizon (the arm passes 0.3-0.4 from a tree branch early).
    # float64 like the default gains (a weakly typed jnp.asarray(0.5) would be another program).
    g = sp.default_gains()._replace(d0=jnp.asarray(0.5, jnp.float64))
    steps = 10  # no rollout ends within 10 steps: the loss is smooth in the gains
    # One compilation for the loss and its gradient (the finite differences use its value),
    # with the package's XLA options as the notebook and tune_gains compile it.
    loss_and_grad = jax.jit(jax.value_and_grad(sp.tuning.pathwise.batch_loss), static_argnames=("options", "max_steps"),
                            compiler_options=rollout_compiler_options("curve"))
    _, grad = loss_and_grad(g, batch, opts, steps)
    for k in ("k_att", "v_max", "eta", "d0", "dt"):
        h = 1e-6 * float(getattr(g, k))
        fp = float(loss_and_grad(g._replace(**{k: getattr(g, k) + h}), batch, opts, steps)[0])
        fm = float(loss_and_grad(g._replace(**{k: getattr(g, k) - h}), batch, opts, steps)[0])
        fd = (fp - fm) / (2 * h)
        ad = float(getattr(grad, k))
        assert np.isfinite(ad)
        assert abs(ad - fd) <= 1e-3 * abs(fd) + 1e-9, (k, ad, fd)
    # The repulsion gains matter (the arm passes within d0 of a branch).
    assert abs(float(grad.eta)) > 1e-3 and abs(float(grad.d0)) > 1e-3, grad


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
    from softplan_jax.planning import apply_collision_checks

    q0 = sp.scenarios.default_start()
    wire = sp.line_segment([0.9, -1.5, 1.2], [0.9, 1.5, 1.9])
    for eta in (1e-12, 1e-3):
        sc = sp.make_scenario([1.4, 0.2, 0.9], [wire], q0, curve_slots=5, degree=2)
        g = sp.default_gains()._replace(eta=jnp.asarray(eta))
        checked = rollout_jit(sc, g, make_options("curve", **sp.PAPER_STEP), 200)
        opts = make_options("curve", check_collisions=False, **sp.PAPER_STEP)
        free = rollout_jit(sc, g, opts, 200)
        assert np.isnan(np.asarray(free.clearance)).all() and int(free.status) != sp.Status.COLLIDED
        post = jax.jit(apply_collision_checks, static_argnums=2)(free, sc, opts)
        assert int(post.status) == int(checked.status), eta
        assert int(post.iterations) == int(checked.iterations)
        np.testing.assert_allclose(np.asarray(post.q), np.asarray(checked.q), atol=1e-12)
        np.testing.assert_allclose(float(post.min_clearance), float(checked.min_clearance), atol=1e-12)
        # The same motions searched (the swept proof) and the same between-step clearance.
        np.testing.assert_array_equal(np.asarray(post.between_searched), np.asarray(checked.between_searched))
        # Below d0 + far_margin the in-scan records are exact; above it they may be lower bounds.
        cb, cb_post = np.asarray(checked.between), np.asarray(post.between)
        exact = cb < float(g.d0) + sp.PlanOptions().far_margin
        np.testing.assert_allclose(cb[exact], cb_post[exact], rtol=0, atol=1e-9)
        assert exact.any() and np.all(cb <= cb_post + 1e-9)
        if eta == 1e-12:
            assert bool(checked.collided)


def _swept_cases():
    """(label, scenario, gains, options): random scenes (default and paper step, curve and
    10 points) and random wires across the path with weak repulsion (paper step: some
    collide). Every rollout is a compilation of this module's other tests (one padded shape)."""
    scs = sp.random_scenarios(5, 3, obstacles=(1, 5), curve_slots=5, degree=2)
    cases = []
    for b in range(3):
        sc = jax.tree_util.tree_map(lambda x, b=b: x[b], scs)
        for label, opts in (("curve", make_options("curve")), ("points 10", make_options("points", 10)),
                            ("curve, paper step", make_options("curve", **sp.PAPER_STEP))):
            cases.append((f"random {b}, {label}", sc, sp.default_gains(), opts))
    rng = np.random.default_rng(11)
    for k in range(4):
        goal = rng.uniform([0.5, -1.2, 0.6], [1.6, 1.2, 2.2])
        mid = 0.5 * (goal + np.array([0, 0, 2.0])) + rng.normal(0, 0.15, 3)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        sc = sp.make_scenario(goal, [sp.line_segment(mid - 1.5 * d, mid + 1.5 * d)], **PAD)
        weak = sp.default_gains()._replace(eta=jnp.asarray(1e-5 * rng.uniform(0, 1) + 1e-9))
        cases.append((f"wire {k}, paper step", sc, weak, make_options("curve", **sp.PAPER_STEP)))
    return cases


def test_swept_proof_skips_only_motions_that_cannot_collide():
    """The checked rollout searches a motion between two steps only where the motion bound
    does not prove it clear (PlanOptions.swept_proof). Against the post-hoc checks searching
    EVERY motion (swept_proof=False, the earlier behaviour) on the same trajectory: same
    status and iterations; the same between-step clearance where the rollout searched; where
    it skipped, the full search finds no collision, lies above the proof's lower bound
    (clearance at the start minus the motion bound), and the rollout's record (the smaller
    end clearance) is at least the search's value. A searched motion with an end beyond
    d0 + far_margin starts from that end's bound's placeholder pair: its value is compared with
    the proof's bound only. The skipped motions nearest the contact
    tolerance are checked by brute force too. Not vacuous: most motions are skipped, some
    are searched, some rollouts collide."""
    from softplan_jax.geometry._clearance import contact_tolerance
    from softplan_jax.planning import apply_collision_checks

    always = make_options("curve", check_collisions=False, swept_proof=False, **sp.PAPER_STEP)
    post = jax.jit(apply_collision_checks, static_argnums=2)
    contact = contact_tolerance(always, jnp.float64)
    tip_bound = jax.jit(jax.vmap(lambda q_a, q_b: sp.geometry.motion_bound(q_a, q_b)[-1]))
    skipped = searched = exact_searches = 0
    collided = []
    for label, sc, gains, opts in _swept_cases():
        r = jax.device_get(rollout_jit(sc, gains, opts, 200))
        ref = jax.device_get(post(r, sc, always))
        assert int(ref.status) == int(r.status) and int(ref.iterations) == int(r.iterations), label
        collided.append(int(r.status) == sp.Status.COLLIDED)
        it = int(r.iterations)
        mask = np.asarray(sc.curve_mask)
        c = np.asarray(r.clearance)[: it + 1][:, mask]
        cb, cb_ref = (np.asarray(x.between)[1 : it + 1][:, mask] for x in (r, ref))
        did = np.asarray(r.between_searched)[1 : it + 1][:, mask]
        assert not np.asarray(r.between_searched)[it + 1 :].any() and not np.asarray(r.between_searched)[0].any()
        assert np.asarray(ref.between_searched)[1 : it + 1][:, mask].all()
        bound = np.asarray(tip_bound(r.q[:-1], r.q[1:]))[:it]  # every motion of the padded record, one program
        lower = c[:-1] - bound[:, None]
        # Every search result is achieved during the motion: never below the proof's bound.
        assert np.all(cb_ref >= lower - 1e-9), label
        # Both ends exact (below d0 + far_margin): the search starts where the post-hoc one does.
        reach = float(gains.d0) + sp.PlanOptions().far_margin
        seeded = did & (np.maximum(c[:-1], c[1:]) < reach)
        np.testing.assert_allclose(cb[seeded], cb_ref[seeded], rtol=0, atol=1e-9, err_msg=label)
        assert np.all(cb[did] >= lower[did] - 1e-9), label  # an end beyond reach: still achieved
        exact_searches += int(seeded.sum())
        skip = ~did
        assert np.all(cb_ref[skip] > contact), label  # a skipped motion never hides a collision
        assert np.all(lower[skip] > contact), label
        np.testing.assert_array_equal(cb[skip], np.minimum(c[:-1], c[1:])[skip], err_msg=label)
        exact = skip & (cb < reach)  # above: ends may be bounds
        assert np.all(cb[exact] >= cb_ref[exact] - 1e-12), label
        skipped += int(skip.sum())
        searched += int(did.sum())
        # Independent brute force over the skipped motions nearest contact (sampling only over-estimates).
        for flat in np.argsort(np.where(skip, lower, np.inf), axis=None)[:2]:
            k, j = np.unravel_index(flat, skip.shape)
            if not skip[k, j]:
                continue
            dense = np.asarray(sp.geometry.dense_trajectory_clearance(jnp.asarray(r.q[k : k + 2]), sc, substeps=20,
                                                             arm_samples=100, curve_samples=1000))[0][mask]
            assert dense[j] >= lower[k, j] - 1e-9 and dense[j] > contact, (label, k, j, dense[j], lower[k, j])
    assert skipped > 3 * searched and searched >= exact_searches > 0, (skipped, searched, exact_searches)
    assert 0 < sum(collided) < len(collided), collided


def test_swept_clear_edge_cases(paper):
    """swept_clear: a zero motion proves every clear slot clear; NaN, a clearance at the contact
    tolerance, a motion as long as the clearance or a solve that did not converge never do."""
    from softplan_jax.geometry._clearance import swept_clear
    from softplan_jax.geometry._obstacles import radius_and_mask

    sc = paper["tree"]
    q = sc.q0
    truth = jax.jit(sp.geometry.true_closest, static_argnums=2)(q, sc, make_options().solver)
    _, mask = radius_and_mask(sc)
    c = jnp.where(mask, truth.distance - sc.arm_radius - sc.curves.radius, jnp.inf)
    contact = 1e-6
    swept_clear = jax.jit(swept_clear)
    assert bool(jnp.all(swept_clear(q, q, truth, c, contact)))
    moved = q.at[0, 2].add(1.0)  # turn the whole arm: the bound (~ the arm's length) exceeds every clearance
    assert float(sp.geometry.motion_bound(q, moved)[-1]) > float(jnp.max(jnp.where(mask, c, 0.0)))
    assert not bool(jnp.any(swept_clear(q, moved, truth, c, contact) & mask))
    assert not bool(jnp.any(swept_clear(q, q, truth, jnp.full_like(c, contact), contact)))
    assert not bool(jnp.any(swept_clear(q, q, truth, c * jnp.nan, contact)))
    assert not bool(jnp.any(swept_clear(q, q, truth._replace(converged=~truth.converged), c, contact)))


@pytest.mark.slow  # the deprecated pathwise tuner: its loss-and-gradient program (~30 s compile)
def test_tune_gains_lowers_the_loss_and_compiles_once(paper):
    from softplan_jax.tuning.pathwise import tune_gains

    # The call of notebooks/tuning.ipynb at its test size (tests/test_notebooks.py): the two
    # share one compilation through the persistent compilation cache.
    sc = sp.scenarios.stack_scenarios([paper["sim1"], paper["tree"]])
    first = tune_gains(sc, steps=2, max_steps=10, progress=False, tune=("k_att", "eta", "d0", "dt"))
    assert first.compile_seconds > 0
    assert np.all(np.isfinite(first.losses)) and first.losses[-1] < first.losses[0], first.losses
    assert all(float(getattr(first.gains, k)) > 0 for k in sp.Gains._fields)
    assert float(first.gains.v_max) == float(sp.default_gains().v_max)  # not tuned: unchanged
    # Same shapes, another goal: the compiled loss-and-gradient is reused.
    again = tune_gains(sc._replace(goal=sc.goal + 0.01), steps=1, max_steps=10, progress=False,
                       tune=("k_att", "eta", "d0", "dt"))
    assert again.compile_seconds == 0.0
    with pytest.raises(ValueError, match="tune must name"):
        tune_gains(sc, tune=("nope",), progress=False)


def test_seed_keys_and_strong_gains_are_the_arrays_jax_would_make():
    """prng_key of an int seed is jax.random.PRNGKey(seed) (made once per seed: the same
    values on every call); strong_gains keeps arrays already of the dtype and converts Python
    floats and weakly typed arrays to strong arrays of the dtype."""
    from softplan_jax.planning._programs import prng_key, strong_gains

    for seed in (0, 7, 2**40, -3, np.int64(5)):
        for _ in range(2):
            np.testing.assert_array_equal(prng_key(seed), jax.random.PRNGKey(int(seed)))
    with pytest.raises(ValueError, match="out of the range"):
        prng_key(2**70)
    strong = sp.default_gains(jnp.float64)
    mixed = strong._replace(k_att=2.0, d0=jnp.asarray(0.07))
    out = strong_gains(mixed, jnp.float64)
    assert out.v_max is strong.v_max
    for name in ("k_att", "d0"):
        leaf = getattr(out, name)
        assert leaf.dtype == jnp.float64 and not leaf.weak_type and float(leaf) == float(getattr(strong, name))
    assert strong_gains(strong, jnp.float32).k_att.dtype == jnp.float32
    # Made first inside a jit (tracers), they are not kept: the next calls outside are concrete.
    seed = 987654321
    jax.jit(lambda x: x + prng_key(seed)[1].astype(x.dtype) + sp.default_gains(x.dtype).k_att)(
        jnp.float16(1.0))
    assert not isinstance(prng_key(seed), jax.core.Tracer)
    assert not isinstance(sp.default_gains(jnp.float16).k_att, jax.core.Tracer)


@pytest.mark.slow  # its own rollout program (~15 s compile on 2 CPUs)
def test_forty_segment_arm_plans_without_collision():
    """The tree scene with an arm of 40 short segments (total length 3, as the paper's arm;
    the frames composed in a lax.scan): the plan reaches the goal, and an independent
    brute-force check (NumPy oracle kinematics on sampled motions, densely sampled
    obstacles) finds no sampled point of the motion within the arm's radius of an obstacle (sampling can only
    over-estimate the clearance: a sampled clearance at or below zero is a collision)."""
    from scipy.spatial import cKDTree

    from softplan_jax.geometry._obstacles import obstacle_samples

    n = 40
    sc = sp.paper_scenario("tree")
    sc = sc._replace(q0=sp.scenarios.default_start(n, 3.0 / n), L_min=jnp.full(n, sc.L_min[0]),
                     L_max=jnp.full(n, sc.L_max[0]))
    r = sp.plan(sc, max_steps=300)
    assert r.q.shape == (r.iterations + 1, n, 3)
    assert r.status == "reached", (r.status, r.final_error)
    assert not r.collided and r.min_clearance > 0
    np.testing.assert_allclose(r.tip[-1], oracle.tip_position(np.asarray(r.q[-1])), atol=1e-12)
    t = np.linspace(0.0, 1.0, 5)[:-1]
    qs = np.asarray(r.q)
    moving = (qs[:-1, None] + t[None, :, None, None] * (qs[1:] - qs[:-1])[:, None]).reshape(-1, n, 3)
    arm = oracle.arm_points_many(np.concatenate([moving, qs[-1:]]), np.linspace(0.0, 1.0, 8)).reshape(-1, 3)
    for ob in obstacle_samples(sc, 4000):
        gap = cKDTree(ob["pts"]).query(arm)[0].min() - ob["radius"] - float(sc.arm_radius)
        assert gap > 0, (ob["slot"], gap)
