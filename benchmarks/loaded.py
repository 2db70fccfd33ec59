"""PCC plans on a loaded arm, and the load-aware planner: random scenes at three load levels.

For every scene of ``random_scenarios(seed, n)`` and every load level (a
:class:`~softplan_jax.rod.RodModel` of weight ``w = 0.3 N/m`` per metre and a
bending stiffness ``EI = w L^3 / gamma`` for the arm's length L = 3 at rest,
``GJ = 2 EI / 3``, no tip load; ``gamma`` 0.25, 0.8, 1.6: a horizontal cantilever
of these would drop by ``gamma L / 8`` at its tip, 3 %, 10 % and 20 % of L):

* **PCC plans executed on the loaded arm**: the library's default plan
  (``plan_batch``, the PCC model), its configurations commanded to the loaded
  arm. Its loaded tip at the end is compared with the goal (the planner's goal
  tolerance), and its path audited by a brute force on the equilibria along it
  (``loaded_backbone`` at every step and ``--between`` instants between
  steps, 17 points per segment) against the obstacles sampled at 401 points
  each: a "touch" is a sampled clearance <= 0 (the sampling can miss a shallow
  touch, never invent one: the count is a lower bound).
* **The load-aware planner**: ``plan_batch(..., model=RodModel)``, the same
  scenes, audited the same way (0 touches expected: its clearances are proven
  lower bounds).

Reported per level, paired on the same scenes: success of each (the loaded
arm's tip at the goal, and no touch by the audit), touches, McNemar's test of the paired success, 95 % Wilson
intervals; the cost of a taken step of each planner (batch run time divided by
the steps taken, compile time apart). A figure of the tree under load: the
commanded PCC shape as a ghost, the loaded shape, the branches.

Usage::

    python benchmarks/loaded.py --seed 1 --n 1000 --between 0   # the committed report (about an hour)
    python benchmarks/loaded.py --cost                          # the cost of a step, alone
    python benchmarks/loaded.py --moving --n 256 --levels medium  # tracking moving scenes
    python benchmarks/loaded.py --fallback --n 128 --levels medium  # with the global fallback
    python benchmarks/loaded.py --quick                         # smoke run into results/quick/

Writes ``benchmarks/results/loaded_seed<seed>_n<n>.{md,json}`` and
``results/figures/loaded_tree.png`` (``--cost``: ``results/loaded_cost.{md,json}``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _common import log, output_paths, write_results  # noqa: E402
from _stats import fmt_rate, paired_table  # noqa: E402

GAMMAS = {"light": 0.25, "medium": 0.8, "heavy": 1.6}
WEIGHT = 0.3  # N/m
ARM_LENGTH = 3.0  # the random suite's arm at rest: 3 segments of 1 m
POINTS = 17  # backbone samples per segment of the audit
OBSTACLE_SAMPLES = 401
GOAL_TOLERANCE = 0.01  # the planner's default (PlanOptions.goal_tolerance)


def command(args, levels, mode: str = "") -> str:
    """The report's command line (``mode``: "", "--moving" or "--fallback"), in backticks."""
    return (f"`python benchmarks/loaded.py {mode + ' ' if mode else ''}--seed {args.seed} --n {args.n} --levels "
            f"{','.join(levels)} --max-steps {args.max_steps} --chunk {args.chunk} --between {args.between}`")


def model_of(gamma: float):
    import softplan_jax as sp

    EI = WEIGHT * ARM_LENGTH**3 / gamma
    return sp.RodModel(EI, 2.0 * EI / 3.0, WEIGHT)


def _obstacle_table(scenes, slots: int):
    """Per scene: obstacle samples (slots, S, 3) padded with far points, radii (slots,), the
    arm's radius."""
    import jax

    from softplan_jax.geometry._obstacles import obstacle_samples

    tables = []
    host = jax.tree_util.tree_map(np.asarray, scenes)
    for b in range(host.q0.shape[0]):
        scene = jax.tree_util.tree_map(lambda x, b=b: x[b], host)
        obs = obstacle_samples(scene, OBSTACLE_SAMPLES)
        pts = [np.resize(o["pts"], (OBSTACLE_SAMPLES, 3)) for o in obs]
        O = np.full((slots, OBSTACLE_SAMPLES, 3), 1e6)
        R = np.zeros(slots)
        for j, (p, o) in enumerate(zip(pts, obs, strict=True)):
            O[j], R[j] = p, o["radius"]
        tables.append((O, R, float(scene.arm_radius)))
    return tables


