"""Baseline arrays for refactors: save every array of a fixed set of runs, compare two saves.

A refactor that moves code must keep results bit-identical. This script saves
the arrays of: the paper scenes (sim1, sim2, tree) x (curve, 10 points, 100
points) x (default options, the paper's step and gains), 600 steps; two random
batches (``plan_batch``: seed 1 curve, seed 2 points, 64 scenes); the three
moving presets (400 steps) and a tracked batch of 32 random moving scenes; and
with ``--fallback`` the ``plan_fallback`` results of 48 random scenes. Run it
with each version of the package first on ``PYTHONPATH``, then compare: the
comparison says which arrays differ, and for per-step arrays whether they
differ within the steps taken or only after a rollout's end.

    PYTHONPATH=/path/to/previous python benchmarks/baselines.py save before.npz --fallback   # ~5 min
    python benchmarks/baselines.py save after.npz --fallback
    python benchmarks/baselines.py compare before.npz after.npz
    python benchmarks/baselines.py --quick    # a small set (the tree, 8 random scenes, one moving preset)

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


def save(path: str, fallback: bool, quick: bool = False) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import finish_machine, machine_info, machine_lines, write_results

    import softplan_jax as sp
    from softplan_jax.planning import make_options, make_track_options, rollout_jit

    machine = machine_info("float64")
    out, t0 = {}, time.perf_counter()

    def put(prefix, tree):
        for f, v in tree._asdict().items():
            if v is not None and f != "moving":
                out[f"{prefix}/{f}"] = np.asarray(v)

    paper_gains = sp.Gains(**{k: np.float64(v) for k, v in sp.planning.preset("paper").gains.items()})
    scenes = ("tree",) if quick else ("sim1", "sim2", "tree")
    models = (("curve", 10), ("points", 10)) if quick else (("curve", 10), ("points", 10), ("points", 100))
    steps = 200 if quick else 600
    settings = (("default", {}, sp.default_gains()), ("paper", sp.PAPER_STEP, paper_gains))
    for name in scenes:
        sc = sp.paper_scenario(name)
        for method, N in models:
            for label, kw, gains in settings[:1] if quick else settings:
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
    if fallback:
        for i, p in enumerate(sp.plan_fallback(sp.random_scenarios(1, 8 if quick else 48), max_steps=300)):
            for f in ("q", "status", "planner", "min_clearance"):
                out[f"fallback/{i}/{f}"] = np.asarray(getattr(p, f))
        print(f"fallback: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez(path, **out)
    print(f"{len(out)} arrays written to {path}")
    wall = time.perf_counter() - t0
    runs = summary(out)
    prefix = path.removesuffix(".npz")
    lines = [f"# Baseline arrays{' (QUICK MODE)' if quick else ''}", "",
             f"- {len(out)} arrays of {len(runs)} runs in `{os.path.basename(path)}`, saved in {wall:.0f} s "
             f"(`python benchmarks/baselines.py save{' --quick' if quick else ''}{' --fallback' if fallback else ''}`)",
             *machine_lines(finish_machine(machine)), "",
             "| run | status | iterations | SHA-256 of its arrays (first 16) |", "|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['status']} | {r['iterations']} | `{r['digest']}` |" for r in runs]
    write_results(prefix, dict(machine=machine, quick=quick, fallback=fallback, arrays=len(out), wall_s=wall,
                               runs=runs), "\n".join(lines) + "\n")
    return 0


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


def compare(path_a: str, path_b: str) -> int:
    a, b = np.load(path_a), np.load(path_b)
    missing = sorted(set(a.files) ^ set(b.files))
    equal, lines = 0, []
    for k in sorted(set(a.files) & set(b.files)):
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
    print(f"{equal} of {len(set(a.files) & set(b.files))} arrays bit-identical" +
          (f"; {len(missing)} in one file only: {missing[:5]}" if missing else ""))
    print("\n".join(lines))
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        argv = ["save", *argv]  # no command: save to benchmarks/results/ (quick: results/quick/)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("save", help="run the fixed set and save its arrays (and a summary beside them)")
    s.add_argument("out", nargs="?", default=None,
                   help="the .npz to write (default benchmarks/results/baselines.npz; quick: results/quick/)")
    s.add_argument("--fallback", action="store_true", help="also plan_fallback on 48 scenes (~2 min more)")
    s.add_argument("--quick", action="store_true", help="a small set (< 1 min of runs): a smoke test of the tool")
    c = sub.add_parser("compare", help="compare two saves")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "compare":
        return compare(args.a, args.b)
    out = args.out or os.path.join(RESULTS_DIR, "quick" if args.quick else "", "baselines.npz")
    return save(out, args.fallback, args.quick)


if __name__ == "__main__":
    sys.exit(main())
