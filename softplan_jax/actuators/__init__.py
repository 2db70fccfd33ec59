"""Actuators of the arm (a geometry-level layer: imports only ``base`` and ``geometry``).

* :mod:`._lengths` -- tendon and chamber lengths of a configuration (eq. A1, with the
  tendons' frame carried without twist), their inverses and Jacobians;
* :mod:`._layout` -- :class:`ActuatorLayout`: where the actuators sit;
* :mod:`._limits` -- :class:`ActuatorLimits`, their check on a sampled motion, and the
  segment length limits that follow from them.
"""

from ._layout import ActuatorLayout, actuator_layout
from ._lengths import (
    actuator_jacobian,
    actuator_lengths,
    chamber_lengths,
    configuration_from_chambers,
    configuration_from_lengths,
    configuration_from_tendons,
    tendon_lengths,
)
from ._limits import ActuatorLimits, LimitReport, actuator_limits, check_limits, segment_length_limits

__all__ = [
    "tendon_lengths",
    "chamber_lengths",
    "configuration_from_tendons",
    "configuration_from_chambers",
    "ActuatorLayout",
    "actuator_layout",
    "actuator_lengths",
    "configuration_from_lengths",
    "actuator_jacobian",
    "ActuatorLimits",
    "actuator_limits",
    "LimitReport",
    "check_limits",
    "segment_length_limits",
]
