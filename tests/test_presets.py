"""Gain presets (softplan_jax.planning._presets) and the CLI's ``--gains`` option.

The paper preset's figures checked here are the ones issue 10 quotes (and an
independent NumPy implementation, benchmarks/_numpy_baseline.py, reproduces:
see benchmarks/results/paper_tables.md); the fast tests run short rollouts,
the full table is a slow test.
"""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.planning._presets import PRESETS, preset


def test_preset_data():
    p = preset("paper")
    assert p.gains == dict(k_att=1.0, v_max=0.1, eta=1e-3, d0=0.15, rep_max=math.inf, damping=0.0, dt=1.0)
    assert p.options == dict(sp.PAPER_STEP)
    assert (p.start_theta, p.start_phi) == (0.1, 0.0)
    d = preset("default")
    assert d.gains == {k: float(v) for k, v in sp.default_gains()._asdict().items()}
    assert d.options == {} and d.start_theta is None and d.start_phi is None
    assert set(PRESETS) == {"paper", "default"}
    with pytest.raises(ValueError, match="unknown gain preset"):
        preset("fast")
    with pytest.raises(ValueError, match="must be a Scenario"):
        sp.apply_preset("paper", np.zeros((3, 3)))


def test_apply_preset_start_pose_and_plain_pinv_well_defined():
    for name in ("sim1", "sim2", "tree"):
        base = sp.paper_scenario(name)
        sc, gains, opts = sp.apply_preset("paper", base)
        q0 = np.asarray(sc.q0)
        np.testing.assert_array_equal(q0[:, 0], np.asarray(base.q0)[:, 0])
        np.testing.assert_array_equal(q0[:, 1:], np.tile([0.1, 0.0], (3, 1)))
        assert float(gains.damping) == 0 and float(gains.rep_max) == math.inf
        # The plain pseudo-inverse J^T (J J^T)^-1 needs J J^T invertible at the start: it is.
        J = np.asarray(sp.geometry.tip_jacobian(sc.q0))
        assert np.linalg.svd(J, compute_uv=False)[-1] > 0.05
        same, g_def, o_def = sp.apply_preset("default", base)
        np.testing.assert_array_equal(np.asarray(same.q0), np.asarray(base.q0))
        assert o_def == {} and float(g_def.d0) == float(sp.default_gains().d0)
    # A batch of scenarios: the start pose of every one is set.
    batch = sp.random_scenarios(0, 3)
    sc, _, _ = sp.apply_preset("paper", batch)
    np.testing.assert_array_equal(np.asarray(sc.q0)[..., 1], 0.1)


def test_uncapped_repulsion_is_khatib_and_differentiable():
    g = sp.default_gains()._replace(rep_max=jnp.asarray(jnp.inf), eta=jnp.asarray(1e-3), d0=jnp.asarray(0.15))
    V = jnp.array([0.0, 0.0, 0.05])
    for d in (0.01, 0.05, 0.149, 0.2):
        raw = 1e-3 * (1 / d - 1 / 0.15) / d**2 if d < 0.15 else 0.0
        np.testing.assert_allclose(float(jnp.linalg.norm(sp.planning.repulsion(V, d, g))), raw, rtol=1e-12, atol=1e-300)

    def mag(eta, d):
        return jnp.linalg.norm(sp.planning.repulsion(V, d, g._replace(eta=eta)))

    for d in (0.05, 0.2):
        grad = jax.grad(mag)(jnp.asarray(1e-3), d)
        assert np.isfinite(float(grad))
    np.testing.assert_allclose(float(jax.grad(mag)(jnp.asarray(1e-3), 0.05)), (1 / 0.05 - 1 / 0.15) / 0.05**2)


def test_paper_preset_sim2_ten_points_collide_at_step_21():
    sc, gains, opts = sp.apply_preset("paper", sp.paper_scenario("sim2"))
    r = sp.plan(sc, "points", 10, gains=gains, max_steps=40, **opts)
    assert r.status == "collided" and r.iterations == 21


def test_cli_gains_paper_shows_the_collision(capsys, monkeypatch):
    # The run of the test above: without the CLI's traced-program artifact (the artifact is
    # test_compilation_cache's), the command compiles the same program as sp.plan did, found
    # in the compilation cache instead of compiled a second time.
    monkeypatch.setattr(sp.base._compilation_cache, "_exported_dir", lambda: None)
    code = main(["run", "sim2", "--gains", "paper", "--method", "points", "--n-points", "10",
                 "--max-steps", "40", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    s = json.loads(out)
    assert (s["gains"], s["step"], s["status"], s["iterations"], s["collided"]) == ("paper", "plain", "collided",
                                                                                     21, True)
    assert main(["run", "sim2", "--gains", "fast"]) == 2  # neither a preset nor a gains file
    assert "neither a gain preset" in capsys.readouterr().err


# The figures of issue 10 (curve / 1 / 10 / 50 / 100 points); "c21" = collided at step 21.
# Sim2's curve count depends on rounding (the plain step with dt = 1 amplifies a 1e-16
# difference to 1e-1 within 60 steps): 73 with LAPACK's 3x3 solve, 69 with solve_small,
# 70 with the rollouts' first XLA options (no YNN fusions), 72 with the present ones
# (also no MLIR fusion emitters), 71 and 75 in two NumPy implementations; the outcome
# (reached, clearance 0.109) is the same. That entry is checked as "reached within
# ROUNDING_SENSITIVE's range"; every other entry exactly.
PAPER_PRESET_TABLE = {
    "sim1": ["r33", "r23", "r30", "r35", "r32"],
    "sim2": ["r72", "c21", "c21", "c32", "r64"],
    "tree": ["r27", "r20", "r36", "r36", "r28"],
}
ROUNDING_SENSITIVE = {("sim2", 0): range(66, 77)}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(PAPER_PRESET_TABLE))
def test_paper_preset_table(name):
    # Padded to one shape (one compilation per method for the three scenes); padding changes
    # nothing (with the plain pseudo-inverse it once gave NaN: the padding slots' Jacobians).
    sc, gains, opts = sp.apply_preset("paper", sp.paper_scenario(name, curve_slots=5, degree=2))
    got = []
    for method, n in (("curve", 10), ("points", 1), ("points", 10), ("points", 50), ("points", 100)):
        r = sp.plan(sc, method, n, gains=gains, max_steps=150, **opts)
        got.append(f"{r.status[0]}{r.iterations}")
    want = list(PAPER_PRESET_TABLE[name])
    for (scene, k), allowed in ROUNDING_SENSITIVE.items():
        if scene == name:
            assert got[k][0] == "r" and int(got[k][1:]) in allowed, (got[k], allowed)
            got[k] = want[k] = "r"
    assert got == want
