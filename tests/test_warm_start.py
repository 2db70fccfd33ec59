"""The planner's warm-started, certified closest points (softplan_jax.geometry._warm_start).

References: dense sampling of the curve (the lower bound never exceeds the
sampled distance; a certified answer is the sampled global minimum) and the
full solver (every step of warm-started rollouts of random scenes gives the
full solver's distances). The rollouts reuse the compilations of
tests/test_planner.py (plan_batch of 3 scenes padded like the paper scenes,
200 steps; apply_collision_checks with the paper's step).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.geometry import _warm_start as ws
from softplan_jax.geometry._closest import DEFAULT_OPTIONS
from softplan_jax.geometry._closest_newton import Segment, project_to_arc, solve_pair_reduced
from softplan_jax.geometry._kinematics import segment_frames
from softplan_jax.planning import apply_collision_checks
from softplan_jax.planning._planner import make_options

SAMPLES = 2001  # dense samples of u per case


def _segments(q):
    R, P = segment_frames(q)
    return Segment.from_frame(q, R, P)


def _random_cases(seed, n_cases, degree):
    """Random arms (one straight segment in each: theta = 0), random polynomial
    curves of the given degree near them, random window centres."""
    rng = np.random.default_rng(seed)
    qs = np.stack([np.full((n_cases, 3), 1.0), rng.uniform(-1.5, 1.5, (n_cases, 3)),
                   rng.uniform(-np.pi, np.pi, (n_cases, 3))], -1)
    qs[:, 1, 1] = 0.0
    coeffs = rng.normal(0.0, 1.0, (n_cases, 3, degree + 1))
    coeffs[:, 2, 0] += 1.5  # around the arm's middle
    u_i = rng.uniform(-1.0, 1.0, n_cases)
    return jnp.asarray(qs), sp.PolynomialCurve(jnp.asarray(coeffs), jnp.tile(jnp.array([-1.0, 1.0]), (n_cases, 1))), \
        jnp.asarray(u_i)


@jax.jit
def _bounds_and_samples(q, curve, u_i):
    """Every piece's lower bound and its sampled minimum, both sides, every segment."""
    segs = _segments(q)
    data = ws.curve_data(curve, DEFAULT_OPTIONS)
    half = ws.WINDOW * (curve.u_range[1] - curve.u_range[0]) / (DEFAULT_OPTIONS.grid_u - 1)

    def per_segment(seg):
        bounds, outside, t = ws._piece_bounds(seg, curve, data, u_i, half)
        a, b = jnp.minimum(t[:, :-1], t[:, 1:]), jnp.maximum(t[:, :-1], t[:, 1:])
        frac = jnp.linspace(0.0, 1.0, SAMPLES, dtype=q.dtype)
        us = a[..., None] + (b - a)[..., None] * frac
        d = jax.vmap(jax.vmap(jax.vmap(lambda u: project_to_arc(seg, curve.point(u))[1])))(us)
        sampled = jnp.sqrt(jnp.min(d, axis=-1))
        return bounds, sampled, jnp.broadcast_to(outside[:, None], bounds.shape)

    return jax.vmap(per_segment)(segs)


@pytest.mark.parametrize("degree", [2, 3])
def test_lower_bound_never_exceeds_the_sampled_distance(degree):
    qs, curves, u_i = _random_cases(degree, 48, degree)
    tight = []
    for k in range(qs.shape[0]):
        curve = jax.tree_util.tree_map(lambda x, k=k: x[k], curves)
        bounds, sampled, outside = (np.asarray(x) for x in _bounds_and_samples(qs[k], curve, u_i[k]))
        assert np.all(np.isfinite(bounds))
        # The sampled minimum is >= the true one, which the bound must not exceed.
        assert np.all(bounds <= sampled + 1e-12), (k, bounds - sampled)
        tight.append((sampled - bounds)[outside])
    gap = np.concatenate([g.ravel() for g in tight])
    # Not vacuous: a second-order bound is close on most pieces.
    assert np.median(gap) < 0.05, np.median(gap)


