"""The closest-point kernel's cost in the planner step (issue 9, item 2).

Two parts, one process:

1. **Speed.** Planning-only rollouts (``check_collisions=False``) of ``--steps``
   steps: the tree scene single and a batch of ``random_scenarios(0, --batch)``,
   curve method and the 10-point reference, float64 and float32. Every
   rollout is compiled ahead with the planner's XLA options (compile time
   reported apart), then timed in interleaved rounds (one call of every
   variant and case per round); min and median per step (per scenario-step in
   a batch). Variants: ``--variant NAME=PATH`` imports the package directory
   PATH (e.g. an older commit's ``softplan_jax`` exported with ``git
   archive``) under its own module name, so two kernels run side by side in
   the same rounds; without ``--variant`` only the installed package runs.
2. **Profile** (every variant; ``--no-profile`` skips it): where a curve step's time
   goes. The tree rollout's trajectory q_0..q_T is replayed through separately
   jitted scans of the pieces of the warm-started closest points
   (:mod:`softplan_jax.geometry.warm_start`): the segment frames, the polish
   (``POLISH_ITERATIONS`` Newton steps per pair), polish + certificate, the
   whole warm closest point (plus fallback and the derivative-carrying tail);
   the rest of the planner step is the rollout's step minus that. Also the
   transcendental operations (sin, cos, atan2, exp, log, ...) in the
   optimised HLO of the polish + certificate.

    python benchmarks/kernel.py --variant base=/path/to/old/softplan_jax   # ~5 min on 2 CPUs

Writes ``benchmarks/results/kernel.md`` (``--out`` elsewhere).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import inspect
import os
import re
import statistics
import sys
import time

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import (  # noqa: E402
    RESULTS_DIR,
    finish_machine,
    fmt_s,
    log,
    machine_info,
    machine_lines,
    rollout_wrappers,
)

import softplan_jax  # noqa: E402

TRANSCENDENTAL = ("sine", "cosine", "atan2", "exponential", "log", "tan", "sqrt", "rsqrt", "divide")


def load_variant(name: str, path: str):
    """The package directory ``path`` imported as module ``softplan_kernel_<name>``."""
    mod_name = f"softplan_kernel_{name}"
    spec = importlib.util.spec_from_file_location(
        mod_name, os.path.join(path, "__init__.py"), submodule_search_locations=[path]
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    spec.loader.exec_module(mod)
    return mod


def _submodule(pkg, name):
    return importlib.import_module(f"{pkg.__name__}.{name}")


def _compiler_options(cc, method):
    """The variant's XLA options for a rollout of ``method``, as its public rollouts use them."""
    try:
        return cc.rollout_compiler_options(method)
    except TypeError:  # a variant from before the options depended on the method
        return cc.rollout_compiler_options()


def compile_rollouts(pkg, dtype, steps, batch_size, methods):
    """{case: (compiled, args, scenario-steps per call, compile seconds)} for one package."""
    planner = _submodule(pkg, "planner")
    cc = _submodule(pkg, "compilation_cache")
    tree = pkg.paper_scenario("tree", dtype=dtype)
    batch = pkg.random_scenarios(0, batch_size, dtype=dtype)
    g = pkg.default_gains(dtype)
    options = {"curve": planner.make_options("curve", check_collisions=False),
               "points10": planner.make_options("points", 10, check_collisions=False)}

    single, batched = rollout_wrappers(planner.rollout)

    out = {}
    for method in methods:
        for where, fn, sc, n in (("single", single, tree, 1), ("batch", batched, batch, batch_size)):
            t0 = time.perf_counter()
            copts = _compiler_options(cc, options[method].method)
            c = (jax.jit(fn, static_argnames=("options", "max_steps"), compiler_options=copts)
                 .lower(sc, g, options=options[method], max_steps=steps).compile())
            ct = time.perf_counter() - t0
            jax.block_until_ready(c(sc, g))  # warm-up
            out[(method, where)] = (c, (sc, g), n * (steps + 1), ct)
    return out


