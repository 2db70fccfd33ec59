"""softplan_jax.geometry._obstacles: the slot layout of a scene, against brute-force references.

One small mixed scene (a padded polynomial curve group, a padded point-set
group, a parametric curve); one jitted function of it shared by every test.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial import cKDTree

import softplan_jax as sp
from softplan_jax.geometry import _obstacles as obstacles
from softplan_jax.geometry._closest import DEFAULT_OPTIONS

N_POINTS = 7


@functools.cache
def _scene():
    curve = sp.PolynomialCurve(jnp.array([[0.4, 0.3, 0.0], [-0.5, 0.0, 0.6], [1.2, 0.5, -0.2]]), (0.0, 1.5), 0.02)
    pts = jnp.array([[0.3, 0.4, 1.9], [-0.2, 0.5, 2.2], [0.0, -0.4, 1.0]])
    helix = sp.ParametricCurve(lambda u: jnp.stack([0.6 * jnp.cos(u), 0.6 * jnp.sin(u), 0.3 * u]), (0.0, 6.0), 0.01)
    q0 = jnp.array([[1.0, 0.4, 0.2], [0.9, 0.7, 2.0], [1.1, 0.3, -1.0]])
    sc = sp.make_scenario(jnp.array([0.5, 0.5, 2.0]), [curve, pts, helix], q0, arm_radius=0.03,
                          curve_slots=2, point_slots=2, max_points=5)
    return sc, [curve, pts, helix]


@functools.cache
def _layout():
    """(true, model "points", model "curve", radius, mask) at q0, one compilation."""
    sc, _ = _scene()

    @jax.jit
    def f(sc):
        q = sc.q0
        truth = obstacles.true_closest(q, sc, DEFAULT_OPTIONS)
        pts = obstacles.model_closest(q, sc, truth, "points", N_POINTS, 10)
        crv = obstacles.model_closest(q, sc, truth, "curve", N_POINTS, 10)
        return truth, pts, crv, *obstacles.radius_and_mask(sc)

    return jax.tree_util.tree_map(np.asarray, f(sc))


def _arm(q, k):
    return np.concatenate([np.zeros((1, 3)), np.asarray(sp.geometry.backbone_points(q, k))])


def _min_dist(a, b):
    """Exact minimum distance between two point samples (a k-d tree's nearest neighbours)."""
    return float(cKDTree(b).query(a)[0].min())


def test_count_radius_mask_labels():
    sc, _ = _scene()
    assert obstacles.obstacle_count(sc) == 5  # 2 curve slots, 2 point-set slots, 1 parametric
    _, _, _, radius, mask = _layout()
    assert mask.tolist() == [True, False, True, False, True]
    np.testing.assert_array_equal(radius[mask], [0.02, 0.0, 0.01])
    assert obstacles.obstacle_labels(sc) == ["curve 1", "points 1", "parametric 1"]


def test_true_closest_against_dense_sampling():
    sc, (curve, pts, helix) = _scene()
    truth, _, _, _, mask = _layout()
    assert truth.distance.shape == (5,) and truth.segment.dtype == np.int32 and truth.u.dtype == np.float64
    arm = _arm(sc.q0, 2000)
    refs = {0: _min_dist(arm, np.asarray(sp.geometry.curve_points(curve, 20001))),
            2: _min_dist(arm, np.asarray(pts)),
            4: _min_dist(arm, np.asarray(sp.geometry.curve_points(helix, 20001)))}
    for slot, ref in refs.items():
        # Exact: never above the sampled minimum, and within the sampling error of it.
        assert truth.distance[slot] <= ref + 1e-12
        assert truth.distance[slot] >= ref - 2e-4
        np.testing.assert_allclose(np.linalg.norm(truth.arm_point[slot] - truth.obstacle_point[slot]),
                                   truth.distance[slot], rtol=1e-12)
    assert truth.converged[mask].all()


def test_model_closest_is_the_n_point_model():
    sc, (curve, pts, helix) = _scene()
    truth, model_pts, model_crv, _, _ = _layout()
    arm = np.asarray(sp.geometry.backbone_points(sc.q0, 10))
    for slot, obs in ((0, sp.geometry.curve_points(curve, N_POINTS)), (2, pts),
                      (4, sp.geometry.curve_points(helix, N_POINTS))):
        obs = np.asarray(obs)
        d = np.sqrt(((arm[:, None, :] - obs[None, :, :]) ** 2).sum(-1))
        a, p = np.unravel_index(np.argmin(d), d.shape)
        assert model_pts.distance[slot] == pytest.approx(d[a, p], rel=1e-14)
        assert model_pts.segment[slot] == a // 10 and model_pts.u[slot] == p
        assert model_pts.s[slot] == pytest.approx((a % 10 + 1) / 10, rel=1e-14)
    assert model_pts.segment.dtype == np.int32 and model_pts.u.dtype == np.float64
    # method "curve": curves exact (the truth), point sets still the N-point model.
    for slot in (0, 4):
        assert model_crv.distance[slot] == truth.distance[slot]
    assert model_crv.distance[2] == model_pts.distance[2]


def test_obstacle_samples_for_plots():
    sc, (curve, pts, helix) = _scene()
    obs = obstacles.obstacle_samples(sc, 50)
    assert [o["kind"] for o in obs] == ["curve", "points", "curve"]
    np.testing.assert_allclose(obs[0]["pts"], np.asarray(sp.geometry.curve_points(curve, 50)), atol=1e-12)
    np.testing.assert_array_equal(obs[1]["pts"], np.asarray(pts))
    np.testing.assert_allclose(obs[2]["pts"], np.asarray(sp.geometry.curve_points(helix, 50)), atol=1e-12)
    assert [o["radius"] for o in obs] == [0.02, 0.0, 0.01]


def test_scene_without_obstacles():
    sc = sp.make_scenario(jnp.array([0.5, 0.5, 2.0]), [])
    assert obstacles.obstacle_count(sc) == 0
    truth = obstacles.true_closest(sc.q0, sc, DEFAULT_OPTIONS)
    assert truth.distance.shape == (0,) and truth.segment.dtype == jnp.int32
    radius, mask = obstacles.radius_and_mask(sc)
    assert radius.shape == mask.shape == (0,)
