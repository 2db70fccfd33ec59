"""Planning with the loaded arm (``sp.plan(..., model=RodModel)``): the recorded clearances are
lower bounds of the loaded arm's, at every step and during every motion, checked by a brute
force on densely sampled equilibria (``loaded_backbone`` at 33 points per segment, at the steps
and 4 instants between them) against the obstacles sampled at 2,001 points (a sampled clearance
is never below the true one, so the checks hold at any resolution), for a tracked moving scene
with the branches at each instant too, and for a path of the global fallback; the input
boundary. (The posed arm's implicit Jacobians, its tip's included, are checked in test_rod.py,
beside the solve's.)
Compiling the loaded rollout takes tens of seconds: the plans are in the slow tier."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial import cKDTree

import softplan_jax as sp
from softplan_jax.geometry._obstacles import obstacle_samples
from softplan_jax.rod import LoadedArm, RodModel, loaded_backbone

POINTS = 33  # backbone samples per segment of the brute force
BETWEEN = 4  # instants sampled strictly between consecutive steps
SAMPLES = 2001  # points per obstacle curve


@functools.cache
def _backbones(model_key):
    model = RodModel(*model_key[:3], model_key[3])
    return jax.jit(jax.vmap(lambda q: loaded_backbone(q, model, POINTS)))


def _arm_points(qs, model_key):
    P = np.asarray(_backbones(model_key)(jnp.asarray(qs)))  # (K, n, POINTS, 3)
    assert np.all(np.isfinite(P)), "an equilibrium along the path did not converge"
    return P.reshape(len(qs), -1, 3)


def brute_clearance(qs, scenario, model_key):
    """(K,) the smallest sampled clearance of the loaded arm at each configuration qs[k],
    arm radius and obstacle radius subtracted (never below the true clearance)."""
    P = _arm_points(qs, model_key)
    out = np.full(len(qs), np.inf)
    for obs in obstacle_samples(scenario, SAMPLES):  # each arm point's nearest obstacle sample (exact)
        d = cKDTree(obs["pts"]).query(P.reshape(-1, 3))[0].reshape(P.shape[:2])
        out = np.minimum(out, np.min(d, axis=1) - float(scenario.arm_radius) - obs["radius"])
    return out


def brute_clearance_moving(qs, times, moving, model_key):
    """(K,) as :func:`brute_clearance`, the arm at qs[k] and the moving scene's curves at times[k]."""
    from softplan_jax.scenarios._motion import scenario_at

    P = _arm_points(qs, model_key)
    curves = jax.jit(jax.vmap(lambda t: scenario_at(moving, t).curves))(jnp.asarray(times))
    scene = moving.scene
    out = np.full(len(qs), np.inf)
    for k in np.nonzero(np.asarray(scene.curve_mask))[0]:
        lo, hi = np.asarray(scene.curves.u_range[k], float)
        u = np.linspace(lo, hi, SAMPLES)
        C = np.asarray(curves.coeffs[:, k], float)  # (K, 3, degree + 1)
        O = np.stack([np.polynomial.polynomial.polyval(u, C[:, a, :].T) for a in range(3)], -1)  # (K, S, 3)
        d2 = np.einsum("kpa,kpa->kp", P, P)[:, :, None] + np.einsum("ksa,ksa->ks", O, O)[:, None, :] \
            - 2.0 * np.einsum("kpa,ksa->kps", P, O)
        d = np.sqrt(np.maximum(np.min(d2, axis=(1, 2)), 0.0))
        out = np.minimum(out, d - float(scene.arm_radius) - float(scene.curves.radius[k]))
    return out


def along_path(q):
    """The configurations at the steps and BETWEEN instants strictly between consecutive steps."""
    t = np.linspace(0.0, 1.0, BETWEEN + 2)[1:-1]
    mid = q[:-1, None] + t[None, :, None, None] * (q[1:] - q[:-1])[:, None]
    return q, mid.reshape(-1, *q.shape[1:])


MODEL_KEY = (6.0, 4.0, 0.3, (0.0, 0.0, -0.05))  # EI, GJ, w, tip load: the straight tree arm's tip sags 0.3