def audit(qs, iterations, tables, model, between: int, chunk: int = 1024):
    """Per scene: the smallest sampled clearance of the loaded arm over its path (steps and
    ``between`` instants between steps), and whether an equilibrium failed (NaN). Every scene's
    configurations go through one program in chunks of ``chunk``."""
    import jax
    import jax.numpy as jnp

    import softplan_jax as sp

    O_all = jnp.asarray(np.stack([t[0] for t in tables]))  # (B, M, S, 3)
    R_all = jnp.asarray(np.stack([t[1] for t in tables]))  # (B, M)
    ra_all = jnp.asarray(np.array([t[2] for t in tables]))  # (B,)

    def one(P, b):  # P (A, 3) backbone samples of a configuration of scene b
        d2 = jnp.sum((P[:, None, None, :] - O_all[b][None]) ** 2, axis=-1)  # (A, M, S)
        return jnp.min(jnp.sqrt(jnp.min(d2, axis=(0, 2))) - R_all[b] - ra_all[b])

    @jax.jit
    def clearance(Q, b):  # Q (K, n, 3) configurations of scenes b (K,)
        P = jax.vmap(lambda q: sp.loaded_backbone(q, model, POINTS))(Q).reshape(Q.shape[0], -1, 3)
        groups = (P.reshape(-1, 32, *P.shape[1:]), b.reshape(-1, 32))  # 32 at a time: memory
        c = jax.lax.map(lambda g: jax.vmap(one)(*g), groups).reshape(-1)
        return c, jnp.all(jnp.isfinite(P), axis=(1, 2))

    t = np.linspace(0.0, 1.0, between + 2)[:-1]
    paths, owner = [], []
    for b in range(len(tables)):
        q = np.asarray(qs[b][: int(iterations[b]) + 1])
        path = (q[:-1, None] + t[None, :, None, None] * (q[1:] - q[:-1])[:, None]).reshape(-1, *q.shape[1:])
        paths.append(np.concatenate([path, q[-1:]]))
        owner.append(np.full(len(paths[-1]), b))
    Q, owner = np.concatenate(paths), np.concatenate(owner)
    K = len(Q)
    pad = -K % chunk
    Q = np.concatenate([Q, np.repeat(Q[-1:], pad, axis=0)])
    owner_p = np.concatenate([owner, np.repeat(owner[-1:], pad)])
    c, ok = np.empty(len(Q)), np.empty(len(Q), bool)
    for k, a in enumerate(range(0, len(Q), chunk)):
        ca, oka = clearance(jnp.asarray(Q[a : a + chunk]), jnp.asarray(owner_p[a : a + chunk]))
        c[a : a + chunk], ok[a : a + chunk] = np.asarray(ca), np.asarray(oka)
        if (k + 1) % 20 == 0:
            log(f"  audited {a + chunk}/{len(Q)} configurations")
    c, ok = c[:K], ok[:K]
    B = len(tables)
    out = np.full(B, np.inf)
    np.minimum.at(out, owner, np.where(ok, c, np.inf))
    failed = np.zeros(B, bool)
    np.logical_or.at(failed, owner, ~ok)
    return out, failed


def loaded_tip_error(scenes, qs, iterations, model):
    """(B,) the loaded arm's tip distance to the goal at each plan's last configuration."""
    import jax
    import jax.numpy as jnp

    import softplan_jax as sp

    last = np.asarray(qs)[np.arange(len(iterations)), np.asarray(iterations)]
    tips = jax.jit(jax.vmap(lambda q: sp.loaded_backbone(q, model, 2)[-1, -1]))(jnp.asarray(last))
    return np.linalg.norm(np.asarray(tips) - np.asarray(scenes.goal), axis=-1)


