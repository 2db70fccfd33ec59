"""JSON scenario files: round trips and rejection of malformed files.

A saved and re-loaded scenario must have identical arrays (values, shapes and
dtypes of every pytree leaf). Every malformed file is rejected with a
ValueError whose message names the offending field, and loading never touches
the file.
"""

from __future__ import annotations

import copy
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp

PHI = 2 * math.pi / 3

# A valid file using every feature: start pose, arm radius, length limits, a
# polynomial curve, a line segment and a point set, each with a radius.
VALID = {
    "format": "softplan-scenario/1",
    "name": "every feature",
    "description": "round-trip test",
    "arm": {
        "segments": 3,
        "start": [[1.0, 0.0, 0.0], [1.1, 0.2, PHI], [0.9, 0.0, PHI]],
        "radius": 0.05,
        "length_limits": [0.5, 1.5],
    },
    "goal": [1.0, 0.5, 1.5],
    "obstacles": [
        {"type": "polynomial", "coeffs": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, -1.0, 0.25]],
         "u_range": [-2.0, 2.0], "radius": 0.02},
        {"type": "line_segment", "start": [0.5, -1.0, 1.0], "end": [0.5, 1.0, 1.2], "radius": 0.03},
        {"type": "points", "points": [[1.0, 1.0, 1.0], [1.2, 1.0, 1.1], [1.4, 1.0, 1.2]], "radius": 0.04},
    ],
}


def _leaves(scenario):
    return jax.tree_util.tree_flatten_with_path(scenario)[0]


def assert_same_scenario(a, b):
    """Every pytree leaf identical: shape, dtype and values (exactly)."""
    la, lb = _leaves(a), _leaves(b)
    assert [p for p, _ in la] == [p for p, _ in lb]
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for (path, x), (_, y) in zip(la, lb, strict=True):
        x, y = np.asarray(x), np.asarray(y)
        name = jax.tree_util.keystr(path)
        assert x.shape == y.shape, name
        assert x.dtype == y.dtype, name
        assert np.array_equal(x, y), f"{name}: {x} != {y}"


def write_json(path, data):
    path.write_text(json.dumps(data, indent=2), encoding="utf-8")  # allow_nan: NaN/Infinity literals
    return path


# ----------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("name", ["sim1", "sim2", "tree"])
def test_paper_scenarios_round_trip(tmp_path, name):
    scenario = sp.paper_scenario(name)
    path = tmp_path / f"{name}.json"
    sp.save_scenario(scenario, path, name=name)
    loaded = sp.load_scenario(path)
    assert_same_scenario(scenario, loaded)
    # Saving the loaded scenario again writes the same file.
    again = tmp_path / f"{name}_again.json"
    sp.save_scenario(loaded, again, name=name)
    assert again.read_bytes() == path.read_bytes()
    assert not (tmp_path / f"{name}.json.tmp").exists()


def test_every_feature_round_trip(tmp_path):
    src = write_json(tmp_path / "src.json", VALID)
    scenario = sp.load_scenario(src)
    # The file's content arrived where it belongs.
    np.testing.assert_array_equal(scenario.q0, np.asarray(VALID["arm"]["start"]))
    np.testing.assert_array_equal(scenario.goal, VALID["goal"])
    assert float(scenario.arm_radius) == 0.05
    np.testing.assert_array_equal(scenario.L_min, [0.5] * 3)
    np.testing.assert_array_equal(scenario.L_max, [1.5] * 3)
    assert np.asarray(scenario.curve_mask).tolist() == [True, True]
    np.testing.assert_array_equal(scenario.curves.radius, [0.02, 0.03])
    np.testing.assert_array_equal(scenario.curves.u_range, [[-2.0, 2.0], [0.0, 1.0]])
    # The line segment is the degree-1 curve a + u (b - a), padded to degree 2.
    a, b = np.array([0.5, -1.0, 1.0]), np.array([0.5, 1.0, 1.2])
    np.testing.assert_array_equal(scenario.curves.coeffs[1], np.stack([a, b - a, np.zeros(3)], axis=1))
    assert np.asarray(scenario.point_mask).sum() == 3
    np.testing.assert_array_equal(scenario.points[0], VALID["obstacles"][2]["points"])
    assert float(scenario.point_radius[0]) == 0.04

    out = tmp_path / "out.json"
    sp.save_scenario(scenario, out)
    assert_same_scenario(scenario, sp.load_scenario(out))
    out2 = tmp_path / "out2.json"
    sp.save_scenario(sp.load_scenario(out), out2)
    assert out2.read_bytes() == out.read_bytes()


