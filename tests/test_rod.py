"""The loaded arm (softplan_jax.rod) against independent references: the PCC kinematics with no
load, the small-deflection cantilever formulas, finite differences, dense sampling of the
equilibrium for the pieces' gap and for the motion bound, and the input boundary. PyElastica's
comparison is in test_rod_elastica.py (slow). Every solve here uses 3 segments; the default tier
keeps the checks that compile few programs (the solve's compilation dominates), the rest is slow."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.rod import (
    LoadedArm,
    RodModel,
    load_number,
    loaded_backbone,
    loaded_motion_bound,
    loaded_pieces,
    loaded_points,
    loaded_points_jacobian,
    piece_location,
    solve_equilibrium,
)

N = 9  # points per segment of every loaded_backbone call here (one compiled program)
FR = np.linspace(0.0, 1.0, N)


def pcc_backbone(q):
    return np.array([[np.asarray(sp.segment_point(jnp.asarray(q), i, float(s))) for s in FR] for i in range(len(q))])


def random_q(rng, straight=False):
    q = np.column_stack([rng.uniform(0.7, 1.3, 3), rng.uniform(-2.5, 2.5, 3), rng.uniform(-3.1, 3.1, 3)])
    if straight:
        q[:, 1] = 0.0
    return q


@pytest.mark.parametrize("seed", range(3))
def test_unloaded_rod_is_the_pcc_shape(seed):
    rng = np.random.default_rng(seed)
    q = random_q(rng, straight=(seed == 2))
    if seed == 1:
        q[1, 1] = 0.0  # one straight segment between bent ones
    model = RodModel(rng.uniform(0.5, 3), rng.uniform(0.5, 3), 0.0)
    got = np.asarray(loaded_backbone(q, model, N))
    assert got.shape == (3, N, 3)
    np.testing.assert_allclose(got, pcc_backbone(q), rtol=0, atol=1e-9)


def _horizontal_cantilever(length, EI):
    """A rigid, weightless elbow (1e-4 long, 1e6 EI) turning the base tangent horizontal, then a
    straight segment of ``length``: a horizontal cantilever clamped at the elbow."""
    q = np.array([[1e-4, np.pi / 2, 0.0], [length, 0.0, 0.0], [1e-4, 0.0, 0.0]])
    EI_seg = np.array([1e6, EI, 1e6])
    return q, EI_seg


@pytest.mark.slow
def test_small_deflection_cantilever_formulas():
    # Straight upright rod, lateral tip force F: tip deflection F L^3 / (3 EI) (Timoshenko & Gere).
    L, EI, F = 1.0, 2.0, 1e-4
    q = np.array([[L / 3, 0.0, 0.0]] * 3)
    tip = np.asarray(loaded_backbone(q, RodModel(EI, EI, 0.0, (F, 0.0, 0.0)), N))[-1, -1]
    np.testing.assert_allclose(tip[0], F * L**3 / (3 * EI), rtol=1e-4)
    # Horizontal cantilever under its weight w: tip drop w L^4 / (8 EI); under a tip load P: P L^3 / (3 EI).
    q, EI_seg = _horizontal_cantilever(L, EI)
    w = np.array([0.0, 1e-4, 0.0])
    base = np.asarray(loaded_backbone(q, RodModel(EI_seg, EI_seg, 0.0), N))[-1, -1]
    drop = base[2] - np.asarray(loaded_backbone(q, RodModel(EI_seg, EI_seg, w), N))[-1, -1, 2]
    np.testing.assert_allclose(drop, 1e-4 * L**4 / (8 * EI), rtol=1e-3)
    drop = base[2] - np.asarray(loaded_backbone(q, RodModel(EI_seg, EI_seg, 0.0, (0.0, 0.0, -1e-4)), N))[-1, -1, 2]
    np.testing.assert_allclose(drop, 1e-4 * L**3 / (3 * EI), rtol=1e-3)


MODEL = RodModel(9.0, 6.0, 0.3, (0.02, -0.01, -0.1))  # a heavy load: the tip sags by ~0.3 of 3


@pytest.mark.slow
def test_jacobian_matches_finite_differences_and_reverse_mode():
    rng = np.random.default_rng(4)
    seg = jnp.array([0, 1, 2, 2])
    fr = jnp.array([0.5, 0.25, 0.75, 1.0])
    Js, q0 = [], random_q(rng, straight=True)
    for q in (q0, random_q(rng)):
        Js.append(J := np.asarray(loaded_points_jacobian(q, MODEL, seg, fr)))
        assert np.all(np.isfinite(J))
        f = lambda x: np.asarray(loaded_points(x.reshape(3, 3), MODEL, seg, fr)).reshape(-1)
        x0, h = q.reshape(-1), 1e-6
        fd = np.stack([(f(x0 + h * e) - f(x0 - h * e)) / (2 * h) for e in np.eye(9)], axis=-1).reshape(4, 3, 9)
        np.testing.assert_allclose(J, fd, rtol=0, atol=1e-6)
    # The posed arm of the planner (LoadedArm.at) gives the same Jacobian, by the
    # implicit-function theorem on its own solve (pieces 2, 5, 11, 11 at s = 0, 0, 0, 1 are
    # the fractions above with 4 pieces per segment).
    arm = LoadedArm(MODEL)
    pieces, s = jnp.array([2, 5, 11, 11]), jnp.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_array_equal(np.stack(piece_location(pieces, s, arm.pieces)), np.stack([seg, fr]))
    def posed_jacobians(q_):
        posed = arm.at(q_)
        return posed.jacobians_with_tip(q_, pieces, s), posed.tip_jacobian(q_)

    (posed, with_tip), tip = jax.jit(jax.vmap(posed_jacobians))(jnp.asarray(np.stack([q0, q])))
    np.testing.assert_allclose(np.asarray(posed), np.stack(Js), rtol=0, atol=1e-10)
    # the tip's Jacobian (the fallback's IK), alone and beside the points (its push), is the last
    # point's: segment 2 at fraction 1
    np.testing.assert_allclose(np.asarray(tip), np.stack(Js)[:, 3], rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(with_tip), np.stack(Js)[:, 3], rtol=0, atol=1e-10)
    # Reverse mode through the implicit solve, in q and in the material (one program):
    # against forward mode in q, and central differences in EI.
    def objective(x, EI):
        model = RodModel(EI, MODEL.torsional_stiffness, MODEL.weight_per_length, MODEL.tip_load)
        return jnp.sum(loaded_points(x, model, seg, fr) ** 2)

    g_q, g_EI = jax.jit(jax.grad(objective, argnums=(0, 1)))(jnp.asarray(q), 9.0)
    pts = np.asarray(loaded_points(q, MODEL, seg, fr))
    np.testing.assert_allclose(np.asarray(g_q).reshape(-1), 2 * np.einsum("ka,kaj->j", pts, J), atol=1e-8)
    fd = (float(objective(jnp.asarray(q), 9.0 + 1e-5)) - float(objective(jnp.asarray(q), 9.0 - 1e-5))) / 2e-5
    np.testing.assert_allclose(float(g_EI), fd, rtol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("p", [2, 4])
def test_pieces_gap_bounds_the_distance_to_the_dense_equilibrium(p):
    rng = np.random.default_rng(6)
    q = random_q(rng)
    k = 60
    fr = np.linspace(0, 1, k)
    seg = np.repeat(np.arange(3), k)
    true = np.asarray(loaded_points(q, MODEL, seg, np.tile(fr, 3), 64))  # a finer solve as the truth
    Q, gap = loaded_pieces(q, MODEL, p)
    assert Q.shape == (3 * p, 3)
    frs = np.tile(fr, 3)
    piece = np.minimum((frs * p).astype(int), p - 1) + seg * p
    s_in = frs * p - np.minimum((frs * p).astype(int), p - 1)
    pts = np.array([np.asarray(sp.segment_point(Q, int(a), float(b))) for a, b in zip(piece, s_in, strict=True)])
    measured = np.linalg.norm(pts - true, axis=-1).max()
    assert 0 < measured <= float(gap), (measured, float(gap))
    assert float(gap) < 30 * measured  # the bound is not vacuous (docs/loaded-arm.md: 10-20x)
    segs, frac = piece_location(jnp.asarray(piece), jnp.asarray(s_in), p)
    np.testing.assert_array_equal(np.asarray(segs), seg)
    np.testing.assert_allclose(np.asarray(frac), frs, atol=1e-12)


def test_unloaded_pieces_have_no_gap():
    q = random_q(np.random.default_rng(7))
    Q, gap = loaded_pieces(q, RodModel(1.0, 1.0, 0.0), 4)
    assert float(gap) == 0.0
    tips = [np.asarray(sp.segment_point(Q, 4 * i + 3, 1.0)) for i in range(3)]
    np.testing.assert_allclose(tips, pcc_backbone(q)[:, -1], atol=1e-12)


@pytest.mark.slow
def test_motion_bound_holds_on_densely_sampled_equilibria():
    rng = np.random.default_rng(8)
    k = 20
    seg, fr = np.repeat(np.arange(3), k), np.tile(np.linspace(0, 1, k), 3)
    model = RodModel(27.0, 18.0, 0.3, (0.02, -0.01, -0.1))  # tip drop ~0.1 of the arm: load number < 1
    pts = jax.jit(jax.vmap(lambda q: loaded_points(q, model, seg, fr)))
    worst = 0.0
    for _ in range(4):
        q_a = random_q(rng)
        q_b = q_a + rng.normal(size=(3, 3)) * np.array([0.05, 0.15, 0.15])
        ts = np.linspace(0, 1, 41)
        P = np.asarray(pts(jnp.asarray(q_a[None] + ts[:, None, None] * (q_b - q_a)[None])))
        moved = np.linalg.norm(P - P[0][None], axis=-1).max(axis=(0,))  # per point
        bound = np.asarray(loaded_motion_bound(q_a, q_b, model))
        assert float(load_number(q_a, q_b, model)) < 1
        per_seg = moved.reshape(3, k).max(axis=1)
        assert np.all(per_seg <= bound + 1e-12), (per_seg, bound)
        worst = max(worst, float(np.max(per_seg / bound)))
    assert worst > 0.02  # the bound is not vacuous
    # a load the bound cannot close (load number >= 1): +inf, never a wrong finite number
    soft = RodModel(1.0, 1.0, 0.3)
    assert not np.isfinite(np.asarray(loaded_motion_bound(q_a, q_b, soft))[-1])


def test_solve_reports_convergence_and_rejects_what_it_cannot_carry():
    q = random_q(np.random.default_rng(9))
    shape = solve_equilibrium(q, MODEL)
    assert bool(shape.converged) and float(shape.residual) < 1e-10
    # an upright column past Euler's load pi^2 EI / (4 L^2): the straight shape is unstable
    column = np.array([[1.0, 0.0, 0.0]] * 3)
    crushing = RodModel(1.0, 1.0, 0.0, (0.0, 0.0, -0.5))
    assert not bool(solve_equilibrium(column, crushing).converged)
    with pytest.raises(ValueError, match="did not converge"):
        loaded_backbone(column, crushing, N)
    traced = jax.jit(lambda q: loaded_points(q, crushing, jnp.array([2]), jnp.array([1.0])))(column)
    assert np.all(np.isnan(np.asarray(traced)))
    # below Euler's load the column stands
    assert bool(solve_equilibrium(column, RodModel(1.0, 1.0, 0.0, (0.0, 0.0, -0.2))).converged)


@pytest.mark.parametrize("kwargs, field", [
    (dict(bending_stiffness=0.0), "bending_stiffness"),
    (dict(torsional_stiffness=-1.0), "torsional_stiffness"),
    (dict(weight_per_length=-0.1), "weight_per_length"),
    (dict(weight_per_length=float("nan")), "weight_per_length"),
    (dict(tip_load=(0.0, 1.0)), "tip_load"),
    (dict(tip_load=(0.0, float("inf"), 0.0)), "tip_load"),
    (dict(bending_stiffness="stiff"), "bending_stiffness"),
    (dict(bending_stiffness=np.ones((2, 2))), "bending_stiffness"),
])
def test_bad_material_names_the_field(kwargs, field):
    args = dict(bending_stiffness=1.0, torsional_stiffness=1.0, weight_per_length=0.1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        RodModel(**args)


def test_bad_shapes_are_rejected():
    q = np.array([[1.0, 0.5, 0.0]] * 3)
    with pytest.raises(ValueError, match="bending_stiffness"):
        loaded_backbone(q, RodModel(np.ones(2), 1.0, 0.1), N)
    with pytest.raises(ValueError, match="model"):
        loaded_backbone(q, (1.0, 1.0, 0.1), N)
    with pytest.raises(ValueError, match="n must be"):
        loaded_backbone(q, MODEL, 1)
    with pytest.raises(ValueError, match="q"):
        loaded_backbone(q[:, :2], MODEL, N)
    with pytest.raises(ValueError, match="multiple"):
        loaded_pieces(q, MODEL, 3, steps=16)


@pytest.mark.slow
def test_jit_vmap_and_float32():
    rng = np.random.default_rng(10)
    qs = np.stack([random_q(rng) for _ in range(3)])
    seg, fr = jnp.repeat(jnp.arange(3), N), jnp.tile(jnp.asarray(FR), 3)
    batched = jax.jit(jax.vmap(lambda q: loaded_points(q, MODEL, seg, fr)))(qs)
    for q, b in zip(qs, np.asarray(batched), strict=True):
        np.testing.assert_allclose(b.reshape(3, N, 3), np.asarray(loaded_backbone(q, MODEL, N)), atol=1e-12)
    # per-segment material, float32
    model32 = RodModel(np.array([9.0, 8.0, 7.0], np.float32), np.float32(6.0), np.float32(0.3))
    model64 = RodModel(np.array([9.0, 8.0, 7.0]), 6.0, 0.3)
    got = np.asarray(loaded_backbone(qs[0].astype(np.float32), model32, N))
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, np.asarray(loaded_backbone(qs[0], model64, N)), atol=2e-4)
