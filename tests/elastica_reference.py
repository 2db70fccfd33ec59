"""The loaded arm's independent reference: PyElastica (Gazzola et al. 2018), a Cosserat rod
simulator, relaxing the same rod under the same loads to rest with damping.

The rod is discretised into elements (PyElastica's staggered grid), started in the unloaded PCC
shape (written here in NumPy from the paper's section 2.1, independently of the package), whose
own discrete curvature becomes the rest curvature: with no load the rest state is the PCC shape.
Shear and stretch are made stiff (``STIFF`` times the bending stiffness over the arm's length
squared), so the rod is nearly Kirchhoff's (inextensible, unshearable). Gravity acts on the
nodes' masses, the tip load on the last node; the base node and the first element's directors
are clamped. The dynamics is integrated (position Verlet) with linear damping until the nodes
stop moving. The answer is the nodes' positions at rest.

The 21 cases of ``tests/test_rod_elastica.py`` (:func:`cases`) take about 3 CPU-minutes, so their
answers are kept in ``tests/data/elastica_reference.npz``, written by::

    python tests/elastica_reference.py

and the slow tier relaxes a few of them again to check that the file is PyElastica's answer.
"""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

STIFF = 1e4  # shear and stretch stiffness / (EI / L^2)
GRAVITY = 9.81
COARSE, FINE = 6, 12  # PyElastica elements per segment of the two resolutions extrapolated
REFERENCE_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "elastica_reference.npz")


def cases():
    """(q, EI, GJ, w, tip_load) of the 21 cases: 3 segments, EI from the load number
    gamma = w L^3 / EI of 0.05 to 2.8 (slight to heavy sag), per-segment stiffness in every
    third case, a tip load in two of three."""
    rng = np.random.default_rng(62)
    out = []
    for k, gamma in enumerate(np.repeat([0.05, 0.2, 0.5, 1.0, 1.6, 2.2, 2.8], 3)):
        q = np.column_stack([rng.uniform(0.8, 1.2, 3), rng.uniform(-1.8, 1.8, 3), rng.uniform(-3.1, 3.1, 3)])
        L = q[:, 0].sum()
        w = 0.3
        EI = w * L**3 / gamma
        per_segment = k % 3 == 1
        EI_arg = EI * np.array([1.2, 1.0, 0.8]) if per_segment else EI
        tip = np.array([0.0, 0.0, 0.0]) if k % 3 == 0 else np.array([0.02, -0.01, -0.15]) * w * L
        out.append((q, EI_arg, 0.7 * np.asarray(EI_arg), w, tip))
    return out


def extrapolated(case):
    """A case's rest shape (n, COARSE + 1, 3): PyElastica at COARSE and FINE elements per segment,
    extrapolated (Richardson, its error being first order in the element length: 2 fine - coarse)."""
    q, EI, GJ, w, tip = case
    with contextlib.redirect_stdout(io.StringIO()):
        coarse = relax(q, EI, GJ, w, tip, elements_per_segment=COARSE, tol=1e-6)
        fine = relax(q, EI, GJ, w, tip, elements_per_segment=FINE, tol=1e-6)
    return 2.0 * fine[:, ::2] - coarse


