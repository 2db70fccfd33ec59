"""Where a planner step's time goes: its cost per lane against the lane width, and a profile.

The engine's batch (:func:`softplan_jax.planning.engine.run_lanes`) steps ``lanes``
scenes side by side; what a batch costs is the steps it takes times the cost of one
lane's step at that width. This script measures both halves of that product for
``plan_batch(random_scenarios(1, --batch), max_steps=600)`` (float64, the curve method,
the planner's default options):

* **cost per lane-step**: the vmapped engine step of L scenes, every one still running,
  for each width of ``--lanes``: the batch's 64 longest-running scenes (tiled to L),
  stepped ``--after`` steps first (so that the warm start's fallback rate is a running
  batch's, not that of the first steps, which solve every pair in full), then
  10 steps timed; min over ``--rounds`` interleaved rounds;
* **a profile** at ``--profile-lanes``: a ``jax.profiler`` trace of those steps, each
  XLA operation's time attributed to the package function that emitted it (from the
  compiled program's stack frames), summed at ``--depth`` calls below the step;
* **what lanes can buy**: the batch takes S steps (iterations + 1 summed), so at L
  lanes it takes at least S times the cost per lane-step at L (every lane busy at
  every step); and a replay of ``run_lanes``' schedule in Python (refills in lane
  order, round robin after ``DEFAULT_QUANTUM`` steps, the loop ending at a chunk's
  end) on the scenes' step counts gives the loop steps the engine runs at L lanes,
  idle lanes included, and so the time the step's cost predicts.

    python benchmarks/step_profile.py            # ~6 min on 2 CPUs
    python benchmarks/step_profile.py --quick    # small widths on random_scenarios(1, L), no batch, into results/quick/

Writes ``benchmarks/results/step_profile.{md,json}`` and ``results/figures/step_profile.png``.
The attribution reads the trace jax writes (``perfetto_trace.json.gz``) and the compiled
program's text (its ``StackFrames`` section); a jax that writes neither gives the table
of costs without the profile.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import sys
import tempfile
import time

import jax
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import finish_machine, log, machine_info, machine_lines, output_paths, write_results  # noqa: E402
from lane_schedule import replay  # noqa: E402

STEPS = 10  # steps timed and profiled, after the first


def _stepper(L: int, after: int, longest=None, batch: int = 0):
    """(compiled program of STEPS steps, its arguments) for the vmapped step of L running
    scenes, after ``after`` steps: the scenes ``longest`` of ``random_scenarios(1, batch)``
    tiled to L (None: ``random_scenarios(1, L)``)."""
    import jax.numpy as jnp

    import softplan_jax as sp
    from softplan_jax.planning.engine import init_carry, make_step, prepare
    from softplan_jax.planning.options import rollout_compiler_options
    from softplan_jax.planning.planner import make_options
    from softplan_jax.planning.programs import batch_keys, strong_gains

    if longest is None:
        scenes, keys = sp.random_scenarios(1, L), batch_keys(0, L)
    else:
        sel = np.resize(np.asarray(longest), L)
        scenes = jax.tree_util.tree_map(lambda x: x[sel], sp.random_scenarios(1, batch))
        keys = batch_keys(0, batch)[sel]
    options = make_options("curve", 10)
    gains = strong_gains(sp.default_gains(), scenes.q0.dtype)
    prepared = jax.vmap(lambda w: prepare(w, options))(scenes)
    carry0 = jax.vmap(lambda w, key: init_carry(w, options, key))(scenes, keys)

    def steps(worlds, prep, carry, k, n):
        def one(w, p, c, k):
            return make_step(w, gains, options, 600, p)(c, k)

        def body(c, i):
            c, record = jax.vmap(one)(worlds, prep, c, k + i)
            return c, record.q[:, 0, 0]

        return jax.lax.scan(body, carry, jnp.arange(n))[0]

    f = jax.jit(steps, static_argnums=4, compiler_options=rollout_compiler_options("curve"))
    k = jnp.zeros((L,), jnp.int32)
    carry = f(scenes, prepared, carry0, k, after)  # the first steps: the full solves, then a running batch's
    args = (scenes, prepared, carry, k + after)
    return f.lower(*args, STEPS).compile(), args


def _frames(hlo: str) -> tuple[dict, callable]:
    """The compiled program's op -> stack frame map, and a frame -> [function:line] chain."""
    sec, funcs, locs, frames, op_frame = None, {}, {}, {}, {}
    for line in hlo.split("\n"):
        if line in ("FileNames", "FunctionNames", "FileLocations", "StackFrames"):
            sec = line
            continue
        if sec and not line.strip():
            sec = None
            continue
        if sec == "FunctionNames":
            i, name = line.split(" ", 1)
            funcs[int(i)] = name.strip('"')
        elif sec in ("FileLocations", "StackFrames"):
            i, rest = line.split(" ", 1)
            (locs if sec == "FileLocations" else frames)[int(i)] = dict(re.findall(r"(\w+)=(\d+)", rest))
        m = re.match(r"\s*(?:ROOT )?%(\S+) = .*stack_frame_id=(\d+)", line)
        if m:
            op_frame[m.group(1)] = int(m.group(2))

    def chain(fid):
        out, seen = [], set()
        while fid in frames and fid not in seen:
            seen.add(fid)
            loc = locs[int(frames[fid]["file_location_id"])]
            name = funcs[int(loc["function_name_id"])]
            if not name.endswith(("<listcomp>", "<genexpr>", "<dictcomp>")):  # a comprehension says nothing
                out.append(name)
            fid = int(frames[fid].get("parent_frame_id", 0)) - 1  # printed one above the parent's id
        return out[::-1]

    return op_frame, chain


