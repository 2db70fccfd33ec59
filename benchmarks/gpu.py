"""One accelerator in one call: the single plan's latency against the CPU, the batched
rollout's throughput against the batch size, and a kernel profile of the batched step.

Made for short loans of a GPU machine: everything is prepared
here and run in one process (plus one child process for an XLA-flag variant),
the results written after each part, so a run stopped at its time limit still
leaves what it measured.

Parts (each one timed with compile apart; warm calls interleaved in rounds):

1. ``plan(paper_scenario("tree"))`` at ``max_steps`` = 58 (its 53 steps + 5) and
   600 (the default), on the accelerator and on the host CPU of the same machine.
2. The batched rollout that :func:`softplan_jax.plan_batch` runs
   (:func:`~softplan_jax.planning._engine.run_lanes`) on ``random_scenarios(0, B)``
   with at most ``--steps`` steps, for each B of ``--sizes`` with every scene in
   its own lane (``lanes = B``), float64; at the first size also 64 lanes (a CPU
   batch's width) and the fallback loop's former fixed chunk of 8 ("before");
   float32 at the last size. Reported: taken scenario-steps per
   second (the sum of iterations + 1 over the scenes, over the wall time).
3. A ``jax.profiler`` trace of one warm call at the first and the last size:
   the device's kernel time by kernel, the device-to-host copies (a
   ``while_loop``'s condition goes to the host on every trip), busy time against
   wall time. The optimized HLO of each traced program is saved beside, to map
   kernel names to the code (each kernel's ``op_name``).
4. The float32 run's statuses against float64's, and the float32 trajectories
   of the first 256 scenes, saved for a float64 audit on a host (``--audit
   FILE``: exact clearances and the arm's motion bound over 16 pieces a step).
5. (child process) the single plan again with XLA's command buffers extended to
   ``while`` and ``conditional``.
6. ("defaults", on request) what a user gets without options: ``plan(tree)``
   (one scene goes to the host CPU) against ``device="default"``, and
   ``plan_batch`` with its default lanes against 64.
7. ("tracking", on request) ``track_batch``'s program on moving scenes, the
   evasive step off and on, at the default motion and at twice a brisk one.

    python benchmarks/gpu.py --suites S --sizes 1024,16384 --out $OUT/gpu   # one GPU, ~2.5 min
    python benchmarks/gpu.py --quick                  # smoke run (any machine): B = 8, 10 steps
    python benchmarks/gpu.py --audit $OUT/gpu_float32_q.npz   # the float32 audit, on a CPU

where S holds ``random0_B.npz`` suites written ahead on a CPU (``--write-suites S B ...``).
The H200 runs of ``results/gpu*.md`` used them: ``random_scenarios`` then built a scene at a
time (138 s for 4,096 scenes on the GPU); it now draws 16,384 in seconds, so S is optional.

Writes ``OUT.json``, ``OUT.md``, ``OUT_profile_B*.json``, ``OUT_hlo_B*.txt.gz`` and
``OUT_float32_q.npz`` (OUT: ``--out``, default ``benchmarks/results/gpu``).
"""

from __future__ import annotations

import argparse
import functools
import gzip
import json
import os
import statistics
import subprocess
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

