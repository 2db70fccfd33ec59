"""The skeleton of a cloud that holds several obstacles, joined into one point sequence per
curve (for :func:`~softplan_jax.clouds.fit_curves`): the spanning tree of a connected group
loses its noise spurs, splits at its junctions (nodes of degree >= 3; junctions closer than the
spur length are one), and at each junction the two pieces that continue each other most
straightly (more than 150 degrees apart) are joined, so a trunk stays one curve through its
branch points and two crossing wires stay two (:func:`component_chains`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ._graph import Scales, attach, path_parameters, smooth_cloud, spanning_tree

__all__ = ["component_chains"]


class _Tree:
    """Adjacency lists of a (forest) graph given as a symmetric CSR matrix."""

    def __init__(self, T):
        T = T.tocsr()
        self.n = T.shape[0]
        self.adj = [T.indices[T.indptr[i] : T.indptr[i + 1]].tolist() for i in range(self.n)]
        self.w = [T.data[T.indptr[i] : T.indptr[i + 1]].tolist() for i in range(self.n)]

    def weight(self, i, j):
        return self.w[i][self.adj[i].index(j)]


def _walk(tree: _Tree, alive: np.ndarray, deg: np.ndarray, start: int, first: int):
    """Nodes from ``start`` through ``first`` along degree-2 nodes to the next
    node whose degree is not 2 (included). Returns (nodes, length)."""
    nodes = [start, first]
    length = tree.weight(start, first)
    prev, cur = start, first
    while deg[cur] == 2:
        nxt = [j for j in tree.adj[cur] if alive[j] and j != prev][0]
        length += tree.weight(cur, nxt)
        nodes.append(nxt)
        prev, cur = cur, nxt
    return nodes, length


def _prune(tree: _Tree, nodes: np.ndarray, Q: np.ndarray, spur: float) -> np.ndarray:
    """Skeleton of one tree component: remove leaf branches whose tip lies within
    ``spur`` of the rest of the skeleton (noise spurs), repeatedly, never
    turning a junction into an end. Returns the alive mask (n,)."""
    alive = np.zeros(tree.n, bool)
    alive[nodes] = True
    while True:
        deg = np.array([sum(alive[j] for j in tree.adj[i]) if alive[i] else 0 for i in range(tree.n)])
        if not np.any(deg >= 3):
            return alive
        leaf_branches = []  # (junction, nodes without the junction, length)
        for leaf in np.nonzero(alive & (deg == 1))[0]:
            nb = [j for j in tree.adj[leaf] if alive[j]][0]
            walk, length = _walk(tree, alive, deg, int(leaf), nb)
            if deg[walk[-1]] >= 3:
                leaf_branches.append((walk[-1], walk[:-1], length))
        in_branch = np.zeros(tree.n, bool)
        for _, b, _ in leaf_branches:
            in_branch[b] = True
        core = np.nonzero(alive & ~in_branch)[0]
        if core.size == 0:
            return alive
        core_tree = cKDTree(Q[core])
        by_junction = {}
        for jn, b, length in leaf_branches:
            tip_dist = core_tree.query(Q[b[0]])[0]
            by_junction.setdefault(jn, []).append((tip_dist < spur, length, b))
        removed = False
        for jn, items in by_junction.items():
            cut = [it for it in items if it[0]]
            keep_needed = 2 - (deg[jn] - len(cut))  # the junction must keep degree >= 2
            cut.sort(key=lambda it: it[1])
            if keep_needed > 0:
                cut = cut[: max(len(cut) - keep_needed, 0)]
            for _, _, b in cut:
                alive[b] = False
                removed = True
        if not removed:
            return alive


def _pieces(tree: _Tree, alive: np.ndarray):
    """Split a skeleton at its junctions: list of (nodes, length), each a path
    from a junction or end to the next junction or end."""
    deg = np.array([sum(alive[j] for j in tree.adj[i]) if alive[i] else 0 for i in range(tree.n)])
    stops = np.nonzero(alive & (deg != 2))[0]
    seen = set()
    out = []
    for s in stops:
        for nb in tree.adj[s]:
            if not alive[nb]:
                continue
            walk, length = _walk(tree, alive, deg, int(s), nb)
            key = (min(walk[0], walk[-1]), max(walk[0], walk[-1]), walk[1] if walk[0] < walk[-1] else walk[-2])
            if key in seen:
                continue
            seen.add(key)
            out.append((walk, length))
    if not out and alive.any():  # a single node
        out.append(([int(np.nonzero(alive)[0][0])], 0.0))
    return out, deg


class _UnionFind:
    def __init__(self, n):
        self.p = list(range(n))

    def find(self, i):
        while self.p[i] != i:
            self.p[i] = self.p[self.p[i]]
            i = self.p[i]
        return i

    def union(self, a, b):
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        self.p[ra] = rb
        return True


def _chains(pieces, deg, Q, spur: float, min_angle_deg: float = 150.0):
    """Join skeleton pieces through junctions into obstacle curves.

    Junctions joined by a piece shorter than ``spur`` are one junction (its
    short pieces belong to it). At each junction, pairs of pieces whose
    directions away from it are more than ``min_angle_deg`` apart are joined,
    straightest pair first. Returns a list of node sequences (ordered)."""
    junctions = sorted({int(n) for walk, _ in pieces for n in (walk[0], walk[-1]) if deg[n] >= 3})
    jid = {n: k for k, n in enumerate(junctions)}
    uf = _UnionFind(len(junctions))
    internal = set()
    for p, (walk, length) in enumerate(pieces):
        a, b = walk[0], walk[-1]
        if a in jid and b in jid and length < spur:
            uf.union(jid[a], jid[b])
            internal.add(p)
    cluster_of = {n: uf.find(jid[n]) for n in junctions}
    centre = {}
    for n, c in cluster_of.items():
        centre.setdefault(c, []).append(Q[n])
    centre = {c: np.mean(v, axis=0) for c, v in centre.items()}
    # Incident piece ends per cluster, with the piece's direction away from it.
    ends = {}
    for p, (walk, _length) in enumerate(pieces):
        if p in internal:
            continue
        for side, node in ((0, walk[0]), (1, walk[-1])):
            if node not in cluster_of:
                continue
            c = cluster_of[node]
            seq = walk if side == 0 else walk[::-1]
            pts = Q[seq]
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            lo, hi = spur, 4.0 * spur
            sel = (s >= min(lo, 0.5 * s[-1])) & (s <= min(hi, s[-1]))
            if not sel.any():
                sel = s >= 0.5 * s[-1]
            v = pts[sel].mean(axis=0) - centre[c]
            nv = np.linalg.norm(v)
            ends.setdefault(c, []).append((p, side, v / nv if nv > 0 else v))
    links = {}  # (piece, side) -> (piece, side)
    uf_p = _UnionFind(len(pieces))
    cos_max = math.cos(math.radians(min_angle_deg))
    for items in ends.values():
        pairs = []
        for i in range(len(items)):
            for j in range(i + 1, len(items)):
                cs = float(np.dot(items[i][2], items[j][2]))
                if cs < cos_max and items[i][0] != items[j][0]:
                    pairs.append((cs, i, j))
        pairs.sort()
        used = set()
        for _, i, j in pairs:
            if i in used or j in used:
                continue
            (pi, si, _), (pj, sj, _) = items[i], items[j]
            if not uf_p.union(pi, pj):
                continue  # would close a loop
            used.update((i, j))
            links[(pi, si)] = (pj, sj)
            links[(pj, sj)] = (pi, si)
    chains = []
    done = set()
    order = [p for p in range(len(pieces)) if p not in internal]
    # Start at piece ends that are not linked (chain ends); then any left (none: no loops).
    for p in order:
        for side in (0, 1):
            if p in done or (p, side) in links:
                continue
            seq = []
            cur, enter = p, side
            while True:
                walk = pieces[cur][0]
                seq.extend(walk if enter == 0 else walk[::-1])
                done.add(cur)
                out = (cur, 1 - enter)
                if out not in links:
                    break
                cur, enter = links[out]
            chains.append(np.asarray(seq))
    return chains


def component_chains(C: np.ndarray, sc: Scales):
    """The obstacle curves of one connected group of points C (M, 3): a list of
    (member indices into C, initial parameters in [-1, 1]). Points near a
    junction belong to every curve through it."""
    Q = smooth_cloud(C)
    T = spanning_tree(Q)
    tree = _Tree(T)
    alive = _prune(tree, np.arange(C.shape[0]), Q, sc.spur)
    pieces, deg = _pieces(tree, alive)
    chains = _chains(pieces, deg, Q, sc.spur)
    src = attach(T, np.nonzero(alive)[0])  # every point -> the skeleton node it hangs from
    node_chains = {}
    for k, seq in enumerate(chains):
        for node in seq:
            node_chains.setdefault(int(node), []).append(k)
    # A point hanging from a node shared by several chains (a junction) goes to
    # the chain whose other nodes are nearest.
    trees = [cKDTree(Q[seq]) if len(seq) else None for seq in chains]
    owner = np.full(C.shape[0], -1)
    for i in range(C.shape[0]):
        ks = node_chains.get(int(src[i]), [])
        if len(ks) == 1:
            owner[i] = ks[0]
        elif ks:
            owner[i] = min(ks, key=lambda k: _distance_excluding(trees[k], chains[k], Q[i], int(src[i])))
    out = []
    for k, seq in enumerate(chains):
        members = np.nonzero(owner == k)[0]
        if len(seq) < 2 or members.size == 0:
            continue
        t_seq = path_parameters(Q, seq)
        _, j = trees[k].query(Q[members])
        out.append((members, t_seq[j]))
    return out


def _distance_excluding(tree, seq, p, node: int) -> float:
    """Distance from p to the nearest node of a chain other than ``node``."""
    d, j = tree.query(p, k=min(2, len(seq)))
    d, j = np.atleast_1d(d), np.atleast_1d(j)
    for dist, idx in zip(d, j, strict=True):
        if int(seq[idx]) != node:
            return float(dist)
    return math.inf