def run_level(scenes, tables, gamma: float, args, pcc):
    """One load level: the load-aware batch (timed), the audits of both planners' paths."""

    model = model_of(gamma)
    r, run_s, compile_s = timed_batch(scenes, args, model=model)
    iters = np.asarray(r.iterations)
    log(f"  loaded planner: {run_s:.1f} s for {int(iters.sum())} steps; auditing both planners' paths")
    t0 = time.perf_counter()
    c_pcc, f_pcc = audit(pcc["q"], pcc["iterations"], tables, model, args.between)
    tip_err = loaded_tip_error(scenes, pcc["q"], pcc["iterations"], model)
    c_load, f_load = audit(np.asarray(r.q), iters, tables, model, args.between)
    log(f"  audits: {time.perf_counter() - t0:.1f} s")
    return dict(gamma=gamma, EI=float(model.bending_stiffness), status=np.asarray(r.status), iterations=iters,
                reached=np.asarray(r.reached), c_pcc=c_pcc, failed_pcc=f_pcc, tip_error_pcc=tip_err, c_loaded=c_load,
                failed_loaded=f_load, run_s=run_s, compile_s=compile_s)


def timed_batch(scenes, args, model=None):
    """``(rollout, run seconds, compile seconds)``: ``plan_batch`` in chunks of ``args.chunk``,
    compiled first on one chunk of the same shape (its time less its run is the compile time)."""
    import jax

    import softplan_jax as sp

    kw = dict(max_steps=args.max_steps, chunk=args.chunk, model=model)
    part = jax.tree_util.tree_map(lambda x: x[: args.chunk], scenes)
    t0 = time.perf_counter()
    jax.block_until_ready(sp.plan_batch(part, **kw))
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = jax.block_until_ready(sp.plan_batch(scenes, progress=True, **kw))
    run_s = time.perf_counter() - t0
    chunks = -(-int(scenes.q0.shape[0]) // args.chunk)
    return r, run_s, max(warm - run_s / chunks, 0.0)


def pcc_batch(scenes, args):
    """The PCC planner's batch (:func:`timed_batch`)."""
    r, run_s, compile_s = timed_batch(scenes, args)
    return dict(q=np.asarray(r.q), iterations=np.asarray(r.iterations), reached=np.asarray(r.reached),
                run_s=run_s, compile_s=compile_s)


def level_lines(name: str, lv: dict, pcc: dict) -> list[str]:
    n = len(lv["c_pcc"])
    touch_pcc = (lv["c_pcc"] <= 0.0) | lv["failed_pcc"]
    touch_load = (lv["c_loaded"] <= 0.0) | lv["failed_loaded"]
    ok_pcc = pcc["reached"] & (lv["tip_error_pcc"] < GOAL_TOLERANCE) & ~touch_pcc
    ok_load = lv["reached"] & ~touch_load
    tab = paired_table(ok_load, ok_pcc)
    per_step_pcc = pcc["run_s"] / max(int(pcc["iterations"].sum()), 1)
    per_step_load = lv["run_s"] / max(int(lv["iterations"].sum()), 1)
    return [
        f"| {name} (gamma {lv['gamma']}, EI {lv['EI']:.3g}) | {fmt_rate(int(touch_pcc.sum()), n)} | "
        f"{np.median(lv['tip_error_pcc'][pcc['reached']]):.3f} | "
        f"{fmt_rate(int(ok_pcc.sum()), n)} | {fmt_rate(int(ok_load.sum()), n)} | "
        f"{fmt_rate(int(touch_load.sum()), n)} | {tab['only_x']} / {tab['only_y']} (p = {tab['mcnemar_p']:.2g}) | "
        f"{1e3 * per_step_load:.2f} ms / {1e3 * per_step_pcc:.3f} ms = {per_step_load / per_step_pcc:.0f}x |",
    ]


def tree_figure(path: str, gamma: float) -> None:
    """The tree under load: the PCC plan's configurations commanded to the loaded arm (ghost:
    the PCC shape) beside the load-aware plan's final shape."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import softplan_jax as sp
    from softplan_jax.geometry._obstacles import obstacle_samples

    scene = sp.paper_scenario("tree")
    model = model_of(gamma)
    pcc = sp.plan(scene)
    loaded = sp.plan(scene, model=model)
    fig = plt.figure(figsize=(11, 5.5))
    for k, (title, r) in enumerate([("PCC plan, commanded to the loaded arm", pcc),
                                    (f"load-aware plan ({loaded.status}, {loaded.iterations} steps)", loaded)]):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for o in obstacle_samples(scene, 200):
            ax.plot(*o["pts"].T, color="saddlebrown", lw=3)
        for j in np.linspace(0, len(r.q) - 1, 5).astype(int):
            q = np.asarray(r.q[j])
            ghost = np.asarray(sp.loaded_backbone(q, sp.RodModel(1.0, 1.0, 0.0), 17)).reshape(-1, 3)
            bent = np.asarray(sp.loaded_backbone(q, model, 17)).reshape(-1, 3)
            ax.plot(*ghost.T, color="0.6", lw=1, ls="--")
            ax.plot(*bent.T, color="tab:blue", lw=2)
        ax.scatter(*np.asarray(scene.goal), color="tab:green", s=30)
        ax.set_title(title, fontsize=9)
        ax.set_box_aspect((1, 1, 1))
    fig.suptitle(f"The tree under load (gamma {gamma}: EI {float(model.bending_stiffness):.3g} N m^2, "
                 f"w {WEIGHT} N/m). Dashed: the commanded PCC shape; blue: the loaded shape.", fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def audit_moving(qs, times, iterations, movings, model, between: int, chunk: int = 256):
    """:func:`audit` on moving scenes: the loaded arm at each configuration against the scene's
    curves at that instant (steps at their times, ``between`` instants between steps with the
    curves moved to the instant's time). Per scene: the smallest sampled clearance and whether an
    equilibrium failed."""
    import jax
    import jax.numpy as jnp

    import softplan_jax as sp
    from softplan_jax.scenarios._motion import scenario_at

    u = jnp.linspace(0.0, 1.0, OBSTACLE_SAMPLES)

    def one(q, b, t):
        mv = jax.tree_util.tree_map(lambda x: x[b], movings)
        curves = scenario_at(mv, t).curves
        lo, hi = curves.u_range[:, :1], curves.u_range[:, 1:]
        uu = lo + (hi - lo) * u[None]  # (M, S)
        powers = uu[..., None] ** jnp.arange(curves.coeffs.shape[-1])  # (M, S, K)
        O = jnp.einsum("mak,msk->msa", curves.coeffs, powers)  # (M, S, 3), power basis
        P = sp.loaded_backbone(q, model, POINTS).reshape(-1, 3)
        d2 = jnp.sum((P[:, None, None, :] - O[None]) ** 2, axis=-1)  # (A, M, S)
        c = jnp.sqrt(jnp.min(d2, axis=(0, 2))) - curves.radius - mv.scene.arm_radius
        return jnp.min(jnp.where(mv.scene.curve_mask, c, jnp.inf)), jnp.all(jnp.isfinite(P))

    clearance = jax.jit(lambda Q, b, t: jax.lax.map(lambda g: jax.vmap(one)(*g), (
        Q.reshape(-1, 32, *Q.shape[1:]), b.reshape(-1, 32), t.reshape(-1, 32))))
    tau = np.linspace(0.0, 1.0, between + 2)[:-1]
    Qs, Ts, owner = [], [], []
    for b in range(len(iterations)):
        k = int(iterations[b]) + 1
        q, t = np.asarray(qs[b][:k]), np.asarray(times[b][:k])
        Qs += [(q[:-1, None] + tau[None, :, None, None] * (q[1:] - q[:-1])[:, None]).reshape(-1, *q.shape[1:]), q[-1:]]
        Ts += [(t[:-1, None] + tau[None, :] * (t[1:] - t[:-1])[:, None]).reshape(-1), t[-1:]]
        owner.append(np.full(len(Qs[-2]) + 1, b))
    Q, T, owner = np.concatenate(Qs), np.concatenate(Ts), np.concatenate(owner)
    K = len(Q)
    pad = -K % chunk
    Q, T, owner_p = (np.concatenate([x, np.repeat(x[-1:], pad, axis=0)]) for x in (Q, T, owner))
    c, ok = np.empty(len(Q)), np.empty(len(Q), bool)
    for k, a in enumerate(range(0, len(Q), chunk)):
        part = (jnp.asarray(x[a : a + chunk]) for x in (Q, owner_p, T))
        ca, oka = clearance(*part)
        c[a : a + chunk], ok[a : a + chunk] = np.asarray(ca).reshape(-1), np.asarray(oka).reshape(-1)
        if (k + 1) % 40 == 0:
            log(f"  audited {a + chunk}/{len(Q)} configurations")
    c, ok = c[:K], ok[:K]
    out = np.full(len(iterations), np.inf)
    np.minimum.at(out, owner, np.where(ok, c, np.inf))
    failed = np.zeros(len(iterations), bool)
    np.logical_or.at(failed, owner, ~ok)
    return out, failed


def moving_report(args, levels) -> int:
    """Tracking on random moving scenes: the PCC tracker's paths commanded to the loaded arm,
    and the load-aware tracker, audited with the curves at every instant; paired, with intervals."""
    import jax

    import softplan_jax as sp

    prefix = output_paths(f"loaded_moving_seed{args.seed}_n{args.n}", args.quick, args.out)[0]
    movings = sp.moving.random_moving_scenarios(args.seed, args.n)
    hold = sp.planning.TrackOptions().hold_tolerance
    kw = dict(max_steps=args.max_steps, chunk=args.chunk, progress=True)
    log(f"PCC tracker on {args.n} moving scenes (seed {args.seed})")
    t0 = time.perf_counter()
    pcc = jax.device_get(sp.track_batch(movings, **kw))
    log(f"  {time.perf_counter() - t0:.1f} s")
    goal_end = lambda r: np.asarray(r.goal)[np.arange(args.n), np.asarray(r.iterations)]
    stopped = [int(s) for s in (sp.Status.COLLIDED, sp.Status.NONFINITE, sp.Status.TOO_FAST, sp.Status.START_COLLIDED)]
    ran_out = lambda r: ~np.isin(np.asarray(r.status), stopped)  # ran to its horizon
    lines = [f"# Tracking with the loaded arm: {args.n} random moving scenes (seed {args.seed})", "",
             f"{command(args, levels, '--moving')} (audit: the equilibria at "
             f"every step and {args.between} instants between, the curves moved to each instant, {POINTS} points per "
             f"segment, curves at {OBSTACLE_SAMPLES} points). Load as the static report: w = {WEIGHT} N/m, "
             f"EI = w L^3 / gamma, GJ = 2 EI / 3.", "",
             "| load | PCC track touches under load | PCC track holds the goal under load | load-aware tracker holds "
             "the goal | load-aware touches | load-aware ends too_fast | paired: only load-aware / only PCC (McNemar) |",
             "|---|---|---|---|---|---|---|"]
    report = dict(seed=args.seed, n=args.n, max_steps=args.max_steps, levels={})
    for name in levels:
        model = model_of(GAMMAS[name])
        log(f"load level {name}: the load-aware tracker")
        t0 = time.perf_counter()
        r = jax.device_get(sp.track_batch(movings, model=model, **kw))
        log(f"  {time.perf_counter() - t0:.1f} s; auditing both trackers' paths")
        c_pcc, f_pcc = audit_moving(pcc.q, pcc.time, pcc.iterations, movings, model, args.between)
        c_load, f_load = audit_moving(r.q, r.time, r.iterations, movings, model, args.between)
        last = np.asarray(pcc.q)[np.arange(args.n), np.asarray(pcc.iterations)]
        tips = np.asarray(jax.jit(jax.vmap(lambda q, m=model: sp.loaded_backbone(q, m, 2)[-1, -1]))(last))
        touch_pcc, touch_load = (c_pcc <= 0) | f_pcc, (c_load <= 0) | f_load
        ok_pcc = (np.linalg.norm(tips - goal_end(pcc), axis=-1) <= hold) & ~touch_pcc & ran_out(pcc)
        ok_load = (np.asarray(r.error)[np.arange(args.n), np.asarray(r.iterations)] <= hold) & ~touch_load & ran_out(r)
        too_fast = np.asarray(r.status) == int(sp.Status.TOO_FAST)
        tab = paired_table(ok_load, ok_pcc)
        lines.append(f"| {name} (gamma {GAMMAS[name]}) | {fmt_rate(int(touch_pcc.sum()), args.n)} | "
                     f"{fmt_rate(int(ok_pcc.sum()), args.n)} | {fmt_rate(int(ok_load.sum()), args.n)} | "
                     f"{fmt_rate(int(touch_load.sum()), args.n)} | {fmt_rate(int(too_fast.sum()), args.n)} | "
                     f"{tab['only_x']} / {tab['only_y']} (p = {tab['mcnemar_p']:.2g}) |")
        report["levels"][name] = dict(c_pcc=c_pcc, c_loaded=c_load, ok_pcc=ok_pcc, ok_loaded=ok_load,
                                      status=np.asarray(r.status))
    lines += ["", f"Holds the goal: the loaded arm's tip within the hold tolerance ({hold}) of the goal at the last "
              "step, no touch by the audit, and the rollout ran to its horizon (no collision, non-finite or "
              "too_fast ending). The PCC tracker without "
              f"load holds {fmt_rate(int(np.sum(np.asarray(pcc.held_to_end))), args.n)} (held from its first reach "
              "to the end). Rates with 95 % Wilson intervals."]
    write_results(prefix, report, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def rescued_paths(scenes, r, model, args):
    """The global fallback (``rescue_batch`` with the loaded arm) on the scenes the load-aware
    batch ``r`` did not reach: per scene, the final path (B lists of configurations), reached,
    and the fallback's reason ("" where the local planner reached, or the search did)."""
    import softplan_jax as sp
    from softplan_jax.search._fallback import rescue_batch

    qs = [np.asarray(r.q[b][: int(r.iterations[b]) + 1]) for b in range(args.n)]
    reached, reason = np.asarray(r.reached).copy(), np.array([""] * args.n, dtype=object)
    idx, results = rescue_batch(scenes, r, sp.PlanOptions(), model=model, progress=True)
    for b, res in zip(idx, results, strict=True):
        qs[b], reached[b], reason[b] = np.asarray(res.q), res.status == "reached", res.reason
    return qs, reached, reason, idx


def fallback_report(args, levels) -> int:
    """The load-aware planner with the global fallback on random scenes: the local batch, then
    reachability and the search (the loaded arm's IK, certified motions and check) on every scene
    it left stalled or at max_steps; every final path audited by the brute force."""
    import jax

    import softplan_jax as sp

    prefix = output_paths(f"loaded_fallback_seed{args.seed}_n{args.n}", args.quick, args.out)[0]
    scenes = sp.random_scenarios(args.seed, args.n)
    tables = _obstacle_table(scenes, scenes.curves.coeffs.shape[1])
    lines = [f"# The loaded arm with the global fallback: {args.n} random scenes (seed {args.seed})", "",
             f"{command(args, levels, '--fallback')} (audit: the equilibria at "
             f"every step and {args.between} instants between, {POINTS} points per segment, obstacles at "
             f"{OBSTACLE_SAMPLES} points). Load as the static report: w = {WEIGHT} N/m, EI = w L^3 / gamma, "
             "GJ = 2 EI / 3.", "",
             "| load | load-aware planner succeeds | with the fallback | rescued by the search | unreachable "
             "(proof / no IK solution) | search exhausted | touches (audit) | paired: only with / only without "
             "(McNemar) | fallback time |",
             "|---|---|---|---|---|---|---|---|---|"]
    report = dict(seed=args.seed, n=args.n, max_steps=args.max_steps, levels={})
    for name in levels:
        model = model_of(GAMMAS[name])
        log(f"load level {name}: the load-aware batch")
        r = jax.device_get(sp.plan_batch(scenes, max_steps=args.max_steps, chunk=args.chunk, progress=True,
                                         model=model))
        t0 = time.perf_counter()
        qs, reached, reason, idx = rescued_paths(scenes, r, model, args)
        fb_s = time.perf_counter() - t0
        log(f"  fallback on {idx.size} scenes: {fb_s:.1f} s; auditing the final paths")
        c, failed = audit(qs, [len(q) - 1 for q in qs], tables, model, args.between)
        touch = (c <= 0.0) | failed
        ok_local = np.asarray(r.reached) & ~touch
        ok = reached & ~touch
        tab = paired_table(ok, ok_local)
        rescued = int(np.sum(ok & ~np.asarray(r.reached)))
        proofs = int(np.sum(np.isin(reason, ("beyond_reach", "goal_in_obstacle"))))
        no_ik = int(np.sum(reason == "no_ik_solution"))
        lines.append(f"| {name} (gamma {GAMMAS[name]}) | {fmt_rate(int(ok_local.sum()), args.n)} | "
                     f"{fmt_rate(int(ok.sum()), args.n)} | {rescued} of {idx.size} | {proofs} / {no_ik} | "
                     f"{int(np.sum(reason == 'search_exhausted'))} | {fmt_rate(int(touch.sum()), args.n)} | "
                     f"{tab['only_x']} / {tab['only_y']} (p = {tab['mcnemar_p']:.2g}) | {fb_s:.0f} s |")
        report["levels"][name] = dict(reached_local=np.asarray(r.reached), reached=reached, reason=reason.tolist(),
                                      clearance=c, failed=failed, fallback_s=fb_s)
    lines += ["", "Succeeds: reached (the loaded tip within the goal tolerance) and no touch by the audit. The "
              "fallback runs one scene at a time; its time includes compiling its program once per level. Rates "
              "with 95 % Wilson intervals."]
    write_results(prefix, report, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def step_cost(repeats: int = 7) -> list[str]:
    """The cost of a step of one plan of the tree, PCC against loaded (the medium level), in one
    process, interleaved: ``repeats`` warm plans of each, per step taken (min and median)."""
    import jax

    import softplan_jax as sp

    scene, model = sp.paper_scenario("tree"), model_of(GAMMAS["medium"])
    runs = {"PCC": {}, "loaded": dict(model=model)}
    times = {k: [] for k in runs}
    steps = {}
    for k, kw in runs.items():  # compile
        t0 = time.perf_counter()
        steps[k] = jax.block_until_ready(sp.plan(scene, **kw)).iterations
        log(f"  {k}: first plan (compile and run) {time.perf_counter() - t0:.1f} s, {steps[k]} steps")
    for _ in range(repeats):
        for k, kw in runs.items():
            t0 = time.perf_counter()
            sp.plan(scene, **kw)
            times[k].append((time.perf_counter() - t0) / max(steps[k], 1))
    per = {k: (min(v), float(np.median(v))) for k, v in times.items()}
    return [
        f"One plan of the tree ({repeats} warm plans each, interleaved, per step taken): PCC "
        f"{1e3 * per['PCC'][0]:.3f} / {1e3 * per['PCC'][1]:.3f} ms (min / median, {steps['PCC']} steps), loaded "
        f"(medium) {1e3 * per['loaded'][0]:.3f} / {1e3 * per['loaded'][1]:.3f} ms ({steps['loaded']} steps): "
        f"{per['loaded'][0] / per['PCC'][0]:.1f}x (min) / {per['loaded'][1] / per['PCC'][1]:.1f}x (median).",
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=1, help="the random suite's seed (held out)")
    ap.add_argument("--n", type=int, default=1000, help="scenes")
    ap.add_argument("--levels", default="light,medium,heavy", help=f"load levels, of {sorted(GAMMAS)}")
    ap.add_argument("--max-steps", type=int, default=300)
    ap.add_argument("--chunk", type=int, default=64)
    ap.add_argument("--between", type=int, default=2, help="instants audited between steps")
    ap.add_argument("--quick", action="store_true", help="smoke run (16 scenes, one level) into results/quick/")
    ap.add_argument("--out", default=None, help="results prefix (default results/loaded_seed<seed>_n<n>)")
    ap.add_argument("--cost", action="store_true",
                    help="only the cost of a step (one plan of the tree, PCC against loaded), into results/loaded_cost")
    ap.add_argument("--fallback", action="store_true",
                    help="the load-aware planner with the global fallback, into results/loaded_fallback_seed<seed>_n<n>")
    ap.add_argument("--moving", action="store_true",
                    help="tracking on random moving scenes (track_batch), into results/loaded_moving_seed<seed>_n<n>")
    args = ap.parse_args(argv)
    levels = [x for x in args.levels.split(",") if x]
    for x in levels:
        if x not in GAMMAS:
            raise SystemExit(f"unknown load level {x!r} (known: {sorted(GAMMAS)})")
    if args.quick:
        args.n, levels, args.max_steps = 16, levels[:1], min(args.max_steps, 200)
    import jax

    jax.config.update("jax_enable_x64", True)
    import softplan_jax as sp

    if args.moving:
        return moving_report(args, levels)
    if args.fallback:
        return fallback_report(args, levels)
    if args.cost:
        prefix = output_paths("loaded_cost", args.quick, args.out)[0]
        lines = ["# The cost of a loaded step", "", "`python benchmarks/loaded.py --cost`", "",
                 *step_cost(3 if args.quick else 7)]
        write_results(prefix, {"lines": lines}, "\n".join(lines) + "\n")
        print("\n".join(lines))
        return 0
    prefix, figures = output_paths(f"loaded_seed{args.seed}_n{args.n}", args.quick, args.out)
    scenes = sp.random_scenarios(args.seed, args.n)
    tables = _obstacle_table(scenes, scenes.curves.coeffs.shape[1])
    log(f"PCC planner on {args.n} scenes (seed {args.seed})")
    pcc = pcc_batch(scenes, args)
    report = dict(seed=args.seed, n=args.n, max_steps=args.max_steps, between=args.between,
                  pcc=dict(reached=pcc["reached"], iterations=pcc["iterations"], run_s=pcc["run_s"],
                           compile_s=pcc["compile_s"]), levels={})
    lines = [
        f"# PCC plans on the loaded arm, and the load-aware planner: {args.n} random scenes (seed {args.seed})", "",
        f"{command(args, levels)} (max_steps {args.max_steps}, chunk "
        f"{args.chunk}; audit: the equilibria at every step and {args.between} instants between, {POINTS} points "
        f"per segment, obstacles at {OBSTACLE_SAMPLES} points). Load: w = {WEIGHT} N/m, EI = w L^3 / gamma "
        f"(L = {ARM_LENGTH} m), GJ = 2 EI / 3.", "",
        f"PCC planner (no load in its model): reached {fmt_rate(int(pcc['reached'].sum()), args.n)}.", "",
        "| load | PCC plan touches under load | its loaded tip's goal error (median of reached) | "
        "PCC plan succeeds under load | load-aware planner succeeds | "
        "load-aware planner touches | paired: only load-aware / only PCC (McNemar) | cost of a step: loaded / PCC |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in levels:
        log(f"load level {name} (gamma {GAMMAS[name]})")
        lv = run_level(scenes, tables, GAMMAS[name], args, pcc)
        report["levels"][name] = lv
        lines += level_lines(name, lv, pcc)
    lines += ["", f"Success: the loaded arm's tip within the goal tolerance ({GOAL_TOLERANCE}) at the end, and no "
              "touch by the audit (a sampled clearance <= 0, or an equilibrium that did not converge). Rates with "
              "95 % Wilson intervals. The cost of a step is the batch's run time divided by the steps its scenes "
              "took (compile time apart)."]
    fig_path = os.path.join(figures, "loaded_tree.png")
    tree_figure(fig_path, GAMMAS[levels[-1]])
    lines += ["", f"![the tree under load]({os.path.relpath(fig_path, os.path.dirname(prefix))})", ""]
    write_results(prefix, report, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
