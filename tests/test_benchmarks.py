"""Smoke tests of the benchmark scripts and tests of ``random_scenarios``.

* ``benchmarks/paper_tables.py --quick`` (default run) and every other
  script's quick run (``slow``) run in subprocesses or in-process (outputs
  written to a temporary directory): they must finish, and their Markdown, JSON
  and figures must exist and parse. No timing is asserted (timings belong in
  the benchmarks). Each spends most of its time compiling; they share the
  suite's persistent compilation cache (conftest.py), so a rerun of the suite
  is much faster. Sharding over 2 host devices is tested on plan_batch itself
  (tests/test_batch.py), which the sweep calls.
* ``benchmarks/run_all.py`` knows every script of the folder, and each has a
  ``--quick`` mode; the scripts' argument checks and pure helpers.
* ``baselines.py judge`` on made-up saves (no planning): equal saves pass; a
  success rate moved by more than half a point or by a significant McNemar
  test, a collision of the curve model, mean iterations off by more than 2 %,
  the tree beyond 3 steps of 53 and a missing suite each fail their criterion
  and only theirs.
* ``random_scenarios``: seeded and deterministic, the requested shapes, each
  entry equal to ``make_scenario`` of its own obstacles, goals reachable (an
  independent least-squares inverse kinematics finds a configuration within
  the generator's bounds), obstacles crossing the straight start-tip -> goal
  path, and the promised clearances (checked with independent oracles: the
  closed-form closest point of a quadratic to a point, dense sampling against
  the straight start arm).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize
from session import subprocess_env

import softplan_jax as sp

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "benchmarks")
SUBPROCESS_TIMEOUT = 1200  # seconds; generous for a loaded 2-core machine


def _env(devices: int | None):
    # This checkout's softplan_jax, and the suite's persistent XLA compilation
    # cache, shared by these runs across test sessions (compilation dominates
    # the quick runs; a rerun reuses it).
    env = subprocess_env()
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    if devices:
        flags.append(f"--xla_force_host_platform_device_count={devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    env["MPLBACKEND"] = "Agg"
    return env


def _run(cmd, devices=None):
    """Run a benchmark script in a subprocess; (exit code, stdout, stderr)."""
    p = subprocess.run(cmd, cwd=ROOT, env=_env(devices), capture_output=True, text=True,
                       timeout=SUBPROCESS_TIMEOUT)
    return p.returncode, p.stdout, p.stderr


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory):
    """``paper_tables.py --quick`` once for the module: (output directory, its run)."""
    d = tmp_path_factory.mktemp("paper")
    cmd = [sys.executable, os.path.join(BENCH, "paper_tables.py"), "--quick", "--out", str(d / "paper_tables"),
           "--figures", str(d / "figures")]
    return d, _run(cmd)


def _ok(run):
    rc, stdout, stderr = run
    assert rc == 0, f"exit code {rc}\nstdout:\n{stdout[-3000:]}\nstderr:\n{stderr[-5000:]}"


@pytest.mark.slow  # a subprocess compiling the benchmark's own programs (~25 s); the paper's
# numbers themselves are checked in the default suite by test_presets
def test_paper_tables_quick(paper_run):
    d, run = paper_run
    _ok(run)
    report = json.loads((d / "paper_tables.json").read_text())
    md = (d / "paper_tables.md").read_text()
    assert report["quick"] is True
    assert report["machine"]["cpu_count"] >= 1 and report["machine"]["jax"] == jax.__version__
    assert report["machine"]["dtype"] == "float64"
    rows = report["rows"]
    assert {(r["scenario"], r["label"]) for r in rows} == {
        (s, m) for s in ("sim1", "sim2", "tree") for m in ("Proposed (curve)", "1 point")
    }
    for r in rows:
        assert r["status"] in sp.planning.STATUS_NAMES.values()
        assert 0 < r["iterations"] <= report["max_steps"]
        assert r["per_iteration_s"] > 0 and r["rollout_median_s"] > 0
        assert r["collided"] == (r["status"] == "collided")
        if r["method"] == "curve":
            assert r["reached"], r  # the paper's method reaches every paper goal
        paper = report["paper_results"][r["scenario"]].get("curve" if r["method"] == "curve" else str(r["n_points"]))
        if r["scenario"] == "tree":
            assert r["paper_iterations"] is None and paper is None
        else:
            assert [r["paper_iterations"], r["paper_time_s"]] == list(paper)
    for key in (
        "# The paper's Tables 2-4",
        "Table 2.",
        "Table 3.",
        "Table 4.",
        "not legible",
        "## Where ours differ",
        "start pose",
        "CPUs",
        f"jax {jax.__version__}",
        "float64",
        "## Compile times",
    ):
        assert key in md, key
    for name in ("sim1", "sim2", "tree"):
        assert (d / "figures" / f"paper_{name}_curve.png").stat().st_size > 10_000
    assert all(os.path.exists(p) for p in report["figures"])


# ----------------------------------------------------------------------------
# run_all.py and every script's quick run

# Modules of benchmarks/ that are not benchmark scripts: the runner, and the shared helpers, the NumPy peer
# and the parts of a script (each named with a leading underscore).
HELPERS = {"run_all"}
MOST_SCRIPTS = 16  # one per question, at most 16 in all (the curation's budget)


def _scripts():
    return sorted(f[:-3] for f in os.listdir(BENCH)
                  if f.endswith(".py") and f[:-3] not in HELPERS and not f.startswith("_"))


def test_run_all_runs_every_script_and_each_has_a_quick_mode():
    import run_all

    assert sorted(run_all.SCRIPTS) == _scripts() and len(_scripts()) <= MOST_SCRIPTS
    for name in _scripts():
        with open(os.path.join(BENCH, f"{name}.py"), encoding="utf-8") as fh:
            text = fh.read()
            assert '"--quick"' in text or "held_out_parser(" in text, f"{name}.py has no --quick"  # _common's has

    def planned(*argv):
        return run_all.plan_runs(run_all.parse_args(list(argv)))

    quick = planned("--quick")
    assert [n for n, _ in quick] == [n for n in run_all.SCRIPTS for _ in run_all.QUICK.get(n, [0])]
    assert all("--quick" in argv for _, argv in quick)
    assert ("paper_tables", ["--presets", "--quick"]) in quick and ("tuning", ["--tuners", "--quick"]) in quick
    assert [n for n, _ in planned("--quick", "--only", "evasion,closest")] == ["closest", "evasion"]
    assert "gpu" not in [n for n, _ in planned("--skip", "gpu")]
    assert [n for n, _ in planned("--only", "safe_step")] == ["safe_step"] * 3  # the three committed held-out runs
    assert planned("--only", "ab", "--with", "ab:--base /tmp/x/softplan_jax") == [
        ("ab", ["--base", "/tmp/x/softplan_jax"])]


def test_run_all_rejects_unknown_scripts(capsys):
    import run_all

    with pytest.raises(SystemExit):
        run_all.main(["--only", "no_such_script", "--dry-run"])
    assert "no_such_script" in capsys.readouterr().err
    assert run_all.main(["--quick", "--only", "closest", "--with", "closest:--candidates default", "--dry-run"]) == 0
    assert "closest.py --quick --candidates default" in capsys.readouterr().err


# Quick runs no other test below runs: (report name, script, its arguments before --quick --out DIR/NAME),
# in a subprocess.
QUICK_ONLY = [("ab", "ab", []), ("baselines", "baselines", []), ("closest", "closest", []),
              ("evasion", "evasion", []), ("gpu", "gpu", []), ("paper_presets", "paper_tables", ["--presets"]),
              ("speed_targets", "speed_targets", []), ("speed_targets_segments", "speed_targets", ["--segments"]),
              ("speed_targets_cold", "speed_targets", ["--cold"]),
              ("sweep_scale", "sweep_scale", []),
              ("throughput", "throughput", []), ("timing", "timing", []), ("tuners", "tuning", ["--tuners"]),
              ("viewer_latency", "viewer_latency", []), ("loaded", "loaded", [])]


@pytest.mark.bench
@pytest.mark.parametrize("name, script, extra", QUICK_ONLY, ids=[q[0] for q in QUICK_ONLY])
def test_quick_run_writes_its_report(tmp_path, name, script, extra):
    prefix = tmp_path / name
    args = (["save", f"{prefix}.npz", "--quick", "--fallback", "--suite", "16"] if name == "baselines"
            else [*extra, "--quick", "--out", str(prefix)])
    _ok(_run([sys.executable, os.path.join(BENCH, f"{script}.py"), *args]))
    report = json.loads((tmp_path / f"{name}.json").read_text())
    assert report and (tmp_path / f"{name}.md").read_text().startswith("#")
    if name in ("ab", "throughput", "tuners"):
        assert (tmp_path / "figures" / f"{name}.png").stat().st_size > 10_000
    if name == "baselines":
        assert (tmp_path / "baselines.npz").exists() and report["arrays"] > 0
        assert baselines_compare(tmp_path / "baselines.npz", tmp_path / "baselines.npz").startswith(
            f"{report['arrays']} of {report['arrays']} arrays bit-identical")
        assert report["suite"] == 16 and report["suite_seed"] == 1
        judged = _run([sys.executable, os.path.join(BENCH, "baselines.py"), "judge", str(tmp_path / "baselines.npz"),
                       str(tmp_path / "baselines.npz"), "--min-scenes", "16"])
        _ok(judged)
        assert "**PASS**: 9 of 9 criteria pass" in judged[1] and (tmp_path / "baselines.judge.md").exists()


def baselines_compare(a, b) -> str:
    p = subprocess.run([sys.executable, os.path.join(BENCH, "baselines.py"), "compare", str(a), str(b)],
                       capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT, env=_env(None), cwd=ROOT)
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_every_script_is_tested_by_a_quick_run():
    """Every script's quick run is run by one of the tests of this file."""
    own = {"paper_tables": "test_paper_tables_quick", "safe_step": "test_safe_step_quick_run_writes_its_report",
           "science": "test_science_quick_run", "tuning": "test_tuning_benchmark_quick_run",
           "reach": "test_reach_benchmark_quick_run"}
    assert all(callable(globals().get(test)) for test in own.values())
    assert {script for _, script, _ in QUICK_ONLY} | set(own) == set(_scripts())


