"""Kernels per planner step, and what cutting them buys (issue 25, item 1).

XLA's CPU runtime runs a compiled program as a sequence of *thunks* (one per
fusion, dot, copy, loop, ... at the top level of a computation), each launched
separately. This script counts them per planner step in the optimised HLO of
the rollout programs, and times the same programs, for the package as installed
and for each VARIANT: a patch in ``benchmarks/variants/`` applied to a copy of
the package (``git apply``), imported under its own name, so every variant runs
in the same interleaved rounds.

Counted per step (static, from ``compiled.as_text()``): the scan body's thunks,
plus each loop of known trip count inside it times its trip count (its body
and its condition); a loop of data-dependent trip count (the warm start's
fallback, the between-step search) is listed apart, per iteration, with how
often it ran. Timed: planning-only and checked rollouts (``--steps`` steps) of
the tree scene (single) and of ``random_scenarios(0, --batch)`` (vmapped), curve
method and the 10-point reference, float64; min and median per step (per
scenario-step in a batch) over ``--rounds`` interleaved rounds, compile apart.

    python benchmarks/step_kernels.py                 # ~15 min on 2 CPUs
    python benchmarks/step_kernels.py --variants polish_unrolled --rounds 3

Writes ``benchmarks/results/step_kernels.{md,json}``.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import jax

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import (  # noqa: E402
    RESULTS_DIR,
    finish_machine,
    fmt_s,
    log,
    machine_info,
    machine_lines,
    rollout_wrappers,
    write_results,
)
from kernel import load_variant  # noqa: E402

import softplan_jax  # noqa: E402

VARIANTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "variants")
# HLO instructions that are not launched as thunks of their own.
NOT_THUNKS = {"parameter", "constant", "get-tuple-element", "tuple", "bitcast", "after-all", "opt-barrier"}


def available_variants() -> list[str]:
    return sorted(f[: -len(".patch")] for f in os.listdir(VARIANTS_DIR) if f.endswith(".patch"))


def make_variant(name: str, workdir: str):
    """The installed package with ``variants/<name>.patch`` applied, imported as a module."""
    src = os.path.dirname(softplan_jax.__file__)
    root = os.path.join(workdir, name)
    shutil.copytree(src, os.path.join(root, "softplan_jax"), ignore=shutil.ignore_patterns("__pycache__"))
    patch = os.path.join(VARIANTS_DIR, name + ".patch")
    done = subprocess.run(["git", "apply", "-p1", patch], cwd=root, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"variant {name}: the patch does not apply to this package: {done.stderr.strip()}")
    return load_variant(name, os.path.join(root, "softplan_jax"))


# ----------------------------------------------------------------------------
# Thunk counts from optimised HLO text.


def parse_hlo(text: str) -> tuple[dict, str]:
    """{computation: [(opcode, line), ...]} and the entry computation's name."""
    comps, cur, entry = {}, None, None
    for line in text.splitlines():
        if not line.startswith(" ") and line.rstrip().endswith("{"):
            m = re.match(r"^(ENTRY )?%?([\w.\-]+) ", line)
            if m:
                cur = m.group(2)
                comps[cur] = []
                entry = cur if m.group(1) else entry
            continue
        if cur and line.strip() == "}":
            cur = None
            continue
        m = re.match(r"\s*(?:ROOT )?%?[\w.\-]+ = (.*)$", line) if cur else None
        if m:
            op = re.search(r"(?:^|[\s)])([a-z][\w\-]*)\(", m.group(1))
            if op:
                comps[cur].append((op.group(1), line))
    return comps, entry


def _small(line: str) -> bool:
    """A call XLA's CPU backend compiles into ONE kernel (``xla_cpu_small_call``: e.g. the
    PRNG's threefry loop), counted as one thunk."""
    return 'xla_cpu_small_call="true"' in line


def _thunks(comps, name) -> int:
    """Thunks of one computation's own instructions (a small call is one; any other call
    counts as its callee's thunks, see :func:`_calls`)."""
    return sum(op not in NOT_THUNKS and (op != "call" or _small(line)) for op, line in comps[name])


def _calls(comps, name):
    """The computations a computation calls and runs as thunks of their own (not small calls)."""
    return [re.search(r"to_apply=%?([\w.\-]+)", line).group(1) for op, line in comps[name]
            if op == "call" and not _small(line)]


def _loops(comps, name):
    """(body, condition, known trip count or None) of each while loop in a computation."""
    out = []
    for op, line in comps[name]:
        if op == "while":
            body = re.search(r"body=%?([\w.\-]+)", line).group(1)
            cond = re.search(r"condition=%?([\w.\-]+)", line).group(1)
            trip = re.search(r'known_trip_count[^}]*"n":"(\d+)"', line)
            out.append((body, cond, int(trip.group(1)) if trip else None))
    return out


