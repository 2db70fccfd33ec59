"""The global search as one loop with one exact solve per iteration. RRT-Connect's extensions and
connections, the shortcut attempts, the smoothing moves, the walk along the final polyline, the
check of the found path and, for the fallback, the IK's assessments are phases (``_P_*``) of one
``while_loop`` over a state machine: each iteration lets the phase's handler consume the motion
that just ended and set up the next one (a ``lax.switch`` on the phase), then takes one
conservative-advancement substep of the current motion,
``q = q_a + t dq, alpha = safe_scale(q, q_e, c(q), 2 contact, f), t <- 1 if alpha >= 1 else
t + alpha (1 - t)`` (:func:`~softplan_jax.planning._step.safe_scale`), the only exact solve, so the
compiled program holds one copy of the solver. Each motion does the arithmetic of nested loops in
the same order (docs: "How the planner works inside", "The search machine")."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..geometry._arm import PCC
from ..geometry._clearance import swept_clear
from ..geometry._obstacles import radius_and_mask
from ..planning._batching import lanes_map
from . import _motions as mo
from ._reach import (
    ReachOptions,
    ik_assess,
    ik_more,
    ik_result,
    ik_round_configurations,
    ik_round_end,
    ik_start,
    posed_clearances,
    random_configurations,
)

__all__ = ["run_search"]

# The handler to run when no motion is active (what the last motion was for).
(_P_TREE, _P_EXTENDED, _P_CONNECTED, _P_TREE_DONE, _P_CUT, _P_SMOOTH_START, _P_SMOOTH_A, _P_SMOOTH_B, _P_WALK_START,
 _P_WALK, _P_CHECK, _P_IK_ROUND, _P_IK_SOLVE, _P_DONE) = range(14)
_IK_PHASES = (_P_IK_ROUND, _P_IK_SOLVE)


class _State(NamedTuple):
    phase: jax.Array  # () int32: the handler to run when the motion ends
    # The current motion: the line q_a -> q_e (= q_a + dq), at fraction t after k substeps.
    q_a: jax.Array
    dq: jax.Array
    q_e: jax.Array
    t: jax.Array
    k: jax.Array
    limit: jax.Array  # () int32 substeps allowed
    active: jax.Array  # () bool: a motion is under way (it stops at its end, a failed solve, or its substeps)
    # RRT-Connect.
    trees: tuple  # motions.Trees
    near: jax.Array  # () int32: the node of tree a the extension left from
    new_idx: jax.Array  # () int32: where the extension's node went
    added: jax.Array  # () bool: it was added
    near_b: jax.Array  # () int32: the node of tree b the connection left from
    # The polyline: shortcuts, smoothing, the walk.
    path: jax.Array  # (2T, n, 3)
    length: jax.Array  # () int32 nodes
    start: jax.Array  # () int32 the start root
    count: jax.Array  # () int32: shortcut attempts made / smoothing passes made
    node: jax.Array  # () int32: the inner node being smoothed; the walk's edge
    key: jax.Array  # the shortcuts' key
    possible: jax.Array  # () bool: the shortcut attempt's j is on the path
    cut: jax.Array  # (2,) int32: the attempt's i, j
    cand: jax.Array  # (n, 3) the smoothing candidate
    first_ok: jax.Array  # () bool: the motion path[k-1] -> cand reached
    steps: jax.Array  # () int32 steps of the walk
    # The check of the walk's path: the step to solve at next, and every motion proven so far.
    check_k: jax.Array  # () int32
    proven: jax.Array  # () bool
    # The walk's step of this substep, written by the loop into its steps (S + 1, n, 3), a carry
    # of its own: the handlers never touch it.
    row: jax.Array  # () int32
    q_next: jax.Array  # (n, 3)
    write: jax.Array  # () bool
    # The check's clearances at step check_k - 1, written by the loop likewise into (S + 1, m).
    c_now: jax.Array  # (m,)
    c_write: jax.Array  # () bool
    # The IK (None in a search given its goal roots): its loop's state, its starts, the start
    # to assess next, and whether the goal is proven unreachable (no search then).
    ik: object = None  # reach.IKState
    ik_starts: object = None  # (S, n, 3)
    ik_i: object = None  # () int32
    proof: object = None  # () bool


def _add(trees, T: int, tree, q, par, allowed):
    """Node q (parent par) into tree ``tree`` if allowed and the tree has room."""
    idx = jnp.minimum(trees.count[tree], T - 1)
    ok = allowed & (trees.count[tree] < T)
    nodes = trees.nodes.at[tree, idx].set(jnp.where(ok, q, trees.nodes[tree, idx]))
    parent = trees.parent.at[tree, idx].set(jnp.where(ok, par, trees.parent[tree, idx]))
    return trees._replace(nodes=nodes, parent=parent, count=trees.count.at[tree].add(ok.astype(jnp.int32))), idx, ok


def run_search(scenarios, q_starts, n_starts, q_goals, n_goals, keys, options: ReachOptions, solver,
               contact: float, ik=None, arm=PCC):
    """The search of :func:`~softplan_jax.search._tree.global_search` for a batch of B scenes
    (module docstring; every argument with a leading axis B): ``(trees, length, start, out,
    steps, complete, clearance, proven)``, batched: ``clearance`` (B, S + 1, m) the check's
    exact clearances at the path's steps (the last one repeated after the end), ``proven``
    the check's swept proof of every motion (False where no path was found).

    ``ik``: ``(ik_keys, q_extra, proof)`` (leading axis B) in place of ``q_goals, n_goals``
    (then None): the goal roots are the IK's (reach.goal_configurations with these keys and
    extra starts, in this loop: one start's exact solve per iteration), the first
    ``goal_roots`` of its sorted results; a lane searches where its first is certified and
    ``proof`` (the goal proven unreachable) is False. The tuple then ends with the IK's
    final :class:`~softplan_jax.search._reach.IKState` (batched).

    ``arm``: the arm model (:mod:`~softplan_jax.geometry._arm`; one for the batch) whose tip,
    Jacobians, clearances and motion bound the IK, every certified motion and the check use.

    The loop runs over the whole batch: in an iteration, a phase's handler runs (on the
    lanes whose motion ended in that phase; skipped when there is none), then one
    substep of every lane, kept where its motion is under way. So a lane costs one
    exact solve per iteration, and the handlers cost only when a motion ended: the
    batch needs no vmap of the loop, which would evaluate every handler on every
    iteration. The walk's steps (B, S + 1, n, 3) and the check's clearances (B, S + 1, m)
    are carries of their own, one row per lane written after the substep."""
    B = keys.shape[0]
    with_ik = ik is not None
    n, dtype = q_starts.shape[-2], q_starts.dtype

    def lane(sc):
        return _lane(sc, options, solver, contact, n, dtype, with_ik, arm)

    if with_ik:
        state = lanes_map(lambda sc, *a: lane(sc)[0](*a), scenarios, q_starts, n_starts, keys, *ik)
    else:
        state = lanes_map(lambda sc, *a: lane(sc)[0](*a), scenarios, q_starts, n_starts, q_goals, n_goals, keys)
    live = [p for p in range(_P_DONE) if with_ik or p not in _IK_PHASES]  # the phases with a handler

    def run(index, s, out=None):
        """Lane-wise: handler ``index`` (or the substep, which reads the walk's steps ``out``:
        index None) on every lane."""
        def one(st, sc, *lane_out):
            _, handlers, substep = lane(sc)
            return substep(st, *lane_out) if index is None else handlers[index](st)

        return lanes_map(one, s, scenarios) if out is None else lanes_map(one, s, scenarios, out)

    def select(mask, new, old):
        return jax.tree_util.tree_map(lambda a, b: jnp.where(mask.reshape((B,) + (1,) * (a.ndim - 1)), a, b), new, old)

    def handle(s):
        """The handler of each lane whose motion ended (phase p: handlers[p])."""
        idle = ~s.active & (s.phase != _P_DONE)
        if B == 1:  # one branch, chosen by the lane's phase (the last: no handler)
            branches = [(lambda s, p=p: run(p, s)) if p in live else (lambda s: s) for p in range(_P_DONE)]
            branches.append(lambda s: s)
            return jax.lax.switch(jnp.where(idle[0], s.phase[0], _P_DONE), branches, s)
        phase = s.phase
        for p in live:  # each handler only where some lane needs it
            mask = idle & (phase == p)
            s = jax.lax.cond(jnp.any(mask), lambda s, p=p, mask=mask: select(mask, run(p, s), s), lambda s: s, s)
        return s

    lanes = jnp.arange(B)

    def body(carry):
        s, out, clear = carry
        s = handle(s) if B == 1 else jax.lax.cond(jnp.any(~s.active & (s.phase != _P_DONE)), handle, lambda s: s, s)
        s = substep_all(s, out)  # every iteration: a lane with no motion under way keeps its state
        rows = out[lanes, s.row]
        out = out.at[lanes, s.row].set(jnp.where(s.write[:, None, None], s.q_next, rows))
        c_row = jnp.maximum(s.check_k - 1, 0)
        clear = clear.at[lanes, c_row].set(jnp.where(s.c_write[:, None], s.c_now, clear[lanes, c_row]))
        return s, out, clear

    def substep_all(s, out):
        new = run(None, s, out)
        # ``write``, ``c_write`` as the substep set them: false where no motion was under way.
        return select(s.active, new, s)._replace(write=new.write, c_write=new.c_write)

    S = int(options.path_steps)
    out = jnp.zeros((B, S + 1, *q_starts.shape[-2:]), q_starts.dtype)
    clear = jnp.zeros((B, S + 1, state.c_now.shape[-1]), q_starts.dtype)
    s, out, clear = jax.lax.while_loop(lambda c: jnp.any(c[0].phase != _P_DONE), body, (state, out, clear))
    # The walk's steps: the first node (unwrapping keeps it), the steps taken, then the last one repeated.
    out = out.at[:, 0].set(s.path[:, 0])
    taken = (jnp.arange(S + 1, dtype=jnp.int32) <= s.steps[:, None])[:, :, None]
    out = jnp.where(taken[..., None], out, out[lanes, s.steps][:, None])
    clear = jnp.where(taken, clear, clear[lanes, s.steps][:, None])
    found = (s.trees, s.length, s.start, out, s.steps, s.node >= s.length - 1, clear, s.proven)
    return found + (s.ik,) if with_ik else found


def _ended(s):
    """The motion that ended: ``(q reached, t, reached)`` as motions.advance returns them."""
    return s.q_a + s.t * s.dq, s.t, s.t >= 1.0


def _when(c, a, b):
    """``a if c else b`` for two states (c a traced bool)."""
    return jax.tree_util.tree_map(lambda x, y: jnp.where(c, x, y), a, b)


class _Lane:
    """One lane of the search machine: the state of a new search (``with_ik``: of the IK, then
    the search), the phases' handlers (:meth:`handlers`, list index = phase) and the substep
    of the current motion (:meth:`substep`, the one exact solve)."""

    def __init__(self, scenario, options: ReachOptions, solver, contact: float, n: int, dtype, with_ik: bool,
                 arm=PCC):
        self.scenario, self.options, self.solver, self.contact, self.arm = scenario, options, solver, contact, arm
        self.n, self.dtype, self.with_ik = n, dtype, with_ik
        self.T, self.S = int(options.tree_size), int(options.path_steps)
        self.G, self.S_ik = int(options.goal_roots), int(options.ik_starts)
        self.i0, self.f0, self.q0 = jnp.zeros((), jnp.int32), jnp.zeros((), bool), jnp.zeros((n, 3), dtype)
        self.mask = radius_and_mask(scenario)[1]

    def handlers(self) -> list:
        return [self.tree_next, self.extended, self.connected, self.tree_done, self.cut, self.smooth_start,
                self.smooth_a, self.smooth_b, self.walk_start, self.walk_end, self.check_end, self.ik_round,
                self.ik_solved]

    def init(self, q_starts, n_starts, *args):
        if not self.with_ik:
            return self.search_init(q_starts, n_starts, *args)
        key, ik_key, q_extra, proof = args
        # The goal roots: the IK's.
        s = self.search_init(q_starts, n_starts, jnp.zeros((self.G, self.n, 3), self.dtype), self.i0, key)
        starts, ik = ik_start(self.scenario, ik_key, q_extra, self.options)
        return s._replace(phase=jnp.asarray(_P_IK_ROUND, jnp.int32), ik=ik, ik_starts=starts, ik_i=self.i0,
                          proof=jnp.asarray(proof, bool))

    def search_init(self, q_starts, n_starts, q_goals, n_goals, key):
        k_tree, k_cut = jax.random.split(key)
        nodes = jnp.zeros((2, self.T, self.n, 3), self.dtype)
        nodes = nodes.at[0, : q_starts.shape[0]].set(q_starts[: self.T])
        nodes = nodes.at[1, : q_goals.shape[0]].set(q_goals[: self.T])
        count = jnp.stack([jnp.minimum(n_starts, self.T), jnp.minimum(n_goals, self.T)]).astype(jnp.int32)
        trees = mo.Trees(nodes, jnp.full((2, self.T), -1, jnp.int32), count, jnp.zeros((), bool),
                          jnp.zeros((2,), jnp.int32), jnp.zeros((), jnp.int32), k_tree)
        z, zq = jnp.zeros((), self.dtype), self.q0
        i0, f0 = self.i0, self.f0
        return _State(
            phase=jnp.asarray(_P_TREE, jnp.int32), q_a=zq, dq=zq, q_e=zq, t=z, k=i0, limit=i0, active=f0,
            trees=trees, near=i0, new_idx=i0, added=f0, near_b=i0,
            path=jnp.zeros((2 * self.T, self.n, 3), self.dtype), length=i0, start=i0, count=i0, node=i0, key=k_cut,
            possible=f0, cut=jnp.zeros((2,), jnp.int32), cand=zq, first_ok=f0, steps=i0, check_k=i0, proven=f0,
            row=i0, q_next=zq, write=f0, c_now=jnp.zeros(self.mask.shape, self.dtype), c_write=f0)

    def motion(self, s, q_a, q_b, substeps, phase):
        """Start the certified straight motion q_a -> q_a + wrap_delta(q_a, q_b) (motions.advance)."""
        dq = mo.wrap_delta(q_a, q_b)
        return s._replace(phase=jnp.asarray(phase, jnp.int32), q_a=q_a, dq=dq, q_e=q_a + dq,
                          t=jnp.zeros((), self.dtype), k=self.i0, limit=jnp.asarray(substeps, jnp.int32),
                          active=jnp.ones((), bool))

    # --- RRT-Connect: extend tree a towards a sample, then connect tree b to the new node.
    def tree_next(self, s):
        t = s.trees
        go = ~t.done & (t.it < self.options.iterations) & (t.count[0] > 0) & (t.count[1] > 0)
        a = t.it % 2
        key, k_rand = jax.random.split(t.key)
        q_rand = random_configurations(k_rand, self.scenario, self.options, 1)[0]
        near = mo.nearest(t.nodes[a], t.count[a], q_rand).astype(jnp.int32)
        q_near = t.nodes[a, near]
        dq = mo.wrap_delta(q_near, q_rand)
        B = mo.line_bound(q_near, dq)
        target = q_near + jnp.minimum(1.0, self.options.extend_distance / jnp.maximum(B, 1e-30)) * dq
        s_ext = s._replace(near=near, trees=t._replace(key=key))
        extend = self.motion(s_ext, q_near, target, self.options.extend_substeps, _P_EXTENDED)
        return _when(go, extend, s._replace(phase=jnp.asarray(_P_TREE_DONE, jnp.int32)))

    def extended(self, s):
        t = s.trees
        a = t.it % 2
        q_new, t_ext, _ = _ended(s)
        t, new_idx, added = _add(t, self.T, a, q_new, s.near, t_ext > 0.05)
        b = 1 - a
        near_b = mo.nearest(t.nodes[b], t.count[b], q_new).astype(jnp.int32)
        s = s._replace(trees=t, new_idx=new_idx.astype(jnp.int32), added=added, near_b=near_b)
        return self.motion(s, t.nodes[b, near_b], q_new, self.options.connect_substeps, _P_CONNECTED)

    def connected(self, s):
        t = s.trees
        a = t.it % 2
        q_c, t_c, reached = _ended(s)
        joined = s.added & reached
        t, _, _ = _add(t, self.T, 1 - a, q_c, s.near_b, s.added & ~reached & (t_c > 0.05))
        link = jnp.where(a == 0, jnp.stack([s.new_idx, s.near_b]), jnp.stack([s.near_b, s.new_idx])).astype(jnp.int32)
        t = t._replace(done=joined, link=jnp.where(joined, link, t.link), it=t.it + 1)
        return self.tree_next(s._replace(trees=t))

    # --- The connected path, then random shortcuts.
    def tree_done(self, s):
        path, length, start = mo.tree_path(s.trees, self.T)
        return self.cut_next(s._replace(path=path, length=length, start=start, count=self.i0))

    def cut_next(self, s):
        key, ki, kj = jax.random.split(s.key, 3)
        i = jax.random.randint(ki, (), 0, jnp.maximum(s.length - 2, 1), dtype=jnp.int32)
        j = jax.random.randint(kj, (), i + 2, jnp.maximum(s.length, i + 3), dtype=jnp.int32)
        s_try = s._replace(key=key, possible=j <= s.length - 1, cut=jnp.stack([i, j]))
        q_j = s.path[jnp.minimum(j, 2 * self.T - 1)]
        s_try = self.motion(s_try, s.path[i], q_j, self.options.connect_substeps, _P_CUT)
        return _when(s.count < self.options.shortcut_attempts, s_try,
                    s._replace(phase=jnp.asarray(_P_SMOOTH_START, jnp.int32)))

    def cut(self, s):
        i, j = s.cut[0], s.cut[1]
        removed = jnp.where(s.possible & _ended(s)[2], j - i - 1, 0)
        p = jnp.arange(2 * self.T, dtype=jnp.int32)
        src = jnp.where(p <= i, p, jnp.minimum(p + removed, 2 * self.T - 1))
        return self.cut_next(s._replace(path=s.path[src], length=s.length - removed, count=s.count + 1))

    # --- Smoothing: inner node k moves halfway to its neighbours' midpoint if both motions are certified.
    def smooth_start(self, s):
        return self.smooth_next(s._replace(count=self.i0, node=jnp.ones((), jnp.int32)))

    def smooth_next(self, s):
        over = s.node >= s.length - 1  # this pass has no node left: the next pass, from node 1
        s = s._replace(count=s.count + over.astype(jnp.int32), node=jnp.where(over, 1, s.node))
        k = s.node
        p_k = s.path[k]
        a = p_k + mo.wrap_delta(p_k, s.path[k - 1])
        b = p_k + mo.wrap_delta(p_k, s.path[k + 1])
        cand = p_k + 0.5 * (0.5 * (a + b) - p_k)
        s_move = self.motion(s._replace(cand=cand), s.path[k - 1], cand, self.options.extend_substeps, _P_SMOOTH_A)
        # Passes done, or a path without inner nodes (then every pass is empty): the walk.
        finished = (s.count >= self.options.smooth_passes) | (k >= s.length - 1)
        return _when(finished, s._replace(phase=jnp.asarray(_P_WALK_START, jnp.int32)), s_move)

    def smooth_a(self, s):
        s = s._replace(first_ok=_ended(s)[2])
        return self.motion(s, s.cand, s.path[s.node + 1], self.options.extend_substeps, _P_SMOOTH_B)

    def smooth_b(self, s):
        k = s.node
        moved = s.first_ok & _ended(s)[2]
        path = s.path.at[k].set(jnp.where(moved, s.cand, s.path[k]))
        return self.smooth_next(s._replace(path=path, node=k + 1))

    # --- The walk: every edge of the unwrapped polyline in steps of at most step_motion.
    def walk_start(self, s):
        path = mo.unwrap(s.path)
        s = s._replace(path=path, steps=self.i0, node=self.i0)
        go = s.length - 1 > 0
        q_a, q_e = path[0], path[1]
        s_walk = s._replace(phase=jnp.asarray(_P_WALK, jnp.int32), q_a=q_a, q_e=q_e, dq=q_e - q_a,
                            t=jnp.zeros((), self.dtype), active=jnp.ones((), bool))
        return _when(go, s_walk, s._replace(phase=jnp.asarray(_P_WALK, jnp.int32)))

    def walk_end(self, s):
        """The walk is over: the check of its path if the search found one (tree.global_search's ``found``)."""
        go = s.trees.done & (s.node >= s.length - 1)
        return s._replace(phase=jnp.where(go, _P_CHECK, _P_DONE).astype(jnp.int32), check_k=self.i0, proven=go, active=go)

    def check_end(self, s):
        return s._replace(phase=jnp.asarray(_P_DONE, jnp.int32))

    # --- The IK (with_ik): a round's configurations, their exact solves (substeps), its end.
    def ik_round(self, s):
        q = ik_round_configurations(s.ik, self.scenario, s.ik_starts, self.options, self.arm)
        return s._replace(phase=jnp.asarray(_P_IK_SOLVE, jnp.int32), ik=s.ik._replace(q=q), ik_i=self.i0,
                          active=jnp.ones((), bool))

    def ik_solved(self, s):
        """The round's starts are assessed: another round, or the search from the IK's first
        ``goal_roots`` results (where one is certified and no proof says unreachable), or done."""
        ik = ik_round_end(s.ik)
        more = ik_more(ik, self.options)
        q_goal, certified = ik_result(ik)[:2]
        go = certified[0] & ~s.proof
        roots = q_goal[:self.G][:self.T]
        t = s.trees
        n_goals = jnp.where(go, jnp.minimum(jnp.sum(certified[:self.G]), self.T), 0).astype(jnp.int32)
        t = t._replace(nodes=t.nodes.at[1, : roots.shape[0]].set(roots), count=t.count.at[1].set(n_goals))
        phase = jnp.where(more, _P_IK_ROUND, jnp.where(go, _P_TREE, _P_DONE)).astype(jnp.int32)
        return s._replace(ik=ik, trees=t, phase=phase)  # the next phase's handler runs next iteration

    def substep(self, s, out):
        """One substep: conservative advancement of the current motion, or one step of the check of
        the walk's path ``out`` (S + 1, n, 3); the one exact solve."""
        walk, check = s.phase == _P_WALK, s.phase == _P_CHECK
        # The check: the clearances at step j of the path (row 0 is its first node, written after
        # the loop), the swept proof of the motion to step j + 1 (none after the last step).
        j = s.check_k
        q_j = jnp.where(j == 0, s.path[0], out[jnp.minimum(j, self.S)])
        q = jnp.where(check, q_j, s.q_a + s.t * s.dq)
        if self.with_ik:  # the IK: the round's start ik_i
            assess, i = s.phase == _P_IK_SOLVE, jnp.minimum(s.ik_i, self.S_ik - 1)
            q = jnp.where(assess, s.ik.q[i], q)
        c, truth, ok, posed = posed_clearances(q, self.scenario, self.solver, self.arm)
        swept = swept_clear(q_j, out[jnp.minimum(j + 1, self.S)], truth, c, self.contact, self.arm)
        proof = jnp.all(swept | ~self.mask) | (j >= s.steps)
        checking = s._replace(check_k=j + 1, proven=s.proven & proof, c_now=c, c_write=s.active,
                              active=j + 1 <= s.steps, write=self.f0)
        cap = jnp.where(walk, self.options.step_motion, jnp.inf).astype(self.dtype)  # min(allowed, inf) = allowed
        t_new, good = mo.advance_fraction(q, s.q_e, s.t, c, ok, self.options, self.contact, cap=cap, arm=self.arm)
        # A motion of the search (motions.advance).
        k = s.k + 1
        moving = s._replace(t=t_new, k=k, active=(k < s.limit) & (t_new < 1.0) & good, write=self.f0, c_write=self.f0)
        # The walk: a good substep is a step of the path; at an edge's end the next edge starts.
        end = t_new >= 1.0
        q_next = jnp.where(end, s.q_e, s.q_a + t_new * s.dq)
        steps, e = s.steps + good.astype(jnp.int32), s.node + end.astype(jnp.int32)
        q_a, q_e = s.path[jnp.minimum(e, 2 * self.T - 1)], s.path[jnp.minimum(e + 1, 2 * self.T - 1)]
        walking = s._replace(row=s.steps + 1, q_next=q_next, write=good & s.active, steps=steps, node=e,
                             t=jnp.where(end, 0.0, t_new).astype(self.dtype),
                             q_a=jnp.where(end, q_a, s.q_a), q_e=jnp.where(end, q_e, s.q_e),
                             dq=jnp.where(end, q_e - q_a, s.dq),
                             active=(e < s.length - 1) & (steps < self.S) & good, c_write=self.f0)
        new = _when(check, checking, _when(walk, walking, moving))
        if not self.with_ik:
            return new
        solved, c_min, err, certified, free = ik_assess(q, c, truth, ok, posed, self.scenario, self.options,
                                                        self.contact)
        ik = s.ik
        ik = ik._replace(solved=jax.tree_util.tree_map(lambda a, x: a.at[i].set(x), ik.solved, solved),
                         c=ik.c.at[i].set(c_min), err=ik.err.at[i].set(err), certified=ik.certified.at[i].set(certified),
                         free=ik.free.at[i].set(free))
        assessing = s._replace(ik=ik, ik_i=s.ik_i + 1, active=s.ik_i + 1 < self.S_ik, write=self.f0, c_write=self.f0)
        return _when(assess, assessing, new)


def _lane(scenario, options: ReachOptions, solver, contact: float, n: int, dtype, with_ik: bool = False, arm=PCC):
    """One lane's ``(init, handlers, substep)`` (:class:`_Lane`)."""
    lane = _Lane(scenario, options, solver, contact, n, dtype, with_ik, arm)
    return lane.init, lane.handlers(), lane.substep