def test_saved_file_is_the_documented_format(tmp_path):
    path = tmp_path / "sim1.json"
    sp.save_scenario(sp.paper_scenario("sim1"), path, name="sim1")
    data = json.loads(path.read_text())
    assert data["format"] == "softplan-scenario/1"
    assert data["name"] == "sim1"
    assert data["goal"] == [1.1, -0.8, 0.9]
    assert data["arm"]["segments"] == 3
    assert data["arm"]["length_limits"][1] is None  # no upper limit: null, not Infinity
    (ob,) = data["obstacles"]
    assert ob["type"] == "polynomial"
    assert ob["coeffs"] == [[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]]
    assert ob["u_range"] == [-2.0, 2.0]


def test_load_float32(tmp_path):
    src = write_json(tmp_path / "src.json", VALID)
    scenario = sp.load_scenario(src, dtype=jnp.float32)
    for path, leaf in _leaves(scenario):
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert leaf.dtype == jnp.float32, jax.tree_util.keystr(path)


def test_minimal_file_uses_defaults(tmp_path):
    src = write_json(tmp_path / "min.json", {"goal": [1, 0, 2]})
    scenario = sp.load_scenario(src)
    np.testing.assert_array_equal(scenario.q0, sp.scenarios.default_start())
    assert not np.asarray(scenario.curve_mask).any()
    assert not np.asarray(scenario.point_mask).any()


# ----------------------------------------------------------------------------
# Malformed files.


def _mutate(fn):
    data = copy.deepcopy(VALID)
    fn(data)
    return data


def _set(path, value):
    def fn(d):
        *head, last = path
        for k in head:
            d = d[k]
        d[last] = value

    return fn


def _del(path):
    def fn(d):
        *head, last = path
        for k in head:
            d = d[k]
        del d[last]

    return fn