def profile(L: int, depth: int, stepper) -> dict:
    """Trace STEPS steps of L lanes (``stepper``: :func:`_stepper` of L);
    each op's time summed by the functions ``depth`` calls below the engine's step
    (``other``: ops outside it or without a frame)."""
    f, args = stepper
    jax.block_until_ready(f(*args))
    with tempfile.TemporaryDirectory() as tmp:
        jax.profiler.start_trace(tmp, create_perfetto_trace=True)
        jax.block_until_ready(f(*args))
        jax.profiler.stop_trace()
        found = glob.glob(os.path.join(tmp, "plugins", "profile", "*", "perfetto_trace.json.gz"))
        if not found:
            return {}
        with gzip.open(found[0]) as fh:
            trace = json.load(fh)
    events = trace["traceEvents"] if isinstance(trace, dict) else trace
    op_frame, chain = _frames(f.as_text())
    skip = ("$", "Thunk", "while", "cond", "Pjit", "end:")
    by = collections.Counter()
    for e in events:
        name = e.get("name", "")
        if e.get("ph") != "X" or name.startswith(skip) or name not in op_frame:
            continue
        c = chain(op_frame[name])
        if "make_step.<locals>.step" in c:
            i = len(c) - 1 - c[::-1].index("make_step.<locals>.step")  # the innermost step
            key = " > ".join(c[i + 1 : i + 1 + depth]) or "the step itself"
        else:
            key = "other"
        by[key] += e.get("dur", 0)
    total = sum(by.values())
    return {"lanes": L, "steps": STEPS, "depth": depth, "total_us": total,
            "share": {k: v / total for k, v in by.most_common()} if total else {}}


def batch_steps(batch: int) -> tuple[np.ndarray, float]:
    """Per-scene steps (iterations + 1) of plan_batch(random_scenarios(1, batch), max_steps=600)
    at the default lanes, and the seconds its second (warm) call took."""
    import softplan_jax as sp

    scenes = sp.random_scenarios(1, batch)
    jax.block_until_ready(sp.plan_batch(scenes, max_steps=600))  # compiles; its run ends before the timed one
    t0 = time.perf_counter()
    r = jax.block_until_ready(sp.plan_batch(scenes, max_steps=600))
    return np.asarray(r.iterations) + 1, time.perf_counter() - t0


