"""The user-facing persistent compilation cache (softplan_jax.base._compilation_cache)."""

import os
import subprocess
import sys

import pytest
from session import REPO, subprocess_env

from softplan_jax.base._compilation_cache import compilation_cache_dir


def test_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("SOFTPLAN_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("SOFTPLAN_CACHE_DIR", str(tmp_path / "c"))
    assert compilation_cache_dir() == os.path.join(str(tmp_path / "c"), "jax")
    monkeypatch.delenv("SOFTPLAN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert compilation_cache_dir() == os.path.join(str(tmp_path / "xdg"), "softplan_jax", "jax")
    for off in ("0", "off", "false"):
        monkeypatch.setenv("SOFTPLAN_COMPILATION_CACHE", off)
        assert compilation_cache_dir() is None


def _enable_in_fresh_process(env_updates, drop=()):
    env = subprocess_env()
    for k in ("JAX_COMPILATION_CACHE_DIR", "SOFTPLAN_CACHE_DIR", "SOFTPLAN_COMPILATION_CACHE", *drop):
        env.pop(k, None)
    env.update(env_updates)
    code = ("import jax, softplan_jax as sp; d = sp.enable_compilation_cache(); "
            "print(d); print(jax.config.jax_compilation_cache_dir)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_enable_sets_the_user_cache_and_respects_opt_out_and_user_settings(tmp_path):
    d, cfg = _enable_in_fresh_process({"XDG_CACHE_HOME": str(tmp_path)})
    assert d == cfg == os.path.join(str(tmp_path), "softplan_jax", "jax") and os.path.isdir(d)
    d, cfg = _enable_in_fresh_process({"XDG_CACHE_HOME": str(tmp_path), "SOFTPLAN_COMPILATION_CACHE": "0"})
    assert d == "None" and cfg == "None"
    mine = str(tmp_path / "mine")
    d, cfg = _enable_in_fresh_process({"JAX_COMPILATION_CACHE_DIR": mine, "XDG_CACHE_HOME": str(tmp_path)})
    assert d == cfg == mine


def test_traced_rollout_is_kept_on_disk_and_gives_the_same_result(monkeypatch, tmp_path):
    """rollout_jit.cached: the first call traces and writes a jax.export artifact, the
    next loads it (no tracing) -- both bit-identical to rollout_jit; a damaged artifact
    is traced again; the opt-out writes nothing.
    (The cheapest program of the suite: points method, no checks, 15 steps.)"""
    import jax
    import numpy as np

    import softplan_jax as sp
    from softplan_jax.planning._planner import make_options
    from softplan_jax.planning._programs import rollout_jit

    monkeypatch.delenv("SOFTPLAN_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("SOFTPLAN_CACHE_DIR", str(tmp_path))
    sc, g = sp.paper_scenario("sim1"), sp.default_gains()
    opts = make_options("points", 10, check_collisions=False)
    reference = rollout_jit(sc, g, opts, 15, 2)

    def same(r):
        return all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
                   for a, b in zip(jax.tree_util.tree_leaves(r), jax.tree_util.tree_leaves(reference), strict=True))

    run, loaded = rollout_jit.cached(sc, g, opts, 15)
    files = sorted((tmp_path / "exported").iterdir())
    assert not loaded and len(files) == 1 and same(run(sc, g, 2))
    run, loaded = rollout_jit.cached(sc, g, opts, 15)
    assert loaded and same(run(sc, g, 2))
    # other goals and seeds: the same program
    sc2 = sc._replace(goal=sc.goal + 0.01)
    assert not np.array_equal(np.asarray(run(sc2, g, 2).q), np.asarray(reference.q))
    # a damaged artifact is traced again (and replaced)
    files[0].write_bytes(b"not an artifact")
    run, loaded = rollout_jit.cached(sc, g, opts, 15)
    assert not loaded and same(run(sc, g, 2)) and files[0].stat().st_size > 1000
    # the opt-out
    monkeypatch.setenv("SOFTPLAN_CACHE_DIR", str(tmp_path / "off"))
    monkeypatch.setenv("SOFTPLAN_COMPILATION_CACHE", "0")
    run, loaded = rollout_jit.cached(sc, g, opts, 15)
    assert not loaded and same(run(sc, g, 2)) and not (tmp_path / "off").exists()


def test_rollouts_compile_with_the_package_xla_options(monkeypatch):
    """rollout_jit compiles with compilation_cache.CPU_COMPILER_OPTIONS (no YNN fusions in
    its program, which XLA's defaults put there), and a curve-method rollout also with
    CURVE_CPU_COMPILER_OPTIONS, passed per program: a plain jax.jit of the same rollout
    keeps XLA's defaults, and so does rollout_jit called inside the user's own jit;
    SOFTPLAN_XLA_OPTIONS=0 turns them off.
    (The cheapest program of the suite: points method, no checks, 15 steps.)"""
    import jax
    import numpy as np

    import softplan_jax as sp
    from softplan_jax.base._compilation_cache import (
        CPU_COMPILER_OPTIONS,
        CURVE_CPU_COMPILER_OPTIONS,
        XLA_DEFAULT_OPTIONS,
        compiler_options,
    )
    from softplan_jax.planning._options import rollout_compiler_options
    from softplan_jax.planning._planner import make_options
    from softplan_jax.planning._programs import rollout, rollout_jit

    sc, g, key = sp.paper_scenario("sim1"), sp.default_gains(), jax.random.PRNGKey(0)
    opts = make_options("points", 10, check_collisions=False)
    # the suite runs on the CPU, with a jaxlib that knows every option
    assert rollout_compiler_options("points") == {**XLA_DEFAULT_OPTIONS, **CPU_COMPILER_OPTIONS}
    assert rollout_compiler_options("curve") == {**XLA_DEFAULT_OPTIONS, **CPU_COMPILER_OPTIONS,
                                                 **CURVE_CPU_COMPILER_OPTIONS}
    assert compiler_options(None) == XLA_DEFAULT_OPTIONS
    assert rollout_compiler_options() == rollout_compiler_options("curve") == compiler_options("exact")
    assert rollout_compiler_options("points") == compiler_options("samples")
    with pytest.raises(ValueError, match="method"):
        rollout_compiler_options("Curve")
    with pytest.raises(ValueError, match="kind"):
        compiler_options("curve")
    ours = rollout_jit.lower(sc, g, opts, 15).compile().as_text()
    plain = jax.jit(lambda s, g, k: rollout(s, g, opts, 15, k)).lower(sc, g, key).compile().as_text()
    assert "ynn_fusion" in plain and "ynn_fusion" not in ours
    # Inside a user's jit (compiler options are for top-level jits only): the enclosing program's options.
    inner = jax.jit(lambda s: rollout_jit(s, g, opts, 15, 2).q)(sc)
    outer = rollout_jit(sc, g, opts, 15, 2).q
    np.testing.assert_allclose(np.asarray(inner), np.asarray(outer), rtol=0, atol=1e-9)
    try:
        monkeypatch.setenv("SOFTPLAN_XLA_OPTIONS", "0")
        compiler_options.cache_clear()
        assert rollout_compiler_options("points") is None and rollout_compiler_options("curve") is None
    finally:
        monkeypatch.undo()
        compiler_options.cache_clear()
    assert rollout_compiler_options("points") == {**XLA_DEFAULT_OPTIONS, **CPU_COMPILER_OPTIONS}


def test_xla_options_this_jaxlib_does_not_know_are_left_out(monkeypatch):
    """An option that XLA has renamed or retired is dropped on its own; the others stay."""
    from softplan_jax.base import _compilation_cache as cc

    known = dict(cc.CPU_COMPILER_OPTIONS)
    monkeypatch.setattr(cc, "CPU_COMPILER_OPTIONS", {"xla_cpu_no_such_option": True, **known})
    try:
        cc.compiler_options.cache_clear()
        assert cc.compiler_options("samples") == {**cc.XLA_DEFAULT_OPTIONS, **known}
        monkeypatch.setattr(cc, "CPU_COMPILER_OPTIONS", {"xla_cpu_no_such_option": True})
        monkeypatch.setattr(cc, "CURVE_CPU_COMPILER_OPTIONS", {"xla_cpu_no_such_option_either": False})
        monkeypatch.setattr(cc, "XLA_DEFAULT_OPTIONS", {"xla_cpu_no_such_option_either": True})
        cc.compiler_options.cache_clear()
        assert cc.compiler_options("exact") is None and cc.compiler_options("samples") is None
    finally:
        monkeypatch.undo()
        cc.compiler_options.cache_clear()


def test_package_jit_inside_the_users_jit_and_transforms():
    """package_jit (how the package jits closest_point, planner_step, the fallback's and the
    brute-force programs): called at top level it compiles with the package's options (one
    program, counted); inside the user's jit, where jax refuses compiler options on a nested
    jit, a plain jit of the same function gives the same values; under grad (outside a jit)
    the derivative is right; a ValueError of the function itself is not swallowed."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from softplan_jax.base._compilation_cache import compiler_options, package_jit

    f = package_jit(lambda x, k: jnp.sin(x) * k, static_argnames=("k",))
    x = jnp.linspace(0.0, 1.0, 5)
    np.testing.assert_allclose(np.asarray(f(x, k=2)), 2 * np.sin(np.asarray(x)), rtol=1e-15)
    assert f._cache_size() == 1
    assert f.jitted().lower(x, k=2).compile()  # the top-level jit lowers ahead of time
    inner = jax.jit(lambda x: f(x, k=2) + 1.0)(x)
    np.testing.assert_allclose(np.asarray(inner), 2 * np.sin(np.asarray(x)) + 1.0, rtol=1e-15)
    assert f._cache_size() == 1  # the nested call compiled nothing at top level
    g = jax.grad(lambda x: jnp.sum(f(x, k=3)))(x)
    np.testing.assert_allclose(np.asarray(g), 3 * np.cos(np.asarray(x)), rtol=1e-14)

    def bad(x):
        raise ValueError("bad input, not a nesting")

    with pytest.raises(ValueError, match="bad input"):
        package_jit(bad)(x)
    with pytest.raises(ValueError, match="kind"):
        package_jit(lambda x: x, kind="curve")(x)
    assert compiler_options("exact")  # the suite's CPU jaxlib knows the options


def test_planner_step_rejects_options_that_are_not_plan_options():
    import softplan_jax as sp

    sc = sp.paper_scenario("sim1")
    with pytest.raises(ValueError, match="PlanOptions"):
        sp.planning.planner_step(sc.q0, sc, sp.default_gains(), {"method": "curve"})


# The probe of the test below, run in this process and in one without the suite's XLA flags (OUT: an .npz path).
_FLAG_PROBE = """
import jax
import numpy as np
jax.config.update("jax_enable_x64", True)
import softplan_jax as sp
sc, gains, opts = sp.apply_preset("paper", sp.paper_scenario("sim2"))
runs = {m: sp.plan(sc, m, 10, gains=gains, max_steps=40, **opts) for m in ("points", "curve")}
np.savez(OUT, **{f"{m}/{a}": np.asarray(getattr(r, a)) for m, r in runs.items() for a in ("q", "clearance")})
"""


@pytest.mark.slow
def test_package_programs_do_not_depend_on_the_suites_xla_flags(tmp_path):
    """tests/conftest.py compiles the suite with --xla_cpu_use_fusion_emitters=false and
    --xla_backend_optimization_level=0 (quicker compiles of its many small programs); the
    package's programs name both options per program (rollout_compiler_options, package_jit),
    so the rollouts tested here are the ones a user's process compiles (without the names,
    each flag changes the last bits below). The probe: sim2 with the
    paper's step and gains, where the plain step (dt = 1) turns a 1e-16 difference into
    1e-1 within 40 steps (test_presets), planned with each method here and in a fresh process
    without any XLA_FLAGS or compilation cache: the trajectories and clearances are equal bit
    for bit."""
    import numpy as np

    flags = os.environ.get("XLA_FLAGS", "")
    if "--xla_backend_optimization_level=0" not in flags or "--xla_cpu_use_fusion_emitters=false" not in flags:
        pytest.skip("XLA_FLAGS of the user's own set these options: the suite runs without its flags")
    here, there = str(tmp_path / "here.npz"), str(tmp_path / "there.npz")
    exec(_FLAG_PROBE, {"OUT": here})
    env = subprocess_env()
    for k in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR"):
        env.pop(k, None)
    env["SOFTPLAN_COMPILATION_CACHE"] = "0"
    out = subprocess.run([sys.executable, "-c", f"OUT = {there!r}\n{_FLAG_PROBE}"], capture_output=True,
                         text=True, env=env, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stderr
    a, b = np.load(here), np.load(there)
    assert sorted(a.files) == sorted(b.files) == ["curve/clearance", "curve/q", "points/clearance", "points/q"]
    for k in a.files:
        assert a[k].shape == b[k].shape and np.array_equal(a[k], b[k]), k


def test_a_one_shot_rollout_compiles_at_level_0_and_agrees_to_rounding(monkeypatch, tmp_path):
    """``rollout_jit.cached(..., one_shot=True)``, the program of ``softplan run``: the package's
    XLA options with the lowest optimization level, the same traced artifact as the default
    program, and the default program's results to rounding (the suite's cheapest program)."""
    import jax
    import numpy as np

    import softplan_jax as sp
    from softplan_jax.base._compilation_cache import (
        CPU_COMPILER_OPTIONS,
        ONE_SHOT_OPTIONS,
        XLA_DEFAULT_OPTIONS,
        one_shot_options,
    )
    from softplan_jax.planning._options import rollout_compiler_options
    from softplan_jax.planning._planner import make_options
    from softplan_jax.planning._programs import rollout_jit

    assert ONE_SHOT_OPTIONS == {"xla_backend_optimization_level": 0}
    assert rollout_compiler_options("points", one_shot=True) == {**XLA_DEFAULT_OPTIONS, **CPU_COMPILER_OPTIONS,
                                                                 **ONE_SHOT_OPTIONS}
    assert one_shot_options(None) == {**XLA_DEFAULT_OPTIONS, **ONE_SHOT_OPTIONS}
    monkeypatch.delenv("SOFTPLAN_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("SOFTPLAN_CACHE_DIR", str(tmp_path))
    sc, g = sp.paper_scenario("sim1"), sp.default_gains()
    opts = make_options("points", 10, check_collisions=False)
    reference = jax.device_get(rollout_jit(sc, g, opts, 15, 2))
    run, loaded = rollout_jit.cached(sc, g, opts, 15, one_shot=True)
    r = jax.device_get(run(sc, g, 2))
    assert not loaded and int(r.status) == int(reference.status) and int(r.iterations) == int(reference.iterations)
    np.testing.assert_allclose(r.q, reference.q, rtol=0, atol=1e-9)
    _, loaded = rollout_jit.cached(sc, g, opts, 15)  # the default program, from the same artifact
    assert loaded and len(list((tmp_path / "exported").iterdir())) == 1


def _backend_compiles(fn) -> int:
    """How many XLA programs ``fn()`` compiles (jax's backend-compile events)."""
    import jax

    events = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            events.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    return len(events)


def test_building_a_scene_compiles_nothing():
    """make_scenario and make_moving_scenario work in NumPy and move each array once
    (``host_array``): eager jnp operations would compile a small program for every new shape,
    which a first plan's host path paid many times (a scene of a shape built nowhere else)."""
    import numpy as np

    import softplan_jax as sp

    curves = [sp.PolynomialCurve(np.array([[0.3, 1.0], [0.2, 0.0], [0.5, 0.1]]), (0.0, 1.0), 0.05)] * 2
    motion = sp.moving.curve_motion(pivot=(0.3, 0.2, 0.5), axis=(0.0, 1.0, 0.0), amplitude=0.2, omega=1.0)
    q0 = np.array([[1.1, 0.2, 0.3]] * 3)

    def build():
        scene = sp.make_scenario([1.0, 0.4, 1.9], [*curves, np.ones((5, 3))], q0, arm_radius=0.02, L_min=[0.5] * 3,
                                 L_max=2.0, curve_slots=11, max_points=7)
        sp.moving.make_moving_scenario(scene, {1: motion})

    assert _backend_compiles(build) == 0