# ----------------------------------------------------------------------------
# random_scenarios


def _leaves_equal(a, b):
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b) and all(
        x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(la, lb, strict=True)
    )


def test_random_scenarios_seeded_and_deterministic():
    a = sp.random_scenarios(7, 12)
    assert _leaves_equal(a, sp.random_scenarios(7, 12))
    assert not np.array_equal(a.goal, sp.random_scenarios(8, 12).goal)
    k = sp.random_scenarios(jax.random.PRNGKey(3), 4)
    assert _leaves_equal(k, sp.random_scenarios(jax.random.PRNGKey(3), 4))
    assert _leaves_equal(sp.random_scenarios(jax.random.key(3), 4), sp.random_scenarios(jax.random.key(3), 4))
    assert not np.array_equal(k.goal, sp.random_scenarios(jax.random.PRNGKey(4), 4).goal)


def test_random_scenarios_shapes_and_make_scenario_equality():
    n = 9
    suite = sp.random_scenarios(1, n)
    assert suite.q0.shape == (n, 3, 3) and suite.goal.shape == (n, 3)
    assert suite.curves.coeffs.shape == (n, 8, 3, 3) and suite.curves.u_range.shape == (n, 8, 2)
    assert suite.curve_mask.shape == (n, 8) and suite.curve_mask.dtype == jnp.bool_
    assert suite.q0.dtype == jnp.float64 and suite.goal.dtype == jnp.float64
    counts = np.asarray(suite.curve_mask).sum(1)
    assert counts.min() >= 1 and counts.max() <= 8
    # masks are a prefix: real slots first
    assert np.all(np.asarray(suite.curve_mask) == (np.arange(8)[None, :] < counts[:, None]))
    # each entry is make_scenario of its own curves, padded to (8 slots, degree 2)
    host = jax.tree_util.tree_map(np.asarray, suite)
    rebuilt = []
    for k in range(n):
        curves = [sp.PolynomialCurve(host.curves.coeffs[k, j], host.curves.u_range[k, j]) for j in range(counts[k])]
        rebuilt.append(sp.make_scenario(host.goal[k], curves, curve_slots=8, degree=2))
    assert _leaves_equal(suite, sp.scenarios.stack_scenarios(rebuilt))
    # float32: make_scenario's scenes from the same float64 draws, with a float32 start
    # (random_scenarios assembles the stack on the host, casting once)
    q0_32 = jnp.asarray(sp.scenarios.default_start(), jnp.float32)
    rebuilt32 = [sp.make_scenario(host.goal[k], [sp.PolynomialCurve(host.curves.coeffs[k, j], (0.0, 1.0))
                                                 for j in range(counts[k])], q0_32, curve_slots=8, degree=2)
                 for k in range(n)]
    assert _leaves_equal(sp.random_scenarios(1, n, dtype=jnp.float32), sp.scenarios.stack_scenarios(rebuilt32))
    # goal_clearance 0 (a goal may touch a curve): every scene through make_scenario
    assert sp.random_scenarios(1, 3, goal_clearance=0.0).curves.coeffs.shape == (3, 8, 3, 3)
    # other padded shapes, counts, degrees and dtypes
    small = sp.random_scenarios(2, 5, obstacles=(2, 3), degrees=(1,), curve_slots=4, degree=2, dtype=jnp.float32)
    assert small.curves.coeffs.shape == (5, 4, 3, 3) and small.curves.coeffs.dtype == jnp.float32
    c = np.asarray(small.curve_mask).sum(1)
    assert c.min() >= 2 and c.max() <= 3
    assert np.all(np.asarray(small.curves.coeffs)[..., 2] == 0.0)  # degree 1 only: no u^2 term
    one = sp.random_scenarios(2, 3, degrees=(2,), degree=2, obstacles=(1, 1))
    assert np.all(np.abs(np.asarray(one.curves.coeffs)[:, 0, :, 2]).sum(-1) > 0)


