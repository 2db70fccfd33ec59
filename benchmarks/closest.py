"""Closest-point benchmark: curve method vs N-point method, and the SolverOptions sweep.

Two parts, one run, one report (``benchmarks/results/closest.md`` and ``.json``;
``--quick`` writes ``results/quick/closest.*`` so it never overwrites the full report):

1. Speed. One closest-point query (3 segments x 1 curve) and a vmapped batch of
   10^4 queries, in float64 and float32 (x64 on; the float32 rows cast q, the
   curve and the points to float32), for

   * the curve method, ``curve_closest(q, curve, options)`` (paper §2.3),
   * the N-point method with N = 10 and N = 100 obstacle points,
     ``points_closest(q, curve_points(curve, N), mask, 10)`` (the
     obstacle points are the obstacle model, made once outside the timing).

   Queries: the paper's Sim2 parabola (X = 0.5, Y = u, Z = 5u^2, u in [-2, 2])
   and random cubics; the batch takes random q with the Sim2 curve fixed or
   with a random cubic per query (float32: random cubics only). Compile time
   (``jax.jit(f).lower(...).compile()``) is reported apart; run time is the median of repeats of the compiled
   function with ``block_until_ready``. Curve and N-point functions are timed
   round-robin in the same loop, so the ratios (curve / 10-point,
   curve / 100-point) hold on a shared, noisy machine better than the absolute
   times.

2. Accuracy sweep over ``SolverOptions`` candidates on the test suite's cases
   (``softplan_jax/testing/closest_cases.py``: the ~1000 main cases, the paper
   obstacles and the helix), against the independent NumPy/SciPy oracle
   (``softplan_jax/testing/oracle.py``); ``tests/test_closest.py`` uses the same
   two modules. A miss is |distance - oracle| > 1e-9 (the suite's bar; NaN is a
   miss). Each candidate also gets its single-query and batch times (float64),
   next to the 10-point method's timed in the same loop. The oracle's answers
   are cached on disk by ``closest_cases`` (in ``.cache/oracle/``, keyed by the
   case data and the oracle's source, shared with the tests), so reruns skip
   the slow part.

The fields of ``SolverOptions`` are read at run time (``SolverOptions._fields``
and its defaults); a candidate is written as overrides of the defaults,
``field=value,...``, and candidates are separated by ``;``::

    python benchmarks/closest.py            # full: ~11 CPU-minutes, 19 min wall on 2 CPUs at load 6-9
    python benchmarks/closest.py --quick    # ~50 CPU-seconds (90 s wall at load 5-7): default options only
    python benchmarks/closest.py --candidates "default; iterations=6; starts=2,edge_starts=1"

Compiling dominates (10-15 s per shape and SolverOptions on a loaded 2-CPU
machine); the default candidate list (``default_candidates_spec``) is built
from the current defaults: one knob at a time cheaper, one setting dearer.

Progress goes to stderr; the markdown report is printed to stdout at the end.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import os
import platform
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

import softplan_jax as sp
from softplan_jax.geometry._closest import (
    SolverOptions,
    curve_closest,
)
from softplan_jax.geometry._closest_grid import GridSolverOptions
from softplan_jax.geometry._curves import PolynomialCurve, curve_points
from softplan_jax.geometry._point_sets import points_closest
from softplan_jax.testing import closest_cases as cc

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS_DIR = os.path.join(REPO, "benchmarks", "results")
TOL = cc.TOL  # the suite's bar, 1e-9
CHUNK = 64  # cases per library call (as tests/test_closest.py): one compiled shape per n
ARM_SAMPLES = 10  # points per segment of the N-point method (paper Table 1)

# The grid fields, scaled together (paper §2.3 starts come from the grid).
GRID_FIELDS = ("grid_s", "grid_u")


def default_candidates_spec() -> str:
    """The default candidate list, made from the SolverOptions defaults read at run time.

    For the default solver (``SolverOptions``): cheaper settings one knob at
    a time (Newton iterations in u x 1/2 and x 3/4, one start fewer, the grid x
    3/4, the profile's polishing steps halved), one dearer setting (every knob
    up by half), and the paper's 2-D solver (``grid``: ``GridSolverOptions()``) as the
    reference. The full run then adds the combination of the cheapest zero-miss
    changes (``combined_candidate``). Each candidate costs ~7 compiles (one per
    arm size n, the helix, the two timed functions): 1-2 min on 2 shared CPUs.
    """
    d = {k: v for k, v in _option_defaults().items() if isinstance(v, int) and not isinstance(v, bool)}
    items = ["default"]

    def add(**kw):
        if kw and all(v >= 1 for v in kw.values()):
            items.append(",".join(f"{k}={v}" for k, v in kw.items()))

    its, starts = "iterations", "starts"
    knobs = tuple(d)
    add(**{its: max(1, d[its] // 2)})
    add(**{its: max(1, (3 * d[its]) // 4)})
    add(**{starts: d[starts] - 1})
    if "edge_starts" in knobs:
        add(edge_starts=d["edge_starts"] - 1)
    add(**{k: max(3, (3 * d[k]) // 4) for k in GRID_FIELDS})
    for k in knobs:
        if k not in (its, starts, "edge_starts", *GRID_FIELDS) and d[k] > 1:
            add(**{k: d[k] // 2})
    add(**{k: d[k] + max(1, d[k] // 2) for k in knobs})
    items.append("grid")
    return "; ".join(items)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------
# SolverOptions candidates.


def _option_defaults() -> dict:
    """SolverOptions fields and defaults as they are now (read at run time)."""
    return {f: SolverOptions._field_defaults.get(f) for f in SolverOptions._fields}


def _parse_value(text: str, default):
    if isinstance(default, bool):
        if text.lower() in ("1", "true", "yes"):
            return True
        if text.lower() in ("0", "false", "no"):
            return False
        raise ValueError(f"not a bool: {text!r}")
    if isinstance(default, int):
        return int(text)
    if isinstance(default, float):
        return float(text)
    return text


def parse_candidates(spec: str, strict: bool) -> tuple[list[tuple[str, SolverOptions]], list[str]]:
    """Parse ``"default; field=v,field=v; ..."`` into (label, SolverOptions) pairs.

    strict: unknown fields are an error (user input); otherwise they are dropped
    with a note (the built-in list, written before the fields may have changed).
    Returns (candidates without duplicates, notes).
    """
    defaults = _option_defaults()
    out, notes, seen = [], [], set()
    for item in (s.strip() for s in spec.split(";")):
        if not item:
            continue
        if item == "grid":  # the paper's 2-D solver with its defaults
            opts = GridSolverOptions()
            if opts not in seen:
                seen.add(opts)
                out.append(("grid (the paper's 2-D solver)", opts))
            continue
        overrides = {}
        if item != "default":
            for kv in (p.strip() for p in item.split(",") if p.strip()):
                if "=" not in kv:
                    raise ValueError(f"candidate {item!r}: expected field=value, got {kv!r}")
                key, val = (x.strip() for x in kv.split("=", 1))
                if key not in defaults:
                    msg = f"candidate {item!r}: SolverOptions has no field {key!r} (fields: {list(defaults)})"
                    if strict:
                        raise ValueError(msg)
                    notes.append(msg + "; dropped")
                    continue
                try:
                    overrides[key] = _parse_value(val, defaults[key])
                except ValueError as err:
                    raise ValueError(f"candidate {item!r}: bad value for {key}: {err}") from None
        opts = SolverOptions(**{**defaults, **overrides})
        if opts in seen:
            continue
        seen.add(opts)
        label = (
            "default"
            if opts == SolverOptions()
            else ",".join(f"{k}={v}" for k, v in opts._asdict().items() if v != defaults[k])
        )
        out.append((label, opts))
    if not out:
        raise ValueError(f"no candidates in {spec!r}")
    return out, notes


# ----------------------------------------------------------------------------
# Compiling and timing.

_COMPILED: dict = {}


def _signature(args) -> tuple:
    leaves, treedef = jax.tree_util.tree_flatten(args)
    return (treedef, tuple((tuple(np.shape(x)), str(jnp.result_type(x))) for x in leaves))


def compile_once(tag, fn, args):
    """``jax.jit(fn).lower(*args).compile()``, memoised on (tag, argument shapes and dtypes).

    tag names the function (and its static settings). Returns (compiled,
    compile seconds of the first compile, whether this call reused it).
    """
    key = (tag, _signature(args))
    if key in _COMPILED:
        return (*_COMPILED[key], True)
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    _COMPILED[key] = (compiled, time.perf_counter() - t0)
    return (*_COMPILED[key], False)


def time_round_robin(entries: dict, repeats: int) -> dict:
    """Median run time of compiled functions, timed in turn in one loop.

    entries: name -> (compiled, args). One warm-up call each, then ``repeats``
    rounds; every call is blocked on (``block_until_ready``).
    Returns name -> dict(median_s, min_s, repeats).
    """
    for compiled, args in entries.values():
        jax.block_until_ready(compiled(*args))
    times = {k: [] for k in entries}
    for _ in range(repeats):
        for name, (compiled, args) in entries.items():
            t0 = time.perf_counter()
            jax.block_until_ready(compiled(*args))
            times[name].append(time.perf_counter() - t0)
    return {
        k: dict(median_s=float(np.median(v)), min_s=float(np.min(v)), repeats=repeats)
        for k, v in times.items()
    }


def _curve_fn(options):
    """(q (n, 3), curve) -> ClosestPoint: one query, curve method (paper §2.3)."""
    return lambda q, curve: curve_closest(q, curve, options)


def _points_fn(q, points, mask):
    """(q (n, 3), points (N, 3), mask (N,)) -> ClosestPoint: N-point method."""
    return points_closest(q, points, mask, ARM_SAMPLES)


def _batched(fn, shared_obstacle: bool, n_obstacle_args: int):
    """vmap over q (axis 0), and over the obstacle arguments unless they are shared."""
    axis = None if shared_obstacle else 0
    return jax.vmap(fn, in_axes=(0,) + (axis,) * n_obstacle_args)


def sim2_curve() -> PolynomialCurve:
    """The paper's Sim2 parabola X = 0.5, Y = u, Z = 5u^2, u in [-2, 2], padded to degree 3
    (as ``stack_curves`` pads a scene), so it shares its compiled shape with the cubics."""
    coeffs, u_range = cc.PAPER_OBSTACLES["sim2"]
    padded = np.zeros((3, 4))
    padded[:, : coeffs.shape[1]] = coeffs
    return PolynomialCurve(jnp.asarray(padded), jnp.asarray(u_range))


def random_cubics(rng, count: int) -> PolynomialCurve:
    """count random cubics (coeffs (count, 3, 4)), u in [-1, 1], centred near the arms' reach."""
    coeffs = rng.normal(size=(count, 3, 4)) * np.array([0.7, 1.0, 0.5, 0.3])
    coeffs[:, 2, 0] += 1.5
    u_range = np.tile([-1.0, 1.0], (count, 1))
    return PolynomialCurve(jnp.asarray(coeffs), jnp.asarray(u_range))


