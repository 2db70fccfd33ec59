"""Closest point arm <-> curve (paper section 2.3): the accuracy suite.

Every case (``softplan_jax/testing/closest_cases.py``: ~1000 main cases, the paper's
obstacles, a helix) is compared with ``softplan_jax/testing/oracle.py`` (dense grids + L-BFGS-B +
bounded Brent on the edges + corners + Newton polish, plain NumPy/SciPy),
which is itself checked here against closed-form answers first.

Bar: |distance - oracle| <= 1e-9 (float64) in EVERY case, and the returned
points must be F_R(s) and F_o(u) at the returned parameters with
|arm_point - obstacle_point| == distance.

Importing this module runs nothing: the cases are built on first use and the
oracle's answers come from the on-disk cache of ``closest_cases`` (computed
on the first run after the oracle or the cases change, in 2 worker processes;
``SOFTPLAN_ORACLE_WORKERS=0`` computes them in this process).
"""

from __future__ import annotations

import json
import math
import os
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose, assert_finite, closest_per_obstacle, unpack_stacked

import softplan_jax as sp
from softplan_jax.geometry._closest import SolverOptions
from softplan_jax.testing import closest_cases as cc
from softplan_jax.testing import oracle

TOL = cc.TOL  # 1e-9

# --------------------------------------------------------------------------
# closed-form references used to check the ORACLE
# --------------------------------------------------------------------------


