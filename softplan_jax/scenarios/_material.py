"""Scenario files whose arm carries a ``material`` block (:mod:`._material_block`): the loaded
arm's model read from a file, and a scenario written with it (a round trip)."""

from __future__ import annotations

import json

from ..rod._model import RodModel
from ._json_format import scenario_to_dict, write_json_file
from ._material_block import material_from_dict, material_to_dict

__all__ = ["material_from_dict", "material_to_dict", "load_material", "save_scenario_material"]

def load_material(path) -> RodModel | None:
    """The arm's material of a scenario file, or None where its arm has no ``material`` block."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"cannot read scenario file {path}: {err}") from None
    arm = data.get("arm", {}) if isinstance(data, dict) else {}
    if not isinstance(arm, dict) or "material" not in arm:
        return None
    return material_from_dict(arm["material"], arm.get("segments"))


def save_scenario_material(scenario, model: RodModel, path, name: str | None = None, overwrite: bool = False):
    """Write a scenario file (:func:`~softplan_jax.scenarios._json_format.save_scenario`) whose arm
    carries ``model`` as its ``material`` block."""
    material_from_dict(material_to_dict(model), None)  # checked before anything is written
    data = scenario_to_dict(scenario, name)
    data["arm"]["material"] = material_to_dict(model)
    write_json_file(path, data, overwrite)