def speed(variants, dtype, steps, batch_size, rounds):
    """Interleaved rounds over every (variant, case). Returns rows of
    (variant, method, where, compile s, min, median per scenario-step)."""
    calls = {}
    for k, (name, pkg) in enumerate(variants):
        methods = ("curve", "points10") if k == 0 else ("curve",)
        for (method, where), v in compile_rollouts(pkg, dtype, steps, batch_size, methods).items():
            calls[(name, method, where)] = v
            log(f"  [{dtype}] {name} {method} {where}: compiled in {v[3]:.1f} s")
    times = {key: [] for key in calls}
    for r in range(rounds):
        for key, (c, args, _, _) in calls.items():
            t0 = time.perf_counter()
            jax.block_until_ready(c(*args))
            times[key].append(time.perf_counter() - t0)
        log(f"  [{dtype}] round {r + 1}/{rounds}: "
            + ", ".join(f"{'/'.join(k)} {fmt_s(times[k][-1] / calls[k][2])}" for k in calls))
    return [(*key, calls[key][3], min(t) / calls[key][2], statistics.median(t) / calls[key][2])
            for key, t in times.items()]


def _count_ops(hlo_text):
    """Occurrences of each transcendental (and divide) op in optimised HLO text."""
    return {op: len(re.findall(rf"\b{op}\(", hlo_text)) for op in TRANSCENDENTAL}