def plot(rows, prof, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2 if prof.get("share") else 1, figsize=(11, 4), squeeze=False)
    ax = axes[0, 0]
    ax.plot([r["lanes"] for r in rows], [r["per_lane_step_us"] for r in rows], "o-")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("lanes (scenes stepped side by side)")
    ax.set_ylabel("µs per lane-step (min)")
    ax.set_title("Cost of one running lane's step")
    if prof.get("share"):
        top = list(prof["share"].items())[:8][::-1]
        ax = axes[0, 1]
        ax.barh([k.split(" > ")[-1][:40] for k, _ in top], [100 * v for _, v in top])
        ax.set_xlabel(f"% of the step's XLA op time ({prof['lanes']} lanes)")
        ax.set_title("Where the step's time goes")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lanes", default=None, help="comma list of lane widths (default 16,64,128,256,1024; quick 4,8)")
    ap.add_argument("--profile-lanes", type=int, default=None, help="width profiled (default 256; quick 8; 0: none)")
    ap.add_argument("--depth", type=int, default=3, help="calls below the step the profile sums at")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 5; quick 2)")
    ap.add_argument("--batch", type=int, default=None, help="plan_batch scenes (default 1024; quick 0: none)")
    ap.add_argument("--after", type=int, default=None, help="steps before the timed ones (default 100; quick 1)")
    ap.add_argument("--quick", action="store_true", help="small widths, no batch, into results/quick/")
    ap.add_argument("--out", default=None, help="output prefix (default results/step_profile; quick: results/quick/)")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    lanes = [int(x) for x in (args.lanes or ("4,8" if args.quick else "16,64,128,256,1024")).split(",")]
    if not lanes or min(lanes) < 1:
        raise ValueError(f"--lanes must be positive ints, got {args.lanes!r}")
    rounds = args.rounds or (2 if args.quick else 5)
    prof_lanes = (8 if args.quick else 256) if args.profile_lanes is None else args.profile_lanes
    batch = (0 if args.quick else 1024) if args.batch is None else args.batch
    after = (1 if args.quick else 100) if args.after is None else args.after
    if after < 1 or batch < 0:
        raise ValueError(f"--after must be >= 1 and --batch >= 0, got {after} and {batch}")
    prefix, fig_dir = output_paths("step_profile", args.quick, args.out)
    machine = machine_info("float64")
    t_start = time.perf_counter()

    from softplan_jax.planning.engine import DEFAULT_LANES, DEFAULT_QUANTUM, DEFAULT_STEP_CHUNK

    need, batch_s = batch_steps(batch) if batch else (None, None)
    longest = None if need is None else np.argsort(-need, kind="stable")[:64]
    runs = {}
    for L in lanes:
        log(f"compiling the step of {L} lanes")
        runs[L] = _stepper(L, after, longest, batch)
        jax.block_until_ready(runs[L][0](*runs[L][1]))
    times = {L: [] for L in lanes}
    for r in range(rounds):
        for L in lanes if r % 2 == 0 else lanes[::-1]:
            f, a = runs[L]
            t0 = time.perf_counter()
            jax.block_until_ready(f(*a))
            times[L].append(time.perf_counter() - t0)
        log(f"round {r + 1}/{rounds}")
    rows = [{"lanes": L, "per_step_ms": 1e3 * min(times[L]) / STEPS, "per_lane_step_us": 1e6 * min(times[L]) / STEPS / L,
             "median_per_lane_step_us": 1e6 * float(np.median(times[L])) / STEPS / L} for L in lanes]
    prof = profile(prof_lanes, args.depth, runs.get(prof_lanes) or _stepper(prof_lanes, after, longest, batch)) \
        if prof_lanes else {}
    del runs
    steps_taken = None if need is None else int(need.sum())
    for r in rows if need is not None else ():
        r["floor_s"] = steps_taken * r["per_lane_step_us"] * 1e-6
        r["loop_steps"] = replay(need, r["lanes"], DEFAULT_QUANTUM, DEFAULT_STEP_CHUNK)
        r["busy"] = steps_taken / (r["loop_steps"] * min(r["lanes"], batch))
        r["predicted_s"] = r["loop_steps"] * min(r["lanes"], batch) * r["per_lane_step_us"] * 1e-6

    command = "".join(" " + a for a in (sys.argv[1:] if argv is None else argv))
    source = (f"the {min(64, batch)} longest-running scenes of `random_scenarios(1, {batch})` tiled to L"
              if batch else "`random_scenarios(1, L)`")
    md = ["# Where a planner step's time goes", "", *machine_lines(finish_machine(machine)),
          f"- command: `python benchmarks/step_profile.py{command}`; "
          f"{time.perf_counter() - t_start:.0f} s",
          f"- the vmapped engine step of L scenes ({source}), all running, {STEPS} steps after the first "
          f"{after}; min over {rounds} interleaved rounds", "",
          "| lanes | ms per step | µs per lane-step (min) | median |", "|---|---|---|---|"]
    md += [f"| {r['lanes']} | {r['per_step_ms']:.3f} | {r['per_lane_step_us']:.1f} | "
           f"{r['median_per_lane_step_us']:.1f} |" for r in rows]
    if need is not None:
        md += ["", f"`plan_batch(random_scenarios(1, {batch}), max_steps=600)` takes {steps_taken:,} steps "
               "(iterations + 1 summed; the longest scene "
               f"{int(need.max())}). At L lanes it takes at least that times the cost per lane-step at L "
               "(the floor: every lane busy at every step). The replay of `run_lanes`' schedule "
               f"(quantum {DEFAULT_QUANTUM}, chunks of {DEFAULT_STEP_CHUNK}) gives the loop steps it runs, "
               "idle lanes included, and the time the step's cost predicts (no bookkeeping counted):", "",
               "| lanes | floor | loop steps | lanes busy | predicted |", "|---|---|---|---|---|"]
        md += [f"| {r['lanes']} | {r['floor_s']:.2f} s | {r['loop_steps']:,} | {100 * r['busy']:.1f} % | "
               f"{r['predicted_s']:.2f} s |" for r in rows]
        md += ["", f"Measured: the batch at the default {DEFAULT_LANES} lanes took {batch_s:.2f} s (one warm call)."]
    if prof.get("share"):
        md += ["", f"Profile at {prof['lanes']} lanes ({STEPS} steps; `jax.profiler` trace, each XLA op's time "
               f"attributed to the functions {prof['depth']} calls below the engine's step; "
               f"{prof['total_us'] / 1e3:.1f} ms of op time):", "", "| share | where |", "|---|---|"]
        md += [f"| {100 * v:.1f} % | {k} |" for k, v in list(prof["share"].items())[:20]]
    elif prof_lanes:
        md += ["", "No profile: this jax wrote no perfetto trace."]
    report = {"machine": machine, "steps": STEPS, "after": after, "rounds": rounds, "rows": rows, "profile": prof,
              "batch": batch, "steps_taken": steps_taken, "batch_default_lanes_s": batch_s}
    write_results(prefix, report, "\n".join(md) + "\n")
    os.makedirs(fig_dir, exist_ok=True)
    plot(rows, prof, os.path.join(fig_dir, "step_profile.png"))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
