"""The closest-point case corpus and the oracle's answers, cached on disk (shared by
``tests/test_closest.py`` and ``benchmarks/closest.py``; like :mod:`.oracle` it imports no
other module of ``softplan_jax``, not jax and nothing under ``tests/``, and importing it does
nothing but define names): :func:`cases` builds a family on first use, :func:`oracle_answers`
reads the oracle's answers from a cache keyed by the oracle's source and computes the missing
ones."""

from __future__ import annotations

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

from . import case_makers, oracle, oracle_geometry
from .case_makers import (
    N_RANDOM,
    PAPER_OBSTACLES,
    Case,
    arm_geometry,
    build_cases,
    make_boundary_case,
    make_cross_case,
    make_long_case,
    make_parallel_case,
    make_random_case,
    make_touch_case,
    paper_configs,
    poly_from_local,
    random_q,
    sample_theta,
    unit_perp,
)

__all__ = [
    "TOL", "N_RANDOM", "HELIX_RANGE", "FD_H", "REPO",
    # case generation (the generators are case_makers')
    "Case", "sample_theta", "random_q", "arm_geometry", "unit_perp", "poly_from_local", "make_random_case",
    "make_touch_case", "make_cross_case", "make_parallel_case", "make_boundary_case", "make_long_case",
    "PAPER_OBSTACLES", "paper_configs", "build_cases", "main_cases", "paper_cases", "helix_qs", "helix_cases",
    "ocurve", "gradient_cases", "fd_qs", "grad_fd_cases", "cases",
    # the oracle's answers, cached on disk
    "Answer", "cache_dir", "case_key", "oracle_answers", "oracle_distances",
]

TOL = 1e-9  # the suite's bar: |distance - oracle| <= TOL (float64) in every case
HELIX_RANGE = (-3.0, 3.0)  # helix (cos u, sin u, 0.2 u): oracle.helix's defaults
FD_H = 1e-6  # central-difference step of the gradient checks
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # above softplan_jax/testing/

# --------------------------------------------------------------------------
# the case families
# --------------------------------------------------------------------------


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
    is cached on disk like the answers (keyed by this module's, the case
    generators' and the oracle's source).
    """
    path = _cache_path("grad_select", _source_hash(inspect.getsource(sys.modules[__name__]),
                                                   inspect.getsource(case_makers)))
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
    """The cases of family ``which`` (built on first use, functools.cache):

    * ``"main"``: ~1000 cases: generic random arms and polynomial curves (n = 1..4 segments,
      degree 1..3, theta = 0 / 1e-12 / large), constructed touching, crossing and parallel
      cases, minima on the boundary, long Sim2-like curves;
    * ``"paper"``: 20 arms per obstacle of the paper's Tables 2-4 (the tree: the four legible
      branches plus the trunk X = 1, Y = 1, Z = u, u in [0, 3]);
    * ``"helix"``: 40 arms against the helix (cos u, sin u, 0.2 u), u in [-3, 3] (a
      non-polynomial curve: the library side is a ``ParametricCurve``);
    * ``"grad_fd"``: the central-difference neighbours (h = ``FD_H``) of the 8 gradient cases
      (:func:`gradient_cases`).
    """
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
    """A hash of the oracle's source (both its modules) and of ``extra``."""
    h = hashlib.sha256(inspect.getsource(oracle).encode())
    h.update(inspect.getsource(oracle_geometry).encode())
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
    from the disk cache ``<cache>/oracle/<which>-<hash of the oracle's source>.npz``, one
    entry per case keyed by a hash of the case's data (``<cache>``: ``$SOFTPLAN_CACHE_DIR``
    or ``.cache/`` at the repository root, git-ignored; a changed oracle gets a new file
    name, so stale answers are never read). Missing answers are computed in a pool of
    ``SOFTPLAN_ORACLE_WORKERS`` spawned processes (default 2; 0 = in this process) and
    written back.
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
