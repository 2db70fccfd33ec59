"""The ``softplan`` command, run in-process through ``main([...])`` (plus one
subprocess run of ``python -m softplan_jax.cli`` for the entry point).

Compilation dominates the cost, so every planning run here uses ONE compiled
shape: a sim1-shaped scenario (one degree-1 curve, no point sets), the curve
method with default options, float64 and --max-steps 80. The bad-input cases
fail before anything is compiled.

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

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.planner import PlanResult

STEPS = "80"
SUMMARY_FIELDS = {
    "scenario", "method", "n_points", "repulsion", "dtype", "status", "iterations", "max_steps", "reached",
    "collided", "min_clearance", "final_error", "goal_tolerance", "compile_time_s", "run_time_s",
    "time_per_scan_step_s", "plot", "gif",
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
    for label in ("scenario", "method", "status", "iterations", "reached", "collided",
                  "min true clearance", "final tip error", "compile time", "time per scan step"):
        assert label in out, f"{label!r} missing from the summary:\n{out}"
    assert "sim1" in out and "curve" in out


def test_run_json_summary(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json")
    assert code == 0, err
    s = json.loads(out)
    assert set(s) == SUMMARY_FIELDS
    assert s["scenario"] == "sim1" and s["method"] == "curve" and s["dtype"] == "float64"
    assert s["status"] in sp.STATUS_NAMES.values()
    assert isinstance(s["iterations"], int) and 0 < s["iterations"] <= 80
    assert s["max_steps"] == 80
    assert isinstance(s["reached"], bool) and isinstance(s["collided"], bool)
    assert s["reached"] == (s["status"] == "reached")
    assert s["collided"] == (s["status"] == "collided")
    assert isinstance(s["min_clearance"], float) and isinstance(s["final_error"], float)
    if s["reached"]:
        assert s["final_error"] < s["goal_tolerance"]
    assert s["compile_time_s"] > 0 and s["run_time_s"] > 0
    assert s["time_per_scan_step_s"] == pytest.approx(s["run_time_s"] / 80)
    assert s["plot"] is None and s["gif"] is None


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
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json")
    assert code == 0, err  # planning finished: success whatever the status
    assert json.loads(out)["reached"] is False
    code, out, err = run_main(capsys, "run", far, "--max-steps", STEPS, "--json", "--require-reached")
    assert code == 3
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--json", "--require-reached")
    assert code == (0 if json.loads(out)["reached"] else 3)


# ----------------------------------------------------------------------------
# Other commands.


def test_scenarios_lists_paper_scenarios(capsys):
    code, out, err = run_main(capsys, "scenarios")
    assert code == 0, err
    for name in ("sim1", "sim2", "tree"):
        assert name in out
    code, out, _ = run_main(capsys, "scenarios", "--json")
    assert [r["name"] for r in json.loads(out)] == ["sim1", "sim2", "tree"]


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
        ("unknown command", ["plan", "sim1"]),
        ("run without scenario", ["run"]),
        ("export unknown name", ["export", "sim9", j(tmp, "x.json")]),
        ("export existing file", ["export", "sim1", scenario_file]),
        ("export to missing directory", ["export", "sim1", j(tmp, "no", "x.json")]),
        ("export to a directory", ["export", "sim1", tmp]),
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


# ----------------------------------------------------------------------------
# The installed entry point.


def test_entry_point_subprocess(tmp_path):
    cmd = [sys.executable, "-m", "softplan_jax.cli"]
    ok = subprocess.run(cmd + ["scenarios"], capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert "sim1" in ok.stdout and "tree" in ok.stdout
    bad = subprocess.run(cmd + ["run", str(tmp_path / "missing.json")], capture_output=True, text=True,
                         timeout=120)
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
