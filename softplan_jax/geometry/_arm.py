"""The arm model: what the planner asks of the arm's shape. A model gives the configuration the
closest-point kernel sees, the tip, the Jacobians of arm points and of the tip, a bound on how
far any arm point moves along a straight motion in q, its shape's rows, and the scene widened by
how far the shape may be off the arm.
:data:`PCC` is the piecewise-constant-curvature arm of paper §2.1; a model that bends the arm
otherwise (:class:`~softplan_jax.rod._arm.LoadedArm`) provides the same methods, and ``at(q)``,
the model posed at q, whose methods the planner's step calls with that q."""

from __future__ import annotations

from typing import NamedTuple

import jax

from ._kinematics import motion_bound, points_jacobian, tip_position

__all__ = ["PCCArm", "PCC"]


class PCCArm(NamedTuple):
    """The piecewise-constant-curvature arm (paper §2.1): its shape is q's arcs.

    A pytree without leaves, so it passes through ``jit`` and ``vmap`` as an argument.
    """

    # Its shape at any q is q's arcs, so the between-step search may sample them.
    searchable = True

    def at(self, q):
        """The arm posed at q: itself (nothing to solve)."""
        return self

    def rows(self, n: int) -> int:
        """The rows of :meth:`shape` for an arm of n segments: n."""
        return n

    def widened(self, scene):
        """The scene as the kernel's shape must see it: as it is (the shape is the arm)."""
        return scene

    def shape(self, q):
        """The configuration (n', 3) whose arcs the closest-point kernel sees: q itself."""
        return q

    def tip(self, q):
        """The tip position (3,) (paper §2.1)."""
        return tip_position(q)

    def jacobians(self, q, segments, s):
        """``dP/dq`` (m, 3, 3n) of the shape's points at ``segments`` (m,), fractions ``s`` (m,)
        (paper §2.2)."""
        return points_jacobian(q, segments, s)

    def tip_jacobian(self, q):
        """``d tip / dq`` (3, 3n) by forward mode (paper §2.2)."""
        return jax.jacfwd(tip_position)(q).reshape(3, 3 * q.shape[0])

    def jacobians_with_tip(self, q, segments, s):
        """``(`` :meth:`jacobians` ``,`` :meth:`tip_jacobian` ``)``."""
        return self.jacobians(q, segments, s), self.tip_jacobian(q)

    def motion_bound(self, q_a, q_b):
        """A bound () on how far any arm point moves along ``q_a + t (q_b - q_a)``, t in [0, 1]
        (:func:`~softplan_jax.geometry._kinematics.motion_bound`)."""
        return motion_bound(q_a, q_b)[-1]


PCC = PCCArm()
