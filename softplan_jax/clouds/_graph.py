"""The neighbour graph of a cloud, which both fits build on (host side, NumPy and SciPy): its
noise level from local principal components and the residual tolerance (:func:`noise_level`,
:func:`residual_tolerance`), a Euclidean minimum spanning tree on a k-nearest-neighbour graph
(:func:`spanning_tree`, after :func:`smooth_cloud`), the tree's longest path and the
parameters along it (:func:`diameter_path`, :func:`attach`, :func:`path_parameters`), and the
points and length scales the structure is built on (:func:`graph_subset`,
:func:`cloud_scales`)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree

__all__ = [
    "noise_level",
    "residual_tolerance",
    "spanning_tree",
    "smooth_cloud",
    "diameter_path",
    "attach",
    "path_parameters",
    "Scales",
    "cloud_scales",
    "graph_subset",
]

# Structure (ordering, splitting) uses at most this many points.
_MAX_GRAPH_POINTS = 4000


def noise_level(P: np.ndarray) -> float:
    """Noise standard deviation (per axis) of a curve-like cloud from local PCA.

    Across a curve the cloud's spread is the noise: the two smallest
    eigenvalues of a neighbourhood's covariance are about sigma^2 each. The
    neighbourhood must be longer than it is thick, so the smallest k in
    (8, 16, 32, 64) whose median neighbourhood is elongated (largest / middle
    eigenvalue > 9) is used; the median over points ignores junctions.
    """
    n = P.shape[0]
    if n < 4:
        return 0.0
    tree = cKDTree(P)
    sample = P if n <= 2000 else P[np.random.default_rng(0).choice(n, 2000, replace=False)]
    est = 0.0
    for k in (8, 16, 32, 64):
        kk = min(k, n)
        _, idx = tree.query(sample, kk)
        nb = P[idx]  # (m, k, 3)
        nb = nb - nb.mean(axis=1, keepdims=True)
        cov = np.einsum("mki,mkj->mij", nb, nb) / max(kk - 1, 1)
        ev = np.linalg.eigvalsh(cov)  # ascending
        small = 0.5 * (ev[:, 0] + ev[:, 1])
        est = math.sqrt(max(float(np.median(small)), 0.0))
        if np.median(ev[:, 2]) > 9.0 * np.median(ev[:, 1]) or kk == n:
            break
    return est


def residual_tolerance(noise: float, n: int, extent: float) -> float:
    """Largest acceptable maximum residual: (sqrt(2 ln N) + 2) noise levels,
    with a floor of 1e-4 of the cloud's extent for noise-free clouds."""
    return (math.sqrt(2.0 * math.log(max(n, 2))) + 2.0) * max(noise, 1e-4 * extent)


def spanning_tree(P: np.ndarray, k: int = 10):
    """Euclidean minimum spanning tree over a kNN graph, made connected.

    Returns a symmetric CSR matrix of edge lengths (duplicate points get a tiny
    positive length so that they stay connected).
    """
    n = P.shape[0]
    k = min(k, n - 1)
    tree = cKDTree(P)
    dist, idx = tree.query(P, k + 1)
    tiny = 1e-12 * max(float(np.max(np.ptp(P, axis=0))), 1e-300)
    rows = [np.repeat(np.arange(n), k)]
    cols = [idx[:, 1:].ravel()]
    wts = [np.maximum(dist[:, 1:].ravel(), tiny)]
    G = coo_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    G = G.maximum(G.T)
    ncomp, labels = connected_components(G, directed=False)
    while ncomp > 1:  # Boruvka: join every component to its nearest other component
        extra_r, extra_c, extra_w = [], [], []
        for c in range(ncomp):
            inside = np.nonzero(labels == c)[0]
            outside = np.nonzero(labels != c)[0]
            d, j = cKDTree(P[outside]).query(P[inside])
            b = int(np.argmin(d))
            extra_r.append(inside[b])
            extra_c.append(outside[j[b]])
            extra_w.append(max(float(d[b]), tiny))
        E = coo_matrix((extra_w, (extra_r, extra_c)), shape=(n, n)).tocsr()
        G = G.maximum(E).maximum(E.T)
        ncomp, labels = connected_components(G, directed=False)
    T = minimum_spanning_tree(G)
    return T.maximum(T.T).tocsr()


