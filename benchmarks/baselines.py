"""Baseline arrays for refactors: save every array of a fixed set of runs, compare two saves.

A refactor that moves code must keep results bit-identical. This script saves
the arrays of: the paper scenes (sim1, sim2, tree) x (curve, 10 points, 100
points) x (default options, the paper's preset: step, gains and start pose), 600 steps; two random
batches (``plan_batch``: seed 1 curve, seed 2 points, 64 scenes); the three
moving presets (400 steps) and a tracked batch of 32 random moving scenes; a
loaded arm (the tests' rod) planning the tree and tracking tree_sway; and
with ``--fallback`` the ``plan_fallback`` results of 48 random scenes. Run it
with each version of the package first on ``PYTHONPATH``, then compare: the
comparison says which arrays differ, and for per-step arrays whether they
differ within the steps taken or only after a rollout's end.

    PYTHONPATH=/path/to/previous python benchmarks/baselines.py save before.npz --fallback   # ~5 min
    python benchmarks/baselines.py save after.npz --fallback
    python benchmarks/baselines.py compare before.npz after.npz
    python benchmarks/baselines.py --quick    # a small set (the tree, 8 random scenes, one moving preset)

A change allowed to alter results at rounding level is judged by statistics
instead: ``save --suite 1024`` adds the held-out suites (``_judge.py``: the
static suite planned with the curve and the 10-point models, the moving suite
tracked, per-scene outcomes, and brute-force collision audits of the curve
model), and ``judge BEFORE AFTER`` prints each criterion PASS or FAIL (paired
success, mean iterations, collisions, the paper scenes, the fallback batch),
with the count of bit-identical arrays, writes ``AFTER.judge.md`` and exits 0
only if every criterion passes:

    PYTHONPATH=/path/to/previous python benchmarks/baselines.py save before.npz --fallback --suite 1024  # ~5 min more
    python benchmarks/baselines.py save after.npz --fallback --suite 1024
    python benchmarks/baselines.py judge before.npz after.npz

Besides ``OUT.npz``, ``save`` writes ``OUT.md`` and ``OUT.json``: per run,
its status, iterations and a digest of its arrays (SHA-256 of their bytes), so
two saves can be told apart at a glance (digests hold for one machine: XLA's
CPU code depends on the processor). Without a command the script saves to
``benchmarks/results/baselines.npz`` (quick: ``results/quick/baselines.npz``);
the arrays are not committed.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time

import numpy as np

RESULTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
PER_STEP = ("q", "tip", "clearance", "between", "step_scale", "converged", "fallbacks", "between_searched", "goal",
            "time", "error")


def save(path: str, fallback: bool, quick: bool = False, suite: int = 0) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import finish_machine, machine_info

    import softplan_jax as sp
    from softplan_jax.planning import make_options, make_track_options, rollout_jit

    machine = machine_info("float64")
    out, t0 = {}, time.perf_counter()

    def put(prefix, tree):
        for f, v in tree._asdict().items():
            if v is not None and f != "moving":
                out[f"{prefix}/{f}"] = np.asarray(v)

    scenes = ("tree",) if quick else ("sim1", "sim2", "tree")
    models = (("curve", 10), ("points", 10)) if quick else (("curve", 10), ("points", 10), ("points", 100))
    steps = 200 if quick else 600
    for name in scenes:
        base = sp.paper_scenario(name)
        # The paper's preset: its step, gains and start pose (theta 0.1: its plain pseudo-inverse
        # does not exist at the straight start).
        settings = (("default", base, sp.default_gains(), {}), ("paper", *sp.apply_preset("paper", base)))
        for method, N in models:
            for label, sc, gains, kw in settings[:1] if quick else settings:
                r = jax.device_get(rollout_jit(sc, gains, make_options(method, N, **kw), steps, 0))
                put(f"paper/{name}/{method}{N}/{label}", r)
    print(f"paper scenes: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    batches = ((1, "curve", 100, 8),) if quick else ((1, "curve", 600, 64), (2, "points", 300, 64))
    for seed, method, T, n in batches:
        put(f"batch/{seed}/{method}", jax.device_get(sp.plan_batch(sp.random_scenarios(seed, n), method, 10,
                                                                   max_steps=T)))
    print(f"random batches: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for name in ("tree_sway",) if quick else ("tree_sway", "tree_fruit", "wire_sweep"):
        r = rollout_jit(sp.moving_scenario(name), sp.default_gains(), make_track_options("curve"),
                        100 if quick else 400, jax.random.PRNGKey(0))
        put(f"moving/{name}", jax.device_get(r))
    if not quick:
        put("moving/batch", sp.track_batch(sp.moving.random_moving_scenarios(1, 32), max_steps=300))
    print(f"moving scenes: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if not quick:
        _put_loaded(put)
        print(f"loaded arm: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if fallback:
        for i, p in enumerate(sp.plan_fallback(sp.random_scenarios(1, 8 if quick else 48), max_steps=300)):
            for f in ("q", "status", "planner", "min_clearance"):
                out[f"fallback/{i}/{f}"] = np.asarray(getattr(p, f))
        print(f"fallback: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if suite:
        from _judge import save_suite

        save_suite(out, suite, quick, lambda msg: print(f"{msg}: {time.perf_counter() - t0:.0f} s", file=sys.stderr,
                                                         flush=True))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez(path, **out)
    print(f"{len(out)} arrays written to {path}")
    _report(path, out, finish_machine(machine), time.perf_counter() - t0, quick, fallback, suite)
    return 0


def _put_loaded(put) -> None:
    """The loaded arm (the tests' rod: EI 6, GJ 4, 0.3 N/m and a tip load of 0.05 N, under which
    the straight tree arm's tip sags 0.3): the tree planned, and tree_sway tracked."""
    import jax

    import softplan_jax as sp
    from softplan_jax.planning import make_options, make_track_options, rollout_jit
    from softplan_jax.rod import LoadedArm

    arm = LoadedArm(sp.RodModel(6.0, 4.0, 0.3, (0.0, 0.0, -0.05)))
    r = rollout_jit(sp.paper_scenario("tree"), sp.default_gains(), make_options("curve", 10), 600, 0, arm=arm)
    put("paper/tree/curve10/loaded", jax.device_get(r))
    r = rollout_jit(sp.moving_scenario("tree_sway"), sp.default_gains(), make_track_options("curve"), 400,
                    jax.random.PRNGKey(0), arm=arm)
    put("moving/tree_sway/loaded", jax.device_get(r))


def _report(path: str, out: dict, machine: dict, wall: float, quick: bool, fallback: bool, suite: int) -> None:
    """``OUT.md`` and ``OUT.json`` of a save: the command, the suites, the machine, one row per run."""
    from _common import machine_lines, write_results

    runs = summary(out)
    flags = f"{' --quick' if quick else ''}{' --fallback' if fallback else ''}{f' --suite {suite}' if suite else ''}"
    seed = int(out["suite/seed"]) if suite else None
    held_out = (f"- held-out suites: `random_scenarios({seed}, {suite})` ({int(out['suite/max_steps'])} steps) and "
                f"`random_moving_scenarios({seed}, {suite})` ({int(out['suite/moving_steps'])} steps)" if suite
                else "- no held-out suite (`--suite N`)")
    lines = [f"# Baseline arrays{' (QUICK MODE)' if quick else ''}", "",
             f"- {len(out)} arrays of {len(runs)} runs in `{os.path.basename(path)}`, saved in {wall:.0f} s "
             f"(`python benchmarks/baselines.py save{flags}`)", held_out, *machine_lines(machine), "",
             "| run | status | iterations | SHA-256 of its arrays (first 16) |", "|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['status']} | {r['iterations']} | `{r['digest']}` |" for r in runs]
    write_results(path.removesuffix(".npz"), dict(machine=machine, quick=quick, fallback=fallback, suite=suite,
                                                  suite_seed=seed, arrays=len(out), wall_s=wall, runs=runs),
                  "\n".join(lines) + "\n")


def summary(arrays: dict) -> list:
    """One row per run (the group of arrays under one prefix): statuses, iterations, digest."""
    from softplan_jax.base._status import STATUS_NAMES

    groups = {}
    for k in sorted(arrays):
        groups.setdefault(k.rsplit("/", 1)[0], []).append(k)
    rows = []
    for g, keys in groups.items():
        h = hashlib.sha256()
        for k in keys:
            h.update(k.encode())
            h.update(np.ascontiguousarray(arrays[k]).tobytes())

        def show(field, g=g):
            v = arrays.get(f"{g}/{field}")
            if v is None:
                return "—"
            name = (lambda x: STATUS_NAMES.get(x, x)) if field == "status" and v.dtype.kind in "iu" else str
            if v.ndim == 0:
                return str(name(v.item()))
            vals, counts = np.unique(v, return_counts=True)
            if len(vals) > 6:
                return f"{len(v)} values, {vals.min()}..{vals.max()}"
            return ", ".join(f"{name(x.item())}: {c}" for x, c in zip(vals, counts, strict=True))

        rows.append(dict(run=g, status=show("status"), iterations=show("iterations"), digest=h.hexdigest()[:16]))
    return rows


def differences(a, b) -> tuple[int, int, list, list]:
    """``(bit-identical arrays, arrays in both, names in one only, lines on each that differs)`` of
    two loaded saves; a per-step array of a rollout says whether it differs within the steps taken."""
    missing = sorted(set(a.files) ^ set(b.files))
    common = sorted(set(a.files) & set(b.files))
    equal, lines = 0, []
    for k in common:
        x, y = a[k], b[k]
        if x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            equal += 1
            continue
        group, field = k.rsplit("/", 1)
        its = a.get(group + "/iterations") if group + "/iterations" in a.files else None
        if x.shape != y.shape:
            lines.append(f"  {k}: shapes {x.shape} and {y.shape}")
        elif its is not None and field in PER_STEP:
            xs, ys = (x[None], y[None]) if its.ndim == 0 else (x, y)  # one rollout, or a batch
            its = np.atleast_1d(its)
            inside = sum(not np.array_equal(xs[i, : its[i] + 1], ys[i, : its[i] + 1], equal_nan=True)
                         for i in range(len(its)))
            with np.errstate(invalid="ignore"):  # inf - inf where both are inf: no difference
                d = np.abs(np.where(np.isinf(xs) & np.isinf(ys), 0.0, xs.astype(float) - ys.astype(float)))
            lines.append(f"  {k}: {inside} of {len(its)} rollouts differ within the steps taken; "
                         f"max |diff| {np.nanmax(d):.3g}")
        else:
            n = int(np.sum(x != y))
            d = np.nanmax(np.abs(x.astype(float) - y.astype(float))) if x.dtype.kind in "fiub" else float("nan")
            lines.append(f"  {k}: {n} entries differ, max |diff| {d:.3g}")
    return equal, len(common), missing, lines


def identity_line(equal: int, common: int, missing: list) -> str:
    return f"{equal} of {common} arrays bit-identical" + (
        f"; {len(missing)} in one file only: {missing[:5]}" if missing else "")


def compare(path_a: str, path_b: str) -> int:
    equal, common, missing, lines = differences(np.load(path_a), np.load(path_b))
    print(identity_line(equal, common, missing))
    print("\n".join(lines))
    return 0


def judge(path_a: str, path_b: str, min_scenes: int) -> int:
    """Judge save ``path_b`` (after) against ``path_a`` (before): print the report, write
    ``AFTER.judge.md``; 0 if every criterion passes, else 1."""
    from _judge import verdict, verdict_table, write_markdown

    a, b = np.load(path_a), np.load(path_b)
    body, checks = verdict(a, b, min_scenes)
    equal, common, missing, _ = differences(a, b)
    passed = all(ok for _, ok, _ in checks)
    lines = [f"# Judge: `{os.path.basename(path_b)}` against `{os.path.basename(path_a)}`", "",
             f"- before: `{path_a}`", f"- after: `{path_b}`", f"- {identity_line(equal, common, missing)}",
             "- not judged here: the closest-point oracle suites (`pytest tests/test_closest.py`, 0 misses)", "",
             "## Verdict", "", *verdict_table(checks), "",
             f"**{'PASS' if passed else 'FAIL'}**: {sum(ok for _, ok, _ in checks)} of {len(checks)} criteria pass.",
             "", *body]
    print("\n".join(lines))
    print(f"written to {write_markdown(path_b, lines)}")
    return 0 if passed else 1


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        argv = ["save", *argv]  # no command: save to benchmarks/results/ (quick: results/quick/)
    from _judge import MIN_SCENES

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("save", help="run the fixed set and save its arrays (and a summary beside them)")
    s.add_argument("out", nargs="?", default=None,
                   help="the .npz to write (default benchmarks/results/baselines.npz; quick: results/quick/)")
    s.add_argument("--fallback", action="store_true", help="also plan_fallback on 48 scenes (~2 min more)")
    s.add_argument("--quick", action="store_true", help="a small set (< 1 min of runs): a smoke test of the tool")
    s.add_argument("--suite", type=int, default=0, metavar="N",
                   help="also the held-out suites of N scenes and their brute-force audits (judged: 1024, ~5 min more)")
    c = sub.add_parser("compare", help="compare two saves")
    c.add_argument("a")
    c.add_argument("b")
    j = sub.add_parser("judge", help="judge AFTER against BEFORE by statistics (exit 0: every criterion passes)")
    j.add_argument("before")
    j.add_argument("after")
    j.add_argument("--min-scenes", type=int, default=MIN_SCENES,
                   help=f"held-out scenes a suite needs (default {MIN_SCENES:,}, the judged size)")
    args = ap.parse_args(argv)
    if args.cmd == "compare":
        return compare(args.a, args.b)
    if args.cmd == "judge":
        return judge(args.before, args.after, args.min_scenes)
    if args.suite < 0:
        ap.error(f"--suite must be >= 0, got {args.suite}")
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", "baselines.npz")
    return save(out, args.fallback, args.quick, args.suite)


if __name__ == "__main__":
    sys.exit(main())