CMDBUF_FLAGS = ("--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL "
                "--xla_gpu_graph_min_graph_size=1")


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=None, help="output prefix (default results/gpu; --quick: results/quick/gpu)")
    ap.add_argument("--quick", action="store_true", help="smoke run: B = 8, 10 steps, 1 round, parts plan,batch,"
                                                         "float32")
    ap.add_argument("--sizes", default=None, help="comma list of batch sizes (default 1024,4096,16384)")
    ap.add_argument("--steps", type=int, default=None, help="most steps per scene (default 200)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (default 2)")
    ap.add_argument("--parts", default=None,
                    help="comma list of the parts to run (default all)")
    ap.add_argument("--suites", default=None, help="folder of random0_B.npz suites (the leaves of "
                    "random_scenarios(0, B), float64) made ahead on a host (--write-suites)")
    ap.add_argument("--defaults-size", type=int, default=None, help="the batch of part defaults (default 1024; "
                    "quick 8)")
    ap.add_argument("--no-extras", action="store_true", help="part batch: lanes = B only (no 64-lane and no "
                    "former-fallback-chunk variants)")
    ap.add_argument("--tracking-size", type=int, default=None, help="scenes of part tracking (default 4096; "
                    "quick 8)")
    ap.add_argument("--tracking-steps", type=int, default=None, help="steps of part tracking (default 300; "
                    "quick 20)")
    ap.add_argument("--deadline", type=float, default=None, help="start no part after this many seconds")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--audit", default=None, help="audit a saved OUT_float32_q.npz in float64 and exit")
    ap.add_argument("--write-suites", nargs="+", default=None, metavar=("FOLDER", "B"),
                    help="write random_scenarios(0, B) for each B into FOLDER (for --suites) and exit")
    args = ap.parse_args(argv)
    quick = args.quick
    for key, full, short in (("sizes", "1024,4096,16384", "8"), ("steps", 200, 10), ("rounds", 2, 1),
                             ("defaults_size", 1024, 8), ("tracking_size", 4096, 8), ("tracking_steps", 300, 20),
                             ("parts", "plan,cmdbuf,batch,profile,float32", "plan,batch,float32")):
        if getattr(args, key) is None:  # a value the user gave is kept, and checked below
            setattr(args, key, short if quick else full)
    try:
        args.size_list = [int(x) for x in args.sizes.split(",")]
    except ValueError:
        ap.error(f"--sizes: a comma list of integers, got {args.sizes!r}")
    if not args.size_list or min(args.size_list) < 1 or args.steps < 1 or args.rounds < 1 or args.defaults_size < 1 \
            or args.tracking_size < 1 or args.tracking_steps < 1:
        ap.error("--sizes, --steps, --rounds, --defaults-size, --tracking-size and --tracking-steps must be >= 1")
    if args.write_suites is not None:
        try:
            args.write_sizes = [int(b) for b in args.write_suites[1:]]
        except ValueError:
            ap.error(f"--write-suites FOLDER B ...: the sizes must be integers, got {args.write_suites[1:]}")
        if not args.write_sizes or min(args.write_sizes) < 1:
            ap.error("--write-suites FOLDER B ...: give one or more sizes >= 1")
    args.part_list = [p.strip() for p in args.parts.split(",") if p.strip()]
    bad = set(args.part_list) - {"plan", "batch", "profile", "float32", "cmdbuf", "defaults", "tracking"}
    if bad:
        ap.error(f"--parts: unknown part(s) {sorted(bad)}")
    if args.out is None:
        args.out = os.path.join(HERE, "results", "quick" if quick else "", "gpu")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    return args


class Report:
    """The results so far, written to OUT.json after every part."""

    def __init__(self, out):
        self.out = out
        self.data = {"parts": {}, "errors": {}}

    def put(self, part, value):
        self.data["parts"][part] = value
        self.save()

    def error(self, part):
        self.data["errors"][part] = traceback.format_exc()[-3000:]
        print(f"!! part {part} failed:\n{self.data['errors'][part]}", file=sys.stderr, flush=True)
        self.save()

    def save(self):
        with open(self.out + ".json", "w") as f:
            json.dump(self.data, f, indent=1, default=float)


T0 = time.perf_counter()


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _interleaved(calls: dict, rounds: int, inner: int = 1) -> dict:
    """{name: [seconds per call, ...]}: ``rounds`` rounds, each calling every entry ``inner``
    times, the order reversed every other round."""
    import jax

    times = {k: [] for k in calls}
    names = list(calls)
    for r in range(rounds):
        for name in names if r % 2 == 0 else names[::-1]:
            for _ in range(inner):
                t0 = time.perf_counter()
                jax.block_until_ready(calls[name]())
                times[name].append(time.perf_counter() - t0)
    return times


def _stats(t):
    return {"min_s": min(t), "median_s": statistics.median(t), "n": len(t)}