def segseg_distance(p1, q1, p2, q2):
    """Distance between segments [p1, q1] and [p2, q2] (Ericson 2005, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c = d1 @ r
    b = d1 @ d2
    denom = a * e - b * b
    s = np.clip((b * f - c * e) / denom, 0, 1) if denom > 1e-14 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0:
        t, s = 0.0, np.clip(-c / a, 0, 1)
    elif t > 1:
        t, s = 1.0, np.clip((b - c) / a, 0, 1)
    return float(np.linalg.norm(p1 + d1 * s - (p2 + d2 * t)))


def segseg_distance_brute(p1, q1, p2, q2):
    """Exact min over the 4 edge problems + interior (for the reference)."""

    def pt_seg(p, a, b):
        d = b - a
        t = np.clip((p - a) @ d / (d @ d), 0, 1)
        return np.linalg.norm(a + t * d - p)

    cands = [pt_seg(p1, p2, q2), pt_seg(q1, p2, q2), pt_seg(p2, p1, q1), pt_seg(q2, p1, q1)]
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    M = np.array([[d1 @ d1, -d1 @ d2], [-d1 @ d2, d2 @ d2]])
    if abs(np.linalg.det(M)) > 1e-12:
        s, t = np.linalg.solve(M, [-d1 @ r, d2 @ r])
        if 0 <= s <= 1 and 0 <= t <= 1:
            cands.append(np.linalg.norm(p1 + s * d1 - p2 - t * d2))
    return float(min(cands))


class TestOracleClosedForm:
    """The oracle alone, against answers known in closed form."""

    def test_straight_arm_vs_line_segments(self):
        rng = np.random.default_rng(1000)
        worst = 0.0
        for _ in range(60):
            n = int(rng.integers(1, 4))
            L = rng.uniform(0.3, 2.0, n)
            q = np.stack([L, np.zeros(n), rng.uniform(-3, 3, n)], 1)
            a = rng.normal(size=3) * 1.5 + [0, 0, L.sum() / 2]
            b = a + rng.normal(size=3) * rng.choice([0.1, 1.0, 3.0])
            want = segseg_distance_brute(np.zeros(3), np.array([0, 0, L.sum()]), a, b)
            want2 = segseg_distance(np.zeros(3), np.array([0, 0, L.sum()]), a, b)
            assert abs(want - want2) < 1e-12
            got = oracle.closest_distance(q, oracle.line(a, b))
            worst = max(worst, abs(got - want))
        assert worst < 1e-12, worst

    def test_point_like_curve_on_axis_line(self):
        # line through (x, y, z0) parallel to x: distance |y| from the z-axis
        q = np.array([[1.5, 0.0, 0.7]])
        c = oracle.OPoly(np.array([[-1.0, 2.0], [0.3, 0.0], [0.8, 0.0]]), 0.0, 1.0)
        assert abs(oracle.closest_distance(q, c) - 0.3) < 1e-14

    def test_straight_arm_vs_parabola(self):
        # arm = z axis [0, L]; curve X = a + b u^2, Y = u, Z = z0 -> distance a
        for a, b, z0 in [(0.3, 1.0, 0.5), (1e-5, 3.0, 1.0), (0.7, 0.2, 0.01)]:
            q = np.array([[0.6, 0.0, 0.1], [0.6, 0.0, 2.0]])
            c = oracle.OPoly(np.array([[a, 0, b], [0, 1, 0], [z0, 0, 0]]), -1.0, 2.0)
            assert abs(oracle.closest_distance(q, c) - a) < 1e-14

    def test_arc_vs_its_axis(self):
        # every point of a circular arc is r = L/|theta| from its centre, and
        # the circle's axis is perpendicular to its plane: distance = r
        rng = np.random.default_rng(1001)
        for _ in range(20):
            n = int(rng.integers(1, 4))
            q = np.stack(
                [
                    rng.uniform(0.3, 2, n),
                    rng.uniform(0.3, 6, n) * rng.choice([-1, 1], n),
                    rng.uniform(-3, 3, n),
                ],
                1,
            )
            i = n - 1
            L, th, ph = q[i]
            Rb, Pb = oracle.segment_frames(q)
            r = L / th
            centre = Pb[i] + Rb[i] @ (r * np.array([np.cos(ph), np.sin(ph), 0.0]))
            normal = Rb[i] @ np.array([-np.sin(ph), np.cos(ph), 0.0])
            c = oracle.line(centre - normal, centre + normal)
            if n == 1:
                d = oracle.closest_distance(q, c)
                assert abs(d - abs(r)) < 1e-12 * max(1, abs(r)), (q, d, r)
            # the last segment alone (other segments may be closer)
            prob = oracle._SegmentProblem(q, i, c)
            best = min(
                math.sqrt(f) for f, _, _ in [oracle._refine_2d(prob, s0, 0.5) for s0 in (0.1, 0.5, 0.9)]
            )
            assert abs(best - abs(r)) < 1e-12 * max(1, abs(r))

    def test_point_in_arc_plane_via_normal_line(self):
        # line x + u n (n = plane normal): distance to the arc = | |x-c| - r |
        # when x's direction from the centre lies within the arc's angles
        rng = np.random.default_rng(1002)
        for _ in range(30):
            L, th, ph = rng.uniform(0.5, 2), rng.uniform(0.5, 5) * rng.choice([-1, 1]), rng.uniform(-3, 3)
            q = np.array([[L, th, ph]])
            r = L / th
            e = np.array([np.cos(ph), np.sin(ph), 0.0])
            centre = r * e
            normal = np.array([-np.sin(ph), np.cos(ph), 0.0])
            s_star = rng.uniform(0.1, 0.9)
            p = oracle.segment_point(q, 0, s_star)
            rho = rng.uniform(0.05, 1.9) * abs(r)
            x = centre + (p - centre) / abs(r) * rho
            c = oracle.line(x - 0.7 * normal, x + 0.3 * normal)
            d = oracle.closest_distance(q, c)
            assert abs(d - abs(rho - abs(r))) < 1e-12, (q, d, rho, r)

    def test_touching_single_segment(self):
        # constructed near-touch cases have distance exactly delta (n = 1)
        rng = np.random.default_rng(1003)
        for _ in range(40):
            case = cc.make_touch_case(rng, n=1)
            d = oracle.closest_distance(case.q, case.ocurve())
            assert abs(d - case.expected) < 1e-13, (case, d)

    def test_crossing(self):
        rng = np.random.default_rng(1004)
        for _ in range(20):
            case = cc.make_cross_case(rng)
            d = oracle.closest_distance(case.q, case.ocurve())
            assert d < 1e-14, (case, d)


# --------------------------------------------------------------------------
# running library and oracle (once per session)
# --------------------------------------------------------------------------

# The oracle's answers are cached on disk by closest_cases (keyed by the
# oracle's source and each case's data).  Library batches are padded to CHUNK
# cases so that each (function, n, dtype) compiles once.

CHUNK = 64


def _dist(q, curve):
    return sp.closest_point(q, curve).distance


_pairwise = jax.jit(jax.vmap(sp.closest_point))  # over q AND curve
_pairwise_grad = jax.jit(jax.vmap(jax.grad(_dist)))
_per_q = jax.jit(jax.vmap(sp.closest_point, in_axes=(0, None)))  # one curve


def _helix_fn(u):
    """The helix of closest_cases (oracle.helix: radius 1, pitch 0.2), in jax."""
    return jnp.stack([jnp.cos(u), jnp.sin(u), 0.2 * u])


def _to_numpy(res):
    return {f: np.asarray(getattr(res, f)) for f in res._fields}


def run_pairwise(qs, coeffs, u_ranges, dtype=jnp.float64, fn=_pairwise):
    """Library on case k = (qs[k], curve k); all qs of one n; degree padded to 3."""
    qs = np.asarray(qs)
    B = len(qs)
    outs = []
    for start in range(0, B, CHUNK):
        idx = list(range(start, min(start + CHUNK, B)))
        idx += [idx[-1]] * (CHUNK - len(idx))
        curves = [
            sp.PolynomialCurve(jnp.asarray(coeffs[k], dtype), jnp.asarray(u_ranges[k], dtype)) for k in idx
        ]
        stacked, mask = unpack_stacked(sp.geometry.stack_curves(curves, degree=3))
        assert mask.all() and stacked.coeffs.shape == (CHUNK, 3, 4)
        res = fn(jnp.asarray(qs[idx], dtype), stacked)
        outs.append(_to_numpy(res) if hasattr(res, "_fields") else np.asarray(res))
    if isinstance(outs[0], dict):
        return [{f: o[f][j] for f in o} for o in outs for j in range(CHUNK)][:B]
    return np.concatenate(outs)[:B]


def run_cases(cases, dtype=jnp.float64, fn=_pairwise):
    out = [None] * len(cases)
    by_n = {}
    for k, c in enumerate(cases):
        by_n.setdefault(c.q.shape[0], []).append(k)
    for _n, idx in sorted(by_n.items()):
        res = run_pairwise(
            [cases[k].q for k in idx],
            [cases[k].coeffs for k in idx],
            [cases[k].u_range for k in idx],
            dtype,
            fn,
        )
        for j, k in enumerate(idx):
            out[k] = res[j]
    return out


@cache
def oracle_results(which):
    """The oracle's answers (cached on disk by closest_cases), case by case."""
    return cc.oracle_answers(which)