def _rot(axis, angle):
    """Rodrigues: rotation by ``angle`` about the unit ``axis``."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def pcc_chain(q, fractions):
    """Positions (n, k, 3) and rotation-minimising frames (n, k, 3, 3) of the unloaded PCC arm
    (paper section 2.1: R_i = Rz(phi_i) Ry(theta_i), P_i the arc) at ``fractions`` (k,) of each
    segment. The paper's frame F (which turns by phi_i at each segment) gives the bending
    direction ``F (cos phi, sin phi, 0)``; the material frame G is carried without twist."""
    F, G, P = np.eye(3), np.eye(3), np.zeros(3)
    pos = np.zeros((len(q), len(fractions), 3))
    frames = np.zeros((len(q), len(fractions), 3, 3))
    for i, (L, theta, phi) in enumerate(np.asarray(q, np.float64)):
        t = F[:, 2]
        b = F @ np.array([np.cos(phi), np.sin(phi), 0.0])  # bending direction (unit, normal to t)
        axis = np.cross(t, b)  # rotation axis: takes t toward b
        for j, f in enumerate(fractions):
            a = theta * f
            chord = L * f * t if abs(a) < 1e-12 else L / theta * ((1 - np.cos(a)) * b + np.sin(a) * t)
            pos[i, j] = P + chord
            frames[i, j] = _rot(axis, a) @ G
        c, s = np.cos(phi), np.sin(phi)
        Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        ct, st = np.cos(theta), np.sin(theta)
        Ry = np.array([[ct, 0, st], [0, 1, 0], [-st, 0, ct]])
        P = P + (L * t if abs(theta) < 1e-12 else L / theta * ((1 - ct) * b + st * t))
        G = _rot(axis, theta) @ G
        F = F @ Rz @ Ry
    return pos, frames


def relax(q, EI, GJ, w, tip_load, elements_per_segment=20, tol=1e-7, max_time=200.0):
    """The loaded arm at rest by PyElastica: node positions (n, elements_per_segment + 1, 3) at
    fractions j / elements_per_segment of each segment. ``EI``, ``GJ``, ``w``: (n,) or scalars.

    Raises RuntimeError when the rod has not come to rest by ``max_time``."""
    import elastica as ea

    q = np.asarray(q, np.float64)
    n, k = q.shape[0], elements_per_segment
    EI, GJ, w = (np.broadcast_to(np.asarray(x, np.float64), (n,)) for x in (EI, GJ, w))
    L = q[:, 0]
    L_tot = float(L.sum())
    fr = np.arange(k + 1) / k
    nodes, _ = pcc_chain(q, fr)
    position = np.concatenate([nodes[0]] + [nodes[i, 1:] for i in range(1, n)]).T  # (3, n k + 1)
    mid, frames = pcc_chain(q, (np.arange(k) + 0.5) / k)
    directors = np.transpose(frames.reshape(n * k, 3, 3), (2, 1, 0))  # (3, 3, n k): rows d1, d2, d3
    n_el = n * k

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    sim = Sim()
    radius = 0.01 * L_tot
    area = np.pi * radius**2
    mu = float(np.max(w)) / GRAVITY if np.max(w) > 0 else 1e-3
    rod = ea.CosseratRod.straight_rod(
        n_el, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), L_tot, radius, mu / area,
        youngs_modulus=1.0, shear_modulus=1.0, position=position, directors=directors)
    seg_of_el = np.repeat(np.arange(n), k)
    # Node masses: the weight per length of each element, half to each of its nodes.
    el_mass = (w[seg_of_el] / GRAVITY) * rod.rest_lengths
    mass = np.zeros(n_el + 1)
    mass[:-1] += 0.5 * el_mass
    mass[1:] += 0.5 * el_mass
    gravity_on = np.max(w) > 0
    if gravity_on:
        rod.mass[:] = np.maximum(mass, 1e-12)
    else:
        rod.mass[:] = mu * rod.rest_lengths.mean()
    # Rotational inertia only sets the dynamics (not the rest state): a modest value per element.
    J = np.maximum(rod.mass[:-1], 1e-12) * (0.05 * L_tot / n) ** 2
    rod.mass_second_moment_of_inertia[:] = np.eye(3)[:, :, None] * J
    rod.inv_mass_second_moment_of_inertia[:] = np.eye(3)[:, :, None] / J
    S = STIFF * float(np.max(EI)) / L_tot**2
    rod.shear_matrix[:] = np.eye(3)[:, :, None] * S
    seg_of_vor = seg_of_el[1:]  # voronoi k lies between elements k and k + 1
    bend = np.zeros((3, 3, n_el - 1))
    bend[0, 0], bend[1, 1], bend[2, 2] = EI[seg_of_vor], EI[seg_of_vor], GJ[seg_of_vor]
    rod.bend_matrix[:] = bend
    # Rest curvature: PyElastica's own discrete curvature of the unloaded PCC shape.
    from elastica._rotations import _inv_rotate

    rod.rest_kappa[:] = _inv_rotate(rod.director_collection) / rod.rest_voronoi_lengths
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    if gravity_on:
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -GRAVITY]))
    F = np.asarray(tip_load, np.float64)
    if np.any(F != 0):
        sim.add_forcing_to(rod).using(ea.EndpointForces, start_force=np.zeros(3), end_force=F, ramp_up_time=1e-9)
    # Time step from the stiffest wave (stretch) and the lightest node; damping near the first
    # bending mode's critical value.
    m_min = float(np.min(rod.mass))
    dx = float(np.min(rod.rest_lengths))
    dt = 0.2 * dx / np.sqrt(S * dx / m_min)
    m_tot = float(np.sum(rod.mass))
    omega1 = 3.5 * np.sqrt(float(np.min(EI)) / (m_tot / L_tot)) / L_tot**2
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=2.0 * omega1, time_step=dt)
    sim.finalize()
    stepper = ea.PositionVerlet()
    chunk = max(int(2.0 / omega1 / dt), 100)
    t, last = 0.0, rod.position_collection.copy()
    while t < max_time / omega1:
        t = ea.integrate(stepper, sim, chunk * dt, chunk, restart_time=t, progress_bar=False)
        now = rod.position_collection
        if not np.all(np.isfinite(now)):
            raise RuntimeError("PyElastica diverged")
        moved = float(np.max(np.abs(now - last)))
        last = now.copy()
        if moved < tol * L_tot:
            break
    else:
        raise RuntimeError(f"PyElastica did not come to rest (last chunk moved {moved:.3g})")
    pos = rod.position_collection.T
    return np.stack([pos[i * k: i * k + k + 1] for i in range(n)])


def relax_in_processes(chosen, workers: int = 2):
    """:func:`extrapolated` of ``chosen`` cases in spawned processes (not forked: a caller running
    jax's threads would have them copied mid-flight)."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        return list(pool.map(extrapolated, chosen))


def stacked_inputs(chosen) -> dict:
    """The cases' inputs as arrays: q (k, 3, 3), EI and GJ (k, 3) per segment, w (k,), tip_load (k, 3)."""
    q, EI, GJ, w, tip = zip(*chosen, strict=True)
    per_segment = lambda xs: np.stack([np.broadcast_to(np.asarray(x, np.float64), (3,)) for x in xs])  # noqa: E731
    return dict(q=np.stack(q), EI=per_segment(EI), GJ=per_segment(GJ), w=np.asarray(w, np.float64),
                tip_load=np.stack(tip))


def main() -> int:
    """Relax every case and write :data:`REFERENCE_FILE` (with the inputs and PyElastica's version)."""
    from importlib.metadata import version

    all_cases = cases()
    refs = relax_in_processes(all_cases)
    fields = stacked_inputs(all_cases)
    np.savez(REFERENCE_FILE, positions=np.stack(refs), pyelastica=version("pyelastica"), **fields)
    print(f"{len(refs)} cases written to {REFERENCE_FILE} (PyElastica {version('pyelastica')})")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the spawned workers import this module
    sys.exit(main())
