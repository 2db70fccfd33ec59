"""Gains files (softplan_jax.tuning._gains_file, format ``softplan-gains/1``) and the CLI's
``--gains FILE``.

Compilation dominates the cost, so the planning here reuses programs other tests
of the "cli" unit compile (tests/conftest.py runs this file after them, in one
worker): ``sp.plan`` on the tiny scene padded to sim2's shape with the paper
preset, 10 points, 40 steps (tests/test_presets.py), and ``softplan run sim1
--max-steps 80`` / ``softplan batch`` with test_cli's arguments
(tests/test_cli.py). A gain FUNCTION compiles a program of its own: that
comparison is marked slow. Everything else is host-side (no compilation).
"""

from __future__ import annotations

import json
import os
import re

import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.cli import main

LINE = [[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]]
GOAL = [1.1, -0.8, 0.9]


def _tiny(**pad):
    return sp.make_scenario(goal=GOAL, obstacles=[sp.PolynomialCurve(LINE, (-2.0, 2.0))], **pad)


def _paper_gains():
    """The paper preset's gains: rep_max inf (no cap), damping 0."""
    _, gains, _ = sp.apply_preset("paper", _tiny())
    assert float(gains.rep_max) == np.inf and float(gains.damping) == 0.0
    return gains


def _gain_function():
    gf = sp.GainFunction.from_gains(_paper_gains(), 4, 3)
    return gf._replace(rep_profile=jnp.asarray([0.3, -0.1, 1.0 / 3.0, 0.0]),
                       seg_weights=jnp.asarray([0.2, 0.0, -1.0 / 7.0]))


def _goal_function():
    return _gain_function()._replace(goal_profile=jnp.asarray([[0.5, -0.25], [0.0, 0.125], [1.0, 2.0], [-1.0, 0.0]]))


def _assert_same_gains(a, b):
    assert type(a) is type(b)
    for k in type(a)._fields:
        x, y = np.asarray(getattr(a, k)), np.asarray(getattr(b, k))
        assert x.dtype == y.dtype and x.shape == y.shape, k
        np.testing.assert_array_equal(x, y, err_msg=k)


def _valid(**gains_extra):
    d = sp.tuning.gains_to_dict(sp.default_gains(), "points", 10, metadata={"note": "test"})
    d["gains"].update(gains_extra)
    return d


# ----------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("which", ["default", "paper", "function", "goal-function"])
def test_round_trip_dict_and_file(tmp_path, which):
    gains = {"default": sp.default_gains, "paper": _paper_gains, "function": _gain_function,
             "goal-function": _goal_function}[which]()
    d = sp.tuning.gains_to_dict(gains, "curve", 10)
    text = json.dumps(d, allow_nan=False)  # strict JSON: inf is written as null
    assert d["format"] == "softplan-gains/1" and d["method"] == "curve" and d["n_points"] == 10
    assert ("rep_profile" in d["gains"]) == which.endswith("function") == ("seg_weights" in d["gains"])
    assert ("goal_profile" in d["gains"]) == (which == "goal-function")
    if which == "paper":
        assert d["gains"]["rep_max"] is None and d["gains"]["damping"] == 0.0
    _assert_same_gains(sp.tuning.gains_from_dict(json.loads(text)), gains)

    path = tmp_path / "gains.json"
    sp.save_gains(gains, path, method="points", n_points=50, metadata={"tuned_by": "hand", "scenes": [1, 2]})
    loaded = sp.load_gains(path)
    _assert_same_gains(loaded, gains)
    _assert_same_gains(sp.load_gains(str(path), method="points", n_points=50), gains)
    on_disk = json.loads(path.read_text())
    assert on_disk["metadata"] == {"tuned_by": "hand", "scenes": [1, 2]}
    assert (on_disk["method"], on_disk["n_points"]) == ("points", 50)
    f32 = sp.load_gains(path, dtype=jnp.float32)
    assert type(f32) is type(gains) and all(np.asarray(v).dtype == np.float32 for v in f32 if v is not None)