@cache
def library_results(which):
    if which == "main":
        return run_cases(cc.main_cases())
    if which == "paper":
        return run_cases(cc.paper_cases())
    if which == "helix":
        helix = sp.ParametricCurve(_helix_fn, cc.HELIX_RANGE)
        res = _to_numpy(_per_q(jnp.asarray(np.stack(cc.helix_qs())), helix))
        return [{f: v[j] for f, v in res.items()} for j in range(len(cc.helix_qs()))]
    raise KeyError(which)


# --------------------------------------------------------------------------
# the accuracy tests
# --------------------------------------------------------------------------

WHICH = ["main", "paper", "helix"]


def test_case_counts_and_coverage():
    kinds = {}
    for c in cc.main_cases() + cc.paper_cases():
        kinds[c.kind.split("_")[0]] = kinds.get(c.kind.split("_")[0], 0) + 1
    total = len(cc.main_cases()) + len(cc.paper_cases()) + len(cc.helix_qs())
    assert total >= 1000, kinds
    thetas = np.concatenate([c.q[:, 1] for c in cc.main_cases()])
    assert (thetas == 0).sum() > 50 and (np.abs(thetas) == 1e-12).sum() > 50
    assert (thetas < -1).sum() > 100 and (np.abs(thetas) > 4).sum() > 50
    ns = {c.q.shape[0] for c in cc.main_cases()}
    assert ns == {1, 2, 3, 4}
    degrees = {c.coeffs.shape[1] - 1 for c in cc.main_cases()}
    assert degrees == {1, 2, 3}


def test_oracle_minima_cover_every_case_type():
    # the families above really produce the situations they are meant to
    # (judged by the oracle's answers, not by the construction)
    orc = oracle_results("main")
    ends_s = [o.s in (0.0, 1.0) for o in orc]
    ends_u = [o.u in c.u_range for c, o in zip(cc.main_cases(), orc, strict=True)]
    count = {
        "s at an end, u interior": sum(a and not b for a, b in zip(ends_s, ends_u, strict=True)),
        "u at an end, s interior": sum(b and not a for a, b in zip(ends_s, ends_u, strict=True)),
        "endpoint pair": sum(a and b for a, b in zip(ends_s, ends_u, strict=True)),
        "interior": sum(not a and not b for a, b in zip(ends_s, ends_u, strict=True)),
        "crossing (d < 1e-12)": sum(o.distance < 1e-12 for o in orc),
        "near touch (1e-7 < d < 1e-3)": sum(1e-7 < o.distance < 1e-3 for o in orc),
    }
    need = {
        "s at an end, u interior": 30,
        "u at an end, s interior": 30,
        "endpoint pair": 15,
        "interior": 300,
        "crossing (d < 1e-12)": 60,
        "near touch (1e-7 < d < 1e-3)": 100,
    }
    assert all(count[k] >= need[k] for k in need), count


def _report(rows, header):
    rows = sorted(rows, key=lambda r: -r[0])
    lines = [f"{len(rows)} misses. {header}. worst first:"]
    for err, text in rows[:5]:
        lines.append(f"  err={err:.3e}: {text}")
    return "\n".join(lines)