def test_random_scenarios_bad_input():
    for kwargs in (
        dict(n=0),
        dict(n=3, obstacles=(0, 2)),
        dict(n=3, obstacles=(3, 9)),
        dict(n=3, degrees=(3,)),
        dict(n=3, degrees=(2,), degree=1),
        dict(n=3, curve_length=(0.0, 1.0)),
    ):
        with pytest.raises(ValueError):
            sp.random_scenarios(0, **kwargs)
    with pytest.raises(ValueError):
        sp.random_scenarios("seed", 3)
    with pytest.raises(ValueError):
        sp.random_scenarios(-1, 3)


def _tip_np(q):
    """PCC tip position (paper §2.1) in plain NumPy: an independent oracle."""
    R, P = np.eye(3), np.zeros(3)
    for L, th, ph in q:
        c, s, cp, sph = np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
        Ri = np.array([[cp * c, -sph, cp * s], [sph * c, cp, sph * s], [-s, 0.0, c]])
        r = L / th * (1 - c) if abs(th) > 1e-12 else 0.0
        z = L / th * s if abs(th) > 1e-12 else L
        P = P + R @ np.array([r * cp, r * sph, z])
        R = R @ Ri
    return P


def test_random_scenarios_goals_reachable():
    """An independent IK (NumPy kinematics + scipy least squares, L = 1, theta in [0, 1.6])
    reaches every goal: the goals lie in the workspace the generator promises."""
    suite = sp.random_scenarios(11, 12)
    rng = np.random.default_rng(0)
    start = np.array([0.0, 0.0, 3.0])
    for g in np.asarray(suite.goal):
        assert np.linalg.norm(g - start) >= 0.5 - 1e-12
        best = np.inf
        for _ in range(20):
            x0 = np.concatenate([rng.uniform(0.0, 1.6, 3), rng.uniform(-np.pi, np.pi, 3)])
            sol = optimize.least_squares(
                lambda x, g=g: _tip_np(np.stack([np.ones(3), x[:3], x[3:]], 1)) - g,
                x0,
                bounds=([0.0] * 3 + [-4.0] * 3, [1.6] * 3 + [4.0] * 3),
                xtol=1e-14,
                ftol=1e-14,
                gtol=1e-14,
            )
            best = min(best, np.linalg.norm(sol.fun))
            if best < 1e-8:
                break
        assert best < 1e-8, (g, best)