def test_certified_answer_is_the_sampled_global_minimum():
    """From warm starts near the full solver's answers (as after a planner step) and from
    random ones: whenever every pair is certified, the obstacle's minimum over segments
    equals the dense-sampled one (to the sampling error)."""
    qs, curves, _ = _random_cases(7, 48, 2)
    rng = np.random.default_rng(8)
    # Near starts: u* off by about what one default planner step moves it (0.01 of a range
    # of 2, i.e. 0.01-0.03 along these curves); the polish then converges in its
    # POLISH_ITERATIONS. Larger offsets are the random starts (which must not be
    # certified wrongly) and the planner's fallbacks (docs/conventions.md, measured by an earlier
    # version of benchmarks/warm_start.py).
    noise = rng.normal(0.0, 0.01, (qs.shape[0], 3))
    noise[::2] = rng.uniform(-2.0, 2.0, noise[::2].shape)  # every other case: a random start

    @jax.jit
    def run(q, curve, noise):
        segs = _segments(q)
        data = ws.curve_data(curve, DEFAULT_OPTIONS)
        u_full = jax.vmap(lambda seg: solve_pair_reduced(seg, curve, data.u_grid, data.C_grid, DEFAULT_OPTIONS)[1])(segs)
        u0 = u_full + noise
        stack = jax.tree_util.tree_map(lambda x: x[None], (curve, data))  # a stack of one curve
        pairs, certified = ws.polish_and_certify(segs, *stack, u0[None], DEFAULT_OPTIONS)
        us = jnp.linspace(-1.0, 1.0, 20001, dtype=q.dtype)
        dense = jax.vmap(lambda seg: jax.vmap(lambda u: project_to_arc(seg, curve.point(u))[1])(us))(segs)
        return jnp.sqrt(jnp.min(pairs.d2)), jnp.all(certified), jnp.sqrt(jnp.min(dense))

    n_cert = 0
    for k in range(qs.shape[0]):
        curve = jax.tree_util.tree_map(lambda x, k=k: x[k], curves)
        d_w, certified, dense = (float(x) for x in run(qs[k], curve, jnp.asarray(noise[k])))
        if certified:
            n_cert += 1
            assert d_w <= dense + 1e-12, (k, d_w, dense)
            assert d_w >= dense - 1e-3, (k, d_w, dense)  # an achievable distance near the sampled one
    assert n_cert >= 20, n_cert  # the certificate is not vacuous either


def test_warm_started_rollouts_give_the_full_solvers_distances():
    """Every step of warm-started rollouts of random scenes (plan_batch, default options, so
    the pairs beyond reach keep a bound, softplan_jax.geometry._near_pairs): the recorded
    clearance equals the full solver's at the same q (apply_collision_checks recomputes it with
    the full solve) wherever that is below ``d0 + far_margin``, and is never above it."""
    scs = sp.random_scenarios(3, 3, obstacles=(1, 5), curve_slots=5, degree=2)
    rb = sp.plan_batch(scs, max_steps=200)  # the compilation of test_plan_batch_matches_single
    post = jax.jit(apply_collision_checks, static_argnums=2)
    opts = make_options("curve", check_collisions=False, **sp.PAPER_STEP)  # as test_post_hoc_...
    reach = float(sp.default_gains().d0) + sp.PlanOptions().far_margin
    fallbacks = pair_steps = bounded = 0
    for b in range(3):
        r = jax.tree_util.tree_map(lambda x, b=b: x[b], rb)
        sc = jax.tree_util.tree_map(lambda x, b=b: x[b], scs)
        it = int(r.iterations)
        assert it > 20
        full = post(r, sc, opts)
        mask = np.asarray(sc.curve_mask)
        warm_c = np.asarray(r.clearance)[: it + 1][:, mask]
        full_c = np.asarray(full.clearance)[: it + 1][:, mask]
        near = full_c < reach
        np.testing.assert_allclose(warm_c[near], full_c[near], rtol=0, atol=1e-9)
        assert np.all(warm_c <= full_c + 1e-9)
        bounded += int(np.sum(warm_c < full_c - 1e-6))
        n_pairs = int(mask.sum()) * 3
        fb = np.asarray(r.fallbacks)
        assert fb[0] == n_pairs  # no warm state at the first step: every pair in full
        fallbacks += int(fb[1 : it + 1].sum())
        pair_steps += it * n_pairs
    assert fallbacks < 0.05 * pair_steps, (fallbacks, pair_steps)
    assert bounded > 0  # some clearances beyond reach were bounds, not solves


def _fallback_batch():
    """4 members (2 curves, 3 segments): no warm state, random warm starts, a padding slot."""
    qs, curves, _ = _random_cases(11, 8, 2)
    rng = np.random.default_rng(12)
    m = 2
    stack = jax.tree_util.tree_map(lambda x: x.reshape(4, m, *x.shape[1:]), curves)
    data = jax.vmap(jax.vmap(lambda c: ws.curve_data(c, DEFAULT_OPTIONS)))(stack)
    u_prev = jnp.asarray(rng.uniform(-1.0, 1.0, (4, m, 3)))
    fresh = jnp.array([True, False, False, False])
    active = jnp.array([[True, True], [True, True], [True, False], [True, True]])
    return qs[:4], stack, data, u_prev, fresh, active