def random_qs(rng, count: int, n: int = 3) -> np.ndarray:
    """count configurations from the test suite's generator (theta = 0, tiny, large ...)."""
    return np.stack([cc.random_q(rng, n) for _ in range(count)])


def _points_of(curve, N: int, batched: bool):
    """Obstacle points (N evenly spaced in u, ``curve_points``) and an all-True mask."""
    pts = jax.vmap(lambda c: curve_points(c, N))(curve) if batched else curve_points(curve, N)
    return pts, jnp.ones(pts.shape[:-1], bool)


def speed_table(options: SolverOptions, batch: int, repeats: dict, quick: bool, seed: int = 0):
    """Part 1: curve vs 10- and 100-point, single and batch, float64 and float32."""
    rng = np.random.default_rng(seed)
    q1 = jnp.asarray(random_qs(rng, 1)[0])
    cubic1 = jax.tree_util.tree_map(lambda x: x[0], random_cubics(rng, 1))
    qs = jnp.asarray(random_qs(rng, batch))
    cubics = random_cubics(rng, batch)
    sim2 = sim2_curve()
    # (kind, label, q, curve, batched, obstacle shared by the batch)
    queries = [
        ("single", "Sim2 parabola", q1, sim2, False, True),
        ("single", "random cubic", q1, cubic1, False, True),
        (f"batch {batch}", "random q, Sim2 fixed", qs, sim2, True, True),
        (f"batch {batch}", "random q, random cubics", qs, cubics, True, False),
    ]
    # float32: the fixed-curve batch is left out (one compile less; the random
    # cubics batch says the same). quick: float64, one single and one batch row.
    plan = [(jnp.float64, queries), (jnp.float32, [queries[0], queries[1], queries[3]])]
    if quick:
        plan = [(jnp.float64, [queries[0], queries[3]])]
    rows = []
    for dtype, dtype_queries in plan:
        for kind, label, q, curve, is_batch, shared in dtype_queries:
            q_d, curve_d = q.astype(dtype), curve.astype(dtype)
            methods = [("curve", ("curve", options), _curve_fn(options), (q_d, curve_d), 1)]
            for N in (10, 100):
                pts, mask = _points_of(curve_d, N, batched=is_batch and not shared)
                methods.append((f"{N}-point", ("points", ARM_SAMPLES), _points_fn, (q_d, pts, mask), 2))
            entries, compile_s = {}, {}
            for name, tag, fn, args, n_obs in methods:
                if is_batch:
                    fn, tag = _batched(fn, shared, n_obs), (*tag, "vmap", shared)
                compiled, secs, reused = compile_once(tag, fn, args)
                entries[name], compile_s[name] = (compiled, args), None if reused else secs
            timed = time_round_robin(entries, repeats["batch" if is_batch else "single"])
            out_dtype = entries["curve"][0](*entries["curve"][1]).distance.dtype
            row = dict(
                dtype=str(np.dtype(dtype)),
                out_dtype=str(out_dtype),
                kind=kind,
                query=label,
                queries_per_call=int(q.shape[0]) if is_batch else 1,
                compile_s=compile_s,
                run=timed,
                ratio_curve_10=timed["curve"]["median_s"] / timed["10-point"]["median_s"],
                ratio_curve_100=timed["curve"]["median_s"] / timed["100-point"]["median_s"],
            )
            rows.append(row)
            med = {k: _fmt_s(v["median_s"]) for k, v in timed.items()}
            _log(
                f"  {row['dtype']} {kind}, {label}: curve {med['curve']}, 10-pt {med['10-point']}, "
                f"100-pt {med['100-point']}; compile {_fmt_c(compile_s['curve'])} / "
                f"{_fmt_c(compile_s['10-point'])} / {_fmt_c(compile_s['100-point'])}"
            )
    return rows


