"""Closest-point providers: how a rollout gets the exact closest pair between the arm and every
obstacle slot at each step. Each provider prepares per-scene data once, starts a state, and
answers a query at q with the pairs, its next state and the number of (segment, curve) pairs
that took the full solve of paper §2.3. ``d0`` and ``travel`` of a query (the repulsion's reach,
a clearance, :func:`~softplan_jax.planning._gains.repulsion_reach`; each obstacle's travel since
the previous step) are for :class:`NearPairs`; the other providers ignore them."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from ._closest import SolverOptions
from ._obstacles import (
    near_closest,
    near_state,
    placeholder_closest,
    radius_and_mask,
    true_closest,
    warm_cells,
    warm_closest,
    warm_state,
)

__all__ = ["WarmPairs", "NearPairs", "ExactPairs", "NoPairs"]


def _curve_pairs(q, scene):
    """() int32: the (segment, real curve) pairs of a scene."""
    return q.shape[0] * (jnp.sum(scene.curve_mask) + len(scene.parametric)).astype(jnp.int32)


class WarmPairs(NamedTuple):
    """Each pair carried from step to step, polished and certified the global minimum
    (:mod:`softplan_jax.geometry._warm_start`); a pair whose certificate fails takes the full
    solve. The same pairs as :class:`ExactPairs`, fewer solves."""

    solver: SolverOptions

    def prepare(self, scene):
        """Per-scene data (:func:`~softplan_jax.geometry._obstacles.warm_cells`), once per rollout."""
        return warm_cells(scene, self.solver)

    def init(self, scene, rows=None):
        """The state before the first step, for a shape of ``rows`` segments (None: the scene's arm)."""
        return warm_state(scene, rows)

    def query(self, q, scene, cells, state, fresh, d0=None, travel=None):
        """``(pairs with a leading axis m, next state, full solves () int32)`` at q."""
        return warm_closest(q, scene, self.solver, cells, state, fresh)


class NearPairs(NamedTuple):
    """:class:`WarmPairs` for the pairs that can act on the step, a certified lower bound on the
    distance for the others (:mod:`softplan_jax.geometry._near_pairs`): a pair is solved where its
    bound is below the reach, the arm's and the largest obstacle's radius plus ``d0 + margin``
    (a clearance of ``d0 + margin``). In a moving scene the obstacles' travel is subtracted
    from the bounds, and ``d0`` includes the field's look-ahead."""

    solver: SolverOptions
    margin: float

    def prepare(self, scene):
        return warm_cells(scene, self.solver)

    def init(self, scene, rows=None):
        return near_state(scene, rows)

    def query(self, q, scene, cells, state, fresh, d0=None, travel=None):
        """As :meth:`WarmPairs.query`; ``d0`` the repulsion's reach (a clearance); ``travel``
        (m,) each obstacle's travel since the previous step (None: static)."""
        radius, mask = radius_and_mask(scene)
        widest = jnp.max(jnp.where(mask, radius, 0.0), initial=0.0)
        reach = jnp.max(scene.arm_radius) + widest + d0 + self.margin
        return near_closest(q, scene, self.solver, cells, state, fresh, reach, travel)


class ExactPairs(NamedTuple):
    """The full solve of paper §2.3 for every pair at every step."""

    solver: SolverOptions

    def prepare(self, scene):
        return ()

    def init(self, scene, rows=None):
        return ()

    def query(self, q, scene, cells, state, fresh, d0=None, travel=None):
        return true_closest(q, scene, self.solver), state, _curve_pairs(q, scene)


class NoPairs(NamedTuple):
    """No exact pair (the N-point model without the collision checks): zeros of their shape."""

    def prepare(self, scene):
        return ()

    def init(self, scene, rows=None):
        return ()

    def query(self, q, scene, cells, state, fresh, d0=None, travel=None):
        return placeholder_closest(q, scene), state, jnp.zeros((), jnp.int32)
