"""The loaded arm's material: a Kirchhoff rod's bending and torsional stiffness, its weight per
unit length and a dead load at the tip (Antman 2005, ch. 8; Rucker & Webster 2011), as a
registered pytree whose fields are scalars (every segment alike) or one value per segment."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..base._validation import check_scale, is_concrete

__all__ = ["RodModel", "segment_material", "per_segment"]

_FIELDS = ("bending_stiffness", "torsional_stiffness", "weight_per_length", "tip_load")


def _is_value(x) -> bool:
    """True for a concrete number or array (not a tracer, not a pytree placeholder)."""
    if isinstance(x, (bool, np.bool_)) or not is_concrete(x):
        return False
    return isinstance(x, (int, float, str, np.integer, np.floating, np.ndarray, jax.Array, list, tuple))


def _check_field(name: str, x):
    """The field as an array, checked: finite, a scalar or one value per segment (a (3,) vector
    for the tip load), stiffness > 0 and weight >= 0. Anything but a concrete value (a tracer,
    a placeholder jax puts in a pytree) passes unchanged."""
    if not _is_value(x):
        return x
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"RodModel.{name} must be a number or an array of numbers, got {x!r}: {err}") from None
    if name == "tip_load":
        if arr.shape != (3,):
            raise ValueError(f"RodModel.tip_load must be a force (Fx, Fy, Fz) of shape (3,), got shape {arr.shape}")
    elif arr.ndim > 1:
        raise ValueError(f"RodModel.{name} must be a scalar or one value per segment (shape (n,)), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"RodModel.{name} must be finite, got {arr.tolist()}")
    if name in ("bending_stiffness", "torsional_stiffness") and np.any(arr <= 0):
        raise ValueError(f"RodModel.{name} must be > 0 (N m^2), got {arr.tolist()}")
    if name == "weight_per_length" and np.any(arr < 0):
        raise ValueError(f"RodModel.weight_per_length must be >= 0 (N/m; gravity points along -z), got {arr.tolist()}")
    check_scale(arr, f"RodModel.{name}", jnp.float64, "values")
    return jnp.asarray(x) if isinstance(x, jax.Array) else arr


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RodModel:
    """A loaded arm: each segment a Kirchhoff rod (inextensible, unshearable) under its own
    weight and a dead load at the tip, gravity along -z (Antman 2005; Rucker & Webster 2011).

    The actuators apply a uniform internal moment per segment, ``EI`` times the commanded
    curvature: the segment's intrinsic curvature is the PCC curvature ``theta_i / L_i`` of q,
    so with no load the shape is the PCC shape of q (paper section 2.1).

    Args:
      bending_stiffness: ``EI`` [N m^2], > 0: a scalar or (n,) per segment.
      torsional_stiffness: ``GJ`` [N m^2], > 0: a scalar or (n,).
      weight_per_length: ``w`` [N/m], >= 0 (the rod's weight per unit of its current length):
        a scalar or (n,).
      tip_load: (3,) a dead force [N] at the tip, e.g. a payload's weight ``(0, 0, -m g)``.

    Raises:
      ValueError: naming the field, for a stiffness <= 0, a negative weight, a non-finite
        value, or a wrong shape. Per-segment shapes are checked against q where the model is
        used.
    """

    bending_stiffness: object
    torsional_stiffness: object
    weight_per_length: object
    tip_load: object = (0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in _FIELDS:
            object.__setattr__(self, name, _check_field(name, getattr(self, name)))


def segment_material(model: RodModel, n: int, dtype):
    """The model's fields for ``n`` segments in ``dtype``: ``(EI (n,), GJ (n,), w (n,), F (3,))``.

    Raises:
      ValueError: a per-segment field whose length is not ``n``.
    """
    if not isinstance(model, RodModel):
        raise ValueError(f"model must be a softplan_jax.RodModel, got {type(model).__name__}")
    out = []
    for name in _FIELDS[:3]:
        x = jnp.asarray(getattr(model, name))
        if x.shape not in ((), (n,)):
            raise ValueError(f"RodModel.{name} has shape {x.shape}; give a scalar or one value per segment ({n},)")
        out.append(jnp.broadcast_to(x.astype(dtype), (n,)))
    F = jnp.asarray(model.tip_load)
    if F.shape != (3,):
        raise ValueError(f"RodModel.tip_load must have shape (3,), got {F.shape}")
    return (*out, F.astype(dtype))


def per_segment(model: RodModel, n: int, dtype) -> RodModel:
    """The model with every field given per segment: ``(n,)`` NumPy arrays in ``dtype`` and the
    tip load ``(3,)`` (:func:`segment_material`), so that one compiled program serves a model of
    scalars and one of per-segment values alike (a jitted function keys its programs on the
    shapes of its arguments). ValueError as :func:`segment_material`."""
    return RodModel(*(np.asarray(x) for x in segment_material(model, n, dtype)))