@pytest.mark.slow
def test_a_loaded_plan_stays_clear_of_the_branches_by_a_brute_force():
    scenario = sp.paper_scenario("tree")
    model = RodModel(*MODEL_KEY[:3], MODEL_KEY[3])
    r = sp.plan(scenario, model=model)
    assert r.status == "reached", r.status
    q = np.asarray(r.q)
    at_steps, between = along_path(q)
    c_steps = brute_clearance(at_steps, scenario, MODEL_KEY)
    # The recorded clearance (pieces, less their gap) is a lower bound of the loaded arm's.
    recorded = np.min(np.asarray(r.clearance), axis=1)
    assert np.all(c_steps >= recorded - 1e-9), np.min(c_steps - recorded)
    # During each motion the loaded arm stays clear: the sampled equilibria between steps stay
    # above the plan's minimum clearance over the motion (a lower bound from the motion bound).
    c_between = brute_clearance(between, scenario, MODEL_KEY)
    assert not r.collided and r.min_clearance > 0.0
    assert np.min(c_between) >= r.min_clearance - 1e-9, (np.min(c_between), r.min_clearance)
    # the tip the plan reports is the loaded tip
    tips = np.asarray(_backbones(MODEL_KEY)(jnp.asarray(q[-1:])))[0, -1, -1]
    np.testing.assert_allclose(np.asarray(r.tip)[-1], tips, atol=1e-9)


@pytest.mark.slow
def test_a_loaded_plan_in_float32():
    scenario = sp.paper_scenario("tree", dtype=jnp.float32)
    r = sp.plan(scenario, model=RodModel(*MODEL_KEY[:3], MODEL_KEY[3]))
    assert r.q.dtype == np.float32 and r.status == "reached" and r.min_clearance > 0.0


@pytest.mark.slow
def test_plan_batch_with_a_model_plans_each_scene_as_plan_does():
    # The tree with two goals: plan's program is the brute-force test's (same shape, max_steps).
    model = RodModel(*MODEL_KEY[:3], MODEL_KEY[3])
    tree = sp.paper_scenario("tree")
    scenes = [tree, tree._replace(goal=tree.goal + jnp.asarray([0.05, -0.05, 0.0]))]
    batch = sp.plan_batch(sp.scenarios.stack_scenarios(scenes), model=model)
    for b, scene in enumerate(scenes):
        one = sp.plan(scene, model=model)
        assert int(batch.iterations[b]) == one.iterations and one.status == "reached"
        # A batch agrees with single plans to rounding, which a rollout can amplify (plan_batch's
        # docstring): the first 16 steps.
        np.testing.assert_allclose(np.asarray(batch.q[b])[:16], one.q[:16], atol=1e-8)
        np.testing.assert_allclose(np.asarray(batch.tip[b])[:16], one.tip[:16], atol=1e-8)


def test_a_bad_model_is_a_value_error():
    scenario = sp.paper_scenario("tree")
    with pytest.raises(ValueError, match="model must be None"):
        sp.plan(scenario, model=(1.0, 1.0, 0.1))
    with pytest.raises(ValueError, match="bending_stiffness"):
        sp.plan(scenario, model=RodModel(np.ones(2), 1.0, 0.1))
    with pytest.raises(ValueError, match="model must be"):
        LoadedArm("stiff")
    # an upright arm crushed by its payload past Euler's load: no equilibrium to start from
    with pytest.raises(ValueError, match="did not converge"):
        sp.plan(scenario, model=RodModel(1.0, 1.0, 0.0, (0.0, 0.0, -0.5)))
    with pytest.raises(ValueError, match="pieces_per_segment"):
        LoadedArm(RodModel(1.0, 1.0, 0.1), 0)
    with pytest.raises(ValueError, match="model must be None"):
        sp.plan_fallback(scenario, model="heavy")
    from softplan_jax.search._fallback import rescue

    with pytest.raises(ValueError, match="model must be None"):  # before any result is read
        rescue(scenario, [], sp.PlanOptions(), model=(6.0, 4.0, 0.3))


