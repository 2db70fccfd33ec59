"""The input boundary, fuzzed (hypothesis): scenario JSON, gains files, the moving fields and the
public API's arguments. Every generated input either plans or raises ValueError naming what was
wrong (the command: exit 2 with one line naming the field); never another exception, a NaN
reported as a result, or a modified input file.

Kept cheap: most generated inputs are rejected before anything compiles; the ones that plan
share ONE compiled shape (sim1's: 3 segments, one degree-1 curve, 5 steps, the curve method,
default options), so the rollout compiles once per session.
"""

from __future__ import annotations

import copy
import json
import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.scenarios._json_format import moving_from_dict, moving_to_dict, scenario_from_dict
from softplan_jax.scenarios._scenario import check_scenario
from softplan_jax.tuning._gains_file import gains_from_dict, gains_to_dict

STEPS = 5
FUZZ = settings(max_examples=60, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

BASE = {
    "format": "softplan-scenario/1",
    "arm": {"segments": 3, "start": [[1.0, 0.0, 0.0], [1.0, 0.0, 2.0944], [1.0, 0.0, 2.0944]], "radius": 0.0},
    "goal": [1.1, -0.8, 0.9],
    "obstacles": [{"type": "polynomial", "coeffs": [[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]], "u_range": [-2.0, 2.0],
                   "radius": 0.0}],
}

# Numbers a user types, the extreme and the wrong included.
NUMBERS = st.one_of(
    st.floats(-5.0, 5.0),
    st.sampled_from([0.0, -0.0, 1e-300, 5e-324, 1e300, -1e300, 1.7e308, 1e160, -1e160, 1e20, 3.5]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**400), 10**400),
)
JUNK = st.one_of(st.none(), st.booleans(), st.text(max_size=5), st.just([]), st.just({}), st.just([[1, 2], [3]]),
                 st.integers(-3, 10**30), NUMBERS)


def _no_nan_result(r):
    """A PlanResult reports no NaN: finite configurations and tips, clearances and errors not NaN."""
    assert np.all(np.isfinite(r.q)) and np.all(np.isfinite(r.tip)), r.status
    assert not np.isnan(r.min_clearance) and not np.isnan(r.final_error), (r.status, r.min_clearance, r.final_error)
    assert not np.any(np.isnan(r.clearance)), r.status


