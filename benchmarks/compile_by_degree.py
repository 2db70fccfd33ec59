"""Compile time by curve degree: one ``plan`` on a scene with one polynomial curve.

For each degree (default 2, 4, 8, 12, 16, 30) a scene with one polynomial
obstacle of that degree (the default arm and start; the curve passes beside
the arm's path, u in [-1, 1], its higher coefficients small and seeded) is
planned with :func:`softplan_jax.plan` (curve method, default gains):

* **compile**: the first ``plan`` call less the median run time (tracing,
  lowering and XLA compilation of the rollout; every small helper program was
  compiled before by a warm-up ``plan`` on a degree-1 scene of the same
  max_steps);
* **run**: the median of ``--repeats`` further ``plan`` calls (blocked);
* **program size**: the lines of the lowered StableHLO of the rollout
  (``rollout_jit.lower(...).as_text()``), which should not grow with the degree.

jax's persistent compilation cache is switched off in this process, so every
compile time is a real compilation. Progress goes to stderr; the report is
printed and written as ``results/compile_by_degree.{md,json}``::

    python benchmarks/compile_by_degree.py            # degrees 2..30, 300 steps, 3 repeats
    python benchmarks/compile_by_degree.py --quick    # degrees 2 and 12, 40 steps, into results/quick/
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

FULL_DEGREES = (2, 4, 8, 12, 16, 30)
QUICK_DEGREES = (2, 12)


def parse_args(argv=None):
    """The command line, checked (ValueError naming the option)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="degrees 2 and 12, 40 steps, 1 repeat, into results/quick/")
    ap.add_argument("--degrees", default=None, help="comma list of degrees >= 1 (default 2,4,8,12,16,30)")
    ap.add_argument("--max-steps", type=int, default=None, help="plan's max_steps (default 300; quick 40)")
    ap.add_argument("--repeats", type=int, default=None, help="timed plan calls per degree (default 3; quick 1)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the curves' higher coefficients")
    ap.add_argument("--out", default=None, help="output prefix (default results/compile_by_degree)")
    args = ap.parse_args(argv)
    text = args.degrees or ",".join(str(d) for d in (QUICK_DEGREES if args.quick else FULL_DEGREES))
    try:
        args.degrees = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--degrees must be a comma list of integers, got {text!r}") from None
    if not args.degrees or min(args.degrees) < 1:
        raise ValueError(f"--degrees must be integers >= 1, got {text!r}")
    args.max_steps = args.max_steps or (40 if args.quick else 300)
    args.repeats = args.repeats or (1 if args.quick else 3)
    for name in ("max_steps", "repeats"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    return args


def curve_coeffs(degree: int, seed: int):
    """(3, degree + 1): a line beside the arm's path (x = 0.6, y = u, z = 0.8) bent by small,
    seeded higher terms (coefficient k scaled by 0.3 / k^2)."""
    import numpy as np

    rng = np.random.default_rng([seed, degree])
    c = np.zeros((3, degree + 1))
    c[:, 0] = [0.6, 0.0, 0.8]
    c[1, 1] = 1.0
    if degree >= 2:
        c[:, 2:] = rng.normal(size=(3, degree - 1)) * 0.3 / np.arange(2, degree + 1) ** 2
    return c


def main(argv=None):
    args = parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_enable_compilation_cache", False)  # real compilations only
    import jax.numpy as jnp
    from _common import finish_machine, fmt_s, log, machine_info, machine_lines, output_paths, write_results

    import softplan_jax as sp
    from softplan_jax.planning.programs import rollout_jit

    prefix, _ = output_paths("compile_by_degree", args.quick, args.out)
    machine = machine_info("float64")
    t_start = time.perf_counter()
    goal = jnp.array([0.3, 0.5, 1.2])

    def scene(degree):
        return sp.make_scenario(goal, [sp.PolynomialCurve(curve_coeffs(degree, args.seed), (-1.0, 1.0), 0.02)])

    def timed_plan(sc):
        t0 = time.perf_counter()
        r = sp.plan(sc, max_steps=args.max_steps)
        return r, time.perf_counter() - t0

    log(f"compile_by_degree: warm-up plan (degree 1, {args.max_steps} steps) ...")
    timed_plan(scene(1))
    rows = []
    for degree in args.degrees:
        sc = scene(degree)
        r, first = timed_plan(sc)
        runs = [timed_plan(sc)[1] for _ in range(args.repeats)]
        run = statistics.median(runs)
        lowered = rollout_jit.lower(sc, sp.default_gains(jnp.float64), sp.make_options(), args.max_steps)
        hlo_lines = lowered.as_text().count("\n")
        row = dict(degree=degree, compile_s=max(first - run, 0.0), first_call_s=first, run_s=run, runs_s=runs,
                   stablehlo_lines=hlo_lines, status=r.status, iterations=r.iterations,
                   min_clearance=r.min_clearance, final_error=r.final_error)
        rows.append(row)
        log(f"compile_by_degree: degree {degree}: compile {row['compile_s']:.2f} s, run {fmt_s(run)}, "
            f"StableHLO {hlo_lines} lines, {r.status} after {r.iterations} iterations")
    finish_machine(machine)
    args_used = sys.argv[1:] if argv is None else list(argv)
    cmd = "python benchmarks/compile_by_degree.py" + (" " + " ".join(args_used) if args_used else "")
    report = dict(machine=machine, command=cmd, max_steps=args.max_steps, repeats=args.repeats, seed=args.seed,
                  rows=rows)
    lines = [
        "# Compile time by curve degree",
        "",
        f"- generated by `{cmd}` in {time.perf_counter() - t_start:.0f} s",
        *machine_lines(machine),
        f"- one `sp.plan(scene, max_steps={args.max_steps})` per degree, curve method, default gains; compile = "
        f"first call - median run ({args.repeats} run(s)); jax's persistent cache off",
        "",
        "| degree | compile | run | StableHLO lines | status | iterations |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(f"| {row['degree']} | {row['compile_s']:.2f} s | {fmt_s(row['run_s'])} | "
                     f"{row['stablehlo_lines']:,} | {row['status']} | {row['iterations']} |")
    md = "\n".join(lines) + "\n"
    write_results(prefix, report, md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
