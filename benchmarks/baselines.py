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
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

PER_STEP = ("q", "tip", "clearance", "between", "step_scale", "converged", "fallbacks", "between_searched", "goal",
            "time", "error")


def save(path: str, fallback: bool) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import softplan_jax as sp
    from softplan_jax.planning.planner import make_options, rollout_jit
    from softplan_jax.planning.tracking import make_track_options, track_program

    out, t0 = {}, time.perf_counter()

    def put(prefix, tree):
        for f, v in tree._asdict().items():
            if v is not None and f != "moving":
                out[f"{prefix}/{f}"] = np.asarray(v)

    paper_gains = sp.Gains(**{k: np.float64(v) for k, v in sp.planning.preset("paper").gains.items()})
    for name in ("sim1", "sim2", "tree"):
        sc = sp.paper_scenario(name)
        for method, N in (("curve", 10), ("points", 10), ("points", 100)):
            for label, kw, gains in (("default", {}, sp.default_gains()), ("paper", sp.PAPER_STEP, paper_gains)):
                r = jax.device_get(rollout_jit(sc, gains, make_options(method, N, **kw), 600, 0))
                put(f"paper/{name}/{method}{N}/{label}", r)
    print(f"paper scenes: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for seed, method, T in ((1, "curve", 600), (2, "points", 300)):
        put(f"batch/{seed}/{method}", jax.device_get(sp.plan_batch(sp.random_scenarios(seed, 64), method, 10,
                                                                   max_steps=T)))
    print(f"random batches: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for name in ("tree_sway", "tree_fruit", "wire_sweep"):
        fn = track_program(make_track_options("curve"), 400, False)
        put(f"moving/{name}", jax.device_get(fn(sp.moving_scenario(name), sp.default_gains(),
                                                jax.random.PRNGKey(0))))
    put("moving/batch", sp.track_batch(sp.moving.random_moving_scenarios(1, 32), max_steps=300))
    print(f"moving scenes: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if fallback:
        for i, p in enumerate(sp.plan_fallback(sp.random_scenarios(1, 48), max_steps=300)):
            for f in ("q", "status", "planner", "min_clearance"):
                out[f"fallback/{i}/{f}"] = np.asarray(getattr(p, f))
        print(f"fallback: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    np.savez(path, **out)
    print(f"{len(out)} arrays written to {path}")
    return 0


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
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("save", help="run the fixed set and save its arrays")
    s.add_argument("out")
    s.add_argument("--fallback", action="store_true", help="also plan_fallback on 48 scenes (~2 min more)")
    c = sub.add_parser("compare", help="compare two saves")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    return save(args.out, args.fallback) if args.cmd == "save" else compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
