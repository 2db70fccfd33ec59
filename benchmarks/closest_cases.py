"""The closest-point case corpus and the oracle's answers, cached on disk.

Shared by ``tests/test_closest.py`` (the accuracy suite) and
``benchmarks/closest.py`` (the SolverOptions sweep). Like :mod:`oracle`, it
imports neither ``softplan_jax`` nor jax, nor anything under ``tests/``, and
importing it does nothing but define names:

* the cases are built on first use (:func:`cases`, functools.cache);
* the oracle's answers (:func:`oracle_answers`) are read from
  ``<cache>/oracle/<which>-<hash of oracle.py's source>.npz``, one entry per
  case keyed by a hash of the case's data; missing entries are computed on the
  first request (in a pool of ``SOFTPLAN_ORACLE_WORKERS`` spawned processes,
  default 2; 0 = in this process) and written back. ``<cache>`` is
  ``$SOFTPLAN_CACHE_DIR`` or ``.cache/`` at the repository root (git-ignored).
  A changed oracle gets a new file name, so stale answers are never read.

Case families (``which``):

* ``"main"``: ~1000 cases: generic random arms and polynomial curves (n = 1..4
  segments, degree 1..3, theta = 0 / 1e-12 / large), constructed touching,
  crossing and parallel cases, minima on the boundary, long Sim2-like curves;
* ``"paper"``: 20 arms per obstacle of the paper's Tables 2-4 (the tree: the
  four legible branches plus the trunk X = 1, Y = 1, Z = u, u in [0, 3]);
* ``"helix"``: 40 arms against the helix (cos u, sin u, 0.2 u), u in [-3, 3]
  (a non-polynomial curve: the library side is a ``ParametricCurve``);
* ``"grad_fd"``: the central-difference neighbours (h = ``FD_H``) of the 8
  gradient cases (:func:`gradient_cases`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from functools import cache
from typing import NamedTuple

import numpy as np
import oracle

TOL = 1e-9  # the suite's bar: |distance - oracle| <= TOL (float64) in every case
N_RANDOM = 470  # generic random cases; other families are added below
HELIX_RANGE = (-3.0, 3.0)  # helix (cos u, sin u, 0.2 u): oracle.helix's defaults
FD_H = 1e-6  # central-difference step of the gradient checks
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# --------------------------------------------------------------------------
# case generation
# --------------------------------------------------------------------------


@dataclasses.dataclass
class Case:
    kind: str
    q: np.ndarray  # (n, 3)
    coeffs: np.ndarray  # (3, K)
    u_range: tuple
    expected: float | None = None  # known upper bound / value when constructed
    exact: bool = False  # expected is exact

    def ocurve(self):
        return oracle.OPoly(self.coeffs, *self.u_range)

    def describe(self):
        return (
            f"kind={self.kind} q=np.array({self.q.tolist()!r}), "
            f"coeffs=np.array({self.coeffs.tolist()!r}), u_range={self.u_range!r}"
        )


def sample_theta(rng):
    r = rng.random()
    if r < 0.12:
        return 0.0
    if r < 0.22:
        return float(rng.choice([1e-12, -1e-12]))
    if r < 0.27:
        return float(rng.choice([1e-8, -1e-6, 1e-4, -1e-4]))
    if r < 0.45:
        return float(rng.uniform(-6.0, -0.3))
    if r < 0.55:
        return float(rng.uniform(4.0, 6.0) * rng.choice([-1, 1]))
    return float(rng.uniform(-3.0, 3.0))


def random_q(rng, n, L_range=(0.3, 2.0)):
    return np.array(
        [[rng.uniform(*L_range), sample_theta(rng), rng.uniform(-np.pi, np.pi)] for _ in range(n)]
    )


def arm_geometry(q, i, s):
    """Point, unit tangent, unit 'outward' normal (away from the arc centre)."""
    F, dF, ddF = oracle.segment_point_derivs(q, i, [s])
    p, T = F[0], dF[0] / np.linalg.norm(dF[0])
    if np.linalg.norm(ddF[0]) > 1e-9:
        N = -ddF[0] / np.linalg.norm(ddF[0])  # outward (convex side)
    else:
        N = None
    return p, T, N


def unit_perp(rng, v):
    w = rng.normal(size=3)
    w -= (w @ v) * v
    return w / np.linalg.norm(w)


def poly_from_local(p0, t1, t2, t3, u_star, degree=3):
    """coeffs (3, degree+1) of c(u) = p0 + t1 (u-u*) + t2 (u-u*)^2 + t3 (u-u*)^3,
    the terms above `degree` dropped BEFORE expanding (so c(u*) = p0 always)."""
    P = np.polynomial.polynomial
    coeffs = np.zeros((3, degree + 1))
    for dim in range(3):
        base = np.array([p0[dim]])
        for k, tk in enumerate((t1, t2, t3)[:degree], start=1):
            base = P.polyadd(base, tk[dim] * P.polypow([-u_star, 1.0], k))
        coeffs[dim, : len(base)] = base
    return coeffs


def make_random_case(rng, n=None):
    n = int(rng.integers(1, 5)) if n is None else n
    q = random_q(rng, n)
    degree = int(rng.integers(1, 4))
    i = int(rng.integers(0, n))
    p = oracle.segment_point(q, i, rng.uniform())
    centre = p + rng.normal(size=3) * rng.choice([0.05, 0.3, 1.0])
    long = rng.random() < 0.5
    if long:
        a, b = np.sort(rng.uniform(-3, 3, 2))
        if b - a < 1.0:
            a, b = a - 0.5, b + 0.5
        scale = [1.0, rng.choice([0.3, 1.0, 5.0]), rng.choice([0.1, 0.3, 1.0])]
    else:
        mid = rng.uniform(-1, 1)
        half = rng.uniform(0.02, 0.08)
        a, b = mid - half, mid + half
        scale = [1.0, rng.choice([0.3, 1.0, 5.0]), 1.0]
    coeffs = np.zeros((3, degree + 1))
    for k in range(1, degree + 1):
        coeffs[:, k] = rng.normal(size=3) * scale[k - 1]
    umid = 0.5 * (a + b)
    cmid = sum(coeffs[:, k] * umid**k for k in range(1, degree + 1))
    coeffs[:, 0] = centre - cmid
    return Case("random", q, coeffs, (float(a), float(b)))


def make_touch_case(rng, n=None, delta=None):
    """Curve passing delta (1e-6..1e-3) off an arm point, on the convex side.

    For the touched segment alone the distance is exactly delta: the curve's
    offset along the outward normal is delta + a (u-u*)^2 (a >= 0) and the arc
    lies on the other side of its tangent plane.
    """
    n = int(rng.integers(1, 5)) if n is None else n
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    s = float(rng.choice([rng.uniform(0.05, 0.95), 0.0, 1.0], p=[0.8, 0.1, 0.1]))
    p, T, N = arm_geometry(q, i, s)
    nrm = N if N is not None else unit_perp(rng, T)
    delta = float(10 ** rng.uniform(-6, -3)) if delta is None else delta
    t1 = unit_perp(rng, nrm) * rng.uniform(0.5, 2.0)
    t3 = unit_perp(rng, nrm) * rng.uniform(0, 1.0)
    t2 = nrm * rng.uniform(0, 2.0) + unit_perp(rng, nrm) * rng.uniform(0, 1.0)
    degree = int(rng.integers(1, 4))
    u_star = float(rng.uniform(-1, 1))
    where = rng.random()
    if where < 0.6:
        a, b = u_star - rng.uniform(0.05, 1.5), u_star + rng.uniform(0.05, 1.5)
    elif where < 0.8:
        a, b = u_star, u_star + rng.uniform(0.05, 1.5)  # minimum at u0
    else:
        a, b = u_star - rng.uniform(0.05, 1.5), u_star  # minimum at u1
    coeffs = poly_from_local(p + delta * nrm, t1, t2, t3, u_star, degree)
    # with s at an end of the segment the curve may get closer to a
    # neighbouring segment, so the constructed value is an upper bound
    exact = n == 1 and 0 < s < 1
    return Case("touch", q, coeffs, (a, b), expected=delta, exact=exact)


def make_cross_case(rng):
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    s = float(rng.uniform(0.0, 1.0))
    p, T, _ = arm_geometry(q, i, s)
    t1 = rng.normal(size=3)
    t2 = rng.normal(size=3) * rng.uniform(0, 2)
    t3 = rng.normal(size=3) * rng.uniform(0, 0.5)
    degree = int(rng.integers(1, 4))
    u_star = float(rng.uniform(-1, 1))
    a, b = u_star - rng.uniform(0.05, 1.0), u_star + rng.uniform(0.05, 1.0)
    coeffs = poly_from_local(p, t1, t2, t3, u_star, degree)
    return Case("cross", q, coeffs, (a, b), expected=0.0)


def make_parallel_case(rng):
    """A straight line (nearly) parallel to a straight arm segment."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    q[i, 1] = float(rng.choice([0.0, 1e-12, 0.0]))
    s = float(rng.uniform(0.2, 0.8))
    p, T, _ = arm_geometry(q, i, s)
    nrm = unit_perp(rng, T)
    m = unit_perp(rng, T)
    delta = float(10 ** rng.uniform(-6, -2))
    alpha = float(rng.choice([0.0, 1e-9, 1e-6, 1e-4, 1e-2]))
    direction = np.cos(alpha) * T + np.sin(alpha) * m
    half = rng.uniform(0.05, 1.5) * q[i, 0]
    u_star = float(rng.uniform(-0.5, 0.5))
    coeffs = poly_from_local(p + delta * nrm, direction, 0 * T, 0 * T, u_star, 1)
    shift = rng.uniform(-0.5, 0.5) * half
    return Case("parallel", q, coeffs, (u_star - half + shift, u_star + half + shift), expected=delta)