def _static_count(comps, name):
    """(thunks per run of a computation with its calls inlined and its fixed-trip loops
    expanded, [per-iteration thunks of each data-dependent loop])."""
    total, dynamic = _thunks(comps, name), []
    for callee in _calls(comps, name):
        inner, inner_dyn = _static_count(comps, callee)
        total += inner
        dynamic.extend(inner_dyn)
    for body, cond, trip in _loops(comps, name):
        inner, inner_dyn = _static_count(comps, body)
        per_iter = inner + _static_count(comps, cond)[0]
        if trip is None:
            dynamic.append(per_iter)
        else:
            total += trip * per_iter + _static_count(comps, cond)[0]
        dynamic.extend(inner_dyn)
    return total, dynamic


def step_thunks(hlo_text: str, scan_steps: int) -> dict:
    """Thunks per planner step: the rollout's scan is the loop of ``scan_steps`` iterations
    (``scan_steps // u`` when the scan is unrolled u times); its
    body's count per iteration (fixed loops expanded) times the trip count, over
    ``scan_steps``; and the data-dependent loops' per-iteration counts."""
    comps, entry = parse_hlo(hlo_text)
    loops = [loop for name in comps for loop in _loops(comps, name)]  # the scan may sit in a called computation
    for unroll in range(1, 9):  # the scan's loop: scan_steps iterations, or scan_steps // unroll
        found = [loop for loop in loops if loop[2] == scan_steps // unroll]
        if found:
            break
    else:
        raise RuntimeError(f"no loop of {scan_steps} (or {scan_steps} // k) iterations in the program")
    body, cond, trip = found[0]
    per_iter, dynamic = _static_count(comps, body)
    ops = collections.Counter(op for op, _ in comps[body] if op not in NOT_THUNKS)
    per_step = trip * (per_iter + _static_count(comps, cond)[0]) / scan_steps
    return dict(per_step=round(per_step), scan_trip=trip, dynamic_loops=dynamic, body_ops=dict(ops.most_common(8)),
                setup=_thunks(comps, entry))


# ----------------------------------------------------------------------------
# Programs and timing.


def _planner_modules(pkg):
    import importlib

    return (importlib.import_module(f"{pkg.__name__}.planner"),
            importlib.import_module(f"{pkg.__name__}.compilation_cache"))


def compile_cases(pkg, steps: int, batch_size: int, run: bool = True):
    """{(method, check, where): (compiled, args, scenario-steps per call, compile s, thunks)}."""
    planner, cc = _planner_modules(pkg)
    tree = pkg.paper_scenario("tree")
    batch = pkg.random_scenarios(0, batch_size)
    g = pkg.default_gains()
    single, batched = rollout_wrappers(planner.rollout)
    out = {}
    for method in ("curve", "points10"):
        for check in (False, True):
            options = (planner.make_options("curve", check_collisions=check) if method == "curve"
                       else planner.make_options("points", 10, check_collisions=check))
            copts = cc.rollout_compiler_options(options.method)
            for where, fn, sc, n in (("single", single, tree, 1), ("batch", batched, batch, batch_size)):
                t0 = time.perf_counter()
                c = (jax.jit(fn, static_argnames=("options", "max_steps"), compiler_options=copts)
                     .lower(sc, g, options=options, max_steps=steps).compile())
                ct = time.perf_counter() - t0
                if run:
                    jax.block_until_ready(c(sc, g))  # warm-up
                out[(method, "checked" if check else "plan", where)] = (
                    c, (sc, g), n * (steps + 1), ct, step_thunks(c.as_text(), steps + 1))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", default=None,
                    help=f"comma list of patches in benchmarks/variants/ (default all: {','.join(available_variants())})")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(RESULTS_DIR, "step_kernels"), help="output prefix")
    ap.add_argument("--recount", action="store_true",
                    help="compile again and count the thunks only, keeping the timings of the run in OUT.json "
                    "(after a change to the counter)")
    args = ap.parse_args(argv)
    for name in ("steps", "batch", "rounds"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1; got {getattr(args, name)}")
    names = available_variants() if args.variants is None else [v for v in args.variants.split(",") if v]
    unknown = sorted(set(names) - set(available_variants()))
    if unknown:
        ap.error(f"--variants: unknown {unknown}; choose from {available_variants()}")
    if shutil.which("git") is None and names:
        ap.error("the variants are applied with `git apply`: git is not on PATH")
    jax.config.update("jax_enable_x64", True)
    if args.recount:
        return recount(args, names)
    machine = machine_info("float64")
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        variants = [("installed", softplan_jax)] + [(n, make_variant(n, work)) for n in names]
        calls = {}
        for name, pkg in variants:
            for key, v in compile_cases(pkg, args.steps, args.batch).items():
                calls[(name, *key)] = v
                log(f"  {name} {' '.join(key)}: compiled in {v[3]:.1f} s, {v[4]['per_step']} thunks per step")
        times = {k: [] for k in calls}
        for r in range(args.rounds):
            for key, (c, cargs, n, _, _) in calls.items():
                t0 = time.perf_counter()
                jax.block_until_ready(c(*cargs))
                times[key].append((time.perf_counter() - t0) / n)
            log(f"  round {r + 1}/{args.rounds} done, {time.perf_counter() - t_start:.0f} s")
    rows = []
    for key, (_, _, _, ct, th) in calls.items():
        t = times[key]
        rows.append(dict(variant=key[0], method=key[1], check=key[2], where=key[3], compile_s=ct,
                         min_s=min(t), median_s=statistics.median(t), thunks=th))
    by = {(r["variant"], r["method"], r["check"], r["where"]): r for r in rows}
    for r in rows:
        base = by[("installed", r["method"], r["check"], r["where"])]
        ref = by[(r["variant"], "points10", r["check"], r["where"])]
        r["vs_installed_median"] = r["median_s"] / base["median_s"]
        r["vs_points10_median"] = r["median_s"] / ref["median_s"]
    machine = finish_machine(machine)
    header = [f"- generated by `python benchmarks/step_kernels.py` in {time.perf_counter() - t_start:.0f} s; "
              f"rollouts of {args.steps} steps, float64; single = the tree scene, batch = "
              f"`random_scenarios(0, {args.batch})` vmapped (per scenario-step); {args.rounds} interleaved rounds",
              *machine_lines(machine)]
    write_report(args.out, dict(machine=machine, args=vars(args), rows=rows, header=header), names)


def recount(args, names):
    """--recount: the thunk counts of every program again (no run), the timings kept."""
    with open(args.out + ".json", encoding="utf-8") as fh:
        report = json.load(fh)
    rows = {(r["variant"], r["method"], r["check"], r["where"]): r for r in report["rows"]}
    steps, batch = report["args"]["steps"], report["args"]["batch"]
    with tempfile.TemporaryDirectory() as work:
        for name in ["installed", *names]:
            pkg = softplan_jax if name == "installed" else make_variant(name, work)
            for key, v in compile_cases(pkg, steps, batch, run=False).items():
                if (name, *key) in rows:
                    rows[(name, *key)]["thunks"] = v[4]
                    log(f"  {name} {' '.join(key)}: {v[4]['per_step']} thunks per step")
    report["header"] = report["header"] + [
        "- thunk counts recounted without running (`--recount`: calls other than XLA's one-kernel "
        "small calls inlined into their caller's thunk sequence); times from the run above"]
    write_report(args.out, report, [n for n in names if any(k[0] == n for k in rows)])


def write_report(out: str, report: dict, names) -> None:
    rows = report["rows"]
    lines = ["# Kernels per planner step (issue 25, item 1)", "", *report["header"], "",
             "*thunks / step*: the scan body's thunks with its calls inlined (a small call, compiled "
             "into one kernel, is one thunk) and its fixed-trip "
             "loops expanded (the polish's 3 Newton iterations, ...); *dynamic loops*: thunks per "
             "iteration of each loop whose trip count depends on the data (the warm start's fallback, "
             "the between-step search), which runs only when needed. Times: min / median per step; "
             "*x installed*: median against the installed package's same program; *x 10-point*: "
             "median against the same variant's 10-point program.", "",
             "| variant | method | rollout | where | thunks / step | dynamic loops | compile | min | median "
             "| x installed | x 10-point |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['variant']} | {r['method']} | {r['check']} | {r['where']} | {r['thunks']['per_step']} "
            f"| {', '.join(map(str, r['thunks']['dynamic_loops'])) or '-'} | {r['compile_s']:.1f} s "
            f"| {fmt_s(r['min_s'])} | {fmt_s(r['median_s'])} | {r['vs_installed_median']:.2f} "
            f"| {r['vs_points10_median']:.2f} |")
    lines += ["", "Variants (patches in `benchmarks/variants/`):", ""]
    for n in names:
        with open(os.path.join(VARIANTS_DIR, n + ".patch"), encoding="utf-8") as fh:
            files = sorted(set(re.findall(r"^\+\+\+ b/(\S+)", fh.read(), flags=re.M)))
        lines.append(f"- `{n}`: changes {', '.join(files)}")
    md = "\n".join(lines) + "\n"
    write_results(out, report, md)
    log(f"wrote {out}.md/.json")
    print(md)


if __name__ == "__main__":
    main(sys.argv[1:])