def _quadratic_point_distance(coeffs, p):
    """Exact min over u in [0, 1] of |F(u) - p| for F(u) = k0 + k1 u + k2 u^2: the real
    roots of the cubic d/du |F - p|^2 = 0 in [0, 1], and both ends."""
    k0, k1, k2 = coeffs[:, 0] - p, coeffs[:, 1], coeffs[:, 2]
    # |F|^2 = |k0|^2 + 2 k0.k1 u + (|k1|^2 + 2 k0.k2) u^2 + 2 k1.k2 u^3 + |k2|^2 u^4
    deriv = [2 * k0 @ k1, 2 * (k1 @ k1 + 2 * k0 @ k2), 6 * k1 @ k2, 4 * k2 @ k2]
    roots = np.polynomial.polynomial.polyroots(np.trim_zeros(np.asarray(deriv), "b")) if np.any(deriv) else []
    us = [0.0, 1.0] + [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-9 and 0.0 <= r.real <= 1.0]
    return min(np.linalg.norm(k0 + k1 * u + k2 * u * u) for u in us)


def test_random_scenarios_block_the_path_with_clearance():
    """Every real obstacle crosses the straight start-tip -> goal segment within path_offset,
    perpendicular to it at its middle, at least start_clearance from the start arm and
    goal_clearance from the goal."""
    offset, clr_start, clr_goal = 0.1, 0.15, 0.15
    suite = sp.random_scenarios(5, 40, path_offset=offset, start_clearance=clr_start, goal_clearance=clr_goal)
    coeffs = np.asarray(suite.curves.coeffs)
    mask = np.asarray(suite.curve_mask)
    p0 = np.array([0.0, 0.0, 3.0])
    u = np.linspace(0.0, 1.0, 20001)
    for k, g in enumerate(np.asarray(suite.goal)):
        e = (g - p0) / np.linalg.norm(g - p0)
        for j in np.nonzero(mask[k])[0]:
            C = coeffs[k, j]
            pts = C[:, 0] + np.outer(u, C[:, 1]) + np.outer(u * u, C[:, 2])
            # distance of the curve's middle to the straight path segment (exact point-segment)
            mid = C[:, 0] + 0.5 * C[:, 1] + 0.25 * C[:, 2]
            t = np.clip((mid - p0) @ (g - p0) / ((g - p0) @ (g - p0)), 0.0, 1.0)
            assert np.linalg.norm(mid - (p0 + t * (g - p0))) <= offset + 1e-12
            assert 0.3 - 1e-9 <= t <= 0.7 + 1e-9  # mid lies beside the middle part of the path
            # it runs across the path: tangent at the middle perpendicular to it
            tangent = C[:, 1] + C[:, 2]
            assert abs(tangent @ e) <= 1e-9 * np.linalg.norm(tangent)
            # clearance from the goal (exact) and from the straight start arm (dense samples,
            # exact point-segment distances; upper bound within 1e-4 of the true distance)
            assert _quadratic_point_distance(C, g) >= clr_goal - 1e-12
            z = np.clip(pts[:, 2], 0.0, 3.0)
            d_arm = np.min(np.sqrt(pts[:, 0] ** 2 + pts[:, 1] ** 2 + (pts[:, 2] - z) ** 2))
            assert d_arm >= clr_start - 1e-9, (k, j, d_arm)