def make_boundary_case(rng):
    """Minima on the boundary: beyond the tip / below the base / past u ends."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    degree = int(rng.integers(1, 4))
    kind = rng.choice(["tip", "tip_pair", "base_pair", "u_end"])
    d = float(10 ** rng.uniform(-5, -0.5))
    if kind in ("tip", "tip_pair"):
        p, T, _ = arm_geometry(q, n - 1, 1.0)
        if kind == "tip":  # line across the tangent ray beyond the tip
            m = unit_perp(rng, T)
            coeffs = poly_from_local(p + d * T, m, 0.3 * unit_perp(rng, T) * rng.random(), 0 * T, 0.0, degree)
            a, b = -rng.uniform(0.1, 1), rng.uniform(0.1, 1)
        else:  # a curve starting beyond the tip and leaving it: endpoint pair
            e = T + 0.3 * unit_perp(rng, T)
            e /= np.linalg.norm(e)
            coeffs = poly_from_local(p + d * e, e * rng.uniform(0.5, 2), 0.2 * e, 0 * T, 0.0, degree)
            a, b = 0.0, rng.uniform(0.1, 2)
    elif kind == "base_pair":  # below the base, pointing down: (s=0, u=u0)
        e = np.array([0.0, 0.0, -1.0]) + 0.3 * np.append(rng.normal(size=2), 0)
        e /= np.linalg.norm(e)
        coeffs = poly_from_local(d * e, e * rng.uniform(0.5, 2), 0.1 * e, 0 * e, 0.0, degree)
        a, b = 0.0, rng.uniform(0.1, 2)
    else:  # the foot of the perpendicular lies past u1: minimum at u = u1
        i = int(rng.integers(0, n))
        s = float(rng.uniform(0.1, 0.9))
        p, T, N = arm_geometry(q, i, s)
        nrm = N if N is not None else unit_perp(rng, T)
        t1 = unit_perp(rng, nrm)
        coeffs = poly_from_local(p + d * nrm, t1, 0.2 * unit_perp(rng, nrm), 0 * t1, 0.0, degree)
        off = rng.uniform(0.01, 0.3)
        a, b = -off - rng.uniform(0.1, 1), -off
    return Case("boundary_" + str(kind), q, coeffs, (float(a), float(b)))


def make_long_case(rng):
    """Long ranges and large coefficients (Sim2-like X=c, Y=u, Z=5u^2)."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    X0 = rng.uniform(-1.5, 1.5)
    coeffs = np.array(
        [
            [X0, rng.normal() * 0.2, 0.0, 0.0],
            [rng.normal() * 0.3, 1.0, 0.0, 0.0],
            [rng.uniform(-1, 2), rng.normal() * 0.5, rng.choice([5.0, -5.0, 3.0]), rng.normal()],
        ]
    )
    span = rng.uniform(1, 3)
    return Case("long", q, coeffs[:, : int(rng.integers(3, 5))].copy(), (-span, span))