def part_plan(args, rep, devices):
    """The tree plan's latency at max_steps 58 and 600 on each device (warm, interleaved)."""
    import jax

    import softplan_jax as sp

    calls, first, iters = {}, {}, {}
    for dev_name, dev in devices.items():
        with jax.default_device(dev):
            scn = sp.paper_scenario("tree")
        for ms in (600,) if args.child else (58, 600):
            key = f"{dev_name} max_steps={ms}"

            def call(scn=scn, ms=ms, dev=dev):
                with jax.default_device(dev):
                    return sp.plan(scn, max_steps=ms).q

            t0 = time.perf_counter()
            with jax.default_device(dev):
                res = sp.plan(scn, max_steps=ms)
            jax.block_until_ready(res.q)
            first[key] = time.perf_counter() - t0
            iters[key] = (int(res.iterations), res.status)
            calls[key] = call
            log(f"plan {key}: first call {first[key]:.1f} s, {iters[key]}")
    times = _interleaved(calls, rounds=2 if args.quick else 5, inner=3)
    out = {k: {**_stats(t), "first_call_s": first[k], "iterations": iters[k][0], "status": iters[k][1],
               "device": str(devices[k.split()[0]])} for k, t in times.items()}
    rep.put("plan", out)
    return out


def part_defaults(args, rep):
    """What a user gets without options: plan(tree) (device None: the host CPU where the default
    backend is an accelerator) against device="default"; plan_batch of ``--defaults-size`` scenes
    with its default lanes against 64 lanes. Warm, interleaved."""
    import jax
    import numpy as np

    import softplan_jax as sp
    from softplan_jax.planning._engine import default_lanes
    from softplan_jax.planning._planner import plan_device

    tree = sp.paper_scenario("tree")
    suite = load_suite(args.suites, args.defaults_size, "float64")
    calls = {"plan device=None": lambda: sp.plan(tree).q,
             'plan device="default"': lambda: sp.plan(tree, device="default").q,
             "plan_batch lanes=None": lambda: sp.plan_batch(suite, max_steps=args.steps).q,
             "plan_batch lanes=64": lambda: sp.plan_batch(suite, max_steps=args.steps, lanes=64).q}
    out = {}
    for name, call in calls.items():
        t0 = time.perf_counter()
        jax.block_until_ready(call())
        out[name] = dict(first_call_s=time.perf_counter() - t0)
        log(f"defaults {name}: first call {out[name]['first_call_s']:.1f} s")
    for name, t in _interleaved(calls, rounds=3, inner=2).items():
        out[name].update(_stats(t))
    r = sp.plan(tree)
    out["plan device=None"].update(iterations=int(r.iterations), status=r.status, device=str(plan_device(None)))
    out["default_lanes"] = default_lanes()
    a, b = (jax.device_get(sp.plan_batch(suite, max_steps=args.steps, lanes=x)) for x in (None, 64))
    out["plan_batch statuses equal (lanes None vs 64)"] = int(np.sum(np.asarray(a.status) == np.asarray(b.status)))
    rep.put("defaults", out)
    return out


def part_tracking(args, rep):
    """Tracking among moving curves with and without the evasive step on the
    accelerator: ``track_batch``'s program (default lanes) on ``random_moving_scenarios(1, B)``
    at the benchmark's default motion and at twice the brisk one (sway 0.12 rad, shift 0.08 m,
    1-4 rad/s), ``--tracking-steps`` steps; first call (compile) apart, warm calls interleaved;
    statuses, steps taken and evasive steps of each."""
    import jax
    import numpy as np

    import softplan_jax as sp
    from softplan_jax.planning import make_track_options, rollout_batch

    B, T = args.tracking_size, args.tracking_steps
    suites = {"default": sp.moving.random_moving_scenarios(1, B),
              "brisk x2": sp.moving.random_moving_scenarios(1, B, amplitude=0.12, shift=0.08, omega=(1.0, 4.0))}
    gains = sp.default_gains()
    keys = jax.random.split(jax.random.PRNGKey(0), B)
    calls = {}
    for evasion in (False, True):
        opts = make_track_options("curve", evasion=evasion)
        prog = lambda m, g, k, opts=opts: rollout_batch(m, g, opts, T, k, devices=1)  # noqa: E731
        for name, suite in suites.items():
            calls[f"{name}, evasion {'on' if evasion else 'off'}"] = \
                lambda prog=prog, suite=suite: prog(suite, gains, keys)
    out = {"B": B, "steps": T}
    for name, call in calls.items():
        t0 = time.perf_counter()
        r = jax.device_get(jax.block_until_ready(call()))
        st, counts = np.unique(np.asarray(r.status), return_counts=True)
        out[name] = dict(first_call_s=time.perf_counter() - t0,
                         statuses={sp.planning.status_name(s): int(c) for s, c in zip(st, counts, strict=True)},
                         steps_taken=int(np.sum(np.asarray(r.iterations) + 1)),
                         evasive_steps=int(np.sum(np.asarray(r.evasive))))
        log(f"tracking {name}: first call {out[name]['first_call_s']:.1f} s, {out[name]['statuses']}")
    for name, t in _interleaved({k: (lambda c=c: c().q) for k, c in calls.items()}, rounds=args.rounds).items():
        out[name].update(_stats(t))
        out[name]["steps_per_s_median"] = out[name]["steps_taken"] / out[name]["median_s"]
    rep.put("tracking", out)
    return out