@pytest.mark.parametrize("which", WHICH)
def test_distance_matches_oracle(which):
    cases, lib, orc = cc.cases(which), library_results(which), oracle_results(which)
    misses = []
    for c, r, o in zip(cases, lib, orc, strict=True):
        err = abs(float(r["distance"]) - o.distance)
        if not err <= TOL:  # also catches NaN
            misses.append(
                (
                    err if np.isfinite(err) else np.inf,
                    f"{c.describe()} lib: d={float(r['distance'])!r} seg={int(r['segment'])} "
                    f"s={float(r['s'])!r} u={float(r['u'])!r}; oracle: d={o.distance!r} "
                    f"seg={o.segment} s={o.s!r} u={o.u!r}",
                )
            )
    assert not misses, _report(
        misses, f"{which}: |distance - oracle| > {TOL} in {len(misses)}/{len(cases)} cases"
    )


# The solver's hardest cases met while it was developed (each missed by an
# earlier version): (q, coeffs, u_range, oracle distance).
HARD_CASES = [
    (np.array(c["q"]), np.array(c["coeffs"]), tuple(c["u_range"]), c["oracle_distance"])
    for c in json.load(open(os.path.join(os.path.dirname(__file__), "data", "hard_closest_cases.json")))
]

GRID = sp.geometry.GridSolverOptions()
_pairwise_grid = jax.jit(jax.vmap(lambda q, c: sp.closest_point(q, c, GRID)))


@pytest.mark.parametrize(
    "options",
    [SolverOptions(), pytest.param(GRID, marks=pytest.mark.slow)],  # the grid solver: compiles for ~1 min
    ids=["reduced", "grid"],
)
def test_known_hard_cases(options):
    """The hard cases through the suites' compiled programs (run_pairwise: the cases of one
    segment count in one padded batch, the curves' coefficients padded with zeros to degree 3:
    the same curves, the same solver), so they add no compilation."""
    fn = _pairwise if options == SolverOptions() else _pairwise_grid
    by_n = {}
    for k, (q, _, _, _) in enumerate(HARD_CASES):
        by_n.setdefault(q.shape[0], []).append(k)
    assert sorted(by_n) == [1, 3, 4]  # segment counts of the main suite: its programs
    for idx in by_n.values():
        res = run_pairwise(*zip(*[HARD_CASES[k][:3] for k in idx], strict=True), fn=fn)
        for k, r in zip(idx, res, strict=True):
            q, _, _, d_oracle = HARD_CASES[k]
            assert abs(float(r["distance"]) - d_oracle) <= TOL, (q, float(r["distance"]), d_oracle)


@pytest.mark.slow  # the non-default solver: ~2 min of compiling
def test_grid_method_matches_oracle():
    """The alternative 2-D solver (GridSolverOptions) on the main and paper suites."""
    for which, cases in (("main", cc.main_cases()), ("paper", cc.paper_cases())):
        lib = run_cases(cases, fn=_pairwise_grid)
        errs = [abs(float(r["distance"]) - o.distance) for r, o in zip(lib, oracle_results(which), strict=True)]
        bad = [k for k, e in enumerate(errs) if not e <= TOL]
        assert not bad, (which, len(bad), [cases[k].describe() for k in bad[:3]])


@pytest.mark.parametrize("which", WHICH)
def test_returned_points_are_on_arm_and_curve(which):
    cases, lib = cc.cases(which), library_results(which)
    misses = []
    for c, r in zip(cases, lib, strict=True):
        n = c.q.shape[0]
        seg, s, u = int(r["segment"]), float(r["s"]), float(r["u"])
        u0, u1 = c.u_range
        problems = []
        if not (0 <= seg < n):
            problems.append(f"segment {seg} not in [0, {n})")
            misses.append((np.inf, c.describe() + " " + "; ".join(problems)))
            continue
        if not (0.0 <= s <= 1.0):
            problems.append(f"s={s!r} outside [0, 1]")
        if not (u0 <= u <= u1):
            problems.append(f"u={u!r} outside [{u0}, {u1}]")
        A = oracle.segment_point(c.q, seg, s)
        C = cc.ocurve(which, c).point(np.array([u]))[0]
        scale = max(1.0, np.abs(A).max(), np.abs(C).max())
        ea = np.abs(r["arm_point"] - A).max()
        ec = np.abs(r["obstacle_point"] - C).max()
        eg = abs(np.linalg.norm(r["arm_point"] - r["obstacle_point"]) - float(r["distance"]))
        if not ea <= 1e-12 * scale:
            problems.append(f"arm_point {r['arm_point']} != F_R(s) {A} (err {ea:.2e})")
        if not ec <= 1e-12 * scale:
            problems.append(f"obstacle_point {r['obstacle_point']} != F_o(u) {C} (err {ec:.2e})")
        if not eg <= 1e-12 * scale:
            problems.append(f"|arm_point - obstacle_point| != distance (err {eg:.2e})")
        if r["converged"].dtype != np.bool_ or r["converged"].shape != ():
            problems.append(f"converged is {r['converged']!r}, not a bool scalar")
        if problems:
            misses.append(
                (
                    max(ea, ec, eg) if np.isfinite(max(ea, ec, eg)) else np.inf,
                    c.describe() + " " + "; ".join(problems),
                )
            )
    assert not misses, _report(misses, f"{which}: returned points inconsistent")