@pytest.mark.slow
def test_the_fallback_rescues_the_loaded_arm_and_its_path_stays_clear_by_a_brute_force(tmp_path, capsys):
    # softplan run (rescue with the model, as plan_fallback) on the tree, its local plan cut at 10
    # steps (the brute-force test's program): the loaded arm's IK certifies a goal configuration
    # and the search a path, every motion proven by the loaded arm's clearance (pieces less their
    # gap) and its motion bound.
    import json

    out = tmp_path / "rescued.npz"
    code, text, _ = _cli(capsys, "run", "tree", "--weight", "0.3", "--stiffness", "6", "--torsional-stiffness", "4",
                         "--tip-load", "0,0,-0.05", "--max-steps", "10", "--json", "--out", out)
    summary = json.loads(text)
    assert code == 0 and summary["status"] == "reached" and summary["planner"] == "global", summary["reason"]
    assert summary["arm_model"]["kind"] == "loaded" and summary["fallback"] is True and summary["global_start"] <= 10
    scenario, model = sp.paper_scenario("tree"), RodModel(*MODEL_KEY[:3], MODEL_KEY[3])
    r = np.load(out)
    q = r["q"]
    at_steps, between = along_path(q)
    c_steps = brute_clearance(at_steps, scenario, MODEL_KEY)
    recorded = np.min(r["clearance"], axis=1)
    assert np.all(c_steps >= recorded - 1e-9), np.min(c_steps - recorded)
    # Between steps: each motion's lower bound, its start's recorded clearance less the loaded
    # motion bound, which the safe step keeps above twice the contact tolerance.
    bound = np.asarray(jax.jit(jax.vmap(LoadedArm(model).motion_bound))(jnp.asarray(q[:-1]), jnp.asarray(q[1:])))
    c_between = brute_clearance(between, scenario, MODEL_KEY).reshape(len(q) - 1, BETWEEN)
    assert np.all(c_between >= (recorded[:-1] - bound)[:, None] - 1e-9)
    assert np.all(recorded[:-1] - bound > 0.0) and not summary["collided"] and summary["min_clearance"] > 0.0
    # the reported tip is the loaded tip, on the goal
    tip = np.asarray(_backbones(MODEL_KEY)(jnp.asarray(q[-1:])))[0, -1, -1]
    np.testing.assert_allclose(r["tip"][-1], tip, atol=1e-9)
    assert np.linalg.norm(tip - np.asarray(scenario.goal)) < sp.PlanOptions().goal_tolerance


def _cli(capsys, *argv):
    from softplan_jax.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("argv, message", [
    (("--weight", "0.3"), "needs both --weight and --stiffness"),
    (("--weight", "0.3", "--stiffness", "-1"), "bending_stiffness must be > 0"),
    (("--weight", "nan", "--stiffness", "1"), "weight_per_length must be finite"),
    (("--weight", "0.3", "--stiffness", "1", "--tip-load", "1,2"), "three numbers"),
    (("--pcc", "--weight", "0.3"), "--pcc plans with the PCC arm"),
])
def test_cli_refuses_a_bad_loaded_arm(capsys, argv, message):
    code, _, err = _cli(capsys, "run", "tree", *argv)
    assert code == 2
    assert message in err


TRACK_STEPS = 90  # the loaded arm reaches tree_sway's goal at step 61


@pytest.mark.slow
def test_a_loaded_track_stays_clear_of_the_swaying_branches_by_a_brute_force():
    from softplan_jax.scenarios._moving import moving_scenario

    moving = moving_scenario("tree_sway")
    model = RodModel(*MODEL_KEY[:3], MODEL_KEY[3])
    r = sp.track(moving, max_steps=TRACK_STEPS, model=model)
    assert r.status == "reached" and r.evasive_steps == 0, r.status
    q, t = np.asarray(r.q), np.asarray(r.time)
    # At each step: the recorded clearance (pieces, less their gap, curves at t_k) is a lower
    # bound of the loaded arm's.
    c_steps = brute_clearance_moving(q, t, moving, MODEL_KEY)
    recorded = np.min(np.asarray(r.clearance), axis=1)
    assert np.all(c_steps >= recorded - 1e-9), np.min(c_steps - recorded)
    # During each motion, arm and branches moving together: above the run's minimum clearance.
    between_q = along_path(q)[1]
    tau = np.linspace(0.0, 1.0, BETWEEN + 2)[1:-1]
    between_t = (t[:-1, None] + tau[None, :] * (t[1:] - t[:-1])[:, None]).reshape(-1)
    c_between = brute_clearance_moving(between_q, between_t, moving, MODEL_KEY)
    assert not r.collided and r.min_clearance > 0.0
    assert np.min(c_between) >= r.min_clearance - 1e-9, (np.min(c_between), r.min_clearance)
    # the tip the tracker reports is the loaded tip
    tips = np.asarray(_backbones(MODEL_KEY)(jnp.asarray(q[-1:])))[0, -1, -1]
    np.testing.assert_allclose(r.tip[-1], tips, atol=1e-9)


