"""``softplan run`` with actuators: the layout and limit options, --export (CSV + JSON) and
--plot-actuators, the summary's duration, tightest limit and extension, and bad input (exit
code 2, nothing written). Planning runs use test_cli's one compiled shape (sim1, 80 steps)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.cli import main

STEPS = "80"
LAYOUT = ["--tendons", "3", "--tendon-radius", "0.03"]
LIMITS = ["--max-actuator-speed", "0.05", "--max-actuator-acceleration", "0.2"]


def run_main(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_writes_csv_and_json_and_the_summary_says_duration(tmp_path, capsys):
    csv, fig = tmp_path / "tree.csv", tmp_path / "act.png"
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--no-fallback", *LAYOUT, *LIMITS,
                              "--export", csv, "--plot-actuators", fig)
    assert code == 0, err
    assert csv.exists() and (tmp_path / "tree.json").exists() and fig.stat().st_size > 0
    traj = sp.load_trajectory(csv)
    rows = dict(line.split(None, 1) if not line.startswith(("tightest", "min ", "final", "compile", "run ", "time "))
                else (line[:18].strip(), line[18:].strip()) for line in out.splitlines() if line.strip())
    assert rows["duration"].startswith(f"{traj.duration:.3f} s (smooth path")
    assert rows["tightest limit"].startswith("max_")
    assert rows["actuators"].startswith("3 tendons per segment at radius 0.03")
    assert rows["extension"].startswith("unbounded (no length limit)")
    assert traj.report.ok and traj.layout.kind == "tendon" and traj.t.shape[0] > 100
    meta = json.loads((tmp_path / "tree.json").read_text())
    assert meta["limits"]["max_speed"] == 0.05 and meta["arm"]["scenario"] == "sim1"
    assert meta["units"]["time"] == "s" and meta["plan"]["status"] == traj.status
    # --force is needed to write again; the JSON summary carries the same figures.
    code, _, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--no-fallback", *LAYOUT, *LIMITS, "--export",
                            csv)
    assert code == 2 and "exists; pass --force" in err
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--no-fallback", *LAYOUT, *LIMITS,
                              "--export", tmp_path / "tree.json", "--force", "--json", "--timing", "linear")
    assert code == 0, err
    s = json.loads(out)
    assert s["timing"] == "linear" and s["duration_s"] > traj.duration and s["within_limits"]
    assert s["export"] == [str(csv), str(tmp_path / "tree.json")]
    assert s["actuators"] == {"kind": "tendon", "count": 3, "radius": 0.03}
    assert sp.load_trajectory(csv).path == "linear"


def test_a_plan_outside_the_limits_writes_nothing(tmp_path, capsys):
    """The chambers' bending takes one below its minimum: exit 2, the violation named, no file at all."""
    outs = [tmp_path / "a.csv", tmp_path / "a.json", tmp_path / "p.png", tmp_path / "o.json"]
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--no-fallback", "--chambers", "3",
                              "--chamber-radius", "0.1", "--min-actuator-length", "0.95", "--max-actuator-speed", "0.05",
                              "--export", outs[0], "--plot", outs[2], "--out", outs[3])
    assert code == 2
    assert "min_length: chamber" in err and "nothing written" in err
    assert not any(p.exists() for p in outs)


def test_actuator_length_limits_bound_the_planner(capsys):
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, "--no-fallback", "--chambers", "4",
                              "--chamber-radius", "0.02", "--max-actuator-length", "1.05", "--json")
    assert code == 0, err
    s = json.loads(out)
    assert [hi for _, hi in s["segment_length_limits"]] == [1.05] * 3
    assert s["extension"]["bounded"] and s["extension"]["stretch"] <= 1.05 + 1e-12
    assert "--max-actuator-speed" not in err


def test_unbounded_extension_is_warned(tmp_path, capsys):
    """A goal far away (the arm has no length limit): the plan stretches a segment past twice its start."""
    scene = {"format": "softplan-scenario/1", "goal": [10.0, 10.0, 10.0], "obstacles": []}
    path = tmp_path / "far.json"
    path.write_text(json.dumps(scene))
    code, out, err = run_main(capsys, "run", path, "--max-steps", STEPS, "--no-fallback")
    assert code == 0, err
    assert "its start length, and the arm's extension is unbounded" in err
    assert "unbounded (no length limit); segment" in out and "(over 2x" in out


@pytest.mark.parametrize("argv, message", [
    (["--tendons", "2", "--tendon-radius", "0.03"], "--tendons must be >= 3"),
    (["--tendons", "3"], "--tendons needs --tendon-radius"),
    (["--tendons", "3", "--tendon-radius", "0"], "--tendon-radius must be a finite number > 0"),
    (["--tendons", "3", "--tendon-radius", "nan"], "--tendon-radius must be a finite number > 0"),
    (["--tendons", "3", "--chambers", "3", "--tendon-radius", "0.1"], "--tendons and --chambers exclude"),
    (["--chamber-radius", "0.1"], "--chamber-radius needs --chambers K"),
    (["--max-actuator-speed", "0.1"], "--max-actuator-speed needs an actuator layout"),
    (LAYOUT + ["--max-actuator-speed", "-1"], "--max-actuator-speed must be a finite number > 0"),
    (LAYOUT + ["--max-actuator-acceleration", "0"], "--max-actuator-acceleration must be a finite number > 0"),
    (LAYOUT + ["--min-actuator-length", "2", "--max-actuator-length", "1"], "must be below --max-actuator-length"),
    (LAYOUT + ["--export", "x.csv"], "need a speed limit"),
    (["--export", "x.csv", "--max-tip-speed", "0.1"], "need an actuator layout"),
    (LAYOUT + LIMITS + ["--export", "x.txt"], "--export: the path must end in .csv or .json"),
    (LAYOUT + LIMITS + ["--sample-rate", "0", "--export", "x.csv"], "--sample-rate must be a finite number > 0"),
    (LAYOUT + LIMITS + ["--export", "x.csv", "--out", "x.json"], "--export: x.json is also another output"),
    (LAYOUT + LIMITS + ["--plot-actuators", "x.unknown"], "--plot-actuators: cannot tell the image format"),
    (LAYOUT + ["--max-actuator-length", "0.5"], "limits: the start pose is outside the actuators' length limits: "
                                                "max_length: tendon 0 of segment 2"),
])
def test_bad_actuator_options_exit_2(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", STEPS, *argv)
    assert code == 2 and message in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # a tracking program of its own (about 20 s to compile)
def test_tracked_scene_exports_with_its_time_stamps(tmp_path, capsys):
    """A moving scene keeps the tracker's time; the summary says where the limits are exceeded."""
    csv = tmp_path / "sway.csv"
    code, out, err = run_main(capsys, "run", "tree_sway", "--max-steps", "30", "--no-fallback", *LAYOUT,
                              "--max-actuator-speed", "0.02", "--export", csv)
    assert code == 0, err
    traj = sp.load_trajectory(csv)
    assert traj.path == "tracked" and np.allclose(np.diff(traj.t), 0.1)
    assert "EXCEEDED: max_speed" in out and "exceeds the actuator limits" in err
