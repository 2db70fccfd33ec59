"""A corpus of inputs that once crashed, hung or misled (a new user's first week): each now
gets a clear ValueError at the API, exit 2 with one line at the command, or an honest status.

Cheap: everything is refused before compiling, except the two scenes that plan (sim1's shape,
5 steps: the program of test_fuzz_boundary) and the start-clearance program of a goal proven
unreachable.
"""

from __future__ import annotations

import json
import os
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.planning._planner import check_gains
from softplan_jax.scenarios._json_format import moving_to_dict

STEPS = 5


def run_main(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err, *words):
    assert err.count("\n") == 1 and err.startswith("softplan: error: "), err
    for w in words:
        assert w in err, (w, err)


@pytest.fixture(scope="module")
def sim1_dict():
    return sp.scenarios.scenario_to_dict(sp.paper_scenario("sim1"))


# ----------------------------------------------------------------------------
# Sizes, checked before anything is allocated.


def test_max_steps_beyond_memory(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", 10**12)
    assert code == 2 and out == ""
    _one_error_line(err, "max_steps", "memory")
    with pytest.raises(ValueError, match="max_steps is too large"):
        sp.plan(sp.paper_scenario("sim1"), max_steps=10**12)
    with pytest.raises(ValueError, match="max_steps"):
        sp.plan_batch(sp.scenarios.stack_scenarios([sp.paper_scenario("sim1")] * 2), max_steps=10**11)
    with pytest.raises(ValueError, match="n is too large"):
        sp.random_scenarios(0, 10**12)


@pytest.mark.parametrize("argv", [["--max-steps", "2.5"], ["--max-steps", "1e3"], ["--seed", "1.5"],
                                  ["--seed", str(10**30)]])
def test_fractional_or_huge_integers_on_the_command_line(capsys, argv):
    code, _, err = run_main(capsys, "run", "sim1", *argv)
    assert code == 2 and err.count("\n") == 1 and err.startswith("softplan: error: "), err


def test_fractional_max_steps_and_non_integer_seed_in_the_api():
    s = sp.paper_scenario("sim1")
    for bad in (2.5, 600.0, True, "600", None):
        with pytest.raises(ValueError, match="max_steps"):
            sp.plan(s, max_steps=bad)
    for bad in (1.5, "0", True, 2**70, [0, 1]):
        with pytest.raises(ValueError, match="seed"):
            sp.plan(s, max_steps=STEPS, seed=bad)


@pytest.mark.parametrize("field,value", [("goal", [10**400, 0, 0]), ("arm.segments", 10**15),
                                         ("obstacles.0.coeffs", [[10**400, 0], [0, 1], [0.5, -1]]),
                                         ("obstacles.0.type", [1, 2]), ("goal", [1e300, 0, 0]),
                                         ("obstacles.0.coeffs", [[1.0, 1e160], [0, 1], [0.5, -1]]),
                                         ("arm.start", [[1.0, 1e300, 0.0]] * 3), ("arm.radius", 1e300)])
def test_json_numbers_too_large(tmp_path, capsys, sim1_dict, field, value):
    d = json.loads(json.dumps(sim1_dict))
    target = d
    keys = field.split(".")
    for k in keys[:-1]:
        target = target[int(k)] if k.isdigit() else target[k]
    target[keys[-1]] = value
    path = tmp_path / "big.json"
    path.write_text(json.dumps(d))
    before = path.read_bytes()
    with pytest.raises(ValueError, match="scenario field"):
        sp.load_scenario(path)
    code, _, err = run_main(capsys, "run", path, "--max-steps", STEPS)
    assert code == 2, err
    _one_error_line(err, keys[0] if keys[0] != "obstacles" else "obstacles[0]")
    assert path.read_bytes() == before


def test_gains_file_number_too_large(tmp_path):
    path = tmp_path / "g.json"
    sp.save_gains(sp.default_gains(), path)
    d = json.loads(path.read_text())
    d["gains"]["k_att"] = 10**400
    path.write_text(json.dumps(d))
    with pytest.raises(ValueError, match="gains.k_att"):
        sp.load_gains(path)


# ----------------------------------------------------------------------------
# API edges.


def test_empty_stacked_suite():
    s = sp.paper_scenario("sim1")
    empty = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None][:0], s)
    with pytest.raises(ValueError, match="no scenario"):
        sp.plan_batch(empty, max_steps=STEPS)
    with pytest.raises(ValueError, match="at least one"):
        sp.scenarios.stack_scenarios([])


def test_cloud_at_1e200(tmp_path, capsys):
    u = np.linspace(0.0, 1.0, 200)
    cloud = np.stack([u, u**2, np.ones_like(u)], axis=1) * 1e200
    for fit in (sp.clouds.fit_curves, sp.clouds.fit_curve):
        with pytest.raises(ValueError, match="rescale"):
            fit(cloud)
    path = tmp_path / "cloud.npy"
    np.save(path, cloud)
    code, _, err = run_main(capsys, "fit", path)
    assert code == 2
    _one_error_line(err, "rescale")
    assert sorted(os.listdir(tmp_path)) == ["cloud.npy"]


def test_fit_degree_is_capped_with_the_reason(tmp_path, capsys):
    u = np.linspace(-1.0, 1.0, 300)
    cloud = np.stack([0.5 + 0 * u, u, 1.0 + 0.3 * np.sin(3 * u)], axis=1)
    with pytest.raises(ValueError, match="degree = 60 is too high.*precision"):
        sp.clouds.fit_curve(cloud, degree=60)
    with pytest.raises(ValueError, match="max_degree"):
        sp.clouds.fit_curves(cloud, max_degree=40)
    path = tmp_path / "c.npy"
    np.save(path, cloud)
    code, _, err = run_main(capsys, "fit", path, "--degree", 60)
    assert code == 2
    _one_error_line(err, "degree", "split")