# The paper's obstacles (Tables 2-4; the tree uses the four legible branches
# plus the trunk X=1, Y=1, Z=u, u in [0, 3], as DESIGN.md prescribes).
PAPER_OBSTACLES = {
    "sim1": (np.array([[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]]), (-2.0, 2.0)),
    "sim2": (np.array([[0.5, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 5.0]]), (-2.0, 2.0)),
    "branch1": (np.array([[1.0, -0.2, 0.0], [1.0, -1.0, 0.0], [2.0, 0.0, -1.0]]), (0.0, 1.0)),
    "branch2": (np.array([[1.0, -0.5, 0.0], [1.0, 1.0, -1.0], [1.7, 0.3, 0.0]]), (0.0, 1.5)),
    "branch3": (np.array([[1.0, 1.0, -1.0], [1.0, -1.0, 0.0], [2.0, -0.1, 0.0]]), (0.0, 1.5)),
    "branch4": (np.array([[1.0, 0.0], [1.0, -1.0], [1.5, 0.1]]), (0.0, 1.5)),
    "trunk": (np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), (0.0, 3.0)),
}


def paper_configs(rng, count):
    out = []
    for k in range(count):
        q = np.array(
            [[rng.uniform(0.7, 1.3), sample_theta(rng), rng.uniform(-np.pi, np.pi)] for _ in range(3)]
        )
        if k == 0:
            q[:, 1] = 0.0  # the straight start
        out.append(q)
    return out