@pytest.mark.slow
def test_the_cli_tracks_a_moving_scene_with_the_loaded_arm(capsys):
    import json

    code, out, _ = _cli(capsys, "run", "tree_sway", "--weight", "0.3", "--stiffness", "6",
                        "--torsional-stiffness", "4", "--tip-load", "0,0,-0.05", "--max-steps", TRACK_STEPS, "--json")
    summary = json.loads(out)
    assert code == 0 and summary["status"] == "reached" and not summary["collided"]
    assert summary["arm_model"]["kind"] == "loaded" and summary["evasive_steps"] == 0 and summary["evasion"] is False


def test_track_refuses_a_bad_model():
    from softplan_jax.scenarios._motion import stack_moving_scenarios
    from softplan_jax.scenarios._moving import moving_scenario

    moving = moving_scenario("tree_sway")
    with pytest.raises(ValueError, match="model must be None"):
        sp.track(moving, model="heavy")
    with pytest.raises(ValueError, match="did not converge"):
        sp.track(moving, model=RodModel(1.0, 1.0, 0.0, (0.0, 0.0, -0.5)))
    with pytest.raises(ValueError, match="bending_stiffness"):
        sp.track_batch(stack_moving_scenarios([moving, moving]), model=RodModel(np.ones(2), 1.0, 0.1))
    with pytest.raises(ValueError, match="model must be None"):  # the tracker's fallback passes it on
        sp.track_fallback(moving, model="heavy")


def test_cli_refuses_a_bad_material_block(tmp_path, capsys):
    import json

    path = tmp_path / "tree.json"
    assert _cli(capsys, "export", "tree", path)[0] == 0
    data = json.loads(path.read_text())
    data["arm"]["material"] = {"bending_stiffness": 0.0, "torsional_stiffness": 1.0, "weight_per_length": 0.3}
    path.write_text(json.dumps(data))
    code, _, err = _cli(capsys, "run", path)
    assert code == 2 and "bending_stiffness" in err


@pytest.mark.slow
def test_cli_plans_the_loaded_arm_of_a_material_block(tmp_path, capsys):
    import json

    from softplan_jax.scenarios._material import save_scenario_material

    path = tmp_path / "tree_loaded.json"
    save_scenario_material(sp.paper_scenario("tree"), RodModel(*MODEL_KEY[:3], MODEL_KEY[3]), path)
    code, out, _ = _cli(capsys, "run", path, "--json")
    assert code == 0
    summary = json.loads(out)
    assert summary["arm_model"] == {"kind": "loaded", "bending_stiffness": 6.0, "torsional_stiffness": 4.0,
                                    "weight_per_length": 0.3, "tip_load": [0.0, 0.0, -0.05]}
    assert summary["status"] == "reached" and not summary["collided"] and summary["fallback"] is True
    # --pcc: the same file planned with the PCC arm
    code, out, _ = _cli(capsys, "run", path, "--json", "--pcc")
    assert json.loads(out)["arm_model"] == {"kind": "pcc"}


@pytest.mark.slow
def test_an_unreachable_goal_reports_the_loaded_start():
    # beyond reach: no plan; the start's tip and clearance are the loaded arm's (the tip sags)
    scenario = sp.paper_scenario("tree")
    q0 = jnp.asarray([[1.0, 0.6, 0.0], [1.0, 0.4, 0.0], [1.0, 0.2, 0.0]])  # bent: the load sags it
    scenario = scenario._replace(q0=q0, goal=jnp.asarray([0.0, 0.0, 10.0]), L_max=jnp.full(3, 1.5, jnp.float64))
    model = RodModel(*MODEL_KEY[:3], MODEL_KEY[3])
    r = sp.plan(scenario, model=model)
    assert r.status == "unreachable" and r.iterations == 0
    tip = np.asarray(loaded_backbone(scenario.q0, model, 2))[-1, -1]
    np.testing.assert_allclose(r.tip[0], tip, atol=1e-12)
    assert np.linalg.norm(r.tip[0] - np.asarray(sp.tip_position(scenario.q0))) > 0.1
    # its clearance is the loaded arm's lower bound (the PCC start's is 0.026: the sag moves it away)
    brute = brute_clearance(np.asarray(q0)[None], scenario, MODEL_KEY)[0]
    assert r.min_clearance <= brute < r.min_clearance + 0.02, (r.min_clearance, brute)