def batch_variants(args):
    """[(name, dtype, B, lanes, trips)]: the batched programs of part 2."""
    from softplan_jax.geometry import _warm_start as ws

    s = args.size_list
    trips = ws.fallback_trips()  # the platform's default bound
    v = [(f"f64 B={b} lanes=B", "float64", b, b, trips) for b in (s[0], *s[:0:-1])]
    if not (args.quick or args.no_extras):
        v += [(f"f64 B={s[0]} lanes=64", "float64", s[0], min(64, s[0]), trips),
              (f"f64 B={s[0]} lanes=B chunk8 (before)", "float64", s[0], s[0], 10 ** 9)]
    if "float32" in args.part_list:
        v += [(f"f32 B={s[-1]} lanes=B", "float32", s[-1], s[-1], trips)]
    return v


def load_suite(suites, b, dtype):
    """random_scenarios(0, b) in ``dtype``: from the folder ``suites`` (``--suites``, as
    :func:`write_suites` writes it) if it holds it, else drawn on the host CPU; placed on the
    default device."""
    import jax
    import numpy as np

    import softplan_jax as sp

    path = os.path.join(suites or "", f"random0_{b}.npz")
    if suites and os.path.exists(path):
        template = sp.random_scenarios(0, 2, dtype=np.dtype(dtype))
        treedef = jax.tree_util.tree_structure(template)
        with np.load(path) as z:
            leaves = [z[f"arr_{i}"] for i in range(len(z.files))]
        leaves = [x.astype(dtype) if x.dtype.kind == "f" else x for x in leaves]
        suite = jax.tree_util.tree_unflatten(treedef, leaves)
    else:
        with jax.default_device(jax.devices("cpu")[0]):
            suite = sp.random_scenarios(0, b, dtype=np.dtype(dtype))
    return jax.device_put(suite, jax.devices()[0])