def profile(pkg, dtype, steps, rounds):
    """Per-step seconds of the warm closest point's pieces replayed on the tree rollout's trajectory."""
    planner = _submodule(pkg, "planner")
    obstacles = _submodule(pkg, "obstacles")
    ws = _submodule(pkg, "warm_start")
    closest = _submodule(pkg, "closest")
    kin = _submodule(pkg, "kinematics")
    sc = pkg.paper_scenario("tree", dtype=dtype)
    g = pkg.default_gains(dtype)
    options = planner.make_options("curve", check_collisions=False)
    r = planner.rollout_jit(sc, g, options, steps)
    qs = r.q[: int(r.iterations) + 1]
    T = qs.shape[0]
    solver = options.solver
    cells = obstacles.warm_cells(sc, solver)
    (curves, active), = obstacles._curve_groups(sc)
    (data,) = cells
    curves = curves.astype(qs.dtype)
    # The converged u* of every step (the warm state), from the full warm closest point.
    u0 = obstacles.warm_state(sc)

    def warm_all(qs):
        def body(carry, q):
            state, first = carry
            cp, state, fb = obstacles.warm_closest(q, sc, solver, cells, state, first)
            return (state, jnp.asarray(False)), (cp.distance, state[0], fb)
        return jax.lax.scan(body, (u0, jnp.asarray(True)), qs)[1]

    warm_jit = jax.jit(warm_all)
    _, us, fbs = warm_jit(qs)
    u_prev = jnp.concatenate([us[:1], us[:-1]])  # step k's warm start: u* of step k - 1

    def segs_of(q):
        if hasattr(closest.Segment, "from_frame"):
            return closest.Segment.from_frame(q, *kin.segment_frames(q))
        return closest.Segment(q, *kin.segment_frames(q))  # the kernel before issue 9, item 2

    def frames(qs):
        return jax.lax.map(lambda q: jax.tree_util.tree_map(jnp.sum, segs_of(q)), qs)

    def polish(qs, us):
        def one(q, u):
            segs = segs_of(q)

            def per_curve(c, u_c):
                def pair(seg, u0):
                    s0, f0 = closest.project_to_arc(seg, c.point(u0))
                    return closest.reduced_newton(seg, c, u0, s0, f0, ws.POLISH_ITERATIONS)
                return jax.vmap(pair)(segs, u_c)
            return jax.vmap(per_curve)(curves, u)
        return jax.lax.map(lambda a: one(*a), (qs, us))

    def polish_certify(qs, us):
        def one(q, u):
            segs = segs_of(q)
            if "curves" in inspect.signature(ws._polish_and_certify).parameters:
                return ws._polish_and_certify(segs, curves, data, u, solver)
            # the warm start before session 11: one curve at a time
            return jax.vmap(lambda c, d, u_c: ws._polish_and_certify(segs, c, d, u_c, solver))(curves, data, u)
        return jax.lax.map(lambda a: one(*a), (qs, us))

    def warm_steady(qs, us):
        def one(q, u):
            return obstacles.warm_closest(q, sc, solver, cells, (u,), jnp.asarray(False))[0].distance
        return jax.lax.map(lambda a: one(*a), (qs, us))

    pieces = {"frames": (frames, (qs,)), "polish": (polish, (qs, u_prev)),
              "polish + certificate": (polish_certify, (qs, u_prev)),
              "warm closest point": (warm_steady, (qs, u_prev))}
    compiled, ops = {}, {}
    for name, (fn, args) in pieces.items():
        t0 = time.perf_counter()
        c = jax.jit(fn).lower(*args).compile()
        compiled[name] = (c, args, time.perf_counter() - t0)
        ops[name] = _count_ops(c.as_text())
        jax.block_until_ready(c(*args))
    times = {k: [] for k in compiled}
    for _ in range(rounds):
        for k, (c, args, _) in compiled.items():
            t0 = time.perf_counter()
            jax.block_until_ready(c(*args))
            times[k].append(time.perf_counter() - t0)
    rows = [(k, compiled[k][2], min(t) / T, statistics.median(t) / T) for k, t in times.items()]
    pairs = int(curves.u_range.shape[0] * sc.q0.shape[0] * int(jnp.sum(active)) / curves.u_range.shape[0])
    return rows, ops, int(jnp.sum(fbs[1:])), T, pairs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=PATH",
                    help="a package directory to compare (repeatable); default: the installed package only")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--dtypes", default="float64,float32")
    ap.add_argument("--no-profile", dest="profile", action="store_false")
    ap.add_argument("--out", default=os.path.join(RESULTS_DIR, "kernel.md"))
    args = ap.parse_args(argv)
    for name in ("steps", "batch", "rounds"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1; got {getattr(args, name)}")
    if not set(args.dtypes.split(",")) <= {"float64", "float32"}:
        ap.error(f"--dtypes: a comma list of float64 and float32; got {args.dtypes!r}")
    for spec in args.variant:
        name, _, path = spec.partition("=")
        if not name.isidentifier() or not os.path.isfile(os.path.join(path, "__init__.py")):
            ap.error(f"--variant {spec!r}: need NAME=PATH, PATH a package directory (with __init__.py)")
    jax.config.update("jax_enable_x64", True)  # float64 rollouts (here, not at import)
    variants = [(spec.split("=", 1)[0], load_variant(*spec.split("=", 1))) for spec in args.variant]
    if not variants:
        variants = [("current", softplan_jax)]
    machine = machine_info(args.dtypes)
    lines = ["# The closest-point kernel in the planner step (issue 9, item 2)", "",
             "Written by `benchmarks/kernel.py`; planning-only rollouts of "
             f"{args.steps} steps, {args.rounds} interleaved rounds, batch = `random_scenarios(0, {args.batch})`.", ""]
    lines += [f"- variant `{name}`: `{pkg.__file__}`" for name, pkg in variants]
    speed_rows = {}
    for dtype in args.dtypes.split(","):
        log(f"speed, {dtype}")
        speed_rows[dtype] = speed(variants, dtype, args.steps, args.batch, args.rounds)
    prof = {}
    if args.profile:
        for dtype in args.dtypes.split(","):
            for name, pkg in variants:
                log(f"profile, {dtype}, {name}")
                prof[(dtype, name)] = profile(pkg, dtype, args.steps, args.rounds)
    lines += machine_lines(finish_machine(machine)) + ["", "## Speed (per step; batch: per scenario-step)", "",
                                                       "| dtype | variant | method | rollout | compile | min | median |",
                                                       "|---|---|---|---|---|---|---|"]
    for dtype, rows in speed_rows.items():
        for name, method, where, ct, tmin, tmed in rows:
            lines.append(f"| {dtype} | {name} | {method} | {where} | {ct:.1f} s | {fmt_s(tmin)} | {fmt_s(tmed)} |")
    for (dtype, name), (rows, ops, fallbacks, T, pairs) in prof.items():
        lines += ["", f"## Profile, {dtype}: the tree rollout's {T} steps replayed (variant `{name}`)", "",
                  f"{pairs} (segment, curve) pairs per step; fallbacks after step 0: {fallbacks}.", "",
                  "| piece (cumulative) | compile | min per step | median per step |", "|---|---|---|---|"]
        lines += [f"| {k} | {ct:.1f} s | {fmt_s(a)} | {fmt_s(b)} |" for k, ct, a, b in rows]
        lines += ["", "Transcendental (and divide) ops in the optimised HLO (static count, loop bodies once):", "",
                  "| piece | " + " | ".join(TRANSCENDENTAL) + " |", "|---|" + "---|" * len(TRANSCENDENTAL)]
        lines += [f"| {k} | " + " | ".join(str(v[op]) for op in TRANSCENDENTAL) + " |" for k, v in ops.items()]
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    log(f"wrote {args.out}")
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
