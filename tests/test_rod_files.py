"""The scenario file's optional arm.material block (softplan_jax.scenarios._material): round trip
and clear errors naming the field; a file without it reads as before."""

import json

import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.scenarios._material import load_material, material_from_dict, save_scenario_material


def test_material_round_trip(tmp_path):
    scen = sp.paper_scenario("sim1")
    model = sp.RodModel(np.array([3.0, 2.0, 1.0]), 2.0, 0.3, (0.0, 0.1, -0.5))
    path = tmp_path / "loaded.json"
    save_scenario_material(scen, model, path)
    back = load_material(path)
    for key in ("bending_stiffness", "torsional_stiffness", "weight_per_length", "tip_load"):
        np.testing.assert_array_equal(np.asarray(getattr(back, key)), np.asarray(getattr(model, key)))
    again = sp.load_scenario(path)  # the scene itself still reads
    np.testing.assert_array_equal(np.asarray(again.goal), np.asarray(scen.goal))
    with pytest.raises(ValueError):
        save_scenario_material(scen, model, path)  # never overwrites
    plain = tmp_path / "plain.json"
    sp.save_scenario(scen, plain)
    assert load_material(plain) is None


@pytest.mark.parametrize("block, field", [
    ({"bending_stiffness": 0, "torsional_stiffness": 1, "weight_per_length": 0.1}, "bending_stiffness"),
    ({"bending_stiffness": 1, "torsional_stiffness": 1}, "weight_per_length"),
    ({"bending_stiffness": 1, "torsional_stiffness": 1, "weight_per_length": -1}, "weight_per_length"),
    ({"bending_stiffness": 1, "torsional_stiffness": "x", "weight_per_length": 1}, "torsional_stiffness"),
    ({"bending_stiffness": [1, 2], "torsional_stiffness": 1, "weight_per_length": 1}, "bending_stiffness"),
    ({"bending_stiffness": 1, "torsional_stiffness": 1, "weight_per_length": 1, "tip_load": [0, 1]}, "tip_load"),
    ({"bending_stiffness": 1, "torsional_stiffness": 1, "weight_per_length": 1, "mass": 2}, "mass"),
])
def test_bad_material_block_names_the_field(tmp_path, block, field):
    with pytest.raises(ValueError, match=f"arm.material.*{field}|{field}"):
        material_from_dict(block, 3)
    data = sp.scenarios.scenario_to_dict(sp.paper_scenario("sim1"))
    data["arm"]["material"] = block
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=field):
        sp.load_scenario(path)