def test_save_refuses_to_overwrite(tmp_path):
    path = tmp_path / "g.json"
    path.write_text("keep me")
    with pytest.raises(ValueError, match="exists"):
        sp.save_gains(sp.default_gains(), path)
    assert path.read_text() == "keep me"
    sp.save_gains(sp.default_gains(), path, overwrite=True)
    _assert_same_gains(sp.load_gains(path), sp.default_gains())


@pytest.mark.parametrize("kwargs, match", [
    (dict(gains=sp.Gains(*[0.1] * 7)._replace(d0=-1.0)), "d0"),
    (dict(gains=sp.Gains(*[0.1] * 7)._replace(eta=float("nan"))), "eta"),
    (dict(gains={"k_att": 1.0}), "Gains or a GainFunction"),
    (dict(method="spline"), "method"),
    (dict(method="points", n_points=0), "n_points"),
    (dict(n_points=2.5), "n_points"),
    (dict(metadata=[1, 2]), "metadata"),
    (dict(metadata={"x": float("nan")}), "metadata"),
    (dict(metadata={"x": object()}), "metadata"),
])
def test_gains_to_dict_rejects_bad_arguments(kwargs, match):
    args = dict(gains=sp.default_gains(), method="curve", n_points=10) | kwargs
    with pytest.raises(ValueError, match=match):
        sp.tuning.gains_to_dict(**args)


# ----------------------------------------------------------------------------
# Malformed files: a ValueError naming the field.


def _drop(d, *path):
    d = json.loads(json.dumps(d))
    target = d
    for k in path[:-1]:
        target = target[k]
    del target[path[-1]]
    return d


def _with(d, *path_and_value):
    *path, value = path_and_value
    d = json.loads(json.dumps(d))
    target = d
    for k in path[:-1]:
        target = target[k]
    target[path[-1]] = value
    return d


def _gf_dict():
    return sp.tuning.gains_to_dict(_gain_function(), "curve", 10)


BAD_DICTS = [
    ("top-level list", lambda: [1, 2], "field (top)"),
    ("format missing", lambda: _drop(_valid(), "format"), "field format"),
    ("format wrong", lambda: _with(_valid(), "format", "softplan-scenario/1"), "field format"),
    ("unknown top key", lambda: _with(_valid(), "colour", "red"), "field colour"),
    ("method missing", lambda: _drop(_valid(), "method"), "field method"),
    ("method unknown", lambda: _with(_valid(), "method", "spline"), "field method"),
    ("n_points missing for points", lambda: _drop(_valid(), "n_points"), "field n_points"),
    ("n_points zero", lambda: _with(_valid(), "n_points", 0), "field n_points"),
    ("n_points float", lambda: _with(_valid(), "n_points", 10.5), "field n_points"),
    ("n_points string", lambda: _with(_valid(), "n_points", "10"), "field n_points"),
    ("n_points bool", lambda: _with(_valid(), "n_points", True), "field n_points"),
    ("metadata not an object", lambda: _with(_valid(), "metadata", "hi"), "field metadata"),
    ("gains missing", lambda: _drop(_valid(), "gains"), "field gains:"),
    ("gains not an object", lambda: _with(_valid(), "gains", [1.0] * 7), "field gains:"),
    ("unknown gain", lambda: _with(_valid(), "gains", "k_rep", 1.0), "field gains.k_rep"),
    ("gain missing", lambda: _drop(_valid(), "gains", "dt"), "field gains.dt"),
    ("gain negative", lambda: _with(_valid(), "gains", "d0", -1),
     "field gains.d0: must be a finite positive number, got -1"),
    ("gain zero", lambda: _with(_valid(), "gains", "dt", 0.0), "field gains.dt"),
    ("damping negative", lambda: _with(_valid(), "gains", "damping", -0.1), "field gains.damping"),
    ("gain string", lambda: _with(_valid(), "gains", "eta", "0.001"), "field gains.eta"),
    ("gain bool", lambda: _with(_valid(), "gains", "k_att", True), "field gains.k_att"),
    ("gain list", lambda: _with(_valid(), "gains", "v_max", [0.5]), "field gains.v_max"),
    ("gain null", lambda: _with(_valid(), "gains", "d0", None), "field gains.d0"),
    ("gain nan", lambda: _with(_valid(), "gains", "eta", float("nan")), "field gains.eta"),
    ("gain inf", lambda: _with(_valid(), "gains", "dt", float("inf")), "field gains.dt"),
    ("rep_max inf (use null)", lambda: _with(_valid(), "gains", "rep_max", float("inf")), "field gains.rep_max"),
    ("gain beyond float range", lambda: _with(_valid(), "gains", "k_att", 10**400), "field gains.k_att"),
    ("rep_profile only", lambda: _drop(_gf_dict(), "gains", "seg_weights"), "field gains.seg_weights"),
    ("seg_weights only", lambda: _drop(_gf_dict(), "gains", "rep_profile"), "field gains.rep_profile"),
    ("rep_profile too short", lambda: _with(_gf_dict(), "gains", "rep_profile", [0.0]), "field gains.rep_profile"),
    ("rep_profile not a list", lambda: _with(_gf_dict(), "gains", "rep_profile", 0.5), "field gains.rep_profile"),
    ("rep_profile strings", lambda: _with(_gf_dict(), "gains", "rep_profile", ["0", "1"]), "field gains.rep_profile"),
    ("rep_profile nan", lambda: _with(_gf_dict(), "gains", "rep_profile", [0.0, float("nan")]),
     "field gains.rep_profile"),
    ("seg_weights empty", lambda: _with(_gf_dict(), "gains", "seg_weights", []), "field gains.seg_weights"),
    ("seg_weights nested", lambda: _with(_gf_dict(), "gains", "seg_weights", [[0.0], [0.0]]),
     "field gains.seg_weights"),
]