# ----------------------------------------------------------------------------
# Accuracy: the suite's cases, oracle (cached), library per candidate.


def case_sets(quick: bool) -> dict:
    """which -> list of closest_cases.Case (the helix cases carry only q and the helix's u_range).

    quick: a few n = 3 cases (one compiled shape), no helix.
    """
    sets = {w: list(cc.cases(w)) for w in ("main", "paper", "helix")}
    if quick:
        main3 = [c for c in sets["main"] if c.q.shape[0] == 3]
        sets = {"main": main3[::10], "paper": sets["paper"][::10]}
    return sets


def oracle_distances(sets: dict) -> tuple[dict, dict]:
    """which -> (len,) oracle distances, from closest_cases' on-disk cache
    (computed there on a first run). Returns (distances, info on the oracle's time)."""
    t0 = time.perf_counter()
    out = {which: cc.oracle_distances(which, cases) for which, cases in sets.items()}
    info = dict(
        cases=sum(len(v) for v in out.values()),
        oracle_s=time.perf_counter() - t0,
        cache_dir=os.path.relpath(cc.cache_dir(), REPO),
    )
    return out, info


def _helix_fn(u):
    """closest_cases' helix (oracle.helix: radius 1, pitch 0.2), in jax."""
    return jnp.stack([jnp.cos(u), jnp.sin(u), 0.2 * u])


