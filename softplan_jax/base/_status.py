"""Rollout statuses: how a planning run ended (reached the goal, collided,
stalled in a local minimum of the potential field of paper eq. 9, ran out of
steps, or met a non-finite number; the start pose was already in collision;
the goal was proven unreachable; or, tracking a moving goal, an obstacle moved
too fast to stay provably clear of, or the goal was reached, left, and then
held again at the end or lost).
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Status", "STATUS_NAMES", "status_name"]


class Status(enum.IntEnum):
    """Rollout status codes (stored as int32 in a :class:`~softplan_jax.planning._records.Rollout`;
    ``Status(code).label`` is the name used in reports and JSON)."""

    RUNNING = 0
    REACHED = 1
    COLLIDED = 2
    STALLED = 3
    MAX_STEPS = 4
    NONFINITE = 5
    UNREACHABLE = 6
    TOO_FAST = 7
    LOST = 8
    START_COLLIDED = 9
    HELD = 10

    @property
    def label(self) -> str:
        """The report name: "running", "reached", "collided", "stalled", "max_steps", "non_finite",
        "start_in_collision" (the start pose's exact clearance is already at or below the contact
        tolerance: nothing was planned; ``collided`` is true), "unreachable" (no collision-free
        configuration puts the tip on the goal: proven on the host before planning by
        :func:`~softplan_jax.plan` -- the goal beyond the arm's reach or inside an obstacle --, or
        decided by :func:`~softplan_jax.plan_fallback`, see :mod:`softplan_jax.search._reach`); with
        moving obstacles (:func:`~softplan_jax.track`) also "too_fast" (an obstacle could reach
        the arm within one step whatever the arm did: stopped at the last configuration proven
        clear), "held" (the moving goal was reached, left the hold tolerance, and was regained:
        within the hold tolerance at the last step) and "lost" (reached, left, and not within the
        hold tolerance at the last step)."""
        if self is Status.NONFINITE:
            return "non_finite"
        if self is Status.START_COLLIDED:
            return "start_in_collision"
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> Status:
        """The status of a report name (:attr:`label`); ValueError for an unknown name."""
        for status in cls:
            if status.label == label:
                return status
        raise ValueError(f"unknown status {label!r}; known: {', '.join(s.label for s in cls)}")


STATUS_NAMES = {int(s): s.label for s in Status}


def status_name(code) -> str:
    """Report name of a status code (see :attr:`Status.label`)."""
    return Status(int(np.asarray(code))).label