def part_batch(args, rep, programs):
    import jax
    import numpy as np
    from _common import lanes_program  # imported here: it imports jax and the package

    import softplan_jax as sp
    from softplan_jax.planning._programs import batch_keys, strong_gains

    opts = sp.make_options("curve")
    calls, info = {}, {}
    for name, dtype, b, lanes, trips in batch_variants(args):
        suite = load_suite(args.suites, b, dtype)
        g = strong_gains(sp.default_gains(np.dtype(dtype)), suite.q0.dtype)
        keys = batch_keys(0, b)
        compiled, compile_s = lanes_program(opts, args.steps, lanes, trips)(suite, g, keys=keys)
        t0 = time.perf_counter()
        r = jax.block_until_ready(compiled(suite, g, keys=keys))
        first = time.perf_counter() - t0
        it = np.asarray(r.iterations)
        info[name] = dict(dtype=dtype, batch=b, lanes=lanes, compile_s=compile_s, first_run_s=first,
                          steps_taken=int(np.sum(it + 1)), reached=int(np.sum(np.asarray(r.reached))),
                          collided=int(np.sum(np.asarray(r.collided))))
        programs[name] = (compiled, suite, g, keys, r)
        calls[name] = functools.partial(lambda c, s, g, k: c(s, g, keys=k).q, compiled, suite, g, keys)
        solo = _interleaved({name: calls[name]}, 2)[name]  # timed at once too: a run cut short keeps these
        info[name].update(solo_min_s=min(solo), solo_steps_per_s=info[name]["steps_taken"] / min(solo))
        log(f"batch {name}: compile {compile_s:.1f} s, first run {first:.2f} s, then {min(solo):.3f} s; "
            f"{info[name]['steps_taken']:,} steps taken")
        rep.put("batch", info)
    times = _interleaved(calls, args.rounds)
    for name, t in times.items():
        st = _stats(t)
        info[name].update(st, steps_per_s_median=info[name]["steps_taken"] / st["median_s"],
                          steps_per_s_best=info[name]["steps_taken"] / st["min_s"],
                          scenes_per_s_median=info[name]["batch"] / st["median_s"])
        log(f"batch {name}: median {st['median_s']:.3f} s, {info[name]['steps_per_s_median']:,.0f} taken steps/s")
    # the same statuses, iterations and q in every float64 variant of one size
    agree = {}
    for name, (_, _, _, _, r) in programs.items():
        ref = f"f64 B={info[name]['batch']} lanes=B"
        if name != ref and info[name]["dtype"] == "float64" and ref in programs:
            r0 = programs[ref][4]
            agree[name] = dict(
                status_equal=bool(np.array_equal(np.asarray(r.status), np.asarray(r0.status))),
                iterations_equal=bool(np.array_equal(np.asarray(r.iterations), np.asarray(r0.iterations))),
                q_max_abs_diff=float(np.max(np.abs(np.asarray(r.q) - np.asarray(r0.q)))))
    rep.put("batch", info)
    rep.put("batch_agreement", agree)
    return info


def _summarise_trace(path):
    """Device time by event name and by device thread (the kernels on the "Stream" lines; XLA's
    op and module lines name the HLO), copies, and the kernels' busy time, from a perfetto JSON
    trace of ``jax.profiler``."""
    op = gzip.open if path.endswith(".gz") else open
    with op(path, "rt") as f:
        trace = json.load(f)
    events = trace["traceEvents"] if isinstance(trace, dict) else trace
    pname, tname = {}, {}
    for e in events:
        if e.get("ph") == "M" and e.get("name") == "process_name":
            pname[e["pid"]] = e.get("args", {}).get("name", "")
        elif e.get("ph") == "M" and e.get("name") == "thread_name":
            tname[(e["pid"], e.get("tid"))] = e.get("args", {}).get("name", "")
    lines = {}  # device thread name -> {event name: [count, us]}
    spans, copies = [], {"count": 0, "us": 0.0, "names": {}}
    for e in events:
        if e.get("ph") != "X":
            continue
        proc = pname.get(e.get("pid"), str(e.get("pid")))
        if "GPU" not in proc and "device" not in proc.lower():
            continue
        thread = tname.get((e.get("pid"), e.get("tid")), str(e.get("tid")))
        name, dur = e.get("name", "?"), float(e.get("dur", 0.0))
        d = lines.setdefault(thread, {})
        k = d.setdefault(name, [0, 0.0])
        k[0] += 1
        k[1] += dur
        if thread.startswith("Stream") or "stream" in thread.lower():
            if "memcpy" in name.lower() or "memset" in name.lower():
                copies["count"] += 1
                copies["us"] += dur
                copies["names"][name] = copies["names"].get(name, 0) + 1
            else:
                spans.append((float(e["ts"]), float(e["ts"]) + dur))
    busy, end = 0.0, -1e300
    for a, b in sorted(spans):  # the union of the kernels' intervals
        if b > end:
            busy += b - max(a, end)
            end = b
    per_line = {}
    for thread, d in lines.items():
        top = sorted(d.items(), key=lambda kv: -kv[1][1])
        per_line[thread] = dict(events=sum(v[0] for v in d.values()), us=sum(v[1] for v in d.values()),
                                distinct=len(d), top=[dict(name=n, count=c, us=u) for n, (c, u) in top[:60]])
    return dict(processes=sorted(set(pname.values())), lines=per_line, kernel_launches=len(spans),
                busy_us=busy, span_us=(max(b for _, b in spans) - min(a for a, _ in spans)) if spans else 0.0,
                copies=copies)


