"""The ``softplan`` command, run in-process through ``main([...])`` (plus one
subprocess run of ``python -m softplan_jax.cli`` for the entry point).

Compilation dominates the cost, so every planning run here uses ONE compiled
shape: a sim1-shaped scenario (one degree-1 curve, no point sets), the curve
method with default options, float64 and --max-steps 80 (``softplan batch``:
tests/test_warm_start.py's suite and steps). The bad-input cases fail before
anything is compiled.

The last section smoke-tests the plotting functions the command uses on a
hand-made result (no planning).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from session import subprocess_env

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.planning._planner import PlanResult

STEPS = "80"
SUMMARY_FIELDS = {
    "scenario", "method", "n_points", "repulsion", "gains", "gains_file", "gain_values", "step", "escapes", "dtype",
    "status", "iterations",
    "max_steps", "reached", "collided", "min_clearance", "final_error", "goal_tolerance", "compile_time_s", "run_time_s",
    "time_per_step_s", "plot", "gif", "out", "program_from_cache",
    "planner", "reason", "global_start", "best_error", "fallback", "fallback_time_s", "extension", "arm_model",
}


def run_main(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def sim1_file(tmp_path_factory):
    """sim1 exported by the command itself."""
    path = tmp_path_factory.mktemp("export") / "sim1.json"
    assert main(["export", "sim1", str(path)]) == 0
    return path


# ----------------------------------------------------------------------------
# Planning runs.


def test_run_sim1_with_plot(tmp_path, capsys):
    png = tmp_path / "sim1.png"
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--plot", png)
    assert code == 0, err
    assert png.exists() and png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "overwrote" not in err
    png.write_bytes(b"replaced below")  # an existing figure: replaced with --force, and said so
    code, _, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--plot", png, "--force")
    assert code == 0, err
    assert f"softplan: overwrote {png} (--force)" in err and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for label in ("scenario", "method", "status", "iterations", "reached", "collided",
                  "min true clearance", "final tip error", "compile time", "time per step"):
        assert label in out, f"{label!r} missing from the summary:\n{out}"
    assert "sim1" in out and "curve" in out


def test_run_json_summary(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json")
    assert code == 0, err
    s = json.loads(out)
    assert set(s) == SUMMARY_FIELDS
    assert s["scenario"] == "sim1" and s["method"] == "curve" and s["dtype"] == "float64"
    assert s["status"] in sp.planning.STATUS_NAMES.values()
    assert isinstance(s["iterations"], int) and 0 < s["iterations"] <= 80
    assert s["max_steps"] == 80
    assert isinstance(s["reached"], bool) and isinstance(s["collided"], bool)
    assert s["reached"] == (s["status"] == "reached")
    assert s["collided"] == (s["status"] == "collided")
    assert isinstance(s["min_clearance"], float) and isinstance(s["final_error"], float)
    if s["reached"]:
        assert s["final_error"] < s["goal_tolerance"]
    assert s["compile_time_s"] > 0 and s["run_time_s"] > 0
    assert s["time_per_step_s"] == pytest.approx(s["run_time_s"] / s["iterations"])
    assert s["plot"] is None and s["gif"] is None
    assert s["arm_model"] == {"kind": "pcc"}


def test_export_then_run_file(sim1_file, tmp_path, capsys):
    before = sim1_file.read_bytes()
    png = tmp_path / "from_file.png"
    code, out, err = run_main(capsys, "run", sim1_file, "--max-steps", STEPS, "--json", "--plot", png)
    assert code == 0, err
    from_file = json.loads(out)
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json")
    assert code == 0, err
    from_name = json.loads(out)
    for key in ("status", "iterations", "reached", "collided", "min_clearance", "final_error"):
        assert from_file[key] == from_name[key], key
    assert png.stat().st_size > 10_000
    assert sim1_file.read_bytes() == before  # the input file is never touched


def test_require_reached(sim1_file, tmp_path, capsys):
    # The same shape as sim1 (same compilation), with an unreachable goal.
    data = json.loads(sim1_file.read_text())
    data["goal"] = [4.0, 4.0, 4.0]
    far = tmp_path / "far.json"
    far.write_text(json.dumps(data))
    # Without the fallback (with it, unbounded lengths reach this goal: see test_run_fallback_*).
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json", "--no-fallback")
    assert code == 0, err  # planning finished: success whatever the status
    assert json.loads(out)["reached"] is False
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json", "--require-reached", "--no-fallback")
    assert code == 3
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json", "--require-reached")
    assert code == (0 if json.loads(out)["reached"] else 3)


def test_run_fallback_says_unreachable_and_why(sim1_file, tmp_path, capsys):
    # sim1's shapes and steps (its compiled rollout); lengths capped at 1.05: the goal is beyond reach.
    data = json.loads(sim1_file.read_text())
    data["goal"] = [4.0, 4.0, 4.0]
    data["arm"]["length_limits"] = [0.001, 1.05]
    far = tmp_path / "beyond.json"
    far.write_text(json.dumps(data))
    out_file = tmp_path / "beyond_run.json"
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json", "--out", out_file)
    assert code == 0, err
    s = json.loads(out)
    assert s["status"] == "unreachable" and s["reason"] == "beyond_reach" and s["planner"] == "local"
    assert s["fallback"] is True and not s["reached"] and s["global_start"] is None
    # Proven on the host before planning: returned at once, nothing compiled, no IK (no best error).
    assert s["iterations"] == 0 and s["compile_time_s"] == 0 and s["best_error"] is None
    saved = json.loads(out_file.read_text())
    for key in ("status", "reason", "planner", "global_start", "best_error"):
        assert saved[key] == s[key], key
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--require-reached")
    assert code == 3 and "unreachable (beyond_reach)" in out
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json", "--no-fallback")
    s = json.loads(out)  # the proof is not the fallback: it holds without it
    assert s["status"] == "unreachable" and s["reason"] == "beyond_reach" and s["best_error"] is None
    assert s["fallback"] is False and s["fallback_time_s"] == 0


# ----------------------------------------------------------------------------
# Other commands.


def _check_trajectory(data, summary):
    """A ``run --out`` record (loaded from JSON or NPZ) against the run's summary and independent checks."""
    it = summary["iterations"]
    q, tip, clearance = (np.asarray(data[k], dtype=float) for k in ("q", "tip", "clearance"))
    assert q.shape == (it + 1, 3, 3) and tip.shape == (it + 1, 3) and clearance.shape == (it + 1, 1)
    np.testing.assert_allclose(q[0], np.asarray(sp.paper_scenario("sim1").q0), atol=0)
    for k in (0, it // 2, it):
        np.testing.assert_allclose(tip[k], np.asarray(sp.tip_position(q[k])), atol=1e-12)
    np.testing.assert_allclose(np.asarray(data["goal"], float), [1.1, -0.8, 0.9])
    assert np.all(np.isfinite(clearance))
    assert abs(clearance.min() - summary["min_clearance"]) <= 1e-9 + 0.5 * abs(summary["min_clearance"])
    assert str(data["format"]) == "softplan-trajectory/1"
    for key in ("status", "scenario", "method", "repulsion", "dtype"):
        assert str(data[key]) == summary[key], key
    for key in ("iterations", "max_steps", "reached", "collided"):
        assert data[key] == summary[key], key
    for key in ("min_clearance", "final_error", "goal_tolerance"):
        assert float(data[key]) == summary[key], key
    assert abs(np.linalg.norm(tip[-1] - [1.1, -0.8, 0.9]) - summary["final_error"]) < 1e-12


def test_run_out_json_and_npz_round_trip(tmp_path, capsys):
    path_json, path_npz = tmp_path / "sim1.json", tmp_path / "sim1.npz"
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json", "--out", path_json)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["out"] == str(path_json)
    data = json.loads(path_json.read_text())
    assert data["n_points"] is None  # curve method
    _check_trajectory(data, summary)

    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--out", path_npz)
    assert code == 0, err
    assert "trajectory" in out and str(path_npz) in out
    with np.load(path_npz) as z:  # no pickles needed
        npz = {k: z[k] for k in z.files}
    assert "n_points" not in npz
    _check_trajectory({k: (v.item() if v.ndim == 0 else v) for k, v in npz.items()}, summary)
    for key in ("q", "tip", "clearance", "goal"):  # JSON and NPZ hold the same numbers, exactly
        np.testing.assert_array_equal(np.asarray(data[key]), npz[key])

    # An existing file is replaced only with --force, and the command says so.
    before = path_json.read_bytes()
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--out", path_json)
    assert code == 2 and "--force" in err and path_json.read_bytes() == before
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--out", path_json, "--force")
    assert code == 0 and "overwrote" in err
    assert json.loads(path_json.read_text())["q"] == data["q"]


def test_scenarios_lists_paper_and_moving_scenarios(capsys):
    code, out, err = run_main(capsys, "scenarios")
    assert code == 0, err
    for name in ("sim1", "sim2", "tree"):
        assert name in out
    assert "tree_fruit" in out and "wire_sweep" in out  # the moving presets the README runs, too
    code, out, _ = run_main(capsys, "scenarios", "--json")
    rows = json.loads(out)
    assert [r["name"] for r in rows] == ["sim1", "sim2", "tree", "tree_sway", "tree_fruit", "wire_sweep"]
    assert [r["kind"] for r in rows] == ["paper"] * 3 + ["moving"] * 3
    assert rows[2]["goal"] == [1.0, 0.7, 1.45] and rows[3]["goal"] == rows[2]["goal"]  # tree_sway: the tree's goal
    assert [r["goal_moves"] for r in rows[3:]] == [False, True, False]  # the fruit moves with its branch
    assert [r["obstacles"] for r in rows] == [1, 1, 5, 5, 5, 1]


@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_export_writes_loadable_json(tmp_path, capsys, name):
    path = tmp_path / f"{name}.json"
    code, _, err = run_main(capsys, "export", name, path)
    assert code == 0, err
    loaded = sp.load_scenario(path)
    np.testing.assert_array_equal(loaded.goal, sp.paper_scenario(name).goal)


def test_export_refuses_to_overwrite(tmp_path, capsys):
    path = tmp_path / "taken.json"
    path.write_bytes(b"keep me")
    code, out, err = run_main(capsys, "export", "sim1", path)
    assert code == 2
    assert err.startswith("softplan: error:") and "--force" in err
    assert path.read_bytes() == b"keep me"
    code, _, err = run_main(capsys, "export", "sim1", path, "--force")
    assert code == 0, err
    assert json.loads(path.read_text())["name"] == "sim1"


def test_help_and_version(capsys):
    assert main(["--help"]) == 0
    assert "run" in capsys.readouterr().out
    assert main(["run", "--help"]) == 0
    assert "--require-reached" in capsys.readouterr().out
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("softplan ")
    assert main([]) == 2  # no command: help on stderr


# ----------------------------------------------------------------------------
# Bad input: exit 2, one line on stderr, no traceback, nothing written.


def _bad_cases(tmp: str, scenario_file: str):
    """(id, argv); paths under ``tmp``."""
    j = os.path.join
    return [
        ("unknown scenario", ["run", "sim4"]),
        ("missing file", ["run", j(tmp, "missing.json")]),
        ("directory as scenario", ["run", tmp]),
        ("invalid json", ["run", j(tmp, "invalid.json")]),
        ("goal of 2 numbers", ["run", j(tmp, "goal2.json")]),
        ("unknown key", ["run", j(tmp, "unknown_key.json")]),
        ("n-points 0", ["run", "sim1", "--n-points", "0"]),
        ("n-points -3", ["run", "sim1", "--method", "points", "--n-points", "-3"]),
        ("n-points not int", ["run", "sim1", "--n-points", "ten"]),
        ("max-steps -1", ["run", "sim1", "--max-steps", "-1"]),
        ("max-steps 0", ["run", "sim1", "--max-steps", "0"]),
        ("max-steps float", ["run", "sim1", "--max-steps", "1.5"]),
        ("goal-tolerance 0", ["run", "sim1", "--goal-tolerance", "0"]),
        ("goal-tolerance nan", ["run", "sim1", "--goal-tolerance", "nan"]),
        ("goal-tolerance negative", ["run", "sim1", "--goal-tolerance", "-0.1"]),
        ("unknown method", ["run", "sim1", "--method", "spline"]),
        ("unknown repulsion", ["run", "sim1", "--repulsion", "gauss"]),
        ("unknown option", ["run", "sim1", "--colour", "red"]),
        ("plot in missing directory", ["run", "sim1", "--plot", j(tmp, "no", "such", "dir.png")]),
        ("plot is a directory", ["run", "sim1", "--plot", tmp]),
        ("plot unknown format", ["run", "sim1", "--plot", j(tmp, "out.xyz")]),
        ("plot over the input file", ["run", scenario_file, "--plot", scenario_file]),
        ("gif over the input file", ["run", scenario_file, "--gif", scenario_file]),
        ("gif not .gif", ["run", "sim1", "--gif", j(tmp, "anim.png")]),
        ("gif in missing directory", ["run", "sim1", "--gif", j(tmp, "no", "anim.gif")]),
        ("plot and gif the same", ["run", "sim1", "--plot", j(tmp, "a.gif"), "--gif", j(tmp, "a.gif")]),
        ("plot existing file", ["run", "sim1", "--plot", j(tmp, "figure.png")]),
        ("gif existing file", ["run", "sim1", "--gif", j(tmp, "motion.gif")]),
        ("out unknown extension", ["run", "sim1", "--out", j(tmp, "trajectory.txt")]),
        ("out without extension", ["run", "sim1", "--out", j(tmp, "trajectory")]),
        ("out existing file", ["run", "sim1", "--out", scenario_file]),
        ("out over the input file", ["run", scenario_file, "--out", scenario_file, "--force"]),
        ("out in missing directory", ["run", "sim1", "--out", j(tmp, "no", "t.npz")]),
        ("out and plot the same", ["run", "sim1", "--out", j(tmp, "t.json"), "--plot", j(tmp, "t.json")]),
        ("force without out", ["run", "sim1", "--force"]),
        ("unknown command", ["plan", "sim1"]),
        ("run without scenario", ["run"]),
        ("export unknown name", ["export", "sim9", j(tmp, "x.json")]),
        ("export existing file", ["export", "sim1", scenario_file]),
        ("export to missing directory", ["export", "sim1", j(tmp, "no", "x.json")]),
        ("export to a directory", ["export", "sim1", tmp]),
        ("batch n 0", ["batch", "--n", "0"]),
        ("batch chunk 0", ["batch", "--n", "4", "--chunk", "0"]),
        ("batch max-steps 0", ["batch", "--n", "4", "--max-steps", "0"]),
        ("batch n-points with curve", ["batch", "--n", "4", "--n-points", "5"]),
        ("batch n-points 0", ["batch", "--n", "4", "--method", "points", "--n-points", "0"]),
        ("batch out not npz", ["batch", "--n", "4", "--out", j(tmp, "r.json")]),
        ("batch out existing file", ["batch", "--n", "4", "--out", scenario_file]),
        ("batch more obstacles than slots", ["batch", "--n", "4", "--obstacles", "1", "9"]),
        ("batch too many devices", ["batch", "--n", "4", "--devices", "64"]),
        ("batch host devices after jax started", ["batch", "--n", "4", "--host-devices", "3"]),
        ("batch coordinator alone", ["batch", "--n", "4", "--coordinator", "localhost:1234"]),
        ("batch process id out of range", ["batch", "--n", "4", "--coordinator", "localhost:1234",
                                           "--num-processes", "2", "--process-id", "2"]),
        ("batch num processes 0", ["batch", "--n", "4", "--coordinator", "localhost:1234",
                                   "--num-processes", "0", "--process-id", "0"]),
        ("batch coordinator without port", ["batch", "--n", "4", "--coordinator", "localhost",
                                            "--num-processes", "1", "--process-id", "0"]),
        ("batch devices with coordinator", ["batch", "--n", "4", "--devices", "1", "--coordinator", "localhost:1234",
                                            "--num-processes", "1", "--process-id", "0"]),
    ]


BAD_IDS = [c[0] for c in _bad_cases("t", "f")]


@pytest.mark.parametrize("case_id", BAD_IDS)
def test_bad_input_exits_2(tmp_path, capsys, case_id):
    good = {"goal": [1.0, 0.5, 1.5]}
    (tmp_path / "invalid.json").write_text('{"goal": [1, 2, 3]', encoding="utf-8")
    (tmp_path / "goal2.json").write_text(json.dumps({"goal": [1.0, 2.0]}), encoding="utf-8")
    (tmp_path / "unknown_key.json").write_text(json.dumps({**good, "colour": "red"}), encoding="utf-8")
    scenario_file = tmp_path / "scenario.json"
    scenario_file.write_text(json.dumps(good), encoding="utf-8")
    (tmp_path / "figure.png").write_bytes(b"a figure of mine")
    (tmp_path / "motion.gif").write_bytes(b"an animation of mine")
    files = sorted(tmp_path.iterdir())
    contents = {p: p.read_bytes() for p in files}

    argv = dict(_bad_cases(str(tmp_path), str(scenario_file)))[case_id]
    code, out, err = run_main(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert lines[0].startswith("softplan: error: ")
    assert "Traceback" not in err
    # Nothing written, nothing changed.
    assert sorted(tmp_path.iterdir()) == files
    assert {p: p.read_bytes() for p in files} == contents


def test_bad_file_message_names_the_field(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"goal": [1.0, 2.0]}))
    code, _, err = run_main(capsys, "run", bad)
    assert code == 2
    assert "goal" in err.replace(str(bad), "")


