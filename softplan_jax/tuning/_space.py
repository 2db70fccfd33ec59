"""What gain tuning tunes: :class:`GainSpace`, the parameters ``theta`` of the
scalar gains (log or, for dt, the logit of its fraction of the Euler bound) and of
a :class:`~softplan_jax.planning._gains.GainFunction`'s profiles, and their
encoding and decoding (traceable; zeros of every profile decode to the constant
gains exactly)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..planning._gains import GOAL_GAINS, GainFunction, Gains

__all__ = ["GainSpace", "SCALAR_GAINS"]

SCALAR_GAINS = Gains._fields


class GainSpace(NamedTuple):
    """Which gains are tuned, and how they are parametrised (static, hashable).

    ``theta`` (shape ``(size,)``) is laid out as: the logarithms of the scalar
    gains ``names`` (they stay positive; a step is relative), then, with
    ``knots >= 2``, the K log-multipliers ``rep_profile`` of the repulsion over
    ``d / d0`` in [0, 1], then, with ``segments >= 1``, the n log-multipliers
    ``seg_weights`` of each segment's repulsion, then, with ``goal_knots >= 2``,
    the 4 x K_g log-multipliers ``goal_profile`` of k_att, v_max, eta and d0 over the
    distance to the goal, row by row (see
    :class:`~softplan_jax.planning._gains.GainFunction`). With none of the three,
    :meth:`decode` returns :class:`~softplan_jax.planning._gains.Gains`. Zero
    profile, weights and goal profile decode to the constant gains exactly.

    With ``stable_dt``, ``dt`` is not log-parametrised but as the logit of
    ``r = dt k_att / 2``, its fraction of the Euler step's stability bound: within
    ``v_max / k_att`` of the goal the attraction of eq. (9) is linear, so the
    tip's error obeys ``e <- (1 - dt k_att) e`` (with ``J J^+`` close to the
    identity away from singularities) and converges only for ``dt < 2 / k_att``
    (1.0 at the default ``k_att = 2``). Beyond it the arm oscillates about its
    goal, a cliff in every score (docs: Tuning the gains, "The optimiser"). In
    logit coordinates the bound lies at infinity, so neither a step nor the
    smoothing's perturbations cross it.

    Attributes:
      names: scalar Gains fields tuned (log-parametrised; ``dt`` see ``stable_dt``).
      knots: repulsion profile knots (0: none; else >= 2).
      segments: per-segment repulsion weights (0: none; else the arm's n).
      stable_dt: parametrise ``dt`` as ``logit(dt k_att / 2)`` (bool).
      goal_knots: knots of the goal-distance profile of k_att, v_max, eta, d0
        (0: none; else >= 2: ``4 * goal_knots`` parameters).
    """

    names: tuple = ("d0", "dt", "eta")
    knots: int = 0
    segments: int = 0
    stable_dt: bool = False
    goal_knots: int = 0

    @property
    def size(self) -> int:
        return len(self.names) + self.knots + self.segments + len(GOAL_GAINS) * self.goal_knots

    @property
    def is_function(self) -> bool:
        return self.knots > 0 or self.segments > 0 or self.goal_knots > 0

    def check(self, n_segments: int | None = None) -> GainSpace:
        names = tuple(self.names)
        unknown = [k for k in names if k not in SCALAR_GAINS]
        if unknown or len(set(names)) != len(names):
            raise ValueError(f"GainSpace.names must be distinct Gains fields {list(SCALAR_GAINS)}; got {list(names)}")
        for k in ("knots", "segments", "goal_knots"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ValueError(f"GainSpace.{k} must be an int, got {v!r}")
        if self.knots == 1 or self.knots < 0 or self.segments < 0 or self.goal_knots == 1 or self.goal_knots < 0:
            raise ValueError(f"GainSpace needs knots 0 or >= 2, segments >= 0 and goal_knots 0 or >= 2; got "
                             f"{self.knots}, {self.segments}, {self.goal_knots}")
        if self.segments and n_segments is not None and self.segments != n_segments:
            raise ValueError(f"GainSpace.segments = {self.segments} for an arm of {n_segments} segments")
        if self.size == 0:
            raise ValueError("GainSpace tunes nothing: give names, knots, segments or goal_knots")
        if not isinstance(self.stable_dt, (bool, np.bool_)):
            raise ValueError(f"GainSpace.stable_dt must be a bool, got {self.stable_dt!r}")
        return self._replace(names=names)

    def base(self, gains, n_segments: int):
        """``gains`` as the type this space decodes to (a GainFunction gets a zero
        profile / weights where ``gains`` has none)."""
        if not self.is_function:
            return gains.scalars() if isinstance(gains, GainFunction) else gains
        if not isinstance(gains, GainFunction):
            gains = GainFunction.from_gains(gains, max(self.knots, 2), self.segments or n_segments)
        if self.goal_knots and gains.goal_profile is None:
            gains = gains._replace(goal_profile=jnp.zeros((len(GOAL_GAINS), self.goal_knots),
                                                          jnp.result_type(gains.k_att)))
        for name, field in (("knots", "rep_profile"), ("goal_knots", "goal_profile")):
            k, have = getattr(self, name), getattr(gains, field)
            if k and have.shape[-1] != k:
                raise ValueError(f"GainSpace.{name} = {k}, but the start gain function's {field} has "
                                 f"{have.shape[-1]} knots")
        return gains

    def encode(self, gains) -> jax.Array:
        """theta of ``gains`` (a Gains or GainFunction; zeros where it has no profile).
        With ``stable_dt``, a ``dt`` at or beyond ``2 / k_att`` encodes to +inf or nan."""

        def coord(k):
            v = jnp.asarray(getattr(gains, k))
            if k == "dt" and self.stable_dt:
                r = v * jnp.asarray(gains.k_att) / 2  # fraction of the stability bound 2 / k_att
                return jnp.log(r) - jnp.log1p(-r)
            return jnp.log(v)

        parts = [jnp.stack([coord(k) for k in self.names])] if self.names else []
        if self.knots:
            p = gains.rep_profile if isinstance(gains, GainFunction) else None
            parts.append(jnp.zeros((self.knots,), jnp.result_type(gains.k_att)) if p is None else p)
        if self.segments:
            w = gains.seg_weights if isinstance(gains, GainFunction) else None
            parts.append(jnp.zeros((self.segments,), jnp.result_type(gains.k_att)) if w is None else w)
        if self.goal_knots:
            g = gains.goal_profile if isinstance(gains, GainFunction) else None
            parts.append(jnp.zeros((len(GOAL_GAINS) * self.goal_knots,), jnp.result_type(gains.k_att))
                         if g is None else jnp.reshape(g, (-1,)))
        return jnp.concatenate(parts)

    def decode(self, theta, base):
        """The gains at ``theta``: ``base`` (as :meth:`base` returns it) with the tuned
        entries replaced. Traceable; vmap over theta for many."""
        nn = len(self.names)
        stable = self.stable_dt and "dt" in self.names
        g = base._replace(**{k: jnp.exp(theta[i]).astype(base.k_att.dtype) for i, k in enumerate(self.names)
                             if not (stable and k == "dt")})
        if stable:  # dt = (2 / k_att) sigmoid(theta_dt), with the (possibly tuned) k_att
            g = g._replace(dt=(2 * jax.nn.sigmoid(theta[self.names.index("dt")]) / g.k_att).astype(g.k_att.dtype))
        if self.knots:
            g = g._replace(rep_profile=theta[nn : nn + self.knots].astype(base.k_att.dtype))
        if self.segments:
            g = g._replace(seg_weights=theta[nn + self.knots : nn + self.knots + self.segments].astype(base.k_att.dtype))
        if self.goal_knots:
            tail = theta[nn + self.knots + self.segments :]
            g = g._replace(goal_profile=tail.reshape(len(GOAL_GAINS), self.goal_knots).astype(base.k_att.dtype))
        return g
