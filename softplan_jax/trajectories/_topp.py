"""Time-optimal timing of one path piece under actuator limits by TOPP-RA
(Pham & Pham 2018; the ``toppra`` package).

The piece is handed to TOPP-RA as a path in actuator-length space
(:class:`~.paths.ActuatorPath`, dof n k), so its joint velocity and joint
acceleration constraints are the actuators' own limits, with the exact
derivatives ``dl/ds`` and ``d2l/ds2`` at every grid point:
``|l'(s) sdot| <= v_max`` and ``|l'(s) sddot + l''(s) sdot^2| <= a_max``
(the acceleration constraint discretised by TOPP-RA's first-order
interpolation scheme). Two bounds on ``sdot`` alone join them: the tip speed
``|tip'(s)| sdot <= v_tip`` (optional), and ``|q'(s)|_inf sdot <= q_max``, which
only binds where the actuators barely move with q (a straight segment turning
its bending plane ``phi``) and keeps the solution finite there. The solution is
``sdot`` at the grid points with constant ``sddot`` in between, from rest to rest.
"""

from __future__ import annotations

import numpy as np

from ._paths import ActuatorPath, Piece

__all__ = ["import_toppra", "time_piece"]


def import_toppra():
    """The ``toppra`` package, or an ImportError that says how to install it."""
    try:
        import toppra
        import toppra.algorithm  # noqa: F401
        import toppra.constraint  # noqa: F401
    except ImportError as err:  # pragma: no cover - toppra is a dependency of the package
        raise ImportError("timing a plan needs toppra (TOPP-RA): pip install 'toppra>=0.6' "
                          f"(it is a dependency of softplan_jax; the import failed: {err})") from None
    return toppra


def _sdot_bound_constraint(toppra, bound):
    """A TOPP-RA constraint ``0 <= sdot^2 <= bound(gridpoints)^2`` (a bound on the path speed alone)."""

    class SdotBound(toppra.constraint.LinearConstraint):
        def __init__(self):
            super().__init__()
            self.dof = None  # no joint dimension: the bound acts on sdot only
            self._format_string = "    path speed bound\n"

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            sd = np.asarray(bound(gridpoints), np.float64)
            xbound = np.stack([np.zeros_like(sd), sd * sd], axis=1)
            return None, None, None, None, None, None, xbound

    return SdotBound()


def time_piece(piece: Piece, path: ActuatorPath, max_speed, max_acceleration, max_tip_speed, max_q_speed: float,
               gridpoints) -> tuple[np.ndarray, np.ndarray]:
    """TOPP-RA on one piece, from rest to rest.

    Args:
      piece: the piece (for ``q'(s)``).
      path: the piece as an :class:`~.paths.ActuatorPath`.
      max_speed, max_acceleration: (n k,) limits (inf: none).
      max_tip_speed: float or None.
      max_q_speed: the bound on ``|dq/dt|_inf`` where nothing else binds.
      gridpoints: (N+1,) increasing, from ``piece.s0`` to ``piece.s1``.

    Returns:
      ``(gridpoints, sdot)`` (N+1,) each, ``sdot`` 0 at both ends.

    Raises:
      ValueError: TOPP-RA found no parametrisation (the limits admit no motion along the piece).
    """
    toppra = import_toppra()
    tc = toppra.constraint
    constraints = []
    if np.any(np.isfinite(max_speed)):
        v = np.where(np.isfinite(max_speed), max_speed, 1e300)
        constraints.append(tc.JointVelocityConstraint(np.stack([-v, v], axis=1)))
    if np.any(np.isfinite(max_acceleration)):
        a = np.where(np.isfinite(max_acceleration), max_acceleration, 1e300)
        constraints.append(tc.JointAccelerationConstraint(np.stack([-a, a], axis=1),
                                                          discretization_scheme=tc.DiscretizationType.Interpolation))

    def bound(ss):
        dq = np.max(np.abs(piece.q(ss, 1)), axis=1)
        sd = np.where(dq > 0, max_q_speed / np.maximum(dq, 1e-300), 1e300)
        if max_tip_speed is not None:
            tip_rate = np.linalg.norm(path.terms(ss)[4], axis=1)
            sd = np.minimum(sd, np.where(tip_rate > 0, max_tip_speed / np.maximum(tip_rate, 1e-300), 1e300))
        return np.minimum(sd, 1e150)

    constraints.append(_sdot_bound_constraint(toppra, bound))
    instance = toppra.algorithm.TOPPRA(constraints, path, gridpoints=np.asarray(gridpoints, np.float64),
                                       solver_wrapper="seidel")
    instance.compute_parameterization(0.0, 0.0)
    data = instance.problem_data
    sd = None if data.sd_vec is None else np.asarray(data.sd_vec, np.float64)
    if sd is None or not np.all(np.isfinite(sd)) or data.return_code.name != "Ok":
        raise ValueError(f"limits: TOPP-RA found no timing of the path from s = {piece.s0:.4g} to {piece.s1:.4g} "
                         f"({data.return_code}); the limits admit no motion along it")
    return np.asarray(gridpoints, np.float64), np.maximum(sd, 0.0)