def _warm_member(q, c, d, u, f, a):
    cps, u_next, fb = ws.warm_curves(q, c, d, u, f, a, DEFAULT_OPTIONS)
    return cps.distance, u_next, fb


def test_batched_fallback_equals_one_member_at_a_time():
    """Under vmap the fallback solves the failed pairs of the whole batch together
    (warm_start._fallback_fn's batching rule): the same pairs and fallback counts as
    each member alone, for members with no warm state, with random warm starts and
    with padding slots; the member without warm state gets the full solver's answers."""
    args = _fallback_batch()
    q, stack, data = args[:3]
    m, n = stack.u_range.shape[1], q.shape[1]
    batched = jax.jit(jax.vmap(_warm_member))(*args)
    single = jax.jit(_warm_member)
    fbs = []
    for b in range(4):
        ref = single(*jax.tree_util.tree_map(lambda x, b=b: x[b], args))
        for x, y in zip(batched, ref, strict=True):
            x = np.asarray(x[b])
            y = np.asarray(y)
            if b == 2 and x.ndim:  # the padding slot's values are meaningless (but finite)
                x, y = x[:1], y[:1]
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-13)
        fbs.append(int(ref[2]))
    assert fbs[0] == m * n and sum(fbs[1:]) > 0, fbs  # the fallback ran, in more than one member

    @jax.jit
    def full(q, c, d):  # every (curve, segment) pair of one member by the full solver: (m, n)
        segs = _segments(q)
        return jax.vmap(lambda c, d: jax.vmap(lambda seg: solve_pair_reduced(seg, c, d.u_grid, d.C_grid,
                                                                             DEFAULT_OPTIONS))(segs))(c, d)

    _, u_f, d2_f, _ = full(q[0], *jax.tree_util.tree_map(lambda x: x[0], (stack, data)))
    np.testing.assert_allclose(np.asarray(batched[1][0]), np.asarray(u_f), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(batched[0][0]), np.sqrt(np.min(np.asarray(d2_f), axis=1)), rtol=0,
                               atol=1e-12)


@pytest.mark.slow
def test_batched_fallback_under_nested_vmap():
    """The batching rule folds one axis per vmap level: a nested vmap (2 x 2) gives
    the single vmap's answers."""
    args = _fallback_batch()
    batched = jax.jit(jax.vmap(_warm_member))(*args)
    nested = jax.jit(jax.vmap(jax.vmap(_warm_member)))(
        *jax.tree_util.tree_map(lambda x: x.reshape(2, 2, *x.shape[1:]), args))
    for x, y in zip(nested, batched, strict=True):
        np.testing.assert_allclose(np.asarray(x).reshape(np.shape(y)), np.asarray(y), rtol=1e-12, atol=1e-13)


def test_fallback_trip_bound_by_platform():
    """The fallback loop's trip bound: CPU_FALLBACK_TRIPS in a program traced for a CPU,
    FALLBACK_TRIPS on an accelerator (docs: "How the planner works inside", "The fallback's cost")."""
    assert ws.fallback_trips("cpu") == ws.CPU_FALLBACK_TRIPS
    assert ws.fallback_trips("gpu") == ws.fallback_trips("tpu") == ws.FALLBACK_TRIPS
    assert ws.fallback_trips() == ws.fallback_trips(jax.default_backend())


@pytest.mark.slow
def test_fallback_chunk_changes_no_answer(monkeypatch):
    """The trip bound sets how many failed pairs are solved side by side (the chunk), not
    which or how: all 24 pairs of the batch in one chunk give the default chunk's (8)
    answers bit for bit."""
    args = _fallback_batch()
    default = jax.jit(jax.vmap(_warm_member))(*args)
    monkeypatch.setattr(ws, "CPU_FALLBACK_TRIPS", 1)
    monkeypatch.setattr(ws, "FALLBACK_TRIPS", 1)
    wide = jax.jit(jax.vmap(lambda *a: _warm_member(*a)))(*args)
    assert int(np.sum(np.asarray(wide[2]))) > ws.FALLBACK_CHUNK  # more failed pairs than one default chunk
    for x, y in zip(wide, default, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