def test_constructed_cases_agree_with_construction():
    # independent of the oracle's search: a constructed touching/crossing/
    # parallel case can be no farther than its construction says
    lib = library_results("main")
    orc = oracle_results("main")
    bad = []
    for c, r, o in zip(cc.main_cases(), lib, orc, strict=True):
        if c.expected is None:
            continue
        for name, d in (("oracle", o.distance), ("library", float(r["distance"]))):
            if not d <= c.expected + 1e-12:
                bad.append((d - c.expected, f"{name} d={d!r} > constructed {c.expected!r}: {c.describe()}"))
            if c.exact and not abs(d - c.expected) <= 1e-12:
                bad.append(
                    (abs(d - c.expected), f"{name} d={d!r} != constructed {c.expected!r}: {c.describe()}")
                )
    assert not bad, _report(bad, "constructed distances violated")


# --------------------------------------------------------------------------
# the documented vmap forms, jit/eager agreement, float32
# --------------------------------------------------------------------------


def test_vmap_over_stacked_curves_for_one_q():
    rng = np.random.default_rng(5)
    q = cc.random_q(rng, 3)
    q[1, 1] = 0.0
    curves_np = [
        cc.PAPER_OBSTACLES[k] for k in ("sim1", "sim2", "branch1", "branch2", "branch3", "branch4", "trunk")
    ]
    curves = [sp.PolynomialCurve(jnp.asarray(cf), jnp.asarray(ur)) for cf, ur in curves_np]
    stacked, mask = unpack_stacked(sp.geometry.stack_curves(curves, size=9, degree=3))
    assert mask.tolist() == [True] * 7 + [False] * 2
    res = closest_per_obstacle(jnp.asarray(q), stacked)
    for k, (cf, ur) in enumerate(curves_np):
        o = oracle.closest_point(q, oracle.OPoly(cf, *ur))
        assert abs(float(res.distance[k]) - o.distance) <= TOL, (k, float(res.distance[k]), o.distance)


def test_concrete_q_closed_over_inside_jit():
    # the documented per-obstacle vmap, inside a user's jit, q a closed-over constant
    q = jnp.asarray([[1.0, 0.4, 0.2], [1.0, 0.0, 1.0], [1.0, -0.3, 2.0]])
    c = sp.PolynomialCurve(jnp.asarray(cc.PAPER_OBSTACLES["sim1"][0]), jnp.asarray((-2.0, 2.0)))
    d = jax.jit(lambda cc: sp.closest_point(q, cc).distance)(c)
    o = oracle.closest_point(np.asarray(q), oracle.OPoly(cc.PAPER_OBSTACLES["sim1"][0], -2.0, 2.0))
    assert abs(float(d) - o.distance) <= TOL


def test_eager_single_calls_match_oracle():
    # un-jitted, un-vmapped path, native degree (one shape: one compile)
    picks = [
        c
        for c in cc.main_cases()
        if c.kind in ("touch", "parallel", "cross", "random") and c.q.shape[0] == 3 and c.coeffs.shape[1] == 2
    ][:3]
    for c in picks:
        r = sp.closest_point(
            jnp.asarray(c.q), sp.PolynomialCurve(jnp.asarray(c.coeffs), jnp.asarray(c.u_range))
        )
        o = oracle.closest_point(c.q, c.ocurve())
        assert isinstance(r, tuple) and hasattr(r, "distance")
        assert r.arm_point.shape == (3,) and r.obstacle_point.shape == (3,)
        assert jnp.shape(r.distance) == () and jnp.shape(r.segment) == ()
        assert abs(float(r.distance) - o.distance) <= TOL, (c.describe(), float(r.distance), o.distance)


def test_float32_within_1e4_of_float64():
    cases = [c for c in cc.main_cases() if c.q.shape[0] == 3]
    assert len(cases) >= 200
    lib32 = run_cases(cases, jnp.float32)
    orc = {id(c): o for c, o in zip(cc.main_cases(), oracle_results("main"), strict=True)}
    misses = []
    for c, r in zip(cases, lib32, strict=True):
        assert r["distance"].dtype == np.float32, r["distance"].dtype
        assert r["arm_point"].dtype == np.float32
        err = abs(float(r["distance"]) - orc[id(c)].distance)
        if not err <= 1e-4:
            misses.append(
                (
                    err if np.isfinite(err) else np.inf,
                    f"{c.describe()} f32 d={float(r['distance'])!r} f64 oracle={orc[id(c)].distance!r}",
                )
            )
    assert not misses, _report(misses, f"float32: |d32 - d64| > 1e-4 in {len(misses)}/{len(cases)} cases")


