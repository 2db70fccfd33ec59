"""Gain presets as data: gains, planner options and start pose, by name. ``"paper"`` is the
calibration that reproduces the paper's qualitative findings on its scenes (Sim2: the 1- and
10-point models collide while the curve method reaches) with values the paper does not state:
``k_att = 1``, ``v_max = 0.1``, ``dt = 1``, ``eta = 1e-3``, ``d0 = 0.15``, no repulsion cap, the
plain pseudo-inverse (well defined at its bent start pose), ``theta = 0.1`` and ``phi = 0`` on
every segment at the start, and the paper's plain step
(:data:`~softplan_jax.planning._options.PAPER_STEP`); ``"default"`` is the library's defaults.
Use: ``scenario, gains, options = sp.apply_preset("paper", sp.paper_scenario("sim2"))``, then
``sp.plan(scenario, "points", 10, gains=gains, **options)``."""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp

from ..scenarios import Scenario
from ._options import PAPER_STEP
from ._step import Gains, default_gains

__all__ = ["Preset", "PRESETS", "preset", "apply_preset"]


class Preset(NamedTuple):
    """A named calibration (plain data: floats, dicts, strings).

    Attributes:
      name: the preset's name.
      gains: Gains field -> float (``rep_max = inf``: no cap on the repulsion).
      options: PlanOptions fields (keyword arguments of :func:`softplan_jax.plan`).
      start_theta: theta of every segment at the start (lengths kept), or
        None to keep the scenario's own start pose.
      start_phi: phi (bending plane) of every segment at the start, or None
        to keep the scenario's.
      description: one paragraph: what the preset is for.
    """

    name: str
    gains: dict
    options: dict
    start_theta: float | None
    start_phi: float | None
    description: str


PRESETS: dict[str, Preset] = {
    "paper": Preset(
        name="paper",
        gains=dict(k_att=1.0, v_max=0.1, eta=1e-3, d0=0.15, rep_max=math.inf, damping=0.0, dt=1.0),
        options=dict(PAPER_STEP),
        start_theta=0.1,
        start_phi=0.0,
        description=(
            "Calibration that reproduces the paper's qualitative findings on its scenes (Sim2: 1 and "
            "10 points collide, the curve method reaches): k_att 1, v_max 0.1, dt 1, eta 1e-3, d0 0.15, "
            "no repulsion cap, plain pseudo-inverse, start theta = 0.1 and phi = 0 per segment, the paper's plain "
            "step without escapes. The paper states neither gains nor start pose."
        ),
    ),
    "default": Preset(
        name="default",
        gains=None,  # filled lazily from default_gains (see preset())
        options={},
        start_theta=None,
        start_phi=None,
        description=(
            "The library's defaults: default_gains(), the clearance-bounded step with random-walk "
            "escapes, the scenario's own start pose."
        ),
    ),
}


def preset(name: str) -> Preset:
    """The preset called ``name`` ("paper" or "default"); ValueError otherwise."""
    if name not in PRESETS:
        raise ValueError(f"unknown gain preset {name!r}; choose one of {sorted(PRESETS)}")
    p = PRESETS[name]
    if p.gains is None:
        p = p._replace(gains={k: float(v) for k, v in default_gains()._asdict().items()})
    return p


def apply_preset(name: str, scenario: Scenario, dtype=None) -> tuple[Scenario, Gains, dict]:
    """Apply a preset to a scenario (single or batched).

    Args:
      name: "paper" or "default".
      scenario: a Scenario; a batched one (leading axes) works too.
      dtype: dtype of the gains (default: the scenario's).

    Returns:
      ``(scenario, gains, options)``: the scenario with the preset's start pose
      (theta and phi of every segment set, lengths kept), the
      :class:`~softplan_jax.planning._planner.Gains`, and a dict of PlanOptions fields
      to pass as ``sp.plan(scenario, method, n_points, gains=gains, **options)``.
    """
    p = preset(name)
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    dtype = dtype or scenario.q0.dtype
    if p.start_theta is not None:
        scenario = scenario._replace(q0=scenario.q0.at[..., 1].set(p.start_theta))
    if p.start_phi is not None:
        scenario = scenario._replace(q0=scenario.q0.at[..., 2].set(p.start_phi))
    gains = Gains(**{k: jnp.asarray(p.gains[k], dtype) for k in Gains._fields})
    return scenario, gains, dict(p.options)