def test_save_into_a_missing_folder_names_the_users_path(tmp_path):
    target = tmp_path / "no" / "such" / "scene.json"
    with pytest.raises(ValueError, match="does not exist") as info:
        sp.save_scenario(sp.paper_scenario("sim1"), target)
    assert str(target) in str(info.value) and ".softplan-" not in str(info.value)
    with pytest.raises(ValueError, match=str(tmp_path / "no" / "g.json")):
        sp.save_gains(sp.default_gains(), tmp_path / "no" / "g.json")
    with pytest.raises(ValueError, match="directory"):
        sp.save_scenario(sp.paper_scenario("sim1"), tmp_path)


def test_a_scene_edited_into_a_wrong_shape_is_refused_at_plan():
    s = sp.paper_scenario("sim1")
    for edit, field in ((dict(goal=jnp.zeros(4)), "goal"), (dict(goal=jnp.zeros((1, 3))), "goal"),
                        (dict(goal=jnp.zeros(3, jnp.float32)), "goal"), (dict(q0=jnp.ones((3, 2))), "q0"),
                        (dict(L_max=jnp.ones(2)), "L_max"), (dict(curve_mask=jnp.ones(3, bool)), "curve_mask"),
                        (dict(goal=[1.0, 2.0, 3.0]), "goal"), (dict(arm_radius=jnp.ones(2)), "arm_radius"),
                        (dict(goal=jnp.array([1e300, 0.0, 0.0])), "goal")):
        with pytest.raises(ValueError, match=f"scenario.{field}"):
            sp.plan(s._replace(**edit), max_steps=STEPS)
    batch = sp.scenarios.stack_scenarios([s, s])
    with pytest.raises(ValueError, match="scenario.goal"):
        sp.plan_batch(batch._replace(goal=jnp.zeros((2, 4))), max_steps=STEPS)


# ----------------------------------------------------------------------------
# Warnings and statuses that say what is true.


def test_goal_near_a_long_curve_is_not_called_inside_it():
    """0.29 from a 2000-long wire: a sampled check (spacing ~1) called it inside; the exact one does not."""
    wire = sp.line_segment([-1000.0, 0.0, 1.5], [1000.0, 0.0, 1.5])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = sp.make_scenario([0.3, 0.29, 1.5], [wire])
    assert sp.scenarios.scenario_warnings(s) == []
    with pytest.warns(UserWarning, match="inside obstacle"):
        sp.make_scenario([0.3, 0.29, 1.5], [sp.line_segment([-1000.0, 0.0, 1.5], [1000.0, 0.0, 1.5], radius=0.3)])


def test_goal_proven_unreachable_returns_at_once():
    s = sp.paper_scenario("sim1", L_max=1.05)
    with pytest.raises(ValueError, match="rescale"):  # 1e300: beyond what float64 distances hold
        sp.plan(s._replace(goal=jnp.array([0.0, 0.0, 1e300])), max_steps=STEPS)
    r = sp.plan(s._replace(goal=jnp.array([0.0, 0.0, 1e100])), max_steps=STEPS)
    assert r.status == "unreachable" and r.reason == "beyond_reach" and r.iterations == 0
    assert r.q.shape == (1, 3, 3) and np.isfinite(r.min_clearance) and np.isfinite(r.final_error)
    inside = sp.paper_scenario("sim1")._replace(goal=jnp.array([1.0, 0.0, 0.5]))  # on sim1's line
    r = sp.plan(inside, max_steps=STEPS)
    assert r.status == "unreachable" and r.reason == "goal_in_obstacle" and r.iterations == 0


def test_start_in_collision_has_its_own_status():
    """A wire through the straight arm's middle segment: nothing to plan, and the status says why."""
    wire = sp.line_segment([-1.0, 0.0, 1.5], [1.0, 0.0, 1.5])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = sp.make_scenario([1.1, -0.8, 0.9], [wire], curve_slots=5, degree=2)
    r = sp.plan(s, max_steps=200)  # test_planner's padded shape and horizon: its compiled program
    assert r.status == "start_in_collision" and r.iterations == 0 and r.collided and not r.reached
    assert r.min_clearance <= 0


def test_gains_outside_their_sound_range(tmp_path):
    g = sp.default_gains()
    path = tmp_path / "g.json"
    sp.save_gains(g._replace(damping=jnp.asarray(0.0)), path)
    with warnings.catch_warnings():  # the paper preset's damping 0 loads silently ...
        warnings.simplefilter("error")
        sp.load_gains(path)
    with pytest.warns(UserWarning, match="stability bound"):
        check_gains(g._replace(dt=jnp.asarray(5.0)), jnp.float64)
    straight_in_plane = sp.scenarios.default_start().at[:, 2].set(0.0)
    with pytest.raises(ValueError, match="damping = 0.*rank"):  # ... and is refused where it is singular
        sp.plan(sp.paper_scenario("sim1", q0=straight_in_plane), gains=g._replace(damping=jnp.asarray(0.0)),
                max_steps=STEPS)


def test_moving_goal_disagreeing_with_its_path(tmp_path, capsys):
    d = moving_to_dict(sp.moving_scenario("tree_fruit"))
    d["goal"] = [d["goal"][0] + 0.5, d["goal"][1], d["goal"][2]]
    path = tmp_path / "moving.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"goal.*goal_path.points\[0\]"):
        sp.scenarios.load_moving_scenario(path)
    code, _, err = run_main(capsys, "run", path, "--max-steps", STEPS)
    assert code == 2
    _one_error_line(err, "goal", "goal_path.points[0]")