# --------------------------------------------------------------------------
# d(distance)/dq
# --------------------------------------------------------------------------


def test_distance_gradient():
    cases = [c for c, _ in cc.gradient_cases()]
    g_all = run_pairwise(
        [c.q for c in cases],
        [c.coeffs for c in cases],
        [c.u_range for c in cases],
        fn=_pairwise_grad,
    )
    fd_qs = np.concatenate([cc.fd_qs(c.q) for c in cases])
    rep = 2 * 9
    vals = run_pairwise(
        fd_qs,
        [c.coeffs for c in cases for _ in range(rep)],
        [c.u_range for c in cases for _ in range(rep)],
    )
    vals = np.array([v["distance"] for v in vals]).reshape(len(cases), rep)
    vals_o = cc.oracle_distances("grad_fd").reshape(len(cases), rep)
    for k, (case, o) in enumerate(cc.gradient_cases()):
        q = case.q
        g = np.asarray(g_all[k]).ravel()
        msg = case.describe()
        assert_finite(g, msg)
        # 1) envelope theorem with the ORACLE's minimiser and exact Jacobian
        J = oracle.point_jacobian(q, o.segment, o.s)
        env = (o.arm_point - o.obstacle_point) @ J / o.distance
        assert_allclose(g, env, atol=1e-8, err_msg="envelope " + msg)
        # 2) central differences (h = 1e-6) of the library distance
        fd = (vals[k, :9] - vals[k, 9:]) / (2 * cc.FD_H)
        assert_allclose(g, fd, atol=1e-6, err_msg="FD(lib) " + msg)
        # 3) central differences of the ORACLE distance
        fdo = (vals_o[k, :9] - vals_o[k, 9:]) / (2 * cc.FD_H)
        assert_allclose(g, fdo, atol=1e-6, err_msg="FD(oracle) " + msg)


def test_distance_gradient_finite_everywhere():
    # crossings (distance 0), touching, parallel, theta = 0 / 1e-12 cases
    picks = [c for c in cc.main_cases() if c.kind in ("cross", "touch", "parallel") and c.q.shape[0] == 3]
    assert len(picks) > 30
    grads = run_pairwise(
        [c.q for c in picks],
        [c.coeffs for c in picks],
        [c.u_range for c in picks],
        fn=_pairwise_grad,
    )
    bad = [c.describe() for c, gg in zip(picks, grads, strict=True) if not np.all(np.isfinite(gg))]
    assert not bad, f"{len(bad)}/{len(picks)} non-finite gradients, e.g. {bad[:2]}"


# --------------------------------------------------------------------------
# the N-point method
# --------------------------------------------------------------------------


_points_batched = jax.jit(jax.vmap(sp.geometry.closest_point_to_points))
POINT_BATCH = 8


def _closest_points_lib(qs, pts):
    """Library N-point method on a batch (padded to POINT_BATCH: one compile per shape)."""
    qs, pts = np.asarray(qs), np.asarray(pts)
    B = len(qs)
    idx = list(range(B)) + [B - 1] * (POINT_BATCH - B)
    return _to_numpy(_points_batched(jnp.asarray(qs[idx]), jnp.asarray(pts[idx])))


@pytest.mark.parametrize("n,N", [(1, 1), (2, 2), (3, 50), (4, 7)])
def test_closest_point_to_points_brute_force(n, N):
    rng = np.random.default_rng(99 + n)
    qs = np.stack([cc.random_q(rng, n) for _ in range(POINT_BATCH)])
    qs[0, :, 1] = 0.0
    pts = rng.normal(size=(POINT_BATCH, N, 3)) * 1.5 + [0, 0, 1]
    r = _closest_points_lib(qs, pts)
    for k in range(POINT_BATCH):
        o = oracle.closest_point_to_points(qs[k], pts[k])
        msg = f"q={qs[k].tolist()} pts={pts[k].tolist()}"
        assert abs(float(r["distance"][k]) - o.distance) <= 1e-12, msg
        assert int(r["segment"][k]) == o.segment, msg
        assert abs(float(r["s"][k]) - o.s) <= 1e-12, msg
        assert float(r["u"][k]) == o.u, msg
        assert_allclose(r["arm_point"][k], o.arm_point, atol=1e-12, err_msg=msg)
        assert_allclose(r["obstacle_point"][k], pts[k][o.u], atol=0, err_msg=msg)