def test_batch_command(tmp_path, capsys):
    """``softplan batch``: plan_batch over a random suite, progress on stderr, summary and
    per-scenario results. The suite and steps are test_warm_start's (one compiled program)."""
    out = tmp_path / "batch.npz"
    code, stdout, err = run_main(capsys, "batch", "--n", 3, "--seed", 3, "--obstacles", 1, 5, "--slots", 5,
                                 "--max-steps", 200, "--chunk", 3, "--json", "--out", out)
    assert code == 0, err
    s = json.loads(stdout)
    assert (s["scenarios"], s["devices"], s["chunk"], s["max_steps"]) == (3, 1, 3, 200)
    assert sum(s["status_counts"].values()) == 3 and s["steps_per_s"] > 0 and s["scenes_per_s"] > 0
    assert "batch: 1/1 chunks, 3/3 scenes, reached" in err and "(compile " in err
    saved = np.load(out)
    ref = sp.plan_batch(sp.random_scenarios(3, 3, obstacles=(1, 5), curve_slots=5), max_steps=200, seed=3)
    np.testing.assert_array_equal(saved["status"], np.asarray(ref.status))
    np.testing.assert_array_equal(saved["iterations"], np.asarray(ref.iterations))
    assert s["success_rate"] == float(np.mean(np.asarray(ref.reached)))
    # Text summary, no progress.
    code, stdout, err = run_main(capsys, "batch", "--n", 3, "--seed", 3, "--obstacles", 1, 5, "--slots", 5,
                                 "--max-steps", 200, "--no-progress")
    assert code == 0 and err == "" and "steps taken/s" in stdout