def build_cases():
    rng = np.random.default_rng(20240601)
    out = [make_random_case(rng) for _ in range(N_RANDOM)]
    out += [make_touch_case(rng) for _ in range(150)]
    out += [make_cross_case(rng) for _ in range(80)]
    out += [make_parallel_case(rng) for _ in range(80)]
    out += [make_boundary_case(rng) for _ in range(140)]
    out += [make_long_case(rng) for _ in range(60)]
    return out


@cache
def main_cases() -> tuple:
    """The ~1000 main cases (seeded; built once)."""
    return tuple(build_cases())


@cache
def paper_cases() -> tuple:
    return tuple(
        Case("paper_" + name, q, coeffs, u_range)
        for name, (coeffs, u_range) in PAPER_OBSTACLES.items()
        for q in paper_configs(np.random.default_rng(sum(map(ord, name))), 20)
    )


@cache
def helix_qs() -> tuple:
    return tuple(paper_configs(np.random.default_rng(77), 40))


@cache
def helix_cases() -> tuple:
    """The helix cases carry only q (and the helix's u_range; coeffs are a placeholder)."""
    return tuple(Case("helix", q, np.zeros((3, 1)), HELIX_RANGE) for q in helix_qs())


def ocurve(which: str, case: Case):
    """The oracle's curve of a case of family ``which``."""
    if which == "helix":
        return oracle.helix(*HELIX_RANGE)
    return case.ocurve()