@pytest.mark.parametrize("case", [c[0] for c in BAD_DICTS])
def test_malformed_content_names_the_field(tmp_path, case):
    make, match = next((m, f) for c, m, f in BAD_DICTS if c == case)
    data = make()
    with pytest.raises(ValueError, match=f"^gains file {_re(match)}"):
        sp.tuning.gains_from_dict(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))  # nan / inf as the non-standard NaN / Infinity literals
    with pytest.raises(ValueError, match=f"^{_re(str(path))}: gains file {_re(match)}"):
        sp.load_gains(path)


def _re(text):
    return re.escape(text)


def test_unreadable_files(tmp_path):
    with pytest.raises(ValueError, match="gains file not found"):
        sp.load_gains(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="cannot read gains file"):
        sp.load_gains(tmp_path)
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe\x00{")
    with pytest.raises(ValueError, match="not UTF-8"):
        sp.load_gains(binary)
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "softplan-gains/1", "gains": {')
    with pytest.raises(ValueError, match="not valid JSON"):
        sp.load_gains(broken)
    empty = tmp_path / "empty.json"
    empty.write_text("")
    with pytest.raises(ValueError, match="not valid JSON"):
        sp.load_gains(empty)


def test_file_for_another_obstacle_model(tmp_path):
    curve, points = tmp_path / "tuned.json", tmp_path / "tuned_points.json"
    sp.save_gains(sp.default_gains(), curve, method="curve", n_points=10)
    sp.save_gains(sp.default_gains(), points, method="points", n_points=10)
    msg = f"gains file {curve} was tuned for method 'curve', not 'points' (N=10)"
    with pytest.raises(ValueError, match=f"^{_re(msg)}$"):
        sp.load_gains(curve, method="points", n_points=10)
    with pytest.raises(ValueError, match=_re("tuned for method 'points' (N=10), not 'curve'")):
        sp.load_gains(points, method="curve")
    with pytest.raises(ValueError, match=_re("tuned for method 'points' (N=10), not 'points' (N=50)")):
        sp.load_gains(points, method="points", n_points=50)
    with pytest.raises(ValueError, match=_re("tuned for method 'points' (N=10), not 'points' (N=50)")):
        sp.load_gains(points, n_points=50)  # method from the file
    with pytest.raises(ValueError, match="these gains were tuned for method 'curve'"):
        sp.tuning.gains_from_dict(json.loads(curve.read_text()), method="points")
    # N is compared for the N-point model only; matching models load.
    sp.load_gains(curve, method="curve", n_points=50)
    sp.load_gains(curve, n_points=50)
    sp.load_gains(points, method="points")
    sp.load_gains(points, method="points", n_points=10)
    with pytest.raises(ValueError, match="method must be"):
        sp.load_gains(curve, method="spline")
    with pytest.raises(ValueError, match="n_points must be"):
        sp.load_gains(points, n_points=0)


# ----------------------------------------------------------------------------
# Planning with loaded gains.


def _plan_both(tmp_path, gains):
    """sp.plan with ``gains`` and with the gains saved and loaded again: the paper preset's
    step, the tiny scene padded to sim2's shape, 10 points, 40 steps (test_presets' program)."""
    sc, _, opts = sp.apply_preset("paper", _tiny(degree=2))
    path = tmp_path / "g.json"
    sp.save_gains(gains, path, method="points", n_points=10)
    loaded = sp.load_gains(path, method="points", n_points=10)
    a = sp.plan(sc, "points", 10, gains=gains, max_steps=40, **opts)
    b = sp.plan(sc, "points", 10, gains=loaded, max_steps=40, **opts)
    assert (a.status, a.iterations, a.reached, a.collided) == (b.status, b.iterations, b.reached, b.collided)
    for key in ("q", "tip", "clearance"):
        np.testing.assert_array_equal(np.asarray(getattr(a, key)), np.asarray(getattr(b, key)), err_msg=key)
    assert a.min_clearance == b.min_clearance and a.final_error == b.final_error
    return a


def test_plan_with_loaded_gains_equals_the_original(tmp_path):
    r = _plan_both(tmp_path, _paper_gains())  # rep_max inf and damping 0 through the file
    assert r.iterations > 5


@pytest.mark.slow  # a GainFunction is a program of its own (~12 s to compile)
def test_plan_with_loaded_gain_function_equals_the_original(tmp_path):
    _plan_both(tmp_path, _gain_function())


# ----------------------------------------------------------------------------
# The command: softplan run / batch --gains FILE (sim1, 80 steps: test_cli's program).


def run_main(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_run_with_gains_file(tmp_path, capsys):
    default_file = tmp_path / "default.json"
    sp.save_gains(sp.default_gains(), default_file, metadata={"what": "the defaults"})
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", 80, "--json", "--gains", default_file)
    assert code == 0, err
    s = json.loads(out)
    assert s["gains"] == str(default_file) and s["gains_file"] == os.path.abspath(default_file)
    assert s["gain_values"] == sp.tuning.gains_to_dict(sp.default_gains())["gains"]
    assert s["step"] == "safe"  # the default preset's step options
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", 80, "--json")
    assert code == 0, err
    ref = json.loads(out)
    assert ref["gains"] == "default" and ref["gains_file"] is None and ref["gain_values"] == s["gain_values"]
    for key in ("status", "iterations", "reached", "collided", "min_clearance", "final_error"):
        assert s[key] == ref[key], key

    # Other gain values (the same program): used, reported, and kept with the trajectory.
    slow = tmp_path / "slow.json"
    sp.save_gains(sp.default_gains()._replace(dt=jnp.asarray(0.05)), slow)
    traj = tmp_path / "run.json"
    # --no-fallback: these gains do not reach within 80 steps, and the global search (its own
    # programs, ~20 s of compilation) is not what this test is about.
    code, out, err = run_main(capsys, "run", "sim1", "--max-steps", 80, "--gains", slow, "--out", traj,
                              "--no-fallback")
    assert code == 0, err
    assert "gains file" in out and "dt 0.05" in out
    record = json.loads(traj.read_text())
    assert record["gains"] == str(slow) and record["gains_file"] == os.path.abspath(slow)
    assert record["gain_values"]["dt"] == 0.05 and record["gain_values"]["rep_max"] == 1.0
    assert (record["status"], record["iterations"]) != (ref["status"], ref["iterations"])


def test_cli_batch_with_gains_file(tmp_path, capsys):
    """test_cli's batch arguments (its program), the default gains from a file: the same outcomes."""
    path = tmp_path / "default.json"
    sp.save_gains(sp.default_gains(), path)
    argv = ["batch", "--n", 3, "--seed", 3, "--obstacles", 1, 5, "--slots", 5, "--max-steps", 200, "--chunk", 3,
            "--json", "--no-progress"]
    code, out, err = run_main(capsys, *argv, "--gains", path)
    assert code == 0, err
    s = json.loads(out)
    assert s["gains"] == str(path) and s["gains_file"] == os.path.abspath(path)
    assert s["gain_values"] == sp.tuning.gains_to_dict(sp.default_gains())["gains"]
    code, out, err = run_main(capsys, *argv)
    assert code == 0, err
    ref = json.loads(out)
    assert ref["gains"] == "default" and ref["gains_file"] is None
    assert (s["status_counts"], s["success_rate"]) == (ref["status_counts"], ref["success_rate"])


def _bad_cli_cases(tmp):
    """(id, argv, a piece of the error line)."""
    j = os.path.join
    return [
        ("missing file", ["run", "sim1", "--gains", j(tmp, "missing.json")], "neither a gain preset"),
        ("not a preset", ["run", "sim1", "--gains", "fast"], "neither a gain preset"),
        ("directory", ["run", "sim1", "--gains", tmp], "is a directory"),
        ("not json", ["run", "sim1", "--gains", j(tmp, "not_json.json")], "not valid JSON"),
        ("malformed", ["run", "sim1", "--gains", j(tmp, "negative_d0.json")], "field gains.d0"),
        ("wrong format", ["run", "sim1", "--gains", j(tmp, "scenario.json")], "field format"),
        ("points file, curve run", ["run", "sim1", "--gains", j(tmp, "points10.json")],
         "tuned for method 'points' (N=10), not 'curve'"),
        ("curve file, points run", ["run", "sim1", "--method", "points", "--gains", j(tmp, "curve.json")],
         "tuned for method 'curve', not 'points' (N=10)"),
        ("points N=10 file, N=50 run", ["run", "sim1", "--method", "points", "--n-points", "50",
                                        "--gains", j(tmp, "points10.json")], "not 'points' (N=50)"),
        ("seg_weights for 2 segments", ["run", "sim1", "--gains", j(tmp, "two_segments.json")], "seg_weights"),
        ("out over the gains file", ["run", "sim1", "--gains", j(tmp, "curve.json"), "--out",
                                     j(tmp, "curve.json"), "--force"], "refusing to overwrite"),
        ("batch missing file", ["batch", "--n", "4", "--gains", j(tmp, "missing.json")], "neither a gain preset"),
        ("batch points file", ["batch", "--n", "4", "--gains", j(tmp, "points10.json")], "not 'curve'"),
        ("batch malformed", ["batch", "--n", "4", "--gains", j(tmp, "negative_d0.json")], "field gains.d0"),
    ]


@pytest.mark.parametrize("case_id", [c[0] for c in _bad_cli_cases("t")])
def test_cli_bad_gains_file_exits_2(tmp_path, capsys, case_id):
    sp.save_gains(sp.default_gains(), tmp_path / "curve.json")
    sp.save_gains(sp.default_gains(), tmp_path / "points10.json", method="points", n_points=10)
    (tmp_path / "negative_d0.json").write_text(json.dumps(_with(_valid(), "gains", "d0", -1)))
    (tmp_path / "not_json.json").write_text("k_att = 2")
    (tmp_path / "scenario.json").write_text(json.dumps({"format": "softplan-scenario/1", "goal": [1, 0, 1]}))
    sp.save_gains(sp.GainFunction.from_gains(sp.default_gains(), 3, 2), tmp_path / "two_segments.json")
    files = sorted(tmp_path.iterdir())
    contents = {p: p.read_bytes() for p in files}

    argv, expected = next((a, e) for c, a, e in _bad_cli_cases(str(tmp_path)) if c == case_id)
    code, out, err = run_main(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert lines[0].startswith("softplan: error: ") and "Traceback" not in err
    assert expected in lines[0], lines[0]
    assert sorted(tmp_path.iterdir()) == files
    assert {p: p.read_bytes() for p in files} == contents


def test_cli_mismatch_message(tmp_path, capsys):
    path = tmp_path / "tuned.json"
    sp.save_gains(sp.default_gains(), path)
    code, out, err = run_main(capsys, "run", "sim1", "--method", "points", "--gains", path)
    assert code == 2
    assert err.strip() == f"softplan: error: gains file {path} was tuned for method 'curve', not 'points' (N=10)"
