"""The loaded arm as the planner's arm model (:mod:`softplan_jax.geometry._arm`): the shape the
closest-point kernel sees is the equilibrium as constant-curvature pieces
(:func:`~softplan_jax.rod._pieces.pieces_from_shape`), their proven gap widens the arm's radius,
the Jacobians of eq. (9) come through the equilibrium, and the motion bound is the loaded one
(:func:`~softplan_jax.rod._motion.loaded_motion_bound`).

One equilibrium solve per planner step: :meth:`LoadedArm.at` solves at q and returns the
posed arm whose methods read that solve."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..base._numerics import solve_small
from ..base._validation import check_int
from ._equilibrium import LoadedShape, integrate, point_on, segment_nodes, solve_shape, step_data
from ._model import RodModel
from ._motion import loaded_motion_bound
from ._pieces import piece_location, pieces_from_shape, pieces_steps

__all__ = ["LoadedArm", "DEFAULT_PIECES"]

# Constant-curvature pieces per segment of the kernel's shape: the proven gap shrinks about as
# 1/p^2 and the kernel's cost grows as p (docs: The loaded arm, "The gap").
DEFAULT_PIECES = 4


@jax.tree_util.register_pytree_node_class
class LoadedArm:
    """The loaded arm (a :class:`~softplan_jax.rod._model.RodModel`) as the planner's arm model.

    Args:
      model: the rod's material and loads.
      pieces_per_segment: constant-curvature pieces per segment the closest-point kernel sees.
      steps: integration steps per segment, a multiple of the pieces (None: the default).

    A pytree whose leaves are the model's, so it passes through ``jit`` and ``vmap``.
    """

    searchable = False  # the between-step search samples PCC arcs: the loaded arm uses its bound

    def __init__(self, model: RodModel, pieces_per_segment: int = DEFAULT_PIECES, steps: int | None = None):
        if not isinstance(model, RodModel):
            raise ValueError(f"model must be a softplan_jax.RodModel, got {type(model).__name__}")
        self.model = model
        self.pieces = check_int(pieces_per_segment, "pieces_per_segment", 1)
        self.steps = pieces_steps(self.pieces, steps)

    def tree_flatten(self):
        return (self.model,), (self.pieces, self.steps)

    @classmethod
    def tree_unflatten(cls, aux, children):
        arm = object.__new__(cls)
        arm.model, (arm.pieces, arm.steps) = children[0], aux
        return arm

    def rows(self, n: int) -> int:
        """The rows of :meth:`shape` for an arm of n segments: n times the pieces."""
        return n * self.pieces

    def at(self, q):
        """The arm posed at q: one equilibrium solve that its methods read."""
        return _PosedArm(self, q, solve_shape(q, self.model, self.steps))

    def shape(self, q):
        """The pieces (n p, 3) at q (:meth:`_PosedArm.shape`; one solve)."""
        return self.at(q).shape(q)

    def tip(self, q):
        """The loaded tip (3,) at q (one solve)."""
        return self.at(q).tip(q)

    def jacobians(self, q, segments, s):
        """``dP/dq`` of the loaded points (:meth:`_PosedArm.jacobians`; one solve)."""
        return self.at(q).jacobians(q, segments, s)

    def tip_jacobian(self, q):
        """``d tip / dq`` (3, 3n) of the loaded tip (:meth:`_PosedArm.tip_jacobian`; one solve)."""
        return self.at(q).tip_jacobian(q)

    def jacobians_with_tip(self, q, pieces, s):
        """:meth:`_PosedArm.jacobians_with_tip` (one solve)."""
        return self.at(q).jacobians_with_tip(q, pieces, s)

    def motion_bound(self, q_a, q_b):
        """A bound () on how far any point of the loaded arm moves along the straight motion
        (:func:`~softplan_jax.rod._motion.loaded_motion_bound`; +inf where it does not close,
        0 for no motion)."""
        return jnp.where(jnp.all(q_a == q_b), 0.0, loaded_motion_bound(q_a, q_b, self.model)[-1])


class _PosedArm:
    """The loaded arm at one configuration q (:meth:`LoadedArm.at`): the solved equilibrium,
    its pieces ``Q (n p, 3)`` and their proven gap; NaN everywhere where the solve did not
    converge, which ends a rollout with status "non_finite"."""

    searchable = False

    def __init__(self, arm: LoadedArm, q, solved: LoadedShape):
        self.arm, self.q, self.solved = arm, q, solved
        self.Q, self.gap = pieces_from_shape(solved, q, arm.model, arm.pieces)

    def at(self, q):
        return self

    def shape(self, q):
        """The pieces (n p, 3), a PCC configuration for the closest-point kernel."""
        return self.Q

    def widened(self, scene):
        """The scene with the pieces' proven gap added to the arm's radius: a clearance
        measured on the pieces is then a lower bound of the loaded arm's."""
        return scene._replace(arm_radius=scene.arm_radius + self.gap)

    def tip(self, q):
        """The loaded tip (3,) (NaN where the solve did not converge)."""
        return jnp.where(self.solved.converged, self.solved.positions[-1, -1], jnp.nan)

    def jacobians(self, q, pieces, s):
        """``dP/dq`` (m, 3, 3n) of the equilibrium's points at fraction ``s`` of ``pieces``
        (indices into :meth:`shape`'s rows), through the equilibrium: with R(m0, q) the tip
        moment (zero at the solve) and P(m0, q) the points,
        ``dP/dq = P_q - P_m R_m^-1 R_q`` (the implicit-function theorem)."""
        arm = self.arm
        segment, fraction = piece_location(pieces, s, arm.pieces)
        J = _implicit_jacobian(q, arm.model, self.solved.base_moment, segment, fraction, arm.steps)
        return jnp.where(self.solved.converged, J, jnp.nan)

    def tip_jacobian(self, q):
        """``d tip / dq`` (3, 3n) through the equilibrium: :meth:`jacobians` at the end of the
        last piece."""
        last = self.arm.rows(q.shape[0]) - 1
        return self.jacobians(q, jnp.array([last]), jnp.ones((1,), q.dtype))[0]

    def jacobians_with_tip(self, q, pieces, s):
        """``(`` :meth:`jacobians` ``,`` :meth:`tip_jacobian` ``)`` from one pass through the
        equilibrium (the tip as one more point)."""
        last = jnp.full((1,), self.arm.rows(q.shape[0]) - 1, jnp.asarray(pieces).dtype)
        J = self.jacobians(q, jnp.concatenate([pieces, last]), jnp.concatenate([s, jnp.ones((1,), s.dtype)]))
        return J[:-1], J[-1]

    def motion_bound(self, q_a, q_b):
        return self.arm.motion_bound(q_a, q_b)


def _implicit_jacobian(q, model, m0, segments, fractions, steps: int):
    """``dP/dq`` (m, 3, 3n) at the solved base moment m0: one integration pushing 3 + 3n tangents
    (:meth:`_PosedArm.jacobians`)."""
    n = q.shape[0]
    m0 = jax.lax.stop_gradient(m0)

    def points_and_tip_moment(m, q_):
        data, F = step_data(q_, model, steps)
        Rs, ps, ms = integrate(m, data, F)
        shape = segment_nodes(Rs, ps, ms, m, True, 0.0, 0, n, steps)
        pts = jax.vmap(lambda i, f: point_on(shape, q_, model, steps, i, f))(segments, fractions)
        return pts, ms[-1]

    (P_m, P_q), (R_m, R_q) = jax.jacfwd(points_and_tip_moment, argnums=(0, 1))(m0, q)
    dm = -solve_small(R_m, R_q.reshape(3, 3 * n))  # (3, 3n): d m0 / d q
    return P_q.reshape(-1, 3, 3 * n) + jnp.einsum("kam,mj->kaj", P_m, dm)