def run_pairwise(qs, coeffs, u_ranges, fn):
    """Library on case k = (qs[k], curve k), all qs of one n, in chunks of CHUNK
    (the last padded by repeating its last case), degree padded to 3.
    Returns one dict of numpy fields per case."""
    qs = np.asarray(qs)
    B = len(qs)
    out = []
    for start in range(0, B, CHUNK):
        idx = list(range(start, min(start + CHUNK, B)))
        idx += [idx[-1]] * (CHUNK - len(idx))
        curves = [sp.PolynomialCurve(np.asarray(coeffs[k]), np.asarray(u_ranges[k])) for k in idx]
        stacked, _ = sp.geometry.stack_curves(curves, degree=3)
        res = fn(jnp.asarray(qs[idx]), stacked)
        res = {f: np.asarray(getattr(res, f)) for f in res._fields}
        out += [{f: v[j] for f, v in res.items()} for j in range(CHUNK)]
    return out[:B]


def _stacked_spec(n: int):
    """Abstract (q, stacked curves) of one ``run_pairwise`` chunk: CHUNK cases, degree 3."""
    f64 = jnp.float64
    q = jax.ShapeDtypeStruct((CHUNK, n, 3), f64)
    curve = PolynomialCurve.tree_unflatten(
        None,
        [
            jax.ShapeDtypeStruct((CHUNK, 3, 4), f64),
            jax.ShapeDtypeStruct((CHUNK, 2), f64),
            jax.ShapeDtypeStruct((CHUNK,), f64),
        ],
    )
    return q, curve


def compile_candidate(options: SolverOptions, sets: dict, timed: dict) -> tuple[dict, float]:
    """Compile everything one candidate needs, two functions at a time in threads.

    Compiling dominates the sweep (XLA compiles outside the GIL, so two threads
    use both CPUs). The accuracy functions are ``sp.closest_point(q, curve,
    options)`` vmapped as the suite runs them: over (q, curve) for the
    ``run_pairwise`` chunks (CHUNK cases, degree padded to 3: one compiled
    shape per n), over q for the helix. ``timed``: name -> (tag, fn, args) of
    the timed functions, compiled too unless ``compile_once`` has them already.
    Returns (name -> compiled, wall seconds spent compiling); the names are the
    arm sizes n, "helix" and the keys of ``timed``.
    """
    pairwise = jax.jit(jax.vmap(lambda q, c: sp.closest_point(q, c, options)))
    per_q = jax.jit(jax.vmap(lambda q, c: sp.closest_point(q, c, options), in_axes=(0, None)))
    ns = sorted({c.q.shape[0] for w, cases in sets.items() if w != "helix" for c in cases})
    lowered = {n: pairwise.lower(*_stacked_spec(n)) for n in ns}
    if "helix" in sets:
        lowered["helix"] = per_q.lower(*_helix_args(sets["helix"]))
    compiled = {}
    for name, (tag, fn, args) in timed.items():
        key = (tag, _signature(args))
        if key in _COMPILED:
            compiled[name] = _COMPILED[key][0]
        else:
            lowered[name] = jax.jit(fn).lower(*args)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(2) as pool:
        compiled |= dict(zip(lowered, pool.map(lambda low: low.compile(), lowered.values()), strict=True))
    t_compile = time.perf_counter() - t0
    for name, (tag, _, args) in timed.items():
        _COMPILED.setdefault((tag, _signature(args)), (compiled[name], None))
    return compiled, t_compile


def _helix_args(cases):
    return jnp.asarray(np.stack([c.q for c in cases])), sp.ParametricCurve(_helix_fn, cc.HELIX_RANGE)