def test_closest_point_to_points_uses_ten_samples_per_segment():
    q = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    # a point just below the base is NOT near a sample (s = j/10, j = 1..10):
    # the nearest sample is s = 0.1 of segment 0; and a point between the
    # samples s = 0.3 and 0.4 of segment 1 of the straight arm
    pts = np.array([[[0.0, 0.0, -0.01], [5.0, 5.0, 5.0]], [[0.2, 0.0, 1.33], [5.0, 5.0, 5.0]]])
    r = _closest_points_lib(np.stack([q, q]), pts)
    assert abs(float(r["distance"][0]) - 0.11) < 1e-12
    assert int(r["segment"][0]) == 0 and abs(float(r["s"][0]) - 0.1) < 1e-12
    assert abs(float(r["distance"][1]) - math.hypot(0.2, 0.03)) < 1e-12
    assert int(r["segment"][1]) == 1 and abs(float(r["s"][1]) - 0.3) < 1e-12
    assert float(r["u"][1]) == 0


def test_curve_points_feed_n_point_method():
    c = sp.PolynomialCurve(jnp.asarray(cc.PAPER_OBSTACLES["sim1"][0]), jnp.asarray((-2.0, 2.0)))
    pts = np.asarray(sp.geometry.curve_points(c, 5))
    assert_allclose(pts[:, 1], [-2, -1, 0, 1, 2], atol=1e-15)
    q = np.array([[1.0, 0.5, 0.0], [1.0, -0.3, 1.0], [1.0, 0.2, 2.0]])
    r = sp.geometry.closest_point_to_points(jnp.asarray(q), jnp.asarray(pts))  # eager, once
    o = oracle.closest_point_to_points(q, pts)
    assert abs(float(r.distance) - o.distance) < 1e-12
    # and the N-point distance can never be below the true curve distance
    assert (
        float(r.distance)
        >= oracle.closest_distance(q, oracle.OPoly(cc.PAPER_OBSTACLES["sim1"][0], -2, 2)) - 1e-12
    )


def test_point_distance_matches_dense_sampling():
    """sp.geometry.point_distance (closed-form point-to-arc) against the oracle's arm
    sampled at 20,001 points per segment plus a golden-section polish."""
    rng = np.random.default_rng(11)
    from scipy.optimize import minimize_scalar

    s_dense = np.linspace(0.0, 1.0, 20001)
    for n in (1, 3):
        for _ in range(15):
            q = cc.random_q(rng, n)
            pts = rng.normal(size=(6, 3)) * rng.choice([0.3, 1.0, 3.0])
            pts[0] = oracle.segment_point(q, n - 1, 0.5) + 1e-4 * rng.normal(size=3)  # nearly on the arm
            lib = np.asarray(sp.geometry.point_distance(jnp.asarray(q), jnp.asarray(pts)))
            for k, p in enumerate(pts):
                best = np.inf
                for i in range(n):
                    d = np.linalg.norm(oracle.segment_points(q, i, s_dense) - p, axis=1)
                    j = int(np.argmin(d))
                    lo, hi = s_dense[max(j - 1, 0)], s_dense[min(j + 1, len(s_dense) - 1)]
                    res = minimize_scalar(lambda s, i=i, q=q, p=p: np.linalg.norm(oracle.segment_point(q, i, s) - p),
                                          bounds=(lo, hi), method="bounded", options=dict(xatol=1e-13))
                    best = min(best, d[j], res.fun)
                assert abs(lib[k] - best) <= 1e-9, (q, p, lib[k], best)


@pytest.mark.parametrize("theta", [0.0, 1e-9, 0.05, 1.3])
def test_newton_kernel_matches_autodiff(theta):
    """closest_newton.pair_terms (paper eqs. 13-18, the one Newton kernel) against
    jax.grad / jax.hessian of |F_Ri(s) - F_o(u)|^2 / 2, at and near theta = 0."""
    from softplan_jax.geometry._closest_newton import Segment, pair_terms

    q = jnp.array([[0.9, 0.4, 0.3], [1.1, theta, -0.7]])
    R, P = sp.geometry.segment_frames(q)
    seg = Segment.from_frame(q[1], R[1], P[1])
    curve = sp.PolynomialCurve(jnp.array([[0.2, 0.5, -0.3], [0.1, -0.4, 0.6], [1.5, 0.2, 0.1]]), (0.0, 1.0))

    def f(x):
        r = seg.point(x[0]) - curve.point(x[1])
        return 0.5 * jnp.dot(r, r)

    x = jnp.array([0.37, 0.61])
    t = pair_terms(seg, curve, x[0], x[1])
    assert_allclose(jnp.stack([t.gs, t.gu]), jax.grad(f)(x), rtol=1e-12, atol=1e-14)
    assert_allclose(jnp.array([[t.a, t.b], [t.b, t.c]]), jax.hessian(f)(x), rtol=1e-11, atol=1e-13)