def test_plot_benchmark_rejects_bad_input():
    from softplan_jax.plotting import plot_benchmark

    with pytest.raises(ValueError):
        plot_benchmark(["curve", "N=1"], [1e-3, 0.0], [0.0, 0.5])
    with pytest.raises(ValueError):
        plot_benchmark(["curve", "N=1"], [1e-3], [0.0, 0.5])
    import matplotlib.pyplot as plt

    fig = plot_benchmark(["curve", "N=1", "N=10"], [3e-3, 1e-4, 2e-4], [0.0, 0.4, 0.1], success_rate=[0.8, 0.5, 0.7])
    assert fig.axes[0].get_xscale() == "log"
    plt.close(fig)


# ----------------------------------------------------------------------------
# safe_step.py


def test_safe_step_wilson_interval_matches_the_formula():
    import safe_step

    lo, hi = safe_step.wilson(5, 10)  # Wilson (1927): 0.5 +- 1.96 sqrt(0.025 + 0.0096) / 1.384
    assert abs(lo - 0.2366) < 1e-4 and abs(hi - 0.7634) < 1e-4
    lo, hi = safe_step.wilson(0, 1000)
    assert abs(lo) < 1e-12 and abs(hi - 0.00383) < 1e-5


@pytest.mark.bench
def test_safe_step_quick_run_writes_its_report(tmp_path):
    import safe_step

    out = safe_step.main(["--n", "4", "--chunk", "4", "--max-steps", "20", "--variants", "plain,default",
                          "--out", str(tmp_path / "ss")])
    rows = out["summary"]
    assert [r["label"] for r in rows] == ["plain/curve", "default/curve"]
    for r in rows:
        assert sum(r["counts"].values()) == 4
    saved = json.loads((tmp_path / "ss.json").read_text())
    assert len(saved["records"]["default/curve"]["status"]) == 4
    assert "Wilson" in (tmp_path / "ss.md").read_text()


@pytest.mark.bench
def test_science_quick_run(tmp_path):
    """The whole science pipeline at toy sizes: tuning, held-out, paired tests, figures, files."""
    import json

    import science

    out = tmp_path / "science"
    rep = science.main(["--quick", "--methods", "curve,10", "--grid-d0", "0.07", "--grid-dt", "0.1",
                        "--grid-eta", "0.001", "--grad-updates", "1", "--settings", "default,grid",
                        "--skip-paper-figures", "--out", str(out)])
    saved = json.loads((tmp_path / "science.json").read_text())
    assert saved["complete"] and set(saved["records"]) == {"default", "grid"}
    rec = saved["records"]["default"]["curve"]
    assert len(rec["status"]) == 16 == len(rec["iterations"]) == len(rec["min_clearance"])
    row = rep["summary"][0]
    assert row["intervals"]["reached"] == pytest.approx(science.wilson(row["counts"]["reached"], 16))
    assert (tmp_path / "figures" / "science_rates_vs_n.png").exists()


def test_importing_a_benchmark_script_changes_no_jax_setting():
    """Every script in benchmarks/ imports without switching float64 on (each ``main`` does)."""
    scripts = sorted(f[:-3] for f in os.listdir(BENCH) if f.endswith(".py"))
    code = (f"import importlib, sys, jax; sys.path.insert(0, {BENCH!r})\n"
            f"for m in {scripts!r}: importlib.import_module(m)\n"
            "print(jax.config.jax_enable_x64)")
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(None), capture_output=True, text=True,
                       timeout=SUBPROCESS_TIMEOUT)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.strip().splitlines()[-1] == "False", p.stdout
    assert "closest" in scripts and "science" in scripts


# ----------------------------------------------------------------------------
# tuning.py