def library_results(sets: dict, compiled: dict) -> dict:
    """which -> dict(distance, converged) from the compiled functions of ``compile_candidate``."""
    out = {}
    for which, cases in sets.items():
        if which == "helix":
            res = compiled["helix"](*_helix_args(cases))
            out[which] = dict(distance=np.asarray(res.distance), converged=np.asarray(res.converged))
            continue
        dist, conv = np.empty(len(cases)), np.empty(len(cases), bool)
        by_n = {}
        for k, c in enumerate(cases):
            by_n.setdefault(c.q.shape[0], []).append(k)
        for n, idx in by_n.items():
            res = run_pairwise(
                [cases[k].q for k in idx],
                [cases[k].coeffs for k in idx],
                [cases[k].u_range for k in idx],
                fn=compiled[n],
            )
            for j, k in enumerate(idx):
                dist[k], conv[k] = res[j]["distance"], res[j]["converged"]
        out[which] = dict(distance=dist, converged=conv)
    return out


def n_point_errors(sets: dict, oracle_d: dict) -> list:
    """Distance error of the N-point method (N = 10, 100) on the polynomial cases, for context."""
    fn = jax.jit(jax.vmap(_points_fn))
    rows = []
    for N in (10, 100):
        errs = []
        for which in ("main", "paper"):
            cases = sets[which]
            by_n = {}
            for k, c in enumerate(cases):
                by_n.setdefault(c.q.shape[0], []).append(k)
            d = np.empty(len(cases))
            for idx in by_n.values():
                qs = jnp.asarray(np.stack([cases[k].q for k in idx]))
                pts = jnp.stack(
                    [curve_points(PolynomialCurve(cases[k].coeffs, cases[k].u_range), N) for k in idx]
                )
                d[idx] = np.asarray(fn(qs, pts, jnp.ones(pts.shape[:-1], bool)).distance)
            errs.append(np.abs(d - oracle_d[which]))
        e = np.concatenate(errs)
        rows.append(
            dict(
                N=N,
                cases=int(e.size),
                misses=int(np.sum(~(e <= TOL))),
                median_err=float(np.median(e)),
                max_err=float(np.max(e)),
            )
        )
    return rows


def sweep(candidates, sets, oracle_d, batch: int, repeats: dict, seed: int = 1):
    """Part 2: misses and single-query / batch times (float64) per candidate."""
    rng = np.random.default_rng(seed)
    q1 = jnp.asarray(random_qs(rng, 1)[0])
    sim2 = sim2_curve()
    qs = jnp.asarray(random_qs(rng, batch))
    cubics = random_cubics(rng, batch)
    pts1, mask1 = _points_of(sim2, 10, batched=False)
    ptsb, maskb = _points_of(cubics, 10, batched=True)
    ref_single = (compile_once(("points", ARM_SAMPLES), _points_fn, (q1, pts1, mask1))[0], (q1, pts1, mask1))
    ref_batch = (
        compile_once(
            ("points", ARM_SAMPLES, "vmap", False), _batched(_points_fn, False, 2), (qs, ptsb, maskb)
        )[0],
        (qs, ptsb, maskb),
    )
    rows = []
    for j, (label, opts) in enumerate(candidates):
        t0 = time.perf_counter()
        compiled, t_compile = compile_candidate(
            opts,
            sets,
            {
                "single": (("curve", opts), _curve_fn(opts), (q1, sim2)),
                "batch": (("curve", opts, "vmap", False), _batched(_curve_fn(opts), False, 1), (qs, cubics)),
            },
        )
        lib = library_results(sets, compiled)
        t_acc = time.perf_counter() - t0
        per_set, worst = {}, []
        for which, cases in sets.items():
            err = np.abs(lib[which]["distance"] - oracle_d[which])
            err = np.where(np.isfinite(err), err, np.inf)
            miss = ~(err <= TOL)
            per_set[which] = dict(
                cases=len(cases),
                misses=int(miss.sum()),
                max_err=float(err.max()),
                not_converged=int((~lib[which]["converged"]).sum()),
            )
            for k in np.argsort(-err)[: min(3, int(miss.sum()))]:
                worst.append(
                    dict(
                        set=which,
                        err=float(err[k]),
                        lib=float(lib[which]["distance"][k]),
                        oracle=float(oracle_d[which][k]),
                        case=cases[k].describe(),
                    )
                )
        timed = time_round_robin(
            {"single": (compiled["single"], (q1, sim2)), "10-point single": ref_single}, repeats["single"]
        )
        timed |= time_round_robin(
            {"batch": (compiled["batch"], (qs, cubics)), "10-point batch": ref_batch}, repeats["batch"]
        )
        row = dict(
            label=label,
            options=opts._asdict(),
            sets=per_set,
            misses=sum(s["misses"] for s in per_set.values()),
            cases=sum(s["cases"] for s in per_set.values()),
            max_err=max(s["max_err"] for s in per_set.values()),
            not_converged=sum(s["not_converged"] for s in per_set.values()),
            worst=worst,
            accuracy_s=t_acc,
            compile_s=t_compile,
            single_s=timed["single"]["median_s"],
            batch_s=timed["batch"]["median_s"],
            batch_size=batch,
            ratio_single_10=timed["single"]["median_s"] / timed["10-point single"]["median_s"],
            ratio_batch_10=timed["batch"]["median_s"] / timed["10-point batch"]["median_s"],
        )
        rows.append(row)
        _log(
            f"  [{j + 1}/{len(candidates)}] {label}: {row['misses']}/{row['cases']} misses "
            f"(max err {row['max_err']:.1e}); single {_fmt_s(row['single_s'])}, "
            f"batch {_fmt_s(row['batch_s'])} (x{row['ratio_batch_10']:.1f} of 10-pt); "
            f"compile + accuracy {t_acc:.0f} s ({t_compile:.0f} s compiling)"
        )
    return rows