def part_profile(args, rep, programs):
    import glob

    import jax

    out = {}
    names = [f"f64 B={b} lanes=B" for b in sorted({args.size_list[0], args.size_list[-1]})]
    for name in names:
        if name not in programs:
            continue
        compiled, suite, g, keys, r = programs[name]
        b = suite.q0.shape[0]
        with gzip.open(f"{args.out}_hlo_B{b}.txt.gz", "wt") as f:
            f.write(compiled.as_text())
        d = os.path.join("/tmp", f"softplan_trace_B{b}_{os.getpid()}")
        t0 = time.perf_counter()
        jax.profiler.start_trace(d, create_perfetto_trace=True)
        jax.block_until_ready(compiled(suite, g, keys=keys).q)
        jax.profiler.stop_trace()
        wall = time.perf_counter() - t0
        files = sorted(glob.glob(os.path.join(d, "**", "*.json.gz"), recursive=True)
                       + glob.glob(os.path.join(d, "**", "*.trace.json*"), recursive=True))
        log(f"profile {name}: traced in {wall:.1f} s, files {files}")
        summary = dict(wall_s=wall, steps_taken=int((r.iterations + 1).sum()), files=files)
        if files:
            summary.update(_summarise_trace(files[0]))
        out[name] = summary
        with open(f"{args.out}_profile_B{b}.json", "w") as f:
            json.dump(summary, f, indent=1)
        rep.put("profile", out)
    return out


def part_float32(args, rep, programs):
    import numpy as np

    out = {}
    for b in sorted({args.size_list[0], args.size_list[-1]}):
        a, c = programs.get(f"f64 B={b} lanes=B"), programs.get(f"f32 B={b} lanes=B")
        if a is None or c is None:
            continue
        r64, r32 = a[4], c[4]
        s64, s32 = np.asarray(r64.status), np.asarray(r32.status)
        out[f"B={b}"] = dict(status_equal=int(np.sum(s64 == s32)), batch=b,
                             collided_f32=int(np.sum(np.asarray(r32.collided))),
                             collided_f64=int(np.sum(np.asarray(r64.collided))),
                             reached_f32=int(np.sum(np.asarray(r32.reached))),
                             reached_f64=int(np.sum(np.asarray(r64.reached))),
                             min_clearance_f32=float(np.min(np.asarray(r32.min_clearance))))
        if b == args.size_list[-1]:
            k = min(256, b)
            np.savez_compressed(f"{args.out}_float32_q.npz", q=np.asarray(r32.q[:k]),
                                iterations=np.asarray(r32.iterations[:k]), batch=b, steps=args.steps)
    rep.put("float32", out)
    return out