def smooth_cloud(P: np.ndarray, k: int = 10, rounds: int = 2) -> np.ndarray:
    """Local averaging over k nearest neighbours (of the raw cloud), a few
    rounds: pulls noisy points towards the centre line so that the spanning
    tree grows fewer noise spurs. Used for structure only, never for fits."""
    n = P.shape[0]
    k = min(k, n)
    if k < 3:
        return P
    _, idx = cKDTree(P).query(P, k)
    Q = P
    for _ in range(rounds):
        Q = Q[idx].mean(axis=1)
    return Q


def _tree_path(T, a: int, b: int) -> np.ndarray:
    """Node sequence of the unique tree path from a to b."""
    _, pred = dijkstra(T, directed=False, indices=a, return_predecessors=True)
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return np.asarray(path[::-1])


def diameter_path(T) -> np.ndarray:
    """Longest path of a tree (two farthest-node sweeps)."""
    d0 = dijkstra(T, directed=False, indices=0)
    a = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
    da = dijkstra(T, directed=False, indices=a)
    b = int(np.argmax(np.where(np.isfinite(da), da, -1)))
    return _tree_path(T, a, b)


def attach(T, nodes: np.ndarray) -> np.ndarray:
    """For every node of tree T, the node of ``nodes`` its subtree hangs from
    (the nearest of ``nodes`` along the tree)."""
    _, _, src = dijkstra(T, directed=False, indices=nodes, min_only=True, return_predecessors=True)
    return src


def path_parameters(Q: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Normalised chord length in [-1, 1] along a (smoothed) node path."""
    pts = Q[path]
    w = max(1, min(5, len(path) // 20))
    if w > 1:  # moving average so that zig-zags of the path do not count as length
        kernel = np.ones(2 * w + 1) / (2 * w + 1)
        padded = np.pad(pts, ((w, w), (0, 0)), mode="edge")
        pts = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(3)], axis=1)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    if s[-1] <= 0:
        return np.linspace(-1.0, 1.0, len(path))
    return 2.0 * s / s[-1] - 1.0


def _neighbour_spacing(P: np.ndarray, k: int = 6) -> float:
    """Median distance to the k-th nearest neighbour: the cloud's local point spacing."""
    k = min(k, P.shape[0] - 1)
    if k < 1:
        return 0.0
    d, _ = cKDTree(P).query(P, k + 1)
    return float(np.median(d[:, k]))


class Scales(NamedTuple):
    """Length scales of a cloud that the fits and the splitting use."""

    extent: float  # largest side of the bounding box
    noise: float  # noise level (local PCA)
    tol: float  # largest acceptable maximum residual
    spacing: float  # median distance to the 6th nearest neighbour
    cut: float  # spanning-tree edges longer than this separate obstacles
    spur: float  # side branches of the tree shorter than this are noise
    gap_tol: float  # a fitted curve may stray this far from the nearest point


def cloud_scales(P: np.ndarray, G: np.ndarray) -> Scales:
    extent = float(np.max(np.ptp(P, axis=0)))
    noise = noise_level(P)
    tol = residual_tolerance(noise, P.shape[0], extent)
    spacing = _neighbour_spacing(G)
    cut = max(4.0 * spacing, 10.0 * noise)
    spur = max(4.0 * spacing, 8.0 * noise)
    return Scales(extent, noise, tol, spacing, cut, spur, tol + 0.5 * cut)


def graph_subset(P: np.ndarray):
    """At most _MAX_GRAPH_POINTS points for the structure (seeded random subset)."""
    n = P.shape[0]
    if n <= _MAX_GRAPH_POINTS:
        return P, np.arange(n)
    idx = np.sort(np.random.default_rng(0).choice(n, _MAX_GRAPH_POINTS, replace=False))
    return P[idx], idx