# ---- gradient cases (n = 3, some/all theta = 0 exactly)


def _isolated(o, q, curve, gap=2e-3):
    """The minimum is unique: every candidate within `gap` of it is the same point."""
    A = oracle.segment_point(q, o.segment, o.s)
    for d, i, s, u in o.candidates:
        if d > o.distance + gap:
            break
        Ai = oracle.segment_point(q, i, s)
        Ci = curve.point(np.array([u]))[0]
        if np.linalg.norm(Ai - A) > 1e-4 or np.linalg.norm(Ci - o.obstacle_point) > 1e-4:
            return False
    return True


def _select_gradient_cases(accept):
    """Draw random n = 3 cases until 8 are accepted (``accept(case) -> bool``:
    a unique minimum at least 0.05 away). Returns [(case, accepted?) for every draw].
    """
    rng = np.random.default_rng(4242)
    draws, accepted = [], 0
    while accepted < 8:
        case = make_random_case(rng, n=3)
        if accepted >= 4:  # theta = 0 exactly in some / all segments
            case.q[:, 1] = np.where(rng.random(3) < 0.7, 0.0, case.q[:, 1])
            if accepted == 7:
                case.q[:, 1] = 0.0
        ok = accept(case)
        draws.append((case, ok))
        accepted += ok
    return draws


@cache
def gradient_cases() -> tuple:
    """8 (case, oracle answer) pairs: n = 3, an isolated minimum >= 0.05 away,
    the last four with theta = 0 exactly in some or all segments.

    The choice needs the oracle (with its candidates); which draws were taken
    is cached on disk like the answers (keyed by this module's and the
    oracle's source).
    """
    path = _cache_path("grad_select", _source_hash(inspect.getsource(sys.modules[__name__])))
    taken = None
    if os.path.exists(path):
        with np.load(path) as z:
            taken = z["accepted"].tolist()
    flags = []

    def accept(case):
        k = len(flags)
        flags.append(bool(taken[k]) if taken is not None and k < len(taken) else _accept(case))
        return flags[-1]

    draws = _select_gradient_cases(accept)
    if taken != flags:
        _atomic_savez(path, accepted=np.array(flags, bool))
    chosen = [c for c, ok in draws if ok]
    return tuple(zip(chosen, oracle_answers("grad", chosen), strict=True))


def _accept(case) -> bool:
    o = oracle.closest_point(case.q, case.ocurve())
    return bool(o.distance >= 0.05 and _isolated(o, case.q, case.ocurve()))


def fd_qs(q):
    """(2 * 3n, n, 3): q + h e_k for every k, then q - h e_k (h = FD_H)."""
    n = q.shape[0]
    E = np.eye(3 * n).reshape(3 * n, n, 3) * FD_H
    return np.concatenate([q + E, q - E])


@cache
def grad_fd_cases() -> tuple:
    """The central-difference neighbours of the gradient cases, case by case."""
    return tuple(
        Case("grad_fd", qq, case.coeffs, case.u_range) for case, _ in gradient_cases() for qq in fd_qs(case.q)
    )


def cases(which: str) -> tuple:
    """The cases of family ``which``: "main", "paper", "helix" or "grad_fd"."""
    makers = {"main": main_cases, "paper": paper_cases, "helix": helix_cases, "grad_fd": grad_fd_cases}
    if which not in makers:
        raise KeyError(f"unknown case family {which!r}; choose one of {sorted(makers)}")
    return makers[which]()


# --------------------------------------------------------------------------
# the oracle's answers, cached on disk
# --------------------------------------------------------------------------


class Answer(NamedTuple):
    """The oracle's closest point for one case (its candidates dropped)."""

    distance: float
    segment: int
    s: float
    u: float
    arm_point: np.ndarray  # (3,)
    obstacle_point: np.ndarray  # (3,)


_FIELDS = Answer._fields


