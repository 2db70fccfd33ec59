"""A bound on how far any point of the loaded arm moves along the straight motion
``q(t) = q_a + t (q_b - q_a)``, t in [0, 1]: the PCC motion bound
(:func:`~softplan_jax.geometry._kinematics.motion_bound`) plus a bound on the change of the
load-induced deflection ``d = p_loaded - p_PCC`` (docs/loaded-arm.md, "The motion bound").

In the fraction coordinate xi (segment i is [i, i + 1], ``l = L_i``) the rod's curvature per
unit xi is ``U = U* + l K^-1 R^T m`` with ``U* = theta_i (-sin Phi_i, cos Phi_i, 0)``. Along the
motion (dots: d/dt), with ``rho`` the frames' angular velocity: ``rho_xi = R U_dot``,
``p_xi_dot = l_dot t + l rho x t``, ``m(xi) = int_xi^n p_xi x n`` (free tip). Every quantity
below is bounded a priori over the whole motion (lengths by their larger end, |m| by
``m_bar(xi) = int_xi^n l |n|``, the deflection angle by ``psi(xi) = int_0^xi l m_bar / k``,
``k = min(EI, GJ)``), so the bound holds at every instant, not only at the ends:

* ``|rho_L - rho_P| <= Delta(xi) <= int_0^xi (|dU_dot| + psi |U*_dot|)``,
* ``|dU_dot| <= (|l_dot| m_bar + l (|m_dot| + (P + A) m_bar)) / k``, ``P = int_0^xi |U*_dot|``,
* ``|m_dot(xi)| <= int_xi^n ((|l_dot| + l (P + A)) |n| + l |n_dot|)``,

with ``A = sup Delta``; closing the loop, ``A <= C0 / (1 - Gamma)`` where
``Gamma = int 2 l m_bar / k`` (finite only for ``Gamma < 1``: the load number of the rod), and
``|d_dot(xi)| <= int_0^xi ((|l_dot| + l P) psi + l Delta)``. The integrals are upper Riemann
sums on a grid (decreasing integrands at the left end of each cell, increasing at the right).
The bound is linear in ``q_b - q_a`` for fixed length and angle bounds, so a shorter motion
along the same line has a proportionally smaller bound (what the safe step needs).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..base._validation import check_configuration, check_int
from ..geometry._kinematics import motion_bound
from ._model import RodModel, segment_material

__all__ = ["loaded_motion_bound", "load_number", "GRID"]

GRID = 8  # cells per segment of the upper Riemann sums


def _profiles(q_a, q_b, model: RodModel, cells: int):
    """Per cell (n * cells,): l, |l_dot|, |U*_dot|, k; at the cell's left end n_bar, n_dot_bar;
    and the cell width in xi."""
    n = q_a.shape[0]
    dtype = q_a.dtype
    EI, GJ, w, F = segment_material(model, n, dtype)
    dq = q_b - q_a
    L_bar = jnp.maximum(q_a[:, 0], q_b[:, 0])
    dL = jnp.abs(dq[:, 0])
    theta_bar = jnp.maximum(jnp.abs(q_a[:, 1]), jnp.abs(q_b[:, 1]))
    dPhi = jnp.cumsum(jnp.abs(dq[:, 2]))
    dU_star = jnp.abs(dq[:, 1]) + theta_bar * dPhi  # |d/dt theta (-sin Phi, cos Phi, 0)|
    k = jnp.minimum(EI, GJ)
    rep = lambda x: jnp.repeat(x, cells)
    f0 = jnp.tile(jnp.arange(cells, dtype=dtype) / cells, n)  # the cell's left end, fraction of its segment
    seg_w, seg_wd = w * L_bar, w * dL
    beyond_w = jnp.cumsum(seg_w[::-1])[::-1] - seg_w
    beyond_wd = jnp.cumsum(seg_wd[::-1])[::-1] - seg_wd
    n_bar = jnp.linalg.norm(F) + rep(beyond_w) + rep(seg_w) * (1.0 - f0)
    nd_bar = rep(beyond_wd) + rep(seg_wd) * (1.0 - f0)
    return rep(L_bar), rep(dL), rep(dU_star), rep(k), n_bar, nd_bar, jnp.asarray(1.0 / cells, dtype)


def _to_tip(x):
    """Sum of cells j >= g for each cell g (the integral from the cell's left end to the tip)."""
    return jnp.cumsum(x[::-1])[::-1]


def _from_base(x):
    """Sum of cells j <= g for each cell g (the integral from the base to the cell's right end)."""
    return jnp.cumsum(x)


def _deflection_terms(q_a, q_b, model: RodModel, cells: int):
    l, dl, dU, k, n_bar, nd_bar, dx = _profiles(q_a, q_b, model, cells)
    m_bar = _to_tip(l * n_bar * dx)  # at each cell's left end (decreasing)
    psi = _from_base(l * m_bar / k * dx)  # at each cell's right end (increasing)
    P = _from_base(dU * dx)
    M0 = _to_tip(((dl + l * P) * n_bar + l * nd_bar) * dx)
    c0 = (dl * m_bar + l * (M0 + P * m_bar)) / k
    c1 = 2.0 * l * m_bar / k
    Gamma = jnp.sum(c1 * dx)
    return l, dl, dU, P, psi, c0, c1, Gamma, dx


def load_number(q_a, q_b, model: RodModel, cells: int = GRID):
    """``Gamma = int 2 l m_bar / k`` over the motion (module docstring): the motion bound is
    finite only for Gamma < 1. () scalar."""
    q_a, q_b = check_configuration(q_a), check_configuration(q_b)
    return _deflection_terms(q_a, q_b, model, cells)[7]


def loaded_motion_bound(q_a, q_b, model: RodModel, cells: int = GRID):
    """A sound bound on how far any point of the loaded arm (the equilibrium of
    :func:`~softplan_jax.rod._equilibrium.solve_equilibrium`, followed continuously) moves along
    ``q_a + t (q_b - q_a)``, t in [0, 1] (module docstring).

    Args:
      q_a, q_b: (n, 3) the motion's ends.
      model: :class:`~softplan_jax.rod._model.RodModel`.
      cells: grid cells per segment of the Riemann sums (static).

    Returns:
      (n,) ``bound[i]``: no point of segments 0..i moves farther than this; +inf where the
      load number :func:`load_number` is >= 1 (the bound does not close).
    """
    q_a, q_b = check_configuration(q_a), check_configuration(q_b)
    if q_a.shape != q_b.shape:
        raise ValueError(f"q_a and q_b must have the same shape; got {q_a.shape} and {q_b.shape}")
    cells = check_int(cells, "cells", 1)
    n = q_a.shape[0]
    l, dl, dU, P, psi, c0, c1, Gamma, dx = _deflection_terms(q_a, q_b, model, cells)
    drive = (c0 + psi * dU) * dx
    closes = Gamma < 1.0
    A = jnp.where(closes, jnp.sum(drive) / jnp.where(closes, 1.0 - Gamma, 1.0), jnp.inf)
    Delta = _from_base(drive + A * c1 * dx)
    D = _from_base(((dl + l * P) * psi + l * Delta) * dx)  # at each cell's right end
    deflection = D.reshape(n, cells)[:, -1]
    return motion_bound(q_a, q_b) + jnp.where(closes, deflection, jnp.inf)
