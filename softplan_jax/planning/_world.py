"""The rollout's world: the scene at each step, the attraction towards its goal, the check of
the motion between two steps and the step itself. A static scene is :class:`StaticWorld`; a
moving one (obstacles on rigid motions, a goal on a path) is :class:`MovingWorld`, whose step
subtracts the obstacles' travel, inflates them by their look-ahead and, where no scale of the
field's step is proven safe, takes the evasive step (:mod:`softplan_jax.planning._evasion`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._numerics import evaluate_where, when_any
from ..geometry._clearance import between_steps, contact_tolerance, swept_clear
from ..geometry._obstacles import radius_and_mask
from ..scenarios._motion import goal_velocity, moved_cells, scenario_at, speed_bounds
from ._evasion import evasive_target, slot_clearance
from ._gains import repulsion_reach
from ._step import attraction, goal_scaled, scaled_step, step_target, tracking_attraction

__all__ = ["StaticWorld", "MovingWorld", "make_world", "world_data"]


def world_data(world, su, pairs) -> tuple:
    """What a rollout computes once per scene, before its first step: the closest-point
    provider's data (``pairs.prepare``) and, for a moving scene, its obstacles' speed bounds
    (:func:`~softplan_jax.scenarios._motion.speed_bounds`)."""
    return pairs.prepare(su.scene), (speed_bounds(world) if su.moving else ())


class StaticWorld:
    """A scene at rest: the scene at every step is itself (a tracked static scene holds its goal)."""

    moving = False

    def __init__(self, su, gains, cells, arm):
        self.scene, self.plan, self.gains, self.cells, self.arm = su.scene, su.plan, gains, cells, arm
        radius, self.mask = radius_and_mask(su.scene)
        self.radius_sum = su.scene.arm_radius + radius
        self.contact = contact_tolerance(su.plan, su.scene.q0.dtype)

    def at(self, t):
        """``(scene, provider data)`` at time t."""
        return self.scene, self.cells

    def reach(self):
        """``(d0, travel)`` for a closest-point provider that solves only the pairs within reach
        (:class:`~softplan_jax.geometry._closest_pairs.NearPairs`): the clearance beyond which
        the field exerts no force (:func:`repulsion_reach`), and None: no obstacle moves."""
        return repulsion_reach(self.gains), None

    def attraction(self, V_e, t):
        """Paper eq. (9)'s F_e towards the goal, ``V_e = goal - tip``."""
        return attraction(V_e, goal_scaled(self.gains, V_e))

    def between(self, carry, q, truth, c, running, t, sc):
        """``(cb (m,), searched (m,))``: the clearance during the motion from ``carry.q_prev`` to
        q, searched (:func:`~softplan_jax.geometry._clearance.between_steps`) only where the
        motion bound does not prove it clear (``PlanOptions.swept_proof``)."""
        first, q_a, truth_a = carry.first, carry.q_prev, carry.truth_prev
        if not self.arm.searchable:  # the shape is not q's arcs: the arm's motion bound proves the motion
            return carry.c_prev - self.arm.motion_bound(q_a, q), jnp.zeros(self.mask.shape, bool)
        if self.plan.swept_proof:
            proven = swept_clear(q_a, q, truth_a, carry.c_prev, self.contact)
            searched = self.mask & ~first & running & ~proven
            return between_steps(q_a, q, truth_a, truth, sc, self.radius_sum, search=searched), searched
        searched = self.mask & ~first & running
        return between_steps(q_a, q, truth_a, truth, sc, self.radius_sum), searched

    def step(self, q, sc, truth, c, t, F_e, stepping, arm):
        """``(q_next, alpha, too_fast, evasive)``: paper eq. (9) with the attraction ``F_e``,
        the Euler step, scaled by the safe step; ``arm``: the arm model posed at q."""
        q_full, field_c = step_target(q, sc, self.gains, truth, self.plan, F_e, arm=arm)
        q_next, alpha, too_fast = scaled_step(q, q_full, field_c, self.plan, arm=arm)
        return q_next, alpha, too_fast, jnp.zeros((), bool)