def combined_candidate(rows) -> tuple[str, SolverOptions] | None:
    """The default with every field at its smallest value that passed.

    From the zero-miss candidates that only lower fields below their defaults
    (e.g. ``iterations=5`` or ``grid_s=6,grid_u=12``), per field the smallest
    value; None if that changes fewer than two fields or was measured already.
    """
    defaults = SolverOptions()._asdict()
    best = {}
    for r in rows:
        if set(r["options"]) != set(defaults):  # another solver (the grid's)
            continue
        diff = {k: v for k, v in r["options"].items() if v != defaults[k]}
        lowered = all(isinstance(v, (int, float)) and v < defaults[k] for k, v in diff.items())
        if r["misses"] or not diff or not lowered:
            continue
        for k, v in diff.items():
            best[k] = min(v, best.get(k, v))
    if len(best) < 2:
        return None
    opts = SolverOptions(**{**defaults, **best})
    if any(_options_from_dict(r["options"]) == opts for r in rows):
        return None
    return "combined " + ",".join(f"{k}={v}" for k, v in best.items()), opts


def _options_from_dict(opts: dict):
    """SolverOptions, or GridSolverOptions for the grid solver's fields."""
    return (GridSolverOptions if "edge_starts" in opts else SolverOptions)(**opts)


def _work(opts: dict):
    """Newton iterations per segment-curve pair, if the fields that give it exist."""
    if all(k in opts for k in ("starts", "edge_starts", "iterations")):  # the grid solver
        return (opts["starts"] + 4 * opts["edge_starts"]) * opts["iterations"]
    if all(k in opts for k in ("starts", "iterations")):
        return 2 * opts["starts"] * opts["iterations"]
    return None


def choose(rows) -> dict | None:
    """The cheapest zero-miss candidate: the lowest batch time relative to the 10-point method
    (timed in the same loop, so steadier than the absolute time on a shared machine); within
    5 % of it, the fewest Newton iterations."""
    ok = [r for r in rows if r["misses"] == 0]
    if not ok:
        return None
    best = min(r["ratio_batch_10"] for r in ok)
    near = [r for r in ok if r["ratio_batch_10"] <= 1.05 * best]
    return min(near, key=lambda r: (_work(r["options"]) or 0, r["ratio_batch_10"]))


# ----------------------------------------------------------------------------
# Report.


def _machine() -> dict:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return dict(
        platform=platform.platform(),
        cpu=cpu,
        cpu_count=os.cpu_count(),
        python=platform.python_version(),
        numpy=np.__version__,
        jax=jax.__version__,
        jaxlib=_jaxlib_version(),
        jax_backend=jax.default_backend(),
        devices=[str(d) for d in jax.devices()],
        softplan_jax=getattr(sp, "__version__", None),
        x64=bool(jax.config.jax_enable_x64),
        loadavg_start=_loadavg(),
        solver=_solver_source(),
    )


def _solver_source() -> dict:
    """Which closest.py was measured: git HEAD, whether the file differs from it, its hash.

    The solver is under active change; the hash is of the module as imported.
    """
    import subprocess

    import softplan_jax.geometry._closest as closest_module

    src = inspect.getsource(closest_module)
    info = dict(file="softplan_jax/closest.py", sha256=hashlib.sha256(src.encode()).hexdigest()[:12])
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = (
            subprocess.run(["git", "diff", "--quiet", "HEAD", "--", info["file"]], cwd=REPO).returncode != 0
        )
        info |= dict(git_head=head, modified_since_head=dirty)
    except (OSError, subprocess.CalledProcessError):
        pass
    return info


def _jaxlib_version():
    try:
        import jaxlib

        return jaxlib.__version__
    except Exception:  # noqa: BLE001 - informational only
        return None