def write_suites(folder, sizes):
    """random_scenarios(0, B), float64, as FOLDER/random0_B.npz (its leaves in order), for ``--suites``."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import softplan_jax as sp

    os.makedirs(folder, exist_ok=True)
    for b in sizes:
        t0 = time.perf_counter()
        leaves = jax.tree_util.tree_leaves(sp.random_scenarios(0, b))
        np.savez(os.path.join(folder, f"random0_{b}.npz"), *[np.asarray(x) for x in leaves])
        log(f"wrote random0_{b}.npz in {time.perf_counter() - t0:.0f} s")


def audit(path, suites=None, substeps: int = 16):
    """The float32 trajectories of a saved run, audited in float64 on the host. Each step
    interval is cut into ``substeps`` straight pieces; a piece is proven clear when the exact
    clearance (the oracle-checked closest points) at its start exceeds the arm's motion bound
    over it (conservative advancement). Prints the smallest exact clearance and the pieces
    not proven clear (0: the float32 path is collision-free in float64)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from softplan_jax.geometry._closest import DEFAULT_OPTIONS
    from softplan_jax.geometry._kinematics import motion_bound
    from softplan_jax.geometry._obstacles import radius_and_mask, true_closest

    d = np.load(path)
    q, it, b = d["q"].astype(np.float64), d["iterations"], int(d["batch"])
    suite = load_suite(suites, b, "float64")

    @jax.jit
    def pieces(qs, scn):
        tau = jnp.linspace(0.0, 1.0, substeps + 1)[:-1]
        qa = (qs[:-1, None] + tau[:, None, None] * (qs[1:] - qs[:-1])[:, None]).reshape(-1, *qs.shape[1:])
        qb = jnp.concatenate([qa[1:], qs[-1:]])
        radius, mask = radius_and_mask(scn)

        def clearance(q):
            cp = true_closest(q, scn, DEFAULT_OPTIONS)
            return jnp.min(jnp.where(mask, cp.distance - scn.arm_radius - radius, jnp.inf))

        c = jax.vmap(clearance)(qa)
        bound = jax.vmap(lambda x, y: motion_bound(x, y)[-1])(qa, qb)
        return c, c - bound

    worst, margin_worst, unproven = np.inf, np.inf, 0
    for i in range(q.shape[0]):
        scn = jax.tree_util.tree_map(lambda x, i=i: x[i], suite)
        c, margin = (np.asarray(x) for x in pieces(jnp.asarray(q[i]), scn))
        n = int(it[i]) * substeps  # the pieces up to the scene's last step
        worst, margin_worst = min(worst, float(c[: n + 1].min())), min(margin_worst, float(margin[:n].min()))
        unproven += int(np.sum(margin[:n] <= 0))
    res = dict(scenes=int(q.shape[0]), substeps=substeps, min_exact_clearance_float64=worst,
               min_advancement_margin=margin_worst, pieces_not_proven_clear=unproven)
    print(json.dumps(res))
    with open(path[: -len(".npz")] + "_audit.json" if path.endswith(".npz") else path + "_audit.json", "w") as f:
        json.dump(res, f, indent=1)
    return res


