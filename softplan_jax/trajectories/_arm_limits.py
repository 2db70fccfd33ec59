"""The arm's length limits from its actuators, and the arm's extension in a plan.

:func:`constrain_scenario` gives a scene the segment length limits that follow
from an actuator layout and its limits (:func:`~softplan_jax.actuators.segment_length_limits`):
the planner clips every ``L_i`` to them as it does to any scene's
``L_min``/``L_max``. :func:`extension` measures how far a plan stretched its
segments, for the warning where a scene's extension is unbounded.
"""

from __future__ import annotations

import math

import numpy as np

from ..actuators._layout import ActuatorLayout
from ..actuators._lengths import actuator_lengths, check_bending_radius
from ..actuators._limits import ActuatorLimits, check_limits, segment_length_limits

__all__ = ["constrain_scenario", "extension", "STRETCH_WARNING"]

# A plan that stretches a segment of an arm with unbounded extension past this multiple of its start length is
# worth a warning.
STRETCH_WARNING = 2.0


def constrain_scenario(scenario, layout: ActuatorLayout, limits: ActuatorLimits):
    """The scene with its segment length limits narrowed to those the actuator limits allow.

    Args:
      scenario: a Scenario (one scene).
      layout: its arm's actuators (n segments as the scene's arm).
      limits: their limits.

    Returns:
      The Scenario with ``L_min = max(L_min, from the actuators)`` and ``L_max = min(L_max, ...)``.

    Raises:
      ValueError: a layout for another number of segments, limits that admit no segment length,
        or a start pose outside the actuators' length limits or bending radius (the first named).
    """
    import jax.numpy as jnp

    q0 = np.asarray(scenario.q0, np.float64)
    if q0.ndim != 2 or q0.shape[0] != layout.n_segments:
        raise ValueError(f"layout: it is for {layout.n_segments} segments; the scene's arm has {q0.shape[-2]}")
    try:
        check_bending_radius(q0, np.asarray(layout.radius), layout.kind)
    except ValueError as err:
        raise ValueError(f"layout: at the start pose: {err}") from None
    lo, hi = segment_length_limits(layout, limits)
    L_min = np.maximum(np.asarray(scenario.L_min, np.float64), lo)
    L_max = np.minimum(np.asarray(scenario.L_max, np.float64), hi)
    if np.any(L_min >= L_max):
        i = int(np.argmax(L_min >= L_max))
        raise ValueError(f"limits: with the scene's own length limits, segment {i} would need {L_min[i]:.4g} <= L <= "
                         f"{L_max[i]:.4g}")
    bounds = limits._replace(max_speed=np.inf, max_acceleration=np.inf)
    report = check_limits(bounds, layout, np.asarray(actuator_lengths(q0, layout))[None])
    if not report.ok:
        raise ValueError(f"limits: the start pose is outside the actuators' length limits: {report.first}")
    dtype = scenario.L_min.dtype
    return scenario._replace(L_min=jnp.asarray(L_min, dtype), L_max=jnp.asarray(L_max, dtype))


def extension(scenario, q) -> dict:
    """How far a plan stretched the arm's segments.

    Args:
      scenario: the planned scene (its ``L_max``).
      q: (T, n, 3) the plan's configurations.

    Returns:
      ``{"bounded": any finite L_max, "stretch": the largest L_i(t) / L_i(0), "segment": its i,
      "warn": unbounded and stretch > STRETCH_WARNING}``.
    """
    q = np.asarray(q, np.float64)
    ratio = q[:, :, 0].max(axis=0) / q[0, :, 0]
    i = int(np.argmax(ratio))
    bounded = bool(np.any(np.isfinite(np.asarray(scenario.L_max))))
    stretch = float(ratio[i])
    return {"bounded": bounded, "stretch": stretch, "segment": i,
            "warn": (not bounded) and math.isfinite(stretch) and stretch > STRETCH_WARNING}