# ----------------------------------------------------------------------------
# The installed entry point.


def test_entry_point_subprocess(tmp_path):
    cmd = [sys.executable, "-m", "softplan_jax.cli"]
    env = subprocess_env()  # this checkout's softplan_jax
    ok = subprocess.run(cmd + ["scenarios"], capture_output=True, text=True, timeout=120, env=env)
    assert ok.returncode == 0, ok.stderr
    assert "sim1" in ok.stdout and "tree" in ok.stdout
    bad = subprocess.run(cmd + ["run", str(tmp_path / "missing.json")], capture_output=True, text=True,
                         timeout=120, env=env)
    assert bad.returncode == 2
    assert bad.stdout == ""
    assert bad.stderr.strip().splitlines() == [bad.stderr.strip()]
    assert bad.stderr.startswith("softplan: error: ")


# ----------------------------------------------------------------------------
# Plotting, on a hand-made result (no planning, no rollout compile).


def _fake_result(q0, steps=6):
    """Bend the arm a little per step: a PlanResult-shaped trajectory."""
    q0 = np.asarray(q0)
    qs = np.stack([q0 + np.array([0.0, 0.15 * k, 0.0]) for k in range(steps + 1)])
    tips = np.stack([np.asarray(sp.tip_position(q)) for q in qs])
    clearance = np.linspace(0.5, 0.1, steps + 1)[:, None] * np.ones((1, 2))
    return PlanResult(reached=False, iterations=steps, collided=False, min_clearance=0.1, q=qs, tip=tips,
                      status="max_steps", clearance=clearance, final_error=1.0)