def test_tuning_benchmark_rejects_bad_arguments():
    import tuning as tuning_bench

    for argv, match in ((["--pairs", "1"], "pairs"), (["--n-train", "0"], "n-train"), (["--sigma", "0"], "sigma"),
                        (["--fraction", "1000"], "budget"), (["--grad-names", "dt"], "grad-names"),
                        (["--grad-names", "d0,nope"], "grad-names"), (["--fn-lr", "-1"], "fn-lr"),
                        (["--max-step", "-0.1"], "max-step"), (["--max-step", "nan"], "max-step"),
                        (["--fraction", "nan"], "fraction"), (["--fraction", "0.5"], "fraction"),
                        (["--sigma", "0.3,0.7,0.5"], "one per --grad-names"), (["--sigma", "0.3,x"], "comma list"),
                        (["--sigma", "0.3,-1"], "sigma"), (["--fn-gain-sigma", "0.3,0.7"], "fn-gain-sigma"),
                        (["--fn-gain-sigma", "0,0.7,0.3"], "fn-gain-sigma")):
        with pytest.raises(ValueError, match=match):
            tuning_bench.parse_args(argv)
    # A fractional budget: 2/5 of the grid's 60 x 64 rollouts.
    assert tuning_bench.parse_args(["--fraction", "2.5", "--pairs", "32"]).budget == 1536
    # The guards reach tune_smoothed: by default the clip 0.3; --box: the grid's box; 0: no clip.
    kw = tuning_bench.grad_kwargs(tuning_bench.parse_args([]))
    assert kw["bounds"] is None and kw["max_step"] == 0.3
    # The recipe chosen on the validation seed: one sigma per tuned gain, the natural gradient from 3.75.
    assert kw["sigma"] == (0.3, 0.7) and kw["natural"] is True and kw["learning_rate"] == 3.75
    kw = tuning_bench.grad_kwargs(tuning_bench.parse_args(["--box", "--max-step", "0", "--sigma", "0.4",
                                                           "--no-natural"]))
    assert kw["bounds"] == dict(d0=(0.07, 0.4), dt=(0.1, 0.8)) and kw["max_step"] is None
    assert kw["sigma"] == 0.4 and kw["natural"] is False
    # The gain-function stage: d0, dt, eta's scales, then --fn-sigma for the 17 profile knots and weights.
    from softplan_jax.tuning import GainSpace

    args = tuning_bench.parse_args([])
    kw = tuning_bench.fn_kwargs(args, GainSpace(tuning_bench.TUNED, knots=14, segments=3))
    assert kw["sigma"] == (0.3, 0.7, 0.3) + (0.3,) * 17 and kw["natural"] and kw["max_step"] == 0.3
    assert tuning_bench.fn_kwargs(args, GainSpace(tuning_bench.TUNED))["sigma"] == (0.3, 0.7, 0.3)


@pytest.mark.bench
def test_tuning_benchmark_quick_run(tmp_path):
    """The whole comparison at toy sizes: every tuner, held-out records, paired tests, figures, files."""
    import json

    import tuning as tuning_bench

    out = tmp_path / "tuning"
    rep = tuning_bench.main(["--quick", "--out", str(out)])
    saved = json.loads((tmp_path / "tuning.json").read_text())
    res = saved["methods"]["curve"]
    assert set(res["heldout"]) == set(tuning_bench.SETTINGS)
    for h in res["heldout"].values():
        assert h["n"] == 16 and len(h["status"]) == 16 and 0 <= h["success"] <= 16
    # Equal budgets: random, CMA-ES and the gradient within the grid's / fraction.
    budget = rep["methods"]["curve"]["cost"]["grid"]["rollouts"] // 5
    for name in ("random", "cma", "cma-g", "gradient"):
        assert 0 <= res["cost"][name]["rollouts"] <= budget, name
    assert "Wilson" in (tmp_path / "tuning.md").read_text()
    assert (tmp_path / "figures" / "tuning_heldout.png").exists()


# ----------------------------------------------------------------------------
# reach.py


def test_reach_benchmark_rejects_bad_arguments():
    import reach as reach_bench

    for argv, match in ((["--n", "0"], "--n"), (["--chunk", "0"], "--chunk"), (["--max-steps", "0"], "--max-steps")):
        with pytest.raises(ValueError, match=match):
            reach_bench.parse_args(argv)


@pytest.mark.bench
def test_reach_benchmark_quick_run(tmp_path):
    """The whole benchmark at toy sizes (20 local steps, so that the search runs): files, checks, figures."""
    import json

    import reach as reach_bench

    rep = reach_bench.main(["--quick", "--n", "3", "--max-steps", "20", "--timing-scenes", "2",
                            "--out", str(tmp_path / "reach")])
    saved = json.loads((tmp_path / "reach.json").read_text())
    assert saved["settings"]["n"] == 3 and len(saved["per_scene"]) == 3
    assert rep["global_paths"] >= 1 and rep["collisions"] == 0 and rep["dense_collisions"] == 0
    assert rep["swept_proof_failures"] == 0 and not rep["unlabelled"]
    assert all(v["identical"] for v in rep["paper"].values())
    assert "95 % interval" in (tmp_path / "reach.md").read_text()
    assert (tmp_path / "figures" / "reach_time.png").exists()


def test_throughput_rejects_bad_arguments():
    import throughput

    for argv in (["--sizes", "0,4"], ["--sizes", "a"], ["--devices", "0"], ["--steps", "0"], ["--rounds", "0"],
                 ["--lanes", "0"], ["--lanes", "b"], ["--lanes", ""], ["--dtype", "float16"]):
        with pytest.raises(SystemExit) as e:
            throughput.parse_args(argv)
        assert e.value.code == 2, argv
    assert throughput.parse_args(["--lanes", "64,B"]).lane_list == [64, "B"]


