"""How long does a plan take on a real arm? The paper's tree, timed under actuator limits.

One command, progress on stderr::

    python benchmarks/timing.py            # the tree, every variant, grid study, 3 timed repeats (~2 min)
    python benchmarks/timing.py --quick    # smoke run, written to benchmarks/results/quick/

The tree's plan (``sp.plan(sp.paper_scenario("tree"))``, 53 steps) on an arm of
3 tendons per segment at 0.03 m from the backbone, timed by
:func:`softplan_jax.time_parametrize` (TOPP-RA on a path in actuator-length
space) along the two paths it offers: ``smooth``, the cubic spline through the
plan's steps, proven clear by the swept check, and ``linear``, the plan's own
straight motions with a stop at every step. Limits: actuator speed 0.02 m/s,
with and without an actuator acceleration of 0.05 m/s^2, and with a tip speed
of 0.05 m/s. For each: the duration, the stops, the share of the linear path's
duration the stops cost, and TOPP-RA run directly on the same path (toppra's
own spline through the actuator lengths, its own grid of at least 1,000 points)
as the reference; the compute time (first call, which compiles, and the median
of the next ones). The grid study: the smooth duration against TOPP-RA's grid
points per span (the default is 32).

Writes ``results/timing.{md,json}`` and ``results/figures/timing_tree.png``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

RADIUS, SPEED, ACCELERATION, TIP_SPEED = 0.03, 0.02, 0.05, 0.05


def reference_duration(traj, layout, limits, max_tip_speed):
    """TOPP-RA run directly on the trajectory's path: toppra's SplineInterpolator through the actuator
    lengths sampled along it (the spline rebuilt from the waypoints, or each straight motion), rest to rest."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as tc
    from scipy.interpolate import CubicSpline

    import softplan_jax as sp

    f = jax.jit(jax.vmap(lambda q: sp.actuators.actuator_lengths(q, layout).reshape(-1)))
    lim = limits.per_actuator(layout)
    way = traj.waypoints.reshape(traj.waypoints.shape[0], -1)
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(way, axis=0), axis=1))])

    def run(ss, q):
        lengths = np.asarray(f(jnp.asarray(q.reshape(-1, *traj.waypoints.shape[1:]))))
        path = toppra.SplineInterpolator(ss, lengths)
        cons = [tc.JointVelocityConstraint(lim.max_speed.reshape(-1))]
        if np.all(np.isfinite(lim.max_acceleration)):
            cons.append(tc.JointAccelerationConstraint(lim.max_acceleration.reshape(-1),
                                                       discretization_scheme=tc.DiscretizationType.Interpolation))
        if max_tip_speed is not None:
            return None  # toppra has no tip speed constraint of its own: no reference
        out = algo.TOPPRA(cons, path, solver_wrapper="seidel", gridpt_min_nb_points=1000).compute_trajectory(0, 0)
        return float(out.duration)

    if traj.path == "smooth":
        dense = np.linspace(0, s[-1], 4000)
        return run(dense, CubicSpline(s, way, bc_type="not-a-knot", axis=0)(dense))
    total = 0.0
    for k in range(way.shape[0] - 1):
        u = np.linspace(0, 1, 60)
        d = run(u * (s[k + 1] - s[k]), way[k] + u[:, None] * (way[k + 1] - way[k]))
        if d is None:
            return None
        total += d
    return total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one variant, no grid study, no repeats (results/quick/)")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls after the first (default 3)")
    ap.add_argument("--out", default=None, help="prefix of the result files (default results/timing)")
    args = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import _common as C

    import softplan_jax as sp
    from softplan_jax import actuators as A

    machine = C.machine_info("float64")
    prefix, figures = C.output_paths("timing", args.quick, args.out)
    tree = sp.paper_scenario("tree")
    plan = sp.plan(tree)
    layout = A.actuator_layout("tendon", 3, 3, radius=RADIUS)
    variants = [("speed + acceleration", dict(max_speed=SPEED, max_acceleration=ACCELERATION), None)]
    if not args.quick:
        variants += [("speed only", dict(max_speed=SPEED), None),
                     ("speed + acceleration + tip speed", dict(max_speed=SPEED, max_acceleration=ACCELERATION),
                      TIP_SPEED)]
    rows, trajs = [], {}
    for label, lim_kw, tip in variants:
        limits = A.actuator_limits(**lim_kw)
        for path in ("smooth", "linear"):
            C.log(f"timing: {label}, {path} ...")
            t0 = time.perf_counter()
            traj = sp.time_parametrize(plan, layout, limits, tree, path=path, max_tip_speed=tip)
            first = time.perf_counter() - t0
            again = []
            for _ in range(0 if args.quick else args.repeats):
                t0 = time.perf_counter()
                sp.time_parametrize(plan, layout, limits, tree, path=path, max_tip_speed=tip)
                again.append(time.perf_counter() - t0)
            ref = reference_duration(traj, layout, limits, tip)
            trajs[(label, path)] = traj
            rows.append(dict(limits=label, path=path, duration_s=traj.duration, stops=len(traj.stops),
                             samples=int(traj.t.shape[0]), reference_s=ref,
                             vs_reference=None if ref is None else traj.duration / ref - 1,
                             tightest=traj.report.describe(), within_limits=traj.report.ok, first_call_s=first,
                             median_call_s=statistics.median(again) if again else None))
    for label, _, _ in variants:
        s, lin = trajs[(label, "smooth")], trajs[(label, "linear")]
        next(r for r in rows if r["limits"] == label and r["path"] == "linear")["stops_share"] = (
            1 - s.duration / lin.duration)
    grid = []
    if not args.quick:
        limits = A.actuator_limits(max_speed=SPEED, max_acceleration=ACCELERATION)
        for g in (8, 16, 32, 64, 128):
            C.log(f"timing: grid {g} ...")
            t0 = time.perf_counter()
            d = sp.time_parametrize(plan, layout, limits, tree, grid=g).duration
            grid.append(dict(grid=g, duration_s=d, call_s=time.perf_counter() - t0))
    fig = sp.plotting.plot_actuators(trajs[(variants[0][0], "smooth")],
                                     title="the tree's plan, 3 tendons per segment at 0.03 m: smooth path")
    os.makedirs(figures, exist_ok=True)
    fig.savefig(os.path.join(figures, "timing_tree.png"), dpi=110, bbox_inches="tight")
    C.finish_machine(machine)

    lines = ["# Timing the tree's plan under actuator limits", "", *C.machine_lines(machine), "",
             f"Command: `python benchmarks/timing.py{' --quick' if args.quick else ''}`. The tree's plan "
             f"({plan.iterations} steps), 3 tendons per segment at {RADIUS} m; reference: TOPP-RA run directly "
             "(toppra's spline through the actuator lengths along the same path, its own grid).", "",
             "| limits | path | duration | stops | stops' share | TOPP-RA direct | difference | tightest limit | "
             "first call | later calls (median) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        share = f"{100 * r['stops_share']:.1f} %" if "stops_share" in r else ""
        ref = "—" if r["reference_s"] is None else f"{r['reference_s']:.2f} s"
        diff = "—" if r["vs_reference"] is None else f"{100 * r['vs_reference']:+.2f} %"
        lines.append(f"| {r['limits']} | {r['path']} | {r['duration_s']:.2f} s | {r['stops']} | {share} | {ref} | "
                     f"{diff} | {r['tightest']} | {C.fmt_s(r['first_call_s'])} | {C.fmt_s(r['median_call_s'])} |")
    if grid:
        lines += ["", "Smooth path, speed + acceleration: duration against TOPP-RA's grid points per span "
                  "(default 32).", "", "| grid | duration | call |", "|---|---|---|"]
        lines += [f"| {g['grid']} | {g['duration_s']:.3f} s | {C.fmt_s(g['call_s'])} |" for g in grid]
    lines += ["", "![actuators of the smooth path](figures/timing_tree.png)", ""]
    C.write_results(prefix, dict(machine=machine, rows=rows, grid=grid), "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
