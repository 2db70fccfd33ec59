"""The gains of paper eq. (9): the seven scalars (:class:`Gains`), the gain
functions beyond the paper (:class:`GainFunction`: a repulsion profile over the
clearance, per-segment weights, gains that depend on the distance to the goal),
and the defaults.

A :class:`GainFunction` with all-zero profiles is its :class:`Gains` exactly
(multipliers ``exp(0) = 1``); the planner step (:mod:`._step`) applies
:func:`goal_scaled` and :func:`repulsion_scale`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._numerics import safe_norm, shared_constant
from ..base._validation import host_array

__all__ = ["Gains", "GainFunction", "GOAL_GAINS", "default_gains", "repulsion_scale", "repulsion_reach",
           "goal_scaled"]


class Gains(NamedTuple):
    """Gains of the gain functions and of the integration (a pytree of arrays;
    every field is differentiable).

    Attributes:
      k_att: attraction gain [1/s]: F_e(V_e) = k_att V_e below saturation.
      v_max: saturation speed of the attraction [m/s].
      eta: repulsion gain.
      d0: influence distance of the repulsion [m] (clearance beyond it: no force).
      rep_max: smooth cap on the repulsion speed [m/s].
      damping: damping lambda of the pseudo-inverse J^T (J J^T + lambda^2 I)^-1.
      dt: integration step [s]: q <- q + dt * qdot.
    """

    k_att: jax.Array
    v_max: jax.Array
    eta: jax.Array
    d0: jax.Array
    rep_max: jax.Array
    damping: jax.Array
    dt: jax.Array


class GainFunction(NamedTuple):
    """Gains with the repulsion as a tunable FUNCTION of clearance and of the arm
    segment (a pytree of arrays; beyond the paper, tuned by :mod:`softplan_jax.tuning`).

    The first seven fields are those of :class:`Gains`, with the same meaning.
    The repulsion of paper eq. (9) for an obstacle whose closest arm point lies
    on segment i at clearance d is :func:`repulsion`'s magnitude times::

        exp(profile(d / d0) + seg_weights[i])

    where ``profile`` interpolates ``rep_profile`` linearly between K knots evenly
    spaced in ``d / d0`` over [0, 1] (clipped outside).

    With ``goal_profile`` (G x K_g), the gains :data:`GOAL_GAINS` (``k_att``,
    ``v_max``, ``eta``, ``d0``) depend on the state too, on the tip's distance
    to the goal ``rho = |V_e|``: gain ``GOAL_GAINS[i]`` is multiplied by
    ``exp(goal_profile[i](u))``, the row interpolated linearly between K_g knots
    evenly spaced in ``u = rho / (rho + v_max / k_att)`` over [0, 1) (0 at the
    goal, 1/2 at the edge of the attraction's linear zone, towards 1 far away;
    :func:`goal_scaled`). Far from the goal the field can keep the arm well
    clear of the obstacles (longer safe steps), near it let the tip reach a
    goal close to one. ``dt`` stays constant (it is the step's time).

    With all zeros it is the field of its :class:`Gains` exactly
    (:meth:`from_gains` builds that; multipliers ``exp(0) = 1``).

    Attributes:
      rep_profile: (K,) log-multipliers of the repulsion at the knots, K >= 2.
      seg_weights: (n,) log-multipliers of the repulsion per arm segment
        (n: the arm's segment count).
      goal_profile: None (no dependence on the goal distance) or (4, K_g),
        K_g >= 2: log-multipliers of k_att, v_max, eta, d0 at the knots.
    """

    k_att: jax.Array
    v_max: jax.Array
    eta: jax.Array
    d0: jax.Array
    rep_max: jax.Array
    damping: jax.Array
    dt: jax.Array
    rep_profile: jax.Array
    seg_weights: jax.Array
    goal_profile: jax.Array | None = None

    @classmethod
    def from_gains(cls, gains: Gains, knots: int, segments: int, goal_knots: int = 0) -> GainFunction:
        """The gain function equal to ``gains`` (zero profile and weights; with
        ``goal_knots >= 2`` a zero ``goal_profile`` of that many knots)."""
        if int(knots) < 2 or int(segments) < 1 or int(goal_knots) == 1 or int(goal_knots) < 0:
            raise ValueError(f"a GainFunction needs knots >= 2, segments >= 1 and goal_knots 0 or >= 2, got "
                             f"{knots}, {segments}, {goal_knots}")
        dtype = jnp.result_type(gains.k_att)
        goal = jnp.zeros((len(GOAL_GAINS), int(goal_knots)), dtype) if goal_knots else None
        return cls(*gains[:7], jnp.zeros((int(knots),), dtype), jnp.zeros((int(segments),), dtype), goal)

    def scalars(self) -> Gains:
        """The seven scalar gains (without the profile and weights)."""
        return Gains(*self[:7])


GOAL_GAINS = ("k_att", "v_max", "eta", "d0")
"""The gains a :class:`GainFunction`'s ``goal_profile`` rows scale, in order."""


def _knot_interp(values, x):
    """``values[..., K]`` at knots evenly spaced over [0, 1], interpolated linearly at
    ``x`` (clipped to [0, 1]); all zeros give exactly 0."""
    K = values.shape[-1]
    x = jnp.clip(x, 0.0, 1.0) * (K - 1)
    lo = jnp.clip(jnp.floor(x), 0, K - 2).astype(jnp.int32)
    t = x - lo.astype(x.dtype)
    return (1 - t) * values[..., lo] + t * values[..., lo + 1]


def repulsion_scale(gains, clearance, segment):
    """The multiplier of the repulsion of a :class:`GainFunction` (1 for :class:`Gains`):
    ``exp(profile(clearance / d0) + seg_weights[segment])``; shapes broadcast."""
    if not isinstance(gains, GainFunction):
        return jnp.ones_like(clearance)
    return jnp.exp(_knot_interp(gains.rep_profile, clearance / gains.d0) + gains.seg_weights[segment])


def repulsion_reach(gains):
    """() the largest clearance at which the Khatib repulsion acts (beyond it the force is 0,
    paper eq. 9 with Khatib's potential): ``d0``, times the largest multiplier of d0 a
    :class:`GainFunction`'s ``goal_profile`` can apply (:func:`goal_scaled`)."""
    if not isinstance(gains, GainFunction) or gains.goal_profile is None:
        return gains.d0
    return gains.d0 * jnp.exp(jnp.max(gains.goal_profile[GOAL_GAINS.index("d0")]))


def goal_scaled(gains, V_e):
    """The gains at tip error ``V_e`` (3,): a :class:`GainFunction` with a
    ``goal_profile`` has k_att, v_max, eta and d0 multiplied by
    ``exp(goal_profile[i](u))``, ``u = |V_e| / (|V_e| + v_max / k_att)`` (knots over
    [0, 1]; the length ``v_max / k_att`` is the radius of the attraction's linear
    zone, paper eq. 9, of the unscaled gains); other gains are returned as they are."""
    if not isinstance(gains, GainFunction) or gains.goal_profile is None:
        return gains
    rho = safe_norm(V_e)
    u = rho / (rho + gains.v_max / gains.k_att)
    scale = jnp.exp(_knot_interp(gains.goal_profile, u))  # (G,)
    return gains._replace(**{k: getattr(gains, k) * scale[i] for i, k in enumerate(GOAL_GAINS)})


def default_gains(dtype=None) -> Gains:
    """The default gains (chosen by measurement on the paper's scenarios; see
    the documentation's Conventions page, "Gains").

    The tip moves at most ``v_max * dt = 0.05`` per step; the attraction is
    linear within ``v_max / k_att = 0.25`` of the goal. The influence distance
    ``d0 = 0.07`` is below the 0.080 between the tree goal and its nearest
    branch, so the goal lies outside every obstacle's field (d0 = 0.1 stalls
    the tree 0.03 short of its goal).
    """
    dtype = np.dtype(dtype or jnp.result_type(float))
    return shared_constant(("default gains", dtype), lambda: Gains(**{k: host_array(v, dtype) for k, v in
                                                                      _DEFAULT_GAINS.items()}))


_DEFAULT_GAINS = dict(k_att=2.0, v_max=0.5, eta=1e-3, d0=0.07, rep_max=1.0, damping=0.05, dt=0.1)