def part_cmdbuf(args, rep):
    env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + " " + CMDBUF_FLAGS).strip())
    child_out = os.path.join("/tmp", f"softplan_cmdbuf_{os.getpid()}")
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--out", child_out,
           "--sizes", str(args.size_list[0]), "--steps", str(args.steps), "--rounds", str(args.rounds),
           "--parts", "plan"] + (["--quick"] if args.quick else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    res = dict(flags=CMDBUF_FLAGS, exit=p.returncode, wall_s=time.perf_counter() - t0,
               stderr_tail=p.stderr[-2000:])
    path = child_out + ".json"
    if os.path.exists(path):
        with open(path) as f:
            res["results"] = json.load(f)["parts"]
    rep.put("cmdbuf", res)


def markdown(data) -> str:
    p = data["parts"]
    lines = ["# One accelerator: single plan, batch throughput, profile", "",
             f"- {json.dumps(p.get('env', {}))}", ""]
    if "plan" in p:
        lines += ["| plan(tree) | iterations | first call | warm min | warm median |", "|---|---|---|---|---|"]
        for k, v in p["plan"].items():
            lines.append(f"| {k} | {v['iterations']} | {v['first_call_s']:.2f} s | {v['min_s'] * 1e3:.2f} ms "
                         f"| {v['median_s'] * 1e3:.2f} ms |")
        lines.append("")
    if "batch" in p:
        lines += ["| batch | compile | median | taken steps | taken steps/s (median, best) | scenes/s |",
                  "|---|---|---|---|---|---|"]
        for k, v in p["batch"].items():
            if "median_s" in v:
                lines.append(f"| {k} | {v['compile_s']:.1f} s | {v['median_s']:.3f} s | {v['steps_taken']:,} "
                             f"| {v['steps_per_s_median']:,.0f} ({v['steps_per_s_best']:,.0f}) "
                             f"| {v['scenes_per_s_median']:,.0f} |")
        lines.append("")
    for k, v in p.get("profile", {}).items():
        if "busy_us" in v:
            lines.append(f"- profile {k}: wall {v['wall_s']:.3f} s, {v['steps_taken']:,} steps taken; kernels "
                         f"{v['kernel_launches']:,}, busy {v['busy_us'] / 1e6:.3f} s of span "
                         f"{v['span_us'] / 1e6:.3f} s; copies {v['copies']['count']:,} "
                         f"({v['copies']['us'] / 1e6:.3f} s)")
            for thread, d in v["lines"].items():
                lines.append(f"  - line {thread}: {d['events']:,} events, {d['us'] / 1e6:.3f} s, "
                             f"{d['distinct']} distinct")
                for t in d["top"][:8]:
                    lines.append(f"    - {t['name'][:70]}: {t['count']:,} x, {t['us'] / 1e3:.1f} ms")
    for k, v in p.get("float32", {}).items():
        lines.append(f"- float32 {k}: {json.dumps(v)}")
    if "cmdbuf" in p:
        c = p["cmdbuf"]
        lines.append(f"- command buffers (while, conditional): exit {c['exit']}")
        for part in ("plan", "batch"):
            for k, v in c.get("results", {}).get(part, {}).items():
                if "median_s" in v:
                    lines.append(f"    - {k}: median {v['median_s'] * (1e3 if part == 'plan' else 1):.3f} "
                                 f"{'ms' if part == 'plan' else 's'}")
    for k, v in p.get("defaults", {}).items():
        lines.append(f"- defaults, {k}: {json.dumps(v)}")
    if "tracking" in p:
        t = p["tracking"]
        lines += ["", f"Tracking, {t['B']} moving scenes, {t['steps']} steps (track_batch's program, default lanes):", "",
                  "| suite, evasion | first call | warm median | steps taken | steps/s | evasive steps | statuses |",
                  "|---|---|---|---|---|---|---|"]
        for k, v in t.items():
            if isinstance(v, dict) and "median_s" in v:
                lines.append(f"| {k} | {v['first_call_s']:.1f} s | {v['median_s']:.3f} s | {v['steps_taken']:,} | "
                             f"{v['steps_per_s_median']:,.0f} | {v['evasive_steps']:,} | {json.dumps(v['statuses'])} |")
    for k, v in data.get("errors", {}).items():
        lines.append(f"- part {k} FAILED: {v.strip().splitlines()[-1]}")
    return "\n".join(lines) + "\n"


def main(argv=None):
    args = parse_args(argv)
    if args.audit:
        return audit(args.audit, args.suites)
    if args.write_suites:
        return write_suites(args.write_suites[0], args.write_sizes)
    import jax

    jax.config.update("jax_enable_x64", True)
    from softplan_jax.base._compilation_cache import disable_compilation_cache

    disable_compilation_cache()
    rep = Report(args.out)
    devs = {"default-device": jax.devices()[0]}
    try:
        if args.child:
            raise RuntimeError("the child measures the accelerator alone")
        cpu = jax.devices("cpu")[0]
        if cpu != devs["default-device"]:
            devs["host-cpu"] = cpu
    except RuntimeError:
        pass
    rep.put("env", dict(jax=jax.__version__, backend=jax.default_backend(),
                        device=jax.devices()[0].device_kind, host_cpus=os.cpu_count(),
                        xla_flags=os.environ.get("XLA_FLAGS", ""), steps=args.steps, sizes=args.size_list))
    programs = {}
    for part, fn in (("plan", lambda: part_plan(args, rep, devs)),
                     ("cmdbuf", lambda: part_cmdbuf(args, rep)),
                     ("defaults", lambda: part_defaults(args, rep)),
                     ("tracking", lambda: part_tracking(args, rep)),
                     ("batch", lambda: part_batch(args, rep, programs)),
                     ("profile", lambda: part_profile(args, rep, programs)),
                     ("float32", lambda: part_float32(args, rep, programs))):
        if part not in args.part_list or (part == "cmdbuf" and args.child):
            continue
        if args.deadline and time.perf_counter() - T0 > args.deadline:
            log(f"--- part {part} skipped: past --deadline {args.deadline} s")
            continue
        log(f"--- part {part}")
        try:
            fn()
        except Exception:  # noqa: BLE001 - one part's failure must not lose the others' results
            rep.error(part)
    md = markdown(rep.data)
    with open(args.out + ".md", "w") as f:
        f.write(md)
    print(md)
    if rep.data["errors"]:
        log(f"failed parts: {sorted(rep.data['errors'])} (tracebacks in {args.out}.json)")
        sys.exit(1)


if __name__ == "__main__":
    main(sys.argv[1:])