def cache_dir() -> str:
    """Where cached answers live: $SOFTPLAN_CACHE_DIR/oracle or <repo>/.cache/oracle."""
    root = os.environ.get("SOFTPLAN_CACHE_DIR") or os.path.join(REPO, ".cache")
    return os.path.join(root, "oracle")


def _source_hash(*extra: str) -> str:
    h = hashlib.sha256(inspect.getsource(oracle).encode())
    for e in extra:
        h.update(e.encode())
    return h.hexdigest()[:16]


def _cache_path(which: str, key: str) -> str:
    return os.path.join(cache_dir(), f"{which}-{key}.npz")


def case_key(which: str, case: Case) -> str:
    """A hash of the case's data (q, coeffs, u_range) and its family."""
    h = hashlib.sha256(which.encode())
    for a in (case.q, case.coeffs, np.asarray(case.u_range)):
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    return h.hexdigest()[:24]


def _atomic_savez(path: str, **arrays) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.{os.getpid()}.tmp.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _read(path: str) -> dict:
    if not os.path.exists(path):
        return {}
    try:
        with np.load(path) as z:
            cols = [z[f] for f in _FIELDS]
            keys = z["keys"].tolist()
    except (OSError, ValueError, KeyError):  # a damaged file: recompute
        return {}
    return {
        k: Answer(float(cols[0][j]), int(cols[1][j]), float(cols[2][j]), float(cols[3][j]), cols[4][j], cols[5][j])
        for j, k in enumerate(keys)
    }


def _write(path: str, table: dict) -> None:
    keys = sorted(table)
    cols = {f: np.array([getattr(table[k], f) for k in keys]) for f in _FIELDS}
    _atomic_savez(path, keys=np.array(keys), **cols)


def _answer_many(jobs):
    """[(q, curve), ...] -> [Answer, ...] (one task of the process pool)."""
    out = []
    for q, c in jobs:
        o = oracle.closest_point(q, c)
        out.append(Answer(o.distance, int(o.segment), float(o.s), float(o.u), o.arm_point, o.obstacle_point))
    return out


def _compute(jobs, workers: int):
    if workers <= 0 or len(jobs) < 32:
        return _answer_many(jobs)
    batch = 16
    # The oracle calls scipy.optimize thousands of times on tiny problems:
    # one BLAS thread per worker (multi-threaded BLAS is ~4x slower here).
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
    except Exception:  # noqa: BLE001 - no subprocesses here: compute serially
        return _answer_many(jobs)
    with pool:
        futures = [pool.submit(_answer_many, jobs[k : k + batch]) for k in range(0, len(jobs), batch)]
        return [a for f in futures for a in f.result()]


def oracle_answers(which: str, subset=None) -> list:
    """The oracle's :class:`Answer` for every case of family ``which`` (or for
    the cases ``subset``, all of that family; "grad" holds the gradient cases),
    from the disk cache; missing answers are computed (see the module
    docstring) and added to it.
    """
    todo = list(cases(which) if subset is None else subset)
    path = _cache_path(which, _source_hash())
    table = _read(path)
    keys = [case_key(which, c) for c in todo]
    missing = {k: c for k, c in zip(keys, todo, strict=True) if k not in table}
    if missing:
        workers = int(os.environ.get("SOFTPLAN_ORACLE_WORKERS", "2"))
        t0 = time.perf_counter()
        jobs = [(c.q, ocurve(which, c)) for c in missing.values()]
        table.update(zip(missing, _compute(jobs, workers), strict=True))
        table.update(_read(path))  # keep what another process wrote meanwhile
        _write(path, table)
        print(
            f"closest_cases: {len(missing)} oracle answers for {which!r} computed in "
            f"{time.perf_counter() - t0:.0f} s, cached in {path}",
            file=sys.stderr,
        )
    return [table[k] for k in keys]


def oracle_distances(which: str, subset=None) -> np.ndarray:
    """(m,) oracle distances of :func:`oracle_answers`."""
    return np.array([a.distance for a in oracle_answers(which, subset)])