def test_atan_over_x_both_branches():
    from softplan_jax.base._numerics import atan_over_x

    w = jnp.array([0.0, 1e-12, 0.019, 0.021, 0.5, -3.0])
    ref = np.where(np.asarray(w) == 0, 1.0, np.arctan(np.asarray(w)) / np.where(np.asarray(w) == 0, 1, np.asarray(w)))
    assert_allclose(atan_over_x(w), ref, rtol=1e-15)
    assert_finite(jax.vmap(jax.grad(atan_over_x))(w))


@jax.jit
def _arc_distances(q, pts):
    from softplan_jax.geometry._closest_newton import Segment, arc_distance2, project_to_arc

    R, P = sp.geometry.segment_frames(q)
    seg = Segment.from_frame(q[0], R[0], P[0])
    return (jax.vmap(lambda p: arc_distance2(seg, p))(pts), jax.vmap(lambda p: project_to_arc(seg, p)[1])(pts))


@pytest.mark.parametrize("theta", [0.0, 1e-9, -1e-9, 0.7, -2.5, 3.5, -4.5, 6.5])
def test_arc_distance_matches_dense_sampling(theta):
    """closest_newton.arc_distance2 (the certificate's trigonometry-free point-to-arc distance)
    against the oracle's segment sampled at 20,001 points plus a golden-section polish,
    and against project_to_arc's value; points at random, at the circle's centre, on
    its axis, near and beyond both ends, and nearly on the arc."""
    from scipy.optimize import minimize_scalar

    rng = np.random.default_rng(int(abs(theta) * 1e3) + 5)
    s_dense = np.linspace(0.0, 1.0, 20001)
    for _ in range(3):
        L, phi = rng.uniform(0.3, 2.0), rng.uniform(-np.pi, np.pi)
        q = np.array([[L, theta, phi]])
        a, b = oracle.segment_point(q, 0, 0.0), oracle.segment_point(q, 0, 1.0)
        mid = oracle.segment_point(q, 0, 0.5)
        bend = np.array([np.cos(phi), np.sin(phi), 0.0])
        normal = np.array([-np.sin(phi), np.cos(phi), 0.0])
        centre = a + (L / theta) * bend if theta != 0.0 else mid + 0.7 * bend
        pts = np.concatenate([
            rng.normal(size=(6, 3)) * rng.choice([0.3, 1.0, 3.0]),
            [centre, centre + 0.4 * normal, a - 0.2 * np.array([0, 0, 1.0]), b + 0.3 * (b - mid),
             mid + 1e-6 * rng.normal(size=3), a + 1e-3 * normal, b],
        ])
        lib, projected = (np.sqrt(np.asarray(x)) for x in _arc_distances(jnp.asarray(q), jnp.asarray(pts)))
        assert_allclose(lib, projected, rtol=1e-14, atol=1e-12)
        for k, p in enumerate(pts):
            d = np.linalg.norm(oracle.segment_points(q, 0, s_dense) - p, axis=1)
            j = int(np.argmin(d))
            lo, hi = s_dense[max(j - 1, 0)], s_dense[min(j + 1, len(s_dense) - 1)]
            res = minimize_scalar(lambda s, p=p, q=q: np.linalg.norm(oracle.segment_point(q, 0, s) - p),
                                  bounds=(lo, hi), method="bounded", options=dict(xatol=1e-13))
            best = min(d[j], res.fun)
            # Equidistant points (the centre) have many minimisers; the value is what counts.
            assert abs(lib[k] - best) <= 1e-9 * (1.0 + np.linalg.norm(p)), (theta, q, p, lib[k], best)


def test_arc_distance_gradient_finite_at_theta_zero_and_the_centre():
    from softplan_jax.geometry._closest_newton import Segment, arc_distance2

    def f(q, p):
        R, P = sp.geometry.segment_frames(q)
        return arc_distance2(Segment.from_frame(q[0], R[0], P[0]), p)

    for p in ([0.1, 0.2, 0.3], [0.0, 0.0, 0.5], [0.0, 0.0, 0.0]):
        for g in jax.grad(f, argnums=(0, 1))(jnp.array([[0.8, 0.0, 0.4]]), jnp.asarray(p)):
            assert_finite(g)
    q = jnp.array([[0.8, 0.7, 0.4]])
    centre = (0.8 / 0.7) * jnp.array([jnp.cos(0.4), jnp.sin(0.4), 0.0])  # every arc point equally far
    assert_allclose(f(q, centre), (0.8 / 0.7) ** 2, rtol=1e-14)
    for g in jax.grad(f, argnums=(0, 1))(q, centre):
        assert_finite(g)