def test_gpu_script_rejects_bad_arguments(tmp_path):
    import gpu

    for argv in (["--sizes", "0"], ["--sizes", "a"], ["--steps", "0"], ["--rounds", "0"], ["--parts", "plan,x"],
                 ["--tracking-size", "0"], ["--tracking-steps", "-1"]):
        with pytest.raises(SystemExit) as e:
            gpu.parse_args([*argv, "--out", str(tmp_path / "g")])
        assert e.value.code == 2, argv
    a = gpu.parse_args(["--quick", "--out", str(tmp_path / "g")])
    assert (a.size_list, a.steps, a.part_list) == ([8], 10, ["plan", "batch", "float32"])
    assert (a.tracking_size, a.tracking_steps) == (8, 20)


def test_baselines_compare_tells_steps_taken_from_the_tail(tmp_path, capsys):
    """benchmarks/baselines.py compare: equal arrays counted; a difference after a rollout's end
    (its iterations) is told apart from one within the steps taken."""
    import baselines

    q = np.zeros((2, 6, 1))
    a = {"g/iterations": np.array([2, 5]), "g/q": q, "g/status": np.array([1, 4])}
    b = {"g/iterations": np.array([2, 5]), "g/q": q.copy(), "g/status": np.array([1, 4])}
    b["g/q"][0, 4] = 1.0  # scene 0 after its end (step 2)
    b["g/q"][1, 3] = 0.5  # scene 1 within its steps
    np.savez(tmp_path / "a.npz", **a)
    np.savez(tmp_path / "b.npz", **b)
    assert baselines.main(["compare", str(tmp_path / "a.npz"), str(tmp_path / "b.npz")]) == 0
    out = capsys.readouterr().out
    assert "2 of 3 arrays bit-identical" in out
    assert "g/q: 1 of 2 rollouts differ within the steps taken; max |diff| 1" in out


# ----------------------------------------------------------------------------
# baselines.py judge, on synthetic saves (no planning)


def _judged_save(n=1024, seed=0) -> dict:
    """The arrays ``save --fallback --suite n`` writes that ``judge`` reads, made up: n scenes per
    suite, brute-force audits, the paper tree and sim1, a moving preset, 48 fallback scenes."""
    rng = np.random.default_rng(seed)
    reached, max_steps = int(sp.Status.REACHED), int(sp.Status.MAX_STEPS)
    d = {"suite/seed": np.int64(1), "suite/max_steps": np.int64(600), "suite/moving_steps": np.int64(300)}
    for model, rate in (("curve10", 0.9), ("points10", 0.45), ("moving", 0.83)):
        ok = rng.random(n) < rate
        d[f"suite/{model}/status"] = np.where(ok, reached, max_steps).astype(np.int32)
        d[f"suite/{model}/iterations"] = np.where(ok, rng.integers(40, 300, n), 600).astype(np.int32)
        d[f"suite/{model}/reached"] = ok
        d[f"suite/{model}/collided"] = np.zeros(n, bool)
    for audit in ("suite/curve10", "suite/moving"):
        d[f"audit/{audit}/scene"] = np.arange(8, dtype=np.int32)
        d[f"audit/{audit}/brute_clearance"] = rng.uniform(0.01, 0.05, 8)
    for run, its in (("paper/tree/curve10/default", 53), ("paper/sim1/curve10/default", 66), ("moving/tree_sway", 400)):
        d.update({f"{run}/status": np.int32(reached), f"{run}/iterations": np.int32(its), f"{run}/collided": np.False_})
    d.update({f"fallback/{i}/status": np.array("reached") for i in range(48)})
    return d


def _failing(tmp_path, before: dict, after: dict) -> set:
    """The criteria ``judge`` fails for save ``after`` against ``before``."""
    import _judge

    np.savez(tmp_path / "before.npz", **before)
    np.savez(tmp_path / "after.npz", **after)
    _, checks = _judge.verdict(np.load(tmp_path / "before.npz"), np.load(tmp_path / "after.npz"))
    assert len(checks) == 9
    return {name for name, ok, _ in checks if not ok}


def _lose(d: dict, model: str, k: int, gained: int = 0) -> dict:
    """``d`` with the first ``k`` reached scenes of ``model``'s suite at max_steps instead (and the
    first ``gained`` scenes not reached, reached)."""
    d = {key: v.copy() for key, v in d.items()}
    ok = d[f"suite/{model}/reached"]
    lost, won = np.flatnonzero(ok)[:k], np.flatnonzero(~ok)[:gained]
    d[f"suite/{model}/status"][lost] = int(sp.Status.MAX_STEPS)
    d[f"suite/{model}/status"][won] = int(sp.Status.REACHED)
    ok[lost], ok[won] = False, True
    return d


