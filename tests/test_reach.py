"""Reachability (multi-start IK with exact clearances) and the certified global fallback (issue 24).

References: the proofs' own geometry (an arm of total length S reaches no
farther than S from its base), the brute-force sampled clearance of
:func:`softplan_jax.dense_trajectory_clearance` for every path the search
returns, and the local planner's arrays for scenes it reaches itself.

Every test shares one ReachOptions and the padded scene shape of
test_planner (5 curve slots, degree 2), so reachability's program and the
fallback's (the IK, the search and its check) compile once, and the paper
scenes' 200-step plans are test_planner's programs (from the persistent
compilation cache).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.geometry._arm import PCC
from softplan_jax.search import _tree as global_planner
from softplan_jax.search._fallback import _fallback_jit, _search_starts
from softplan_jax.search._reach import _goal_configurations_jit

OPTS = sp.search.ReachOptions()
PAD = dict(curve_slots=5, degree=2)  # test_planner's shape
# The straight start's tip is at (0, 0, 3); a wall of two segments blocks the way to this goal.
GOAL = (1.6, 0.0, 1.4)
WALL = [sp.line_segment([0.9, -1.2, 2.0], [0.9, 1.2, 2.0]), sp.line_segment([0.9, -1.2, 1.3], [0.9, 1.2, 2.6])]


def scene(goal=GOAL, obstacles=WALL, **kw):
    return sp.make_scenario(goal, obstacles, **PAD, **kw)


@pytest.fixture(scope="module")
def decided():
    """One batched reachability call (one compile): reachable, beyond reach, goal on an
    obstacle, goal at the base."""
    scenes = [
        scene(),
        scene(goal=(4.0, 1.0, 2.0), L_max=1.2),  # |goal| = 4.58 > 3 x 1.2
        scene(goal=(0.9, 0.3, 2.0), obstacles=[sp.line_segment([0.9, -1.2, 2.0], [0.9, 1.2, 2.0], radius=0.05)]),
        scene(goal=(0.0, 0.0, 0.0)),
    ]
    batch = sp.scenarios.stack_scenarios(scenes)
    # One scene at a time with an extra start: plan_fallback's program (compiled once for all).
    parts = [sp.search.reachability(s, q_extra=s.q0, options=OPTS) for s in scenes]
    return batch, sp.search.Reachability(*(np.stack([getattr(p, f) for p in parts]) if f != "reason" else
                                    tuple(p.reason for p in parts) for f in sp.search.Reachability._fields))


def test_reachable_goal_has_certified_configuration(decided):
    batch, r = decided
    assert r.reachable[0] and r.reason[0] == ""
    s = jax.tree_util.tree_map(lambda x: x[0], batch)
    q = jnp.asarray(r.q_goal[0, 0])
    assert r.certified[0, 0]
    # Tip on the goal, and the brute-force clearance agrees that the configuration is clear.
    assert float(jnp.linalg.norm(sp.tip_position(q) - s.goal)) <= OPTS.ik_tolerance
    dense = np.asarray(sp.geometry.dense_trajectory_clearance(jnp.stack([q, q]), s, substeps=1))
    assert np.min(dense) >= OPTS.ik_clearance - 1e-9
    assert np.min(dense) == pytest.approx(r.clearance[0, 0], abs=5e-3)  # the sampling error of the brute force
    # Certified rows first, sorted by clearance.
    c = r.clearance[0][r.certified[0]]
    assert np.all(np.diff(c) <= 0)


def test_goal_configurations_and_the_fallback_hold_one_exact_solve(monkeypatch):
    """The IK's program holds one copy of the exact solver, and so does the fallback's (issue
    34: the fallback's compile time): the starts, the tip IK from them and every null-space
    round are assessed at one site, the body of one loop; the fallback's loop assesses the IK's
    starts, walks every certified motion of the search and checks the path at one site.
    Traced only (make_jaxpr): nothing compiles."""
    from softplan_jax.search import _machine as machine
    from softplan_jax.search import _reach as reach_module

    sites = []

    def counting(real):
        def solve(*args, **kwargs):
            sites.append(1)
            return real(*args, **kwargs)
        return solve

    monkeypatch.setattr(reach_module, "posed_clearances", counting(reach_module.posed_clearances))
    monkeypatch.setattr(machine, "posed_clearances", counting(machine.posed_clearances))
    s = scene()
    jax.make_jaxpr(lambda s, key, q: reach_module.goal_configurations(s, key, q, OPTS))(s, jax.random.PRNGKey(0), s.q0)
    assert len(sites) == 1
    args = _fallback_args(s, np.asarray(s.q0)[None])  # a local "path" of the start alone
    for arm in (PCC, sp.rod.LoadedArm(sp.RodModel(6.0, 4.0, 0.3))):  # the loaded arm's too
        sites.clear()
        jax.make_jaxpr(lambda *a, arm=arm: global_planner.reach_and_search_batch(
            *a, OPTS, sp.geometry.SolverOptions(), 1e-6, arm))(*_stack(args))
        assert len(sites) == 1


@pytest.mark.slow
def test_batch_loop_equals_jax_vmap_of_the_scene_loop(decided):
    """goal_configurations_batch runs one loop for the batch (each round every scene's round,
    kept where that scene goes on); jax.vmap of the one-scene loop is the reference, and the
    arrays agree bit for bit on scenes that end at different rounds (certified at once,
    beyond reach: every null-space round). Slow: the reference is a 3-scene IK program of its
    own (about 8 s to trace and compile) that nothing else uses."""
    from softplan_jax.planning._options import rollout_compiler_options
    from softplan_jax.search._reach import goal_configurations

    batch, _ = decided
    batch = jax.tree_util.tree_map(lambda x: x[:3], batch)
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    solver = sp.geometry.SolverOptions()
    ours = _goal_configurations_jit(OPTS, solver, 1e-6, True)(batch, keys, batch.q0)
    reference = jax.jit(jax.vmap(lambda s, k, e: goal_configurations(s, k, e, OPTS, solver, 1e-6)),
                        compiler_options=rollout_compiler_options("curve"))(batch, keys, batch.q0)
    for a, b in zip(ours, reference, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    certified = np.asarray(ours[1])
    assert certified[0].any() and not certified[1].any()  # the scenes end at different rounds


def test_beyond_reach_is_proven_and_best_error_is_sound(decided):
    _, r = decided
    assert not r.reachable[1] and r.reason[1] == "beyond_reach"
    gap = math.sqrt(4.0**2 + 1.0 + 2.0**2) - 3 * 1.2
    # No configuration gets closer than the gap (soundness). The IK is local: it improves on the
    # start pose a lot but need not find the straight arm at the goal (the paper-scene test below does).
    start = math.sqrt(4.0**2 + 1.0 + 1.0)  # the straight start's tip (0, 0, 3)
    assert gap - 1e-9 <= r.best_error[1] <= 0.5 * start


def test_goal_in_obstacle_is_proven(decided):
    _, r = decided
    assert not r.reachable[2] and r.reason[2] == "goal_in_obstacle"
    # The best collision-free tip distance: finite (the start pose counts), not better than the proof allows.
    assert 0.05 - 1e-9 <= r.best_error[2] <= math.dist((0.9, 0.3, 2.0), (0.0, 0.0, 3.0))


def test_goal_at_base_is_decided_without_nan(decided):
    _, r = decided
    assert np.all(np.isfinite(r.q_goal[3]))
    assert np.isfinite(r.best_error[3])
    assert r.reason[3] in ("", "no_ik_solution")
    if r.reachable[3]:  # curled into a loop: the certificate must then hold
        assert r.tip_error[3, 0] <= OPTS.ik_tolerance and r.clearance[3, 0] >= OPTS.ik_clearance


@pytest.fixture(scope="module")
def rescued():
    """The local planner with 15 steps cannot reach GOAL; the fallback must."""
    s = scene()
    return s, sp.plan(s, max_steps=15), sp.plan_fallback(s, max_steps=15)


def test_fallback_reaches_what_the_local_planner_does_not(rescued):
    s, local, r = rescued
    assert local.status == "max_steps" and local.planner == "local"
    assert r.status == "reached" and r.reached and r.planner == "global" and r.reason == ""
    assert r.final_error < 1e-2
    assert r.best_error is not None and r.best_error <= OPTS.ik_tolerance
    # The path is the local path up to global_start, then the search's.
    k = r.global_start
    assert 0 <= k <= local.iterations
    np.testing.assert_array_equal(r.q[: k + 1], local.q[: k + 1])
    assert r.q.shape == (r.iterations + 1, 3, 3) and r.tip.shape == (r.iterations + 1, 3)
    assert r.clearance.shape == (r.iterations + 1, 2)  # the two real obstacles
    np.testing.assert_allclose(r.tip[-1], np.asarray(s.goal), atol=1e-2)


def test_fallback_path_is_collision_free_by_brute_force(rescued):
    s, _, r = rescued
    q = jnp.asarray(r.q[r.global_start:])
    dense = np.asarray(sp.geometry.dense_trajectory_clearance(q, s, substeps=4, arm_samples=60, curve_samples=600))
    assert np.min(dense) > 0
    assert not r.collided and r.min_clearance > 0
    # Every step of the search's part satisfies the swept proof: exact clearance at its start > its motion bound.
    B = np.asarray(jax.vmap(lambda a, b: sp.geometry.motion_bound(a, b)[-1])(q[:-1], q[1:]))
    assert np.all(r.clearance[r.global_start:-1].min(axis=1) - B > 1e-6)
    # Steps are short: the path is a sequence of planner-like steps, not jumps.
    assert np.max(B) <= OPTS.step_motion + 1e-12


def test_plot_shows_the_global_part(rescued):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softplan_jax import plotting

    s, _, r = rescued
    fig = plotting.plot_snapshots(s, r)
    try:
        ax = fig.axes[0]
        labels = [line.get_label() for line in ax.get_lines()]
        assert "tip path (global search)" in labels
        assert f"global search from step {r.global_start}" in fig._suptitle.get_text()
        green = next(line for line in ax.get_lines() if line.get_label() == "tip path (global search)")
        np.testing.assert_allclose(np.asarray(green.get_data_3d()).T, r.tip[r.global_start:])
    finally:
        plt.close(fig)


def test_fallback_programs_compile_with_the_package_xla_options(decided):
    """The fallback's program and reachability's compile with the package's XLA options for
    exact solves (planning.options.rollout_compiler_options("curve")): no YNN fusions, which
    XLA's defaults put in an exact solve's program (test_compilation_cache's rollout test
    shows it on a plain jit). Checked on the IK, with the shapes the fixture compiled (its
    program comes from the persistent cache); an earlier version of
    benchmarks/fallback_compile.py measured what the options buy (docs/performance.md)."""
    from softplan_jax.base._compilation_cache import package_jit

    batch, _ = decided
    one = jax.tree_util.tree_map(lambda x: x[:1], batch)
    ik = _goal_configurations_jit(OPTS, sp.geometry.SolverOptions(), 1e-6, True)
    fallback = _fallback_jit(OPTS, sp.geometry.SolverOptions(), 1e-6)
    # Both are package_jit's with the exact solves' options (test_compilation_cache tests package_jit).
    assert all(isinstance(f, package_jit) and f._kind == "exact" for f in (ik, fallback))
    keys = jax.random.split(jax.random.PRNGKey(0), 1)
    assert "ynn_fusion" not in ik.lower(one, keys, one.q0).compile().as_text()


def test_batch_compiles_the_search_once_and_keeps_local_results(rescued):
    # rescue() on a batch (plan_fallback's second half), from the local results of plan's
    # compiled program: the search runs per scene in chunks of one shape, one program.
    from softplan_jax.search._fallback import rescue

    s, local, single = rescued
    near = scene(goal=(0.005, 0.0, 3.0))  # within the goal tolerance of the start's tip
    local_near = sp.plan(near, max_steps=15)
    assert local_near.reached
    fn = _fallback_jit(OPTS, sp.geometry.SolverOptions(), 1e-6)
    before = fn._cache_size()
    assert before >= 1  # compiled by the single scene (the fixture)
    res = rescue(sp.scenarios.stack_scenarios([s, near, s]), [local, local_near, local], sp.make_options())
    assert [r.planner for r in res] == ["global", "local", "global"]
    assert all(r.reached for r in res)
    assert res[1] is local_near or res[1] == local_near
    assert res[1].best_error is None and res[1].global_start is None
    # Reachability and the search run in chunks of one shape: the batch compiles nothing new.
    assert fn._cache_size() == before


def _fallback_args(s, q_local, proof=False, seed=0):
    """The fallback program's arguments for one scene as plan_fallback passes them (chunk 1),
    after the local path ``q_local``."""
    q_starts, n_starts, _ = _search_starts(np.asarray(q_local), OPTS.start_roots)
    ik_key = jax.random.split(jax.random.PRNGKey(seed), 1)[0]
    key = jax.random.split(jax.random.PRNGKey(seed + 1), 1)[0]
    return (s, np.asarray(q_local[-1]), ik_key, proof, q_starts, n_starts, key)


def _stack(*lanes):
    return jax.tree_util.tree_map(lambda *ys: np.stack([np.asarray(y) for y in ys]), *lanes)


def test_fallback_program_runs_reachabilitys_ik(decided, rescued):  # rescued: compiles the program
    """The fallback's one program finds the goal roots by the IK of reachability (in its own
    loop, one start's exact solve per iteration) and gives reachability's arrays, with
    reachability's key and extra start, on the fixture's scenes that end at different rounds:
    bit for bit where a start is certified at once (rounds 0 and 1); over the null-space
    rounds (beyond reach: every round) the same verdicts and values to rounding (XLA fuses
    the push step differently in the two programs: last bits). A proof of unreachability
    stops the lane before the search. Both programs are the fixtures'."""
    batch, r = decided
    fn = _fallback_jit(OPTS, sp.geometry.SolverOptions(), 1e-6)
    for b in range(4):
        s = jax.tree_util.tree_map(lambda x, b=b: x[b], batch)
        proof = r.reason[b] in ("beyond_reach", "goal_in_obstacle")
        args = _fallback_args(s, np.asarray(s.q0)[None], proof=proof)  # reachability's extra start: q0
        ik, out = jax.device_get(fn(PCC, *_stack(args)))
        want = (r.q_goal[b], r.certified[b], r.clearance[b], r.tip_error[b], r.best_error[b])
        if b == 0:  # certified at once
            assert r.certified[b, 0]
            for got, w in zip(ik, want, strict=True):
                np.testing.assert_array_equal(got[0], w)
        np.testing.assert_array_equal(ik[1][0], r.certified[b])
        for got, w in zip(ik, want, strict=True):
            np.testing.assert_allclose(got[0], w, rtol=0, atol=1e-12)
        if not r.reachable[b]:
            assert not out.found[0] and int(out.iterations[0]) == 0 and int(out.steps[0]) == 0


@pytest.mark.slow
def test_search_lanes_run_independently(rescued):
    """The fallback's batched loop (search.machine): a lane searching beside a lane whose goal
    is proven unreachable (done after its IK) finds the single-lane search's path: same
    trees, iterations and steps, q to rounding (a wider program may round differently),
    every step of it proven by the search's check. Slow: the two-lane program (chunk > 1,
    not the default) compiles for about 20 s, and only this test uses it."""
    s, local, _ = rescued
    args = _fallback_args(s, local.q)
    fn = _fallback_jit(OPTS, sp.geometry.SolverOptions(), 1e-6)
    one = jax.device_get(fn(PCC, *_stack(args))[1])
    idle = (*args[:3], True, *args[4:6], jax.random.PRNGKey(4))  # proven unreachable: no search
    two = jax.device_get(fn(PCC, *_stack(idle, args))[1])
    assert bool(one.found[0]) and bool(two.found[1]) and not bool(two.found[0])
    assert int(two.iterations[0]) == 0 and int(two.steps[0]) == 0
    for f in ("start", "steps", "iterations", "nodes", "path_nodes"):
        np.testing.assert_array_equal(getattr(two, f)[1], getattr(one, f)[0], err_msg=f)
    k = int(one.steps[0])
    np.testing.assert_allclose(two.q[1][: k + 1], one.q[0][: k + 1], rtol=0, atol=1e-12)
    assert bool(two.proven[1]) and bool(one.proven[0]) and not bool(two.proven[0])
    np.testing.assert_allclose(two.clearance[1][: k + 1], one.clearance[0][: k + 1], rtol=0, atol=1e-12)


def test_unreachable_goal_gets_a_status_not_a_path():
    # test_planner's unreachable scene: the arm cannot stretch to the goal.
    s = sp.paper_scenario("sim1", L_max=1.05, **PAD)._replace(goal=jnp.array([0.0, 0.0, 10.0]))
    r = sp.plan_fallback(s, max_steps=200)
    assert r.status == "unreachable" and r.reason == "beyond_reach" and not r.reached
    assert r.planner == "local"
    assert r.iterations == 0 and r.best_error is None  # proven on the host: returned before planning
    assert np.isfinite(r.q).all() and not r.collided


def test_paper_scene_keeps_its_local_result():
    s = sp.paper_scenario("sim1", **PAD)
    a, f = sp.plan(s, max_steps=200), sp.plan_fallback(s, max_steps=200)
    assert f.planner == "local" and f.status == a.status == "reached"
    for field in ("q", "tip", "clearance"):
        np.testing.assert_array_equal(getattr(a, field), getattr(f, field))
    assert (a.iterations, a.min_clearance, a.final_error) == (f.iterations, f.min_clearance, f.final_error)


def test_wrap_delta_turns_the_short_way():
    q_a = jnp.array([[1.0, 0.5, 3.0]])
    q_b = jnp.array([[1.0, 0.5, -3.0]])
    d = global_planner.wrap_delta(q_a, q_b)
    assert float(d[0, 2]) == pytest.approx(2 * math.pi - 6.0)
    assert float(global_planner.wrap_delta(q_b, q_a)[0, 2]) == pytest.approx(6.0 - 2 * math.pi)


@pytest.mark.parametrize(
    "bad, match",
    [
        (dict(ik_starts=0), "ik_starts"),
        (dict(tree_size=1), "tree_size"),
        (dict(extend_distance=-1.0), "extend_distance"),
        (dict(step_motion=float("nan")), "step_motion"),
        (dict(safe_fraction=1.5), "safe_fraction"),
        (dict(length_range=(1.5, 0.5)), "length_range"),
        (dict(iterations=2.5), "iterations"),
    ],
)
def test_bad_reach_options(bad, match):
    with pytest.raises(ValueError, match=match):
        sp.search.reachability(scene(), options=OPTS._replace(**bad))


def test_bad_input():
    s = scene()
    with pytest.raises(ValueError, match="Scenario"):
        sp.search.reachability("not a scene")
    with pytest.raises(ValueError, match="q_extra"):
        sp.search.reachability(s, q_extra=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="q_extra"):
        sp.search.reachability(s, q_extra=np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="chunk"):
        sp.plan_fallback(s, chunk=0)
    with pytest.raises(ValueError, match="Scenario"):
        sp.plan_fallback({"goal": GOAL})
    with pytest.raises(ValueError, match="goal"):
        sp.make_scenario((np.nan, 0.0, 1.0), WALL)


@pytest.mark.slow
def test_float32_reachability_smoke():
    s = sp.make_scenario(GOAL, WALL, q0=sp.scenarios.default_start(dtype=jnp.float32), **PAD)
    r = sp.search.reachability(s, options=OPTS._replace(ik_tolerance=1e-4))
    assert r.q_goal.dtype == np.float32
    assert r.reachable and np.all(np.isfinite(r.q_goal))
    assert r.tip_error[0] <= 1e-4 and r.clearance[0] >= OPTS.ik_clearance