class MovingWorld(StaticWorld):
    """A moving scene: obstacles travel at most ``S_j dt`` during a step (``S_j`` their speed
    bounds), which the safe step and the between-step proof subtract; the goal's velocity is
    fed forward to the attraction."""

    moving = True

    def __init__(self, world, su, gains, cells, speed, arm):
        super().__init__(su, gains, cells, arm)
        self.world, self.track, self.speed = world, su.track, speed
        self.travel = speed * gains.dt  # (m,) how far each obstacle can move in one step
        self.lead = speed * su.track.anticipation  # (m,) the field's inflation (TrackOptions.anticipation)
        self.m_c = su.scene.curves.coeffs.shape[0]
        n = su.track.search_substeps
        self.substeps = jnp.arange(1, n + 1, dtype=su.scene.q0.dtype) / (n + 1)
        # The evasive step needs the true clearance (check_collisions) and the safe step; it
        # plans PCC arcs, so an arm whose shape is not q's arcs does not evade.
        self.evades = su.track.evasion and su.plan.check_collisions and su.plan.step == "safe" and arm.searchable

    def at(self, t):
        sc = scenario_at(self.world, t)
        cells = self.cells
        if cells and self.m_c:
            cells = (moved_cells(cells[0], self.world.motion, t), *cells[1:])
        return sc, cells

    def reach(self):
        """As :meth:`StaticWorld.reach`, with the field's look-ahead added to the reach (the field
        sees each obstacle inflated by it) and each obstacle's travel in one step."""
        return repulsion_reach(self.gains) + jnp.max(self.lead, initial=0.0), self.travel

    def attraction(self, V_e, t):
        """The attraction with the goal's velocity fed forward (:func:`tracking_attraction`)."""
        gains = goal_scaled(self.gains, V_e)
        return tracking_attraction(V_e, goal_velocity(self.world, t), gains, self.track.feedforward)

    def _search(self, q_a, q_b, t_a, w, j):
        """Slot j's smallest exact clearance at the search instants, arm and curves moving together."""

        def at(tau):
            return slot_clearance(w, q_a + tau * (q_b - q_a), t_a + tau * self.gains.dt, j, self.plan.solver)

        return jnp.min(jax.vmap(at)(self.substeps))

    def between(self, carry, q, truth, c, running, t, sc):
        """Proven clear where the clearance at the motion's start, less the arm's motion bound and
        the obstacle's travel, stays above the contact tolerance (or where the evasive step
        proved the motion in time); elsewhere searched at ``search_substeps`` instants. An arm
        whose shape is not q's arcs (``arm.searchable`` False) is not searched: its record is
        that lower bound itself, ``c_prev - travel - motion_bound``."""
        if not self.arm.searchable:  # the arm's motion bound and the obstacles' travel prove the motion
            return carry.c_prev - self.travel - self.arm.motion_bound(carry.q_prev, q), jnp.zeros(self.mask.shape, bool)
        proven = swept_clear(carry.q_prev, q, carry.truth_prev, carry.c_prev - self.travel, self.contact)
        proven = proven | carry.certified
        searched = self.mask & ~carry.first & running & ~proven

        def search(j):
            # The barrier ties the search to the slot index (a loop variable of evaluate_where):
            # without it XLA hoists the loop-invariant solves out of the while loop.
            q_a, q_b, t_a, w, j = jax.lax.optimization_barrier((carry.q_prev, q, t - self.gains.dt, self.world, j))
            return self._search(*jax.lax.stop_gradient((q_a, q_b, t_a, w)), j)

        found = evaluate_where(searched, search, 1, jnp.full(self.mask.shape, jnp.inf, q.dtype))
        cb = jnp.minimum(jnp.minimum(carry.c_prev, c), jnp.where(searched, found, jnp.inf))
        return cb, searched

    def step(self, q, sc, truth, c, t, F_e, stepping, arm):
        """The field sees each curve inflated by its look-ahead; the safe step gets the true
        clearance less the obstacles' travel; the evasive step where no scale is proven safe.
        ``arm``: the arm model posed at q."""
        curves = sc.curves.with_radius(sc.curves.radius + self.lead[: self.m_c])
        field = sc._replace(curves=curves)
        q_full, field_c = step_target(q, field, self.gains, truth, self.plan, F_e, self.lead, arm=arm)
        q_next, alpha, too_fast = scaled_step(q, q_full, field_c, self.plan, self.travel, arm=arm)
        evasive = jnp.zeros((), bool)
        if self.evades:
            want = stepping & too_fast

            def evade(args):  # every array an operand: under vmap each may be batched
                w, q_a, q_b, tr, c_a, t_a, s, g, go = args
                q_ev, proven, _ = evasive_target(w, q_a, q_b, tr, c_a, t_a, s, g, self.track, go)
                return q_ev, proven

            # Held (stop_gradient): a rollout stays differentiable, the evasive step itself is not.
            args = jax.lax.stop_gradient((self.world, q, q_full, truth, c, t, self.speed, self.gains, want))
            q_ev, proven = when_any(want, evade, lambda args: (args[1], jnp.zeros((), bool)), args, chunk="auto")
            evasive = want & proven
            q_next = jnp.where(evasive, q_ev, q_next)
            alpha = jnp.where(evasive, 1.0, alpha)
            too_fast = too_fast & ~evasive
        return q_next, alpha, too_fast, evasive


def make_world(world, su, gains, prepared, arm):
    """The world of a rollout of ``world`` (a Scenario or a MovingScenario; ``su`` its
    :func:`~softplan_jax.planning._records.setup`), given :func:`world_data`."""
    cells, speed = prepared
    if su.moving:
        return MovingWorld(world, su, gains, cells, speed, arm)
    return StaticWorld(su, gains, cells, arm)
