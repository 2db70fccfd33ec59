"""Dodge, don't freeze: the evasive step against today's tracker, over obstacle speed.

One command, progress on stderr::

    python benchmarks/evasion.py            # held-out seed 1, 1,024 scenes a level, 300 steps (~25 min)
    python benchmarks/evasion.py --quick    # smoke run, written to benchmarks/results/quick/

Levels of obstacle motion on ``random_moving_scenarios(seed, n, ...)`` (the
same scenes at rest and the same sway axes and phases at every level, since the
generator's draws do not depend on the ranges' values):

* ``default``: the moving benchmark's motion (sway up to 0.08 rad, shift up to
  0.06 m, 0.5-1.5 rad/s);
* ``brisk x1``, ``x1.5``, ``x2``: sway up to 0.12 rad and shift up to 0.08 m
  at 0.5-2 rad/s, the frequencies times 1, 1.5, 2 (twice the brisk speed).

At every level the same scenes are tracked twice, paired: today's tracker
(``evasion=False``: ends ``too_fast`` where no scale of the field's step is
proven safe) and the evasive step (``evasion=True``, the default). Reported:
the statuses with Wilson 95 % intervals, McNemar's exact test on "reached and
held", and contacts by an independent brute force
(:func:`softplan_jax.testing.oracle.moving_min_clearance`: the oracle's
kinematics, the curves moved by SciPy's expm, sampled in space and time) over
the ``--evasive-brute`` evasive steps of each level with the smallest recorded
clearance (each with the motion after it), and over the whole path of the
``--brute`` scenes with the smallest recorded clearance.
"Reachable": the scenes that ``plan_fallback`` reaches at rest within the same
steps (the local planner, then reachability and the certified global search).
On the ``--fallback`` levels the scenes also run through ``track_fallback``
(the tracker with the evasive step, then, where it never reached the goal, a
run guided by the global search's path at rest), paired against the tracker
alone, its guided runs re-checked by the brute force.

Cost per step where the evasive step never acts: the swaying tree (single) and
``--batch`` scenes of the default level in which no evasive step was taken,
tracked with evasion on and off, interleaved rounds, run time apart from compile.

Writes ``results/evasion.{md,json}`` and ``results/figures/evasion_levels.png``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

STATUSES = ("reached", "held", "lost", "max_steps", "too_fast", "collided", "non_finite")
DEFAULT = dict(amplitude=0.08, shift=0.06, omega=(0.5, 1.5))
BRISK = dict(amplitude=0.12, shift=0.08, omega=(0.5, 2.0))


def levels(quick: bool) -> list[tuple[str, dict]]:
    """The motion levels: (label, random_moving_scenarios keyword arguments)."""
    out = [("default", DEFAULT)]
    for f in ((1.0, 2.0) if quick else (1.0, 1.5, 2.0)):
        lo, hi = BRISK["omega"]
        out.append((f"brisk x{f:g}", dict(BRISK, omega=(lo * f, hi * f))))
    return out


def parse_args(argv=None):
    """The command line, checked (ValueError naming the option)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (small sizes) into results/quick/")
    ap.add_argument("--seed", type=int, default=1, help="held-out seed of random_moving_scenarios")
    ap.add_argument("--n", type=int, default=None, help="scenes a level (default 1024; quick 16)")
    ap.add_argument("--max-steps", type=int, default=None, help="steps of every rollout (default 300; quick 80)")
    ap.add_argument("--brute", type=int, default=None,
                    help="scenes a level whose whole path is re-checked by brute force (default 16; quick 2)")
    ap.add_argument("--evasive-brute", type=int, default=None,
                    help="evasive steps a level re-checked by brute force, the closest first (default 300; quick 8)")
    ap.add_argument("--fallback", default="default",
                    help="comma list of levels also run with track_fallback (default: default; '' for none)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 7; quick 2)")
    ap.add_argument("--batch", type=int, default=None, help="scenes of the batched timing (default 64; quick 4)")
    ap.add_argument("--out", default=None, help="output prefix (default results/evasion; quick: results/quick/...)")
    args = ap.parse_args(argv)
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    for name in ("n", "max_steps", "rounds", "batch"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    for name in ("brute", "evasive_brute"):
        v = getattr(args, name)
        if v is not None and v < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {v}")
    return args


def brute_clearance(oracle, suite, r, b, steps, dt):
    """The brute force's smallest clearance over the motions k -> k+1 of scene b, k in ``steps``."""
    real = np.flatnonzero(np.asarray(suite.scene.curve_mask[b]))
    motions = [{k: np.asarray(v[b, j]) for k, v in suite.motion._asdict().items()} for j in real]
    args = (np.asarray(suite.scene.curves.coeffs[b])[real], np.asarray(suite.scene.curves.u_range[b])[real],
            np.asarray(suite.scene.curves.radius[b])[real], motions, float(suite.scene.arm_radius[b]))
    best = np.inf
    for k in steps:
        ks = np.arange(k, k + 2)
        best = min(best, oracle.moving_min_clearance(r.q[b, ks], ks * dt, *args))
    return best


def main(argv=None):
    args = parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from _common import FIGURES_DIR, RESULTS_DIR, finish_machine, log, machine_info, machine_lines, write_results
    from _stats import paired_table, pct_interval

    import softplan_jax as sp
    from softplan_jax.planning import make_track_options, rollout_batch, rollout_jit
    from softplan_jax.testing import oracle

    quick = args.quick
    n = args.n or (16 if quick else 1024)
    T = args.max_steps or (80 if quick else 300)
    n_brute = min(n, args.brute if args.brute is not None else (2 if quick else 8))
    n_ev = args.evasive_brute if args.evasive_brute is not None else (8 if quick else 300)
    fallback_levels = [x for x in args.fallback.split(",") if x]
    known = [label for label, _ in levels(quick)]
    if any(x not in known for x in fallback_levels):
        raise ValueError(f"--fallback: unknown level(s) {fallback_levels}; the levels: {', '.join(known)}")
    rounds = args.rounds or (2 if quick else 7)
    B = min(n, args.batch or (4 if quick else 64))
    if args.out is not None:
        prefix = args.out
        fig_dir = os.path.join(os.path.dirname(os.path.abspath(args.out)), "figures")
    else:
        out_dir = os.path.join(RESULTS_DIR, "quick") if quick else RESULTS_DIR
        prefix = os.path.join(out_dir, "evasion")
        fig_dir = os.path.join(out_dir, "figures") if quick else FIGURES_DIR
    machine = machine_info("float64")
    dt = float(sp.default_gains().dt)

    # Reachable at rest: the same scenes (every level shares them) planned with the global fallback
    # (plan_fallback); and the ones its local planner alone reaches.
    rest = sp.random_scenarios(args.seed, n)
    t0 = time.perf_counter()
    planned = sp.plan_fallback(rest, max_steps=T)
    at_rest = np.array([p.status == "reached" for p in planned])
    local_rest = np.array([p.status == "reached" and p.planner == "local" for p in planned])
    log(f"evasion: at rest, {int(at_rest.sum())} of {n} reachable (plan_fallback), {int(local_rest.sum())} by the "
        f"local planner ({time.perf_counter() - t0:.0f} s)")

    table, suites, runs = {}, {}, {}
    for label, kw in levels(quick):
        suite = sp.moving.random_moving_scenarios(args.seed, n, **kw)
        suites[label] = suite
        speed = np.asarray(jax.vmap(sp.moving.speed_bounds)(suite))
        row = {"motion": {k: list(v) if isinstance(v, tuple) else v for k, v in kw.items()},
               "max_speed_bound": float(speed.max()), "median_speed_bound": float(np.median(speed[speed > 0]))}
        for variant, evasion in (("today", False), ("evasive", True)):
            t0 = time.perf_counter()
            r = sp.track_batch(suite, max_steps=T, evasion=evasion, progress=True)
            el = time.perf_counter() - t0
            runs[label, variant] = r
            st = np.array([sp.planning.status_name(s) for s in np.asarray(r.status)])
            held = st == "reached"
            row[variant] = {
                "counts": {s: int((st == s).sum()) for s in STATUSES},
                "reached_and_held_of_reachable": [int((held & at_rest).sum()), int(at_rest.sum())],
                "reached_and_held_of_local_at_rest": [int((held & local_rest).sum()), int(local_rest.sum())],
                "evasive_steps": int(np.asarray(r.evasive).sum()),
                "evasive_scenes": int(np.asarray(r.evasive).any(axis=1).sum()),
                "steps_taken": int(np.asarray(r.iterations).sum()),
                "min_clearance": float(np.min(r.min_clearance)),
                "time_s": el,
            }
            log(f"evasion: {label}, {variant}: {el:.0f} s; " + ", ".join(
                f"{s} {row[variant]['counts'][s]}" for s in STATUSES if row[variant]["counts"][s])
                + f"; evasive steps {row[variant]['evasive_steps']}")
        a = np.asarray(runs[label, "today"].status) == sp.Status.REACHED
        b = np.asarray(runs[label, "evasive"].status) == sp.Status.REACHED
        row["paired_reached_and_held"] = paired_table(b, a)  # x: evasive, y: today; with McNemar's p
        # Brute force: every evasive step (and the motion after it), and the lowest-clearance scenes' whole paths.
        r = runs[label, "evasive"]
        ev = np.asarray(r.evasive)
        t0 = time.perf_counter()
        # The evasive steps, the closest first (by the smaller recorded clearance at their two ends), at most
        # --evasive-brute of them, each with the motion after it.
        cands = [(min(float(r.clearance[bi, k].min()), float(r.clearance[bi, k + 1].min())), bi, k)
                 for bi, k in zip(*np.nonzero(ev), strict=True)]
        cands = sorted(cands)[:n_ev]
        worst_ev, motions = np.inf, 0
        for _, bi, k0 in cands:
            steps = [k for k in (k0, k0 + 1) if k < int(r.iterations[bi])]
            motions += len(steps)
            worst_ev = min(worst_ev, brute_clearance(oracle, suite, r, bi, steps, dt))
        worst_full = np.inf
        for bi in np.argsort(np.asarray(r.min_clearance))[:n_brute]:
            worst_full = min(worst_full, brute_clearance(oracle, suite, r, bi, range(int(r.iterations[bi])), dt))
        row["brute_force"] = {"evasive_steps_checked": len(cands), "evasive_motions": motions,
                              "evasive_min_clearance": float(worst_ev),
                              "full_scenes": int(n_brute), "full_min_clearance": float(worst_full),
                              "contacts": int(worst_ev <= 0) + int(worst_full <= 0)}
        log(f"evasion: {label}: brute force over {motions} evasive motions (min {worst_ev:.3e}) and {n_brute} "
            f"whole paths (min {worst_full:.3e}) in {time.perf_counter() - t0:.0f} s")
        if label in fallback_levels:
            row["fallback"] = _fallback(sp, oracle, suite, runs[label, "evasive"], at_rest, local_rest, T, dt,
                                        n_brute)
            log(f"evasion: {label}, with track_fallback: " + ", ".join(
                f"{k} {v}" for k, v in row["fallback"]["counts"].items() if v))
        table[label] = row

    # Cost per step where the evasive step never acts: interleaved, run apart from compile.
    # Quiet: today's tracker does not end too_fast there, so the evasive step is never even tried.
    quiet = np.flatnonzero(np.asarray(runs["default", "today"].status) != sp.Status.TOO_FAST)[:B]
    movers = jax.tree_util.tree_map(lambda x: jnp.asarray(x[quiet]), suites["default"])
    sway = sp.moving_scenario("tree_sway")
    gains = sp.default_gains()
    key = jax.random.PRNGKey(0)
    keys = jax.random.split(key, len(quiet))
    variants = {}
    for evasion in (False, True):
        opts = make_track_options("curve", evasion=evasion)
        one = lambda m, g, k, opts=opts: rollout_jit(m, g, opts, T, k)  # noqa: E731
        many = lambda m, g, k, opts=opts: rollout_batch(m, g, opts, T, k, devices=1)  # noqa: E731
        tag = "on" if evasion else "off"
        variants[f"swaying tree, evasion {tag}"] = lambda one=one: one(sway, gains, key)
        variants[f"{len(quiet)} quiet scenes, evasion {tag}"] = lambda many=many: many(movers, gains, keys)
    compile_s, times = {}, {k: [] for k in variants}
    for name, fn in variants.items():
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        compile_s[name] = time.perf_counter() - t0
        if "on" in name:
            assert not np.asarray(out.evasive).any(), name  # the evasive step must not act here
    for rd in range(rounds):
        for name, fn in variants.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            times[name].append(time.perf_counter() - t0)
        log(f"evasion: timing round {rd + 1}/{rounds}")
    per_step = {name: {"min_us": min(ts) / (T + 1) * 1e6, "median_us": statistics.median(ts) / (T + 1) * 1e6,
                       "first_call_s": compile_s[name]} for name, ts in times.items()}
    names = list(variants)
    ratios = {what: {"min": per_step[names[i + 2]]["min_us"] / per_step[names[i]]["min_us"],
                     "median": per_step[names[i + 2]]["median_us"] / per_step[names[i]]["median_us"]}
              for i, what in enumerate(("single", "batch"))}
    log(f"evasion: cost per step on/off where it does not act: single {ratios['single']['min']:.2f}x, "
        f"batch {ratios['batch']['min']:.2f}x (min)")

    os.makedirs(fig_dir, exist_ok=True)
    figure = _figure(table, n, T, fig_dir)
    wire = _wire(sp, oracle, T, dt, fig_dir, quick)
    machine = finish_machine(machine)
    report = {"seed": args.seed, "n": n, "max_steps": T, "dt": dt, "reachable_at_rest": int(at_rest.sum()),
              "local_at_rest": int(local_rest.sum()),
              "levels": table, "per_step": per_step, "ratios_on_off": ratios, "figure": os.path.relpath(figure, HERE),
              "wire_sweep": wire,
              "machine": machine}
    md = _markdown(report, pct_interval) + "\n" + "\n".join(machine_lines(machine)) + "\n"
    write_results(prefix, report, md)
    log(f"evasion: wrote {prefix}.md/.json")
    return report


def _wire(sp, oracle, T, dt, fig_dir, quick):
    """The wire_sweep preset without its look-ahead: today's tracker against the evasive step, the
    brute force over the evasive run's whole path, and its GIF (the arm ducking the wire)."""
    m = sp.moving_scenario("wire_sweep")
    out = {}
    for variant, evasion in (("today", False), ("evasive", True)):
        r = sp.track(m, max_steps=T, anticipation=0.0, evasion=evasion)
        out[variant] = {"status": r.status, "iterations": r.iterations, "evasive_steps": r.evasive_steps,
                        "held_s": r.held_time, "min_clearance": r.min_clearance}
    motion = [{k: np.asarray(v[0]) for k, v in m.motion._asdict().items()}]
    c = m.scene.curves
    out["evasive"]["brute_min_clearance"] = float(oracle.moving_min_clearance(
        r.q, r.time, np.asarray(c.coeffs[:1]), np.asarray(c.u_range[:1]), np.asarray(c.radius[:1]), motion,
        float(m.scene.arm_radius)))
    if not quick:
        from softplan_jax import plotting

        path = os.path.join(fig_dir, "evasion_wire_sweep.gif")
        plotting.animate_tracking(r, path, title="wire_sweep, no look-ahead: the evasive step")
        out["gif"] = os.path.relpath(path, HERE)
    return out


def _fallback(sp, oracle, suite, evasive, at_rest, local_rest, T, dt, n_brute):
    """track_fallback on the level's scenes (the tracker with the evasive step, then the search's
    guided runs where it never reached the goal), paired against the evasive tracker alone."""
    from _stats import paired_table

    t0 = time.perf_counter()
    res = sp.track_fallback(suite, max_steps=T, progress=True)
    el = time.perf_counter() - t0
    st = np.array([r.status for r in res])
    held = st == "reached"
    guided = np.array([r.planner == "search" for r in res])
    # Brute force over the whole paths of the guided runs with the smallest recorded clearance.
    order = [b for b in np.argsort([r.min_clearance for r in res]) if guided[b]][:n_brute]
    worst = np.inf
    for b in order:
        r = res[b]
        real = np.flatnonzero(np.asarray(suite.scene.curve_mask[b]))
        motions = [{k: np.asarray(v[b, j]) for k, v in suite.motion._asdict().items()} for j in real]
        worst = min(worst, oracle.moving_min_clearance(
            r.q, r.time, np.asarray(suite.scene.curves.coeffs[b])[real], np.asarray(suite.scene.curves.u_range[b])[real],
            np.asarray(suite.scene.curves.radius[b])[real], motions, float(suite.scene.arm_radius[b])))
    reasons = {}
    for r in res:
        if r.reason:
            reasons[r.reason] = reasons.get(r.reason, 0) + 1
    return {
        "counts": {s: int((st == s).sum()) for s in STATUSES},
        "reached_and_held_of_reachable": [int((held & at_rest).sum()), int(at_rest.sum())],
        "reached_and_held_of_local_at_rest": [int((held & local_rest).sum()), int(local_rest.sum())],
        "guided_runs_reached": int(guided.sum()),
        "reasons": reasons,
        "paired_vs_evasive": paired_table(held, np.asarray(evasive.status) == sp.Status.REACHED),
        "collided": int(sum(r.collided for r in res)),
        "min_clearance": float(min(r.min_clearance for r in res)),
        "brute_force": {"guided_paths": len(order), "min_clearance": float(worst), "contacts": int(worst <= 0)},
        "time_s": el,
    }


def _figure(table, n, T, fig_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from _stats import wilson

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=False)
    labels = list(table)
    x = np.arange(len(labels))
    for ax, status, title in ((axes[0], "reached", "reached and held"), (axes[1], "too_fast", "too_fast")):
        for i, (variant, color) in enumerate((("today", "#999999"), ("evasive", "#1b9e77"))):
            k = [table[lab][variant]["counts"][status] for lab in labels]
            v = np.array(k) / n
            lo_hi = np.array([wilson(kk, n) for kk in k])
            ax.bar(x + (i - 0.5) * 0.38, v, 0.38, color=color, label=variant,
                   yerr=[v - lo_hi[:, 0], lo_hi[:, 1] - v], capsize=2)
        ax.set_xticks(x, labels)
        ax.set_title(f"{title} (95 % intervals)")
        ax.set_ylabel(f"share of {n} scenes")
        ax.legend(fontsize=8)
    fig.suptitle(f"Tracking among moving curves, {T} steps: today's tracker against the evasive step")
    fig.tight_layout()
    path = os.path.join(fig_dir, "evasion_levels.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _markdown(rep, pct_interval):
    n = rep["n"]
    lines = [
        "# The evasive step among fast-moving obstacles",
        "",
        f"`python benchmarks/evasion.py` — held-out seed {rep['seed']}, {n} scenes a level, {rep['max_steps']} steps "
        f"of {rep['dt']:g} s, default gains and options; the same scenes at every level, each tracked by today's "
        "tracker (`evasion=False`) and with the evasive step (`evasion=True`, the default).",
        "",
        "| level | motion | tracker | reached and held | never reached | too_fast | collided | reached and held, "
        "of the reachable | evasive steps (scenes) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, row in rep["levels"].items():
        mo = row["motion"]
        motion = f"{mo['amplitude']:g} rad, {mo['shift']:g} m, {mo['omega'][0]:g}-{mo['omega'][1]:g} rad/s"
        rows = [(variant, row[variant], f"{row[variant]['evasive_steps']} ({row[variant]['evasive_scenes']})")
                for variant in ("today", "evasive")]
        if "fallback" in row:
            rows.append(("evasive + track_fallback", row["fallback"],
                         f"({row['fallback']['guided_runs_reached']} guided runs reached)"))
        for tracker, v, last in rows:
            c = v["counts"]
            k, m = v["reached_and_held_of_reachable"]
            lines.append(f"| {label} | {motion} | {tracker} | {pct_interval(c['reached'], n)} | "
                         f"{pct_interval(c['max_steps'], n)} | {pct_interval(c['too_fast'], n)} | "
                         f"{pct_interval(c['collided'], n)} | {pct_interval(k, m)} | {last} |")
    lines += ["", f"Reachable: the scenes `plan_fallback` reaches at rest ({rep['reachable_at_rest']} of {n}; its "
              f"local planner alone: {rep['local_at_rest']}). Of the latter, reached and held:", ""]
    for label, row in rep["levels"].items():
        parts = [f"{variant} {pct_interval(*row[variant]['reached_and_held_of_local_at_rest'])}"
                 for variant in ("today", "evasive")]
        if "fallback" in row:
            parts.append(f"with track_fallback {pct_interval(*row['fallback']['reached_and_held_of_local_at_rest'])}")
        lines.append(f"- {label}: " + ", ".join(parts))
    lines += ["", "Paired on the same scenes (reached and held): evasive only / today only, McNemar's exact test:", ""]
    for label, row in rep["levels"].items():
        p = row["paired_reached_and_held"]
        lines.append(f"- {label}: both {p['both']}, evasive only {p['only_x']}, today only {p['only_y']}, "
                     f"neither {p['neither']}; p = {p['mcnemar_p']:.2g}")
    for label, row in rep["levels"].items():
        if "fallback" in row:
            p = row["fallback"]["paired_vs_evasive"]
            lines.append(f"- {label}, with track_fallback against the evasive tracker alone: both {p['both']}, "
                         f"with fallback only {p['only_x']}, alone only {p['only_y']}, neither {p['neither']}; "
                         f"p = {p['mcnemar_p']:.2g}; why the fallback did not help: {row['fallback']['reasons']}")
    lines += ["", "## Contacts by brute force (the evasive tracker)", "",
              "The oracle's kinematics, the curves moved by SciPy's expm, 4 substeps a step in space and time, "
              "30 arm samples a segment, 300 a curve.", "",
              "| level | evasive steps checked, closest first (motions, with the one after each) | their min clearance "
              "| whole paths checked | their min clearance | contacts |", "|---|---|---|---|---|---|"]
    for label, row in rep["levels"].items():
        bf = row["brute_force"]
        lines.append(f"| {label} | {bf['evasive_steps_checked']} ({bf['evasive_motions']}) | "
                     f"{bf['evasive_min_clearance']:.3e} | "
                     f"{bf['full_scenes']} | {bf['full_min_clearance']:.3e} | {bf['contacts']} |")
    for label, row in rep["levels"].items():
        if "fallback" in row:
            bf = row["fallback"]["brute_force"]
            lines.append(f"\nWith track_fallback ({label}): the {bf['guided_paths']} guided runs with the smallest "
                         f"recorded clearance, whole paths: min {bf['min_clearance']:.3e}, contacts {bf['contacts']}; "
                         f"collisions by the runs' own checks: {row['fallback']['collided']}.")
    lines += ["", "## Cost per step where the evasive step does not act (interleaved, compile apart)", "",
              "| variant | min µs/step | median µs/step | first call (compile + run) |", "|---|---|---|---|"]
    for name, v in rep["per_step"].items():
        lines.append(f"| {name} | {v['min_us']:.1f} | {v['median_us']:.1f} | {v['first_call_s']:.1f} s |")
    r = rep["ratios_on_off"]
    lines += ["", f"On / off: single {r['single']['min']:.2f}x (median {r['single']['median']:.2f}x), batch "
              f"{r['batch']['min']:.2f}x (median {r['batch']['median']:.2f}x); target <= 1.1x.", "",
              f"Figure: `{rep['figure']}`", ""]
    w = rep["wire_sweep"]
    lines += ["## The wire_sweep preset without its look-ahead", "",
              "| tracker | status | steps | evasive steps | held | min clearance |", "|---|---|---|---|---|---|"]
    for variant in ("today", "evasive"):
        v = w[variant]
        lines.append(f"| {variant} | {v['status']} | {v['iterations']} | {v['evasive_steps']} | {v['held_s']:.1f} s "
                     f"| {v['min_clearance']:.4f} |")
    lines += ["", f"Brute force over the evasive run's whole path: smallest clearance "
              f"{w['evasive']['brute_min_clearance']:.4f}." + (f" GIF: `{w['gif']}`." if "gif" in w else ""), ""]
    return "\n".join(lines)


if __name__ == "__main__":
    try:
        main()
    except ValueError as err:
        print(f"evasion: {err}", file=sys.stderr)
        sys.exit(2)