# (id, mutation, the field the message must name)
MALFORMED = [
    ("missing goal", _del(["goal"]), "goal"),
    ("goal of 2 numbers", _set(["goal"], [1.0, 2.0]), "goal"),
    ("goal of 4 numbers", _set(["goal"], [1.0, 2.0, 3.0, 4.0]), "goal"),
    ("goal not numbers", _set(["goal"], ["a", "b", "c"]), "goal"),
    ("goal NaN", _set(["goal"], [1.0, float("nan"), 0.0]), "goal"),
    ("coeffs Infinity", _set(["obstacles", 0, "coeffs"], [[1.0, float("inf")], [0.0, 1.0], [0.5, -1.0]]),
     "obstacles[0].coeffs"),
    ("start NaN", _set(["arm", "start", 1, 1], float("nan")), "arm.start"),
    ("unknown obstacle type", _set(["obstacles", 1, "type"], "sphere"), "obstacles[1].type"),
    ("obstacle without type", _del(["obstacles", 1, "type"]), "obstacles[1]"),
    ("reversed u_range", _set(["obstacles", 0, "u_range"], [2.0, -2.0]), "obstacles[0].u_range"),
    ("empty u_range", _set(["obstacles", 0, "u_range"], [1.0, 1.0]), "obstacles[0].u_range"),
    ("u_range of 3", _set(["obstacles", 0, "u_range"], [0.0, 1.0, 2.0]), "obstacles[0].u_range"),
    ("coeffs of 2 rows", _set(["obstacles", 0, "coeffs"], [[1.0, 0.0], [0.0, 1.0]]), "obstacles[0].coeffs"),
    ("coeffs 1-D", _set(["obstacles", 0, "coeffs"], [1.0, 0.0, 1.0]), "obstacles[0].coeffs"),
    ("coeffs ragged", _set(["obstacles", 0, "coeffs"], [[1.0], [0.0, 1.0], [0.5]]), "obstacles[0].coeffs"),
    ("coeffs missing", _del(["obstacles", 0, "coeffs"]), "obstacles[0].coeffs"),
    ("line end missing", _del(["obstacles", 1, "end"]), "obstacles[1].end"),
    ("line start of 2", _set(["obstacles", 1, "start"], [0.0, 1.0]), "obstacles[1].start"),
    ("empty points", _set(["obstacles", 2, "points"], []), "obstacles[2].points"),
    ("points of 2 columns", _set(["obstacles", 2, "points"], [[1.0, 2.0]]), "obstacles[2].points"),
    ("unknown top-level key", _set(["colour"], "red"), "colour"),
    ("unknown arm key", _set(["arm", "stiffness"], 3.0), "arm.stiffness"),
    ("unknown obstacle key", _set(["obstacles", 0, "colour"], "red"), "obstacles[0].colour"),
    ("segments 0", _set(["arm", "segments"], 0), "arm.segments"),
    ("segments not an integer", _set(["arm", "segments"], 2.5), "arm.segments"),
    ("start of wrong shape", _set(["arm", "start"], [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), "arm.start"),
    ("start with 2 columns", _set(["arm", "start"], [[1.0, 0.0]] * 3), "arm.start"),
    ("start length 0", _set(["arm", "start", 0, 0], 0.0), "arm.start"),
    ("negative arm radius", _set(["arm", "radius"], -0.1), "arm.radius"),
    ("negative obstacle radius", _set(["obstacles", 2, "radius"], -0.1), "obstacles[2].radius"),
    ("reversed length limits", _set(["arm", "length_limits"], [1.5, 0.5]), "arm.length_limits"),
    ("start outside length limits", _set(["arm", "length_limits"], [1.0, 1.05]), "arm.length_limits"),
    ("obstacles not a list", _set(["obstacles"], {"type": "points"}), "obstacles"),
    ("arm not an object", _set(["arm"], [1, 2, 3]), "arm"),
    ("wrong format", _set(["format"], "softplan-scenario/99"), "format"),
]


@pytest.mark.parametrize("case", MALFORMED, ids=[c[0] for c in MALFORMED])
def test_malformed_file_rejected(tmp_path, case):
    _, mutation, field = case
    path = write_json(tmp_path / "bad.json", _mutate(mutation))
    before = path.read_bytes()
    with pytest.raises(ValueError) as info:
        sp.load_scenario(path)
    message = str(info.value).replace(str(path), "<file>")
    assert field in message, f"the message does not name {field!r}: {message}"
    assert path.read_bytes() == before


@pytest.mark.parametrize(
    "text",
    ['{"goal": [1, 2, 3]', "goal = [1, 2, 3]", "", '{"goal": [1, 2, 3],}'],
    ids=["unclosed", "not json", "empty", "trailing comma"],
)
def test_invalid_json_text_rejected(tmp_path, text):
    path = tmp_path / "bad.json"
    path.write_text(text, encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(ValueError, match="not valid JSON"):
        sp.load_scenario(path)
    assert path.read_bytes() == before


def test_top_level_not_an_object(tmp_path):
    path = write_json(tmp_path / "list.json", [1, 2, 3])
    with pytest.raises(ValueError, match="JSON object"):
        sp.load_scenario(path)


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        sp.load_scenario(tmp_path / "nope.json")


# ----------------------------------------------------------------------------
# Saving.


def test_save_refuses_to_overwrite(tmp_path):
    path = tmp_path / "existing.json"
    path.write_bytes(b"precious\n")
    scenario = sp.paper_scenario("sim1")
    with pytest.raises(ValueError, match="overwrite"):
        sp.save_scenario(scenario, path)
    assert path.read_bytes() == b"precious\n"
    sp.save_scenario(scenario, path, overwrite=True)
    assert_same_scenario(scenario, sp.load_scenario(path))
    assert not (tmp_path / "existing.json.tmp").exists()


def test_save_rejects_parametric_curves(tmp_path):
    helix = sp.ParametricCurve(lambda u: jnp.stack([jnp.cos(u), jnp.sin(u), 0.2 * u]), (0.0, 6.0))
    scenario = sp.make_scenario([1.0, 0.0, 1.0], [helix])
    path = tmp_path / "helix.json"
    with pytest.raises(ValueError, match="ParametricCurve"):
        sp.save_scenario(scenario, path)
    assert not path.exists()


def test_written_files_get_an_ordinary_mode(tmp_path):
    """Files written through a temporary file (mkstemp: mode 0600) end with the mode a plain
    open() gives them (0666 less the umask), not private to their owner by accident."""
    import os
    import stat

    from softplan_jax.cli.interrupt import atomic_output

    old = os.umask(0o022)
    try:
        sp.save_scenario(sp.paper_scenario("sim1"), tmp_path / "s.json")
        with atomic_output(str(tmp_path / "t.png")) as tmp:
            with open(tmp, "wb") as fh:
                fh.write(b"x")
        for name in ("s.json", "t.png"):
            assert stat.S_IMODE(os.stat(tmp_path / name).st_mode) == 0o644, name
    finally:
        os.umask(old)