def _loadavg():
    return [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None


def _fmt_s(x):
    if x is None:
        return "—"
    if x >= 1.0:
        return f"{x:.2f} s"
    return f"{x * 1e3:.2f} ms" if x >= 1e-3 else f"{x * 1e6:.0f} µs"


def _fmt_c(x):
    """A compile time; None when the compiled function was reused from an earlier row."""
    return "reused" if x is None else f"{x:.1f} s"


def _markdown(report: dict) -> str:
    m = report["machine"]
    rep = report["repeats"]
    lines = [
        "# Closest point: curve method vs N-point method, and the SolverOptions sweep",
        "",
        f"- mode: {report['mode']}; generated by `benchmarks/closest.py`"
        + (" --quick" if report["mode"] == "quick" else "")
        + f"; wall time {report['wall_time_s']:.0f} s",
        f"- machine: {m['platform']}, {m['cpu']}, {m['cpu_count']} CPUs; load average "
        f"{m['loadavg_start']} at start, {m.get('loadavg_end')} at end (a shared machine: compare ratios)",
        f"- python {m['python']}, numpy {m['numpy']}, jax {m['jax']} (jaxlib {m['jaxlib']}, "
        f"{m['jax_backend']}), softplan_jax {m['softplan_jax']}; x64 {'on' if m['x64'] else 'off'}",
        f"- SolverOptions fields and defaults at run time: {report['solver_defaults']}",
        f"- solver measured: `{m['solver']['file']}` sha256 {m['solver']['sha256']} (as imported), git HEAD "
        f"{m['solver'].get('git_head', '?')}"
        + (", with uncommitted changes" if m["solver"].get("modified_since_head") else ""),
        "",
        "## 1. Speed: one query and a batch, curve method vs N-point method",
        "",
        "Curve method `curve_closest(q, curve, SolverOptions())`, 3 segments x 1 curve; N-point "
        f"method `points_closest(q, curve_points(curve, N), mask, {ARM_SAMPLES})` (the points are "
        "made once, outside the timing). Sim2 = X 0.5, Y u, Z 5u^2, u in [-2, 2], padded to degree 3 like "
        "the cubics. Batch: `jax.vmap` over random q (and over the curves / points for random cubics). "
        "Compile = `jax.jit(f).lower(...).compile()` (*reused*: same compiled shape as the row above); "
        f"run = median of {rep['single']} (single) / {rep['batch']} (batch) calls with `block_until_ready`, "
        "the three methods timed round-robin in one loop. float32 rows: q, curve and points cast to float32 "
        "(x64 on; results are float32).",
        "",
        "| dtype | query | curve | 10-point | 100-point | curve / 10-pt | curve / 100-pt | curve per query "
        "| compile curve / 10-pt / 100-pt |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in report["speed"]:
        run = {k: v["median_s"] for k, v in r["run"].items()}
        c = r["compile_s"]
        lines.append(
            f"| {r['dtype']} | {r['kind']}: {r['query']} | {_fmt_s(run['curve'])} | "
            f"{_fmt_s(run['10-point'])} | {_fmt_s(run['100-point'])} | {r['ratio_curve_10']:.1f} | "
            f"{r['ratio_curve_100']:.1f} | {_fmt_s(run['curve'] / r['queries_per_call'])} | "
            f"{_fmt_c(c['curve'])} / {_fmt_c(c['10-point'])} / {_fmt_c(c['100-point'])} |"
        )
    acc = report["accuracy"]
    n_sets = acc["sets"]
    o = acc["oracle"]
    lines += [
        "",
        "## 2. Accuracy sweep over SolverOptions candidates (float64)",
        "",
        "Cases from `softplan_jax/testing/closest_cases.py` (as `tests/test_closest.py`): "
        + ", ".join(f"{k} {v}" for k, v in n_sets.items())
        + f"; reference `softplan_jax/testing/oracle.py` ({o['cases']} answers via `closest_cases`, cached in "
        f"`{o['cache_dir']}`: {o['oracle_s']:.0f} s). Miss: |distance - oracle| > {TOL:g} (or NaN); "
        "the library runs as the suite runs it (`sp.closest_point(q, curve, options)` vmapped, "
        "`run_pairwise`). *not conv.*: the winning solve's `converged` flag is False. *Newton its*: "
        "(starts + 4 edge_starts) x iterations per segment-curve pair. Single: one query, Sim2; batch: "
        f"{report['sweep_batch']} random q x random cubics; *x 10-pt*: time / the 10-point method's on the "
        "same queries, timed in the same loop. Compile: wall time to compile the candidate's accuracy "
        "shapes (one per n, and the helix) and its single / batch functions (unless compiled in part 1), "
        "two at a time in threads.",
        "",
        "| candidate | misses "
        + " / ".join(n_sets)
        + " | max err | not conv. | Newton its | single | x 10-pt | batch | x 10-pt | compile |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in report["sweep"]:
        s = r["sets"]
        w = _work(r["options"])
        lines.append(
            f"| {r['label']} | "
            + " / ".join(str(s[k]["misses"]) for k in n_sets)
            + f" | {r['max_err']:.1e} | {r['not_converged']} | {w if w is not None else '—'} | "
            f"{_fmt_s(r['single_s'])} | {r['ratio_single_10']:.1f} | {_fmt_s(r['batch_s'])} | "
            f"{r['ratio_batch_10']:.1f} | {r['compile_s']:.0f} s |"
        )
    ch = report["choice"]
    lines.append("")
    if ch is None:
        lines.append("**No candidate had zero misses.**")
    else:
        lines.append(
            "**Cheapest with zero misses** (lowest batch time / 10-point batch time; within 5 % "
            "of it, fewest Newton iterations): "
            f"`{ch['label']}` = {ch['options']}; batch {_fmt_s(ch['batch_s'])} "
            f"(x{ch['ratio_batch_10']:.1f} of the 10-point method), single {_fmt_s(ch['single_s'])}."
        )
    if report["n_point"]:
        lines += [
            "",
            "For context, the N-point method's distance error against the oracle on the polynomial cases:",
            "",
            "| N | cases | error > 1e-9 | median error | max error |",
            "|---|---|---|---|---|",
        ]
        for r in report["n_point"]:
            lines.append(
                f"| {r['N']} | {r['cases']} | {r['misses']} | {r['median_err']:.1e} | {r['max_err']:.1e} |"
            )
    misses = [(r["label"], w) for r in report["sweep"] for w in r["worst"]]
    if misses:
        lines += [
            "",
            "Worst misses (up to 3 per set and candidate, first 15 shown; the cases are in the JSON):",
            "",
        ]
        for label, w in misses[:15]:
            lines.append(
                f"- `{label}`, {w['set']}: err {w['err']:.1e} (library {w['lib']!r}, oracle {w['oracle']!r})"
            )
    if report["notes"]:
        lines += ["", "Notes:", ""] + [f"- {n}" for n in report["notes"]]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--quick",
        action="store_true",
        help="< 60 s on an idle machine: float64 only, batch 1000, a few n = 3 cases, no helix, "
        "the default SolverOptions only; writes results/quick/closest.md/.json",
    )
    ap.add_argument(
        "--candidates",
        default=None,
        help="SolverOptions candidates separated by ';', each 'default' or field=value,... overrides of "
        f"the defaults (fields, read at run time: {list(SolverOptions._fields)}); default: "
        f"{default_candidates_spec()!r} (quick: 'default')",
    )
    ap.add_argument(
        "--no-combine",
        action="store_true",
        help="do not add the candidate that combines the cheapest zero-miss single-field changes",
    )
    ap.add_argument(
        "--out",
        default=None,
        help="output path prefix (.md and .json are appended); default benchmarks/results/closest "
        "(quick: results/quick/closest, so that a quick run never overwrites the full report)",
    )
    args = ap.parse_args(argv)
    # float64 for the accuracy sweep and the float64 rows (the float32 rows cast
    # their inputs). Set here, not at import: importing this module changes nothing.
    jax.config.update("jax_enable_x64", True)
    quick = args.quick
    out = args.out or os.path.join(RESULTS_DIR, "quick" if quick else "", "closest")
    t_start = time.perf_counter()
    try:
        if args.candidates is not None:
            candidates, notes = parse_candidates(args.candidates, strict=True)
        else:
            candidates, notes = parse_candidates(
                "default" if quick else default_candidates_spec(), strict=False
            )
    except ValueError as err:
        ap.error(str(err))
    batch = 1_000 if quick else 10_000
    sweep_batch = 1_000 if quick else 2_000
    repeats = dict(single=30, batch=3) if quick else dict(single=200, batch=5)
    report = dict(
        mode="quick" if quick else "full",
        machine=_machine(),
        solver_defaults=_option_defaults(),
        candidates=[dict(label=lab, options=o._asdict()) for lab, o in candidates],
        repeats=repeats,
        batch=batch,
        sweep_batch=sweep_batch,
        notes=list(notes),
    )

    _log(f"part 1: speed, batch {batch} ...")
    report["speed"] = speed_table(SolverOptions(), batch, repeats, quick)

    _log("part 2: accuracy sweep; oracle ...")
    sets = case_sets(quick)
    oracle_d, oracle_info = oracle_distances(sets)
    report["accuracy"] = dict(sets={k: len(v) for k, v in sets.items()}, oracle=oracle_info)
    _log(
        f"  oracle: {oracle_info['cases']} answers ({oracle_info['oracle_s']:.0f} s)"
    )
    report["n_point"] = n_point_errors(sets, oracle_d)
    _log(f"  {len(candidates)} candidates ...")
    rows = sweep(candidates, sets, oracle_d, sweep_batch, repeats)
    if not quick and not args.no_combine:
        extra = combined_candidate(rows)
        if extra is not None:
            _log("  the cheapest zero-miss single-field changes, combined ...")
            rows += sweep([extra], sets, oracle_d, sweep_batch, repeats)
    report["sweep"] = rows
    report["choice"] = choose(rows)

    report["notes"] += [
        "Times are wall-clock on a shared machine (see the load average): absolute times move by ~2x with "
        "load, the ratios (timed round-robin in one loop) much less.",
        "Single-query times include JAX's per-call dispatch of the compiled function, which is most of the "
        "N-point method's single-query time.",
    ]
    if quick:
        report["notes"].append(
            "quick mode: float64 only, single Sim2 and batch random cubics only, every 10th n = 3 main "
            "case and every 10th paper case, no helix, default SolverOptions only, batch 1000; run "
            "without --quick for the full tables."
        )
    report["machine"]["loadavg_end"] = _loadavg()
    report["wall_time_s"] = time.perf_counter() - t_start
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out + ".json", "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1, default=str)
    with open(out + ".md", "w", encoding="utf-8") as fh:
        fh.write(_markdown(report))
    _log(f"wrote {out}.md and .json in {report['wall_time_s']:.0f} s")
    print(_markdown(report))
    return report


if __name__ == "__main__":
    main()