def test_baselines_judge_passes_equal_saves_and_writes_its_report(tmp_path, capsys):
    import baselines

    save = _judged_save()
    np.savez(tmp_path / "a.npz", **save)
    np.savez(tmp_path / "b.npz", **save)
    assert baselines.main(["judge", str(tmp_path / "a.npz"), str(tmp_path / "b.npz")]) == 0
    out = capsys.readouterr().out
    assert "**PASS**: 9 of 9 criteria pass" in out and "FAIL" not in out
    assert f"{len(save)} of {len(save)} arrays bit-identical" in out
    assert (tmp_path / "b.judge.md").read_text().strip() == out.split("\nwritten to ")[0].strip()
    # The suite must be large enough: 1,024 scenes unless told otherwise.
    small = _judged_save(n=64)
    np.savez(tmp_path / "s.npz", **small)
    assert baselines.main(["judge", str(tmp_path / "s.npz"), str(tmp_path / "s.npz")]) == 1
    assert baselines.main(["judge", str(tmp_path / "s.npz"), str(tmp_path / "s.npz"), "--min-scenes", "64"]) == 0


def test_baselines_judge_success_within_half_a_point_and_mcnemar(tmp_path):
    before = _judged_save()
    # 5 of 1,024 scenes lost: -0.49 points, McNemar p = 2 / 2^5 = 0.0625; 6 lost: -0.59 points, p = 0.031.
    assert _failing(tmp_path, before, _lose(before, "curve10", 5)) == set()
    assert _failing(tmp_path, before, _lose(before, "curve10", 6)) == {"success, curve10"}
    assert _failing(tmp_path, before, _lose(before, "moving", 40)) == {"success, moving"}
    # Lost and gained alike: the rate is the same, McNemar's test sees the 40 discordant scenes as noise.
    assert _failing(tmp_path, before, _lose(before, "points10", 20, gained=20)) == set()
    # 20 lost, 13 gained: -0.68 points with p = 0.30: the rate moved too far, though not significantly.
    assert _failing(tmp_path, before, _lose(before, "points10", 20, gained=13)) == {"success, points10"}
    assert _failing(tmp_path, _lose(before, "points10", 60), before) == {"success, points10"}
    # At 1,024 scenes the half point is the stricter bound; on 2,048, 10 lost are -0.49 points and
    # p = 2 / 2^10: McNemar's test fails them.
    large = _judged_save(n=2048)
    assert _failing(tmp_path, large, _lose(large, "curve10", 10)) == {"success, curve10"}


def test_baselines_judge_fails_a_collision_of_the_curve_model(tmp_path):
    before = _judged_save()
    hit = {k: v.copy() for k, v in before.items()}
    hit["suite/curve10/collided"][3] = True
    assert _failing(tmp_path, before, hit) == {"collisions, curve model"}
    hit = {k: v.copy() for k, v in before.items()}
    hit["audit/suite/moving/brute_clearance"][0] = -1e-4  # the brute force finds a contact the planner missed
    assert _failing(tmp_path, before, hit) == {"collisions, curve model"}
    hit = {k: v.copy() for k, v in before.items()}
    hit["fallback/7/status"] = np.array("collided")
    assert _failing(tmp_path, before, hit) == {"collisions, curve model"}
    # The 10-point model's collisions are its results, not a failure.
    points = {k: v.copy() for k, v in before.items()}
    points["suite/points10/collided"][3] = True
    assert _failing(tmp_path, before, points) == set()


def test_baselines_judge_mean_iterations_within_two_percent(tmp_path):
    before = _judged_save()
    for scale, failing in ((1.01, set()), (1.05, {"iterations, curve10"}), (0.95, {"iterations, curve10"})):
        after = {k: v.copy() for k, v in before.items()}
        its = after["suite/curve10/iterations"]
        after["suite/curve10/iterations"] = np.round(its * scale).astype(its.dtype)
        assert _failing(tmp_path, before, after) == failing, scale


def test_baselines_judge_paper_scenes_and_missing_parts(tmp_path):
    before = _judged_save()
    for its, failing in ((56, set()), (57, {"tree within 3 steps of 53"})):
        after = dict(before, **{"paper/tree/curve10/default/iterations": np.int32(its)})
        assert _failing(tmp_path, before, after) == failing, its
    lost = dict(before, **{"paper/sim1/curve10/default/status": np.int32(sp.Status.STALLED)})
    assert _failing(tmp_path, before, lost) == {"paper scenes and moving presets still reached"}
    bare = {k: v for k, v in before.items() if not k.startswith(("suite/", "fallback/"))}
    assert _failing(tmp_path, before, bare) == {"success, curve10", "success, points10", "success, moving",
                                                "iterations, curve10", "iterations, points10", "fallback batch"}
