"""The optional ``material`` block of a scenario file's arm section (docs/file-formats.md) as a
dict: the loaded arm's stiffness, torsional stiffness, weight per length and tip load, read into
a :class:`~softplan_jax.rod._model.RodModel` and written back."""

from __future__ import annotations

import numpy as np

from ..rod._model import RodModel

__all__ = ["material_from_dict", "material_to_dict"]

_KEYS = {"bending_stiffness": "bending_stiffness", "torsional_stiffness": "torsional_stiffness",
         "weight_per_length": "weight_per_length", "tip_load": "tip_load"}
_REQUIRED = ("bending_stiffness", "torsional_stiffness", "weight_per_length")


def material_from_dict(block, segments: int | None = None) -> RodModel:
    """A :class:`RodModel` from a ``material`` block: ``{"bending_stiffness": EI,
    "torsional_stiffness": GJ, "weight_per_length": w, "tip_load": [Fx, Fy, Fz]}`` (numbers, or
    one number per segment; tip_load optional). ValueError naming ``arm.material.<field>``."""
    if not isinstance(block, dict):
        raise ValueError(f"arm.material must be an object, got {type(block).__name__}")
    unknown = set(block) - set(_KEYS)
    if unknown:
        raise ValueError(f"arm.material.{sorted(unknown)[0]}: unknown key (allowed: {sorted(_KEYS)})")
    for key in _REQUIRED:
        if key not in block:
            raise ValueError(f"arm.material.{key} is missing")
    values = {}
    for key in _KEYS:
        if key not in block:
            continue
        value = block[key]
        flat = value if isinstance(value, list) else [value]
        if not flat or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in flat):
            raise ValueError(f"arm.material.{key} must be a number or a list of numbers, got {value!r}")
        if key != "tip_load" and isinstance(value, list) and segments is not None and len(value) != segments:
            raise ValueError(f"arm.material.{key} has {len(value)} values for {segments} segments")
        values[key] = np.asarray(value, np.float64)
    try:
        return RodModel(**values)
    except ValueError as err:
        raise ValueError(f"arm.material: {err}") from None


def material_to_dict(model: RodModel) -> dict:
    """The ``material`` block of ``model`` (numbers, or lists per segment)."""
    def plain(x):
        arr = np.asarray(x, np.float64)
        return arr.tolist() if arr.ndim else float(arr)

    return {key: plain(getattr(model, key)) for key in _KEYS}