def _plan_or_reject(make):
    """``make()`` gives a Scenario (plan it: sim1's shape) or raises ValueError; anything else fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = make()
        except ValueError as err:
            assert str(err)
            return None
        check_scenario(scene, batched=False)
        r = sp.plan(scene, max_steps=STEPS)
    _no_nan_result(r)
    return r


# ----------------------------------------------------------------------------
# Scenario JSON: the values of sim1's fields (one shape: every accepted scene plans with one program).

VALUE_FIELDS = [("goal", 3), ("arm.start", (3, 3)), ("arm.radius", None), ("obstacles.0.coeffs", (3, 2)),
                ("obstacles.0.u_range", 2), ("obstacles.0.radius", None)]


def _put(d, path, value):
    keys = path.split(".")
    for k in keys[:-1]:
        d = d[int(k)] if k.isdigit() else d[k]
    d[keys[-1]] = value


@st.composite
def valued_scene(draw):
    d = copy.deepcopy(BASE)
    for path, shape in draw(st.lists(st.sampled_from(VALUE_FIELDS), min_size=1, max_size=3, unique=True)):
        if shape is None:
            value = draw(NUMBERS)
        elif isinstance(shape, int):
            value = draw(st.lists(NUMBERS, min_size=shape, max_size=shape))
        else:
            value = [draw(st.lists(NUMBERS, min_size=shape[1], max_size=shape[1])) for _ in range(shape[0])]
        _put(d, path, value)
    return d


@FUZZ
@given(valued_scene())
def test_scenario_values_plan_or_are_rejected(data):
    before = json.dumps(data, sort_keys=True, default=str)
    _plan_or_reject(lambda: scenario_from_dict(data))
    assert json.dumps(data, sort_keys=True, default=str) == before  # the input is not modified


# Any field replaced by anything: only the loader runs (an accepted scene of another shape is not planned).
FIELDS = ["format", "goal", "arm", "arm.segments", "arm.start", "arm.radius", "arm.length_limits", "obstacles",
          "obstacles.0", "obstacles.0.type", "obstacles.0.coeffs", "obstacles.0.u_range", "obstacles.0.radius",
          "name", "metadata"]


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(FIELDS), JUNK), min_size=1, max_size=3))
def test_scenario_fields_load_or_name_the_field(edits):
    d = copy.deepcopy(BASE)
    for path, value in edits:
        try:
            _put(d, path, value)
        except (KeyError, IndexError, TypeError):
            pass  # an earlier edit removed the parent
    try:
        scene = scenario_from_dict(copy.deepcopy(d))
    except ValueError as err:
        assert str(err).startswith("scenario field "), str(err)
        return
    check_scenario(scene, batched=False)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(FIELDS), JUNK), min_size=1, max_size=2))
def test_cli_rejects_a_bad_file_with_one_line_naming_the_field(tmp_path_factory, capsys, edits):
    d = copy.deepcopy(BASE)
    for path, value in edits:
        try:
            _put(d, path, value)
        except (KeyError, IndexError, TypeError):
            pass
    try:
        scenario_from_dict(copy.deepcopy(d))
        return  # loads: planning it is the API test's job
    except ValueError as err:
        field = str(err).split(":")[0].removeprefix("scenario field ")
    path = tmp_path_factory.mktemp("fuzz") / "scene.json"
    path.write_text(json.dumps(d, default=str))
    before = path.read_bytes()
    code = main(["run", str(path), "--max-steps", str(STEPS)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("softplan: error: ") and field in err, err
    assert path.read_bytes() == before


# ----------------------------------------------------------------------------
# Gains files.

GAIN_BASE = gains_to_dict(sp.default_gains(jnp.float64), "curve", 10)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(["format", "method", "n_points", "gains", "metadata", *(
    f"gains.{k}" for k in sp.Gains._fields), "gains.rep_profile", "gains.seg_weights"]), st.one_of(JUNK, NUMBERS)),
    min_size=1, max_size=3))
def test_gains_files_load_or_name_the_field(edits):
    d = copy.deepcopy(GAIN_BASE)
    for path, value in edits:
        try:
            _put(d, path, value)
        except (KeyError, IndexError, TypeError):
            pass
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            gains = gains_from_dict(copy.deepcopy(d), method="curve", dtype=jnp.float64)
        except ValueError as err:
            assert str(err).startswith(("gains file field ", "these gains were tuned")), str(err)
            return
        if isinstance(gains, sp.Gains):  # one program for every Gains: plan with them
            _no_nan_result(sp.plan(sp.paper_scenario("sim1"), gains=gains, max_steps=STEPS))


# ----------------------------------------------------------------------------
# The moving fields (parsed only: tracking programs are large).

MOVING_BASE = moving_to_dict(sp.moving_scenario("tree_fruit"))
MOVING_FIELDS = ["goal", "goal_path", "goal_path.times", "goal_path.points", "goal_path.attach",
                 *(f"obstacles.0.motion.{k}" for k in ("pivot", "axis", "amplitude", "omega", "phase", "shift",
                                                       "velocity")), "obstacles.0.motion"]


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(MOVING_FIELDS), st.one_of(JUNK, st.lists(NUMBERS, max_size=4))),
                min_size=1, max_size=3))
def test_moving_fields_load_or_name_the_field(edits):
    d = copy.deepcopy(MOVING_BASE)
    for path, value in edits:
        try:
            _put(d, path, value)
        except (KeyError, IndexError, TypeError):
            pass
    try:
        m = moving_from_dict(copy.deepcopy(d))
    except ValueError as err:
        assert str(err).startswith("scenario field "), str(err)
        return
    check_scenario(m.scene, batched=False)
    for leaf in (m.motion, m.goal_path):
        for x in leaf:
            assert np.all(np.isfinite(np.asarray(x, float)))
    assert np.all(np.isfinite(np.asarray(sp.moving.speed_bounds(m))))


# ----------------------------------------------------------------------------
# The public API's arguments: each one valid (the default call) or wrong.

SIM1 = sp.paper_scenario("sim1")
BAD_ARGS = {
    "method": st.one_of(st.text(max_size=4), st.none(), st.integers()),
    "n_points": st.one_of(st.integers(-5, 0), st.just(10**12), st.floats(allow_nan=True), st.text(max_size=3)),
    "max_steps": st.one_of(st.integers(-5, 0), st.floats(0.5, 1e3), st.just(10**12), st.booleans(), st.none(),
                           st.text(max_size=3)),
    "seed": st.one_of(st.floats(allow_nan=True), st.text(max_size=3), st.just(2**70), st.booleans(),
                      st.just([1, 2, 3])),
    "gains": st.one_of(st.just(sp.default_gains()._replace(damping=jnp.asarray(-1.0))),
                       st.just(sp.default_gains()._replace(dt=jnp.asarray(np.nan))), st.text(max_size=3),
                       st.just({"k_att": 1.0})),
    "goal_tolerance": st.one_of(st.floats(max_value=0.0), st.just(math.nan), st.text(max_size=2)),
    "step": st.one_of(st.text(max_size=4), st.none()),
    "escapes": st.one_of(st.integers(-5, -1), st.text(max_size=2)),
    "step_chunk": st.one_of(st.integers(-3, 0), st.floats(0.5, 9.5), st.booleans()),
}


@FUZZ
@given(st.dictionaries(st.sampled_from(sorted(BAD_ARGS)), st.just(None), max_size=3).flatmap(
    lambda keys: st.fixed_dictionaries({k: BAD_ARGS[k] for k in keys})))
def test_plan_arguments_plan_or_are_rejected(kwargs):
    kwargs = {"max_steps": STEPS, **kwargs}
    try:
        r = sp.plan(SIM1, **kwargs)
    except ValueError as err:
        assert str(err)
        return
    _no_nan_result(r)


@FUZZ
@given(goal=st.one_of(st.lists(NUMBERS, min_size=0, max_size=4), JUNK),
       obstacles=st.one_of(JUNK, st.lists(st.one_of(JUNK, st.lists(st.lists(NUMBERS, min_size=3, max_size=3),
                                                                  max_size=3)), max_size=2)),
       arm_radius=st.one_of(NUMBERS, JUNK), L_max=st.one_of(st.none(), NUMBERS))
def test_make_scenario_builds_or_is_rejected(goal, obstacles, arm_radius, L_max):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = sp.make_scenario(goal, obstacles, arm_radius=arm_radius, L_max=L_max)
        except ValueError as err:
            assert str(err)
            return
    check_scenario(scene, batched=False)
    assert np.all(np.isfinite(np.asarray(scene.goal)))


@pytest.mark.parametrize("degree", [1, 2, 5, 12])
def test_polynomial_curve_constructor_rejects_or_builds(degree):
    """A few hand-picked bad coefficient arrays per degree."""
    good = np.zeros((3, degree + 1))
    for bad in (good[:2], good[..., None], np.full_like(good, np.nan), np.full_like(good, np.inf), "x",
                [[1, 2], [3]], good.astype(object)):
        with pytest.raises(ValueError):
            sp.PolynomialCurve(bad, (0.0, 1.0))
    for u_range in ((1.0, 1.0), (1.0, 0.0), (0.0, np.inf), (np.nan, 1.0), (0.0,), "ab"):
        with pytest.raises(ValueError):
            sp.PolynomialCurve(good, u_range)