@pytest.fixture(scope="module")
def mixed_scenario():
    import jax.numpy as jnp

    helix = sp.ParametricCurve(lambda u: jnp.stack([0.6 * jnp.cos(u), 0.6 * jnp.sin(u), 0.3 * u]), (0.0, 9.0),
                               radius=0.05)
    points = np.array([[0.8, -0.5, 1.0], [0.9, -0.4, 1.2], [1.0, -0.3, 1.4]])
    line = sp.line_segment([1.0, -1.0, 0.5], [1.0, 1.0, 2.5], radius=0.1)
    return sp.make_scenario([1.0, 0.5, 1.5], [line, points, helix], arm_radius=0.04)


def test_plot_functions_on_every_obstacle_kind(mixed_scenario, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softplan_jax import plotting

    result = _fake_result(mixed_scenario.q0)
    fig = plotting.plot_snapshots(mixed_scenario, result, title="mixed")
    fig.savefig(tmp_path / "snap.png")
    plt.close(fig)
    fig = plotting.plot_snapshots(mixed_scenario, result, steps=[0, -1])
    plt.close(fig)
    fig = plotting.plot_snapshot_panels(mixed_scenario, result)
    plt.close(fig)
    fig = plotting.plot_clearance(result)
    plt.close(fig)
    assert (tmp_path / "snap.png").stat().st_size > 10_000
    empty = sp.make_scenario([1.0, 0.5, 1.5], [])
    fig = plotting.plot_snapshots(empty, _fake_result(empty.q0))
    plt.close(fig)
    with pytest.raises(ValueError, match="out of range"):
        plotting.plot_snapshots(mixed_scenario, result, steps=[99])
    assert plt.get_fignums() == []


def test_animate_writes_gif(mixed_scenario, tmp_path):
    from softplan_jax import plotting

    result = _fake_result(mixed_scenario.q0, steps=3)
    gif = tmp_path / "motion.gif"
    plotting.animate(mixed_scenario, result, gif, fps=5, hold=0.0, max_frames=4, dpi=40)
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    with pytest.raises(ValueError, match=r"\.gif"):
        plotting.animate(mixed_scenario, result, tmp_path / "motion.png")


@pytest.mark.parametrize("name", ["sim1", "tree"])
def test_animation_axis_labels_inside_the_frame(name, tmp_path, monkeypatch):
    """A GIF frame is the whole figure: the X, Y, Z labels must be drawn inside it."""
    from softplan_jax.plotting import _animation as plotting

    fitted = []
    fit = plotting._fit_axis_labels_inside

    def spy(fig, ax, limits, **kw):
        zoom = fit(fig, ax, limits, **kw)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        W, H = fig.canvas.get_width_height()
        boxes = {a.label.get_text(): a.label.get_window_extent(renderer) for a in (ax.xaxis, ax.yaxis, ax.zaxis)}
        boxes["tight"] = ax.get_tightbbox(renderer, bbox_extra_artists=[])
        fitted.append((W, H, boxes))
        return zoom

    monkeypatch.setattr(plotting, "_fit_axis_labels_inside", spy)
    scenario = sp.paper_scenario(name)
    plotting.animate(scenario, _fake_result(scenario.q0, steps=3), tmp_path / "a.gif", hold=0.0, max_frames=4)
    (W, H, boxes), = fitted
    assert set(boxes) == {"X", "Y", "Z", "tight"}
    for label, b in boxes.items():
        assert 0 <= b.x0 and b.x1 <= W and 0 <= b.y0 and b.y1 <= H, (label, b, W, H)


def test_run_warns_about_n_points_with_the_curve_method(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--n-points", "20")
    assert code == 0, err
    assert "warning: --n-points applies to --method points only" in err


def test_run_plain_step_and_bad_escapes(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--step", "plain", "--json")
    assert code == 0, err
    assert json.loads(out)["step"] == "plain"
    code, out, err = run_main(capsys, "run", "sim1", "--escapes", "-1")
    assert code == 2 and "--escapes" in err


def test_run_warns_about_a_goal_inside_an_obstacle(capsys, tmp_path):
    path = tmp_path / "inside.json"
    path.write_text(json.dumps({"format": "softplan-scenario/1", "goal": [1.0, 0.0, 1.0], "obstacles": [
        {"type": "line_segment", "start": [1.0, -1.0, 1.0], "end": [1.0, 1.0, 1.0], "radius": 0.05}]}))
    code, out, err = run_main(capsys, "run", str(path), "--max-steps", STEPS)  # sim1's shapes and steps: its program
    assert code == 0, err
    assert "warning: the goal" in err and "inside obstacle" in err
    assert "unreachable (goal_in_obstacle)" in out  # the fallback's proof


def test_run_exact_clearances(capsys, tmp_path):
    """--exact-clearances solves every pair at every step (PlanOptions.far_margin None): the tree
    (paper Table 1's scene) planned as by default, with its bounds beyond reach: the same 53
    steps and path to rounding, the same clearances below d0 + far_margin, the default's never
    above the exact ones and some below."""
    runs = {}
    for flag in ((), ("--exact-clearances",)):
        out_path = tmp_path / f"tree{len(flag)}.json"
        code, out, err = run_main(capsys, "run", "tree", *flag, "--json", "--out", str(out_path))
        assert code == 0, err
        record = json.loads(out_path.read_text())
        runs[flag] = (json.loads(out), np.asarray(record["q"], float), np.asarray(record["clearance"], float))
    (default, q_default, c_default), (exact, q_exact, c_exact) = runs[()], runs[("--exact-clearances",)]
    assert default["iterations"] == exact["iterations"] == 53
    np.testing.assert_allclose(q_default, q_exact, rtol=0, atol=1e-9)
    assert abs(default["min_clearance"] - exact["min_clearance"]) < 1e-12
    within = c_exact < float(sp.default_gains().d0) + sp.PlanOptions().far_margin
    np.testing.assert_allclose(c_default[within], c_exact[within], rtol=0, atol=1e-9)
    assert np.all(c_default <= c_exact + 1e-9) and np.any(c_default < c_exact - 1e-6)
