"""Helpers shared by the benchmark scripts: machine header, formatting, a text
progress bar, timing of compiled calls, writing results, importing another
version of the package side by side with this one, and running a measurement in
a fresh process on a given checkout.

Import this AFTER choosing jax's precision (``jax_enable_x64``) in the script:
it imports jax but does not change its configuration.
"""

from __future__ import annotations

import importlib.util
import json
import os
import platform
import statistics
import sys
import time

import jax
import numpy as np

from softplan_jax.base._compilation_cache import disable_compilation_cache

# Compile times are measured here: never from the cache that importing softplan_jax turns on by
# default (a cache directory the user or the test session gave jax is kept). Only in a benchmark's
# own process: a test that imports a script to check its arguments keeps its worker's cache.
if os.path.dirname(os.path.abspath(sys.argv[0])) == os.path.dirname(os.path.abspath(__file__)):
    disable_compilation_cache()

RESULTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
FIGURES_DIR = os.path.join(RESULTS_DIR, "figures")
QUICK_DIR = os.path.join(RESULTS_DIR, "quick")  # quick runs (git-ignored): never over the committed results


def output_paths(name: str, quick: bool, out: str | None = None) -> tuple[str, str]:
    """``(prefix, figure folder)`` of a script's results: ``results/NAME`` and
    ``results/figures/``; in quick mode ``results/quick/NAME`` and
    ``results/quick/figures/``; with ``--out PREFIX``, PREFIX and a ``figures/``
    folder beside it."""
    if out:
        return out, os.path.join(os.path.dirname(os.path.abspath(out)), "figures")
    if quick:
        return os.path.join(QUICK_DIR, name), os.path.join(QUICK_DIR, "figures")
    return os.path.join(RESULTS_DIR, name), FIGURES_DIR


def load_variant(name: str, path: str):
    """The package directory ``path`` (e.g. another checkout's ``softplan_jax``) imported
    as module ``softplan_kernel_<name>``, beside the installed package."""
    mod_name = f"softplan_kernel_{name}"
    spec = importlib.util.spec_from_file_location(
        mod_name, os.path.join(path, "__init__.py"), submodule_search_locations=[path]
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    spec.loader.exec_module(mod)
    return mod


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def host_devices_env(k: int) -> dict:
    """The environment of a worker subprocess with k host devices: this process's,
    with ``XLA_FLAGS=--xla_force_host_platform_device_count=k`` (replacing any such
    flag) and the repository first on ``PYTHONPATH``."""
    env = dict(os.environ)
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    env["XLA_FLAGS"] = " ".join(flags + [f"--xla_force_host_platform_device_count={k}"])
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join([repo] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def machine_info(dtype: str) -> dict:
    """Platform, CPU, CPU count, versions, jax backend and devices, dtype, load average."""
    import softplan_jax as sp

    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return dict(
        platform=platform.platform(),
        cpu=cpu,
        cpu_count=os.cpu_count(),
        python=platform.python_version(),
        numpy=np.__version__,
        jax=jax.__version__,
        jax_backend=jax.default_backend(),
        devices=[str(d) for d in jax.devices()],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
        softplan_jax=sp.__version__,
        dtype=dtype,
        loadavg_start=_loadavg(),
    )


def _loadavg():
    return [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None


def finish_machine(machine: dict) -> dict:
    machine["loadavg_end"] = _loadavg()
    return machine


def machine_lines(m: dict) -> list[str]:
    """Markdown bullet lines of the machine header."""
    return [
        f"- machine: {m['platform']}, {m['cpu']}, {m['cpu_count']} CPUs; load average (1, 5, 15 min) "
        f"{m['loadavg_start']} at start, {m.get('loadavg_end')} at end (the machine is shared)",
        f"- python {m['python']}, numpy {m['numpy']}, jax {m['jax']} ({m['jax_backend']}, "
        f"{len(m['devices'])} device(s)), softplan_jax {m['softplan_jax']}; dtype **{m['dtype']}**",
    ]


def fmt_s(x) -> str:
    """Seconds, human-readable (s / ms / µs)."""
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    if x >= 1.0:
        return f"{x:.2f} s"
    if x >= 1e-3:
        return f"{x * 1e3:.3g} ms"
    return f"{x * 1e6:.3g} µs"


def timed(fn, *args):
    """(result, seconds) of fn(*args), blocking on the result."""
    t0 = time.perf_counter()
    out = fn(*args)
    jax.block_until_ready(out)
    return out, time.perf_counter() - t0


def median_time(fn, *args, repeats: int = 3):
    """(last result, median seconds, all seconds) over ``repeats`` blocked calls."""
    times, out = [], None
    for _ in range(max(1, int(repeats))):
        out, dt = timed(fn, *args)
        times.append(dt)
    return out, statistics.median(times), times


def rollout_wrappers(rollout):
    """``(single, batched)``: a rollout of one scenario and the same rollout vmapped over a
    batch of scenarios, both with signature ``(scenario(s), gains, options, max_steps)``
    (``options`` and ``max_steps`` static when jitted). ``rollout``: the planner's
    ``rollout`` (or another package version's)."""

    def single(sc, g, options, max_steps):
        return rollout(sc, g, options, max_steps)

    def batched(scs, g, options, max_steps):
        return jax.vmap(lambda sc: rollout(sc, g, options, max_steps))(scs)

    return single, batched


def lanes_program(opts, max_steps: int, lanes: int, trips: int):
    """``compile_(*args, **kw) -> (compiled, seconds)``: :func:`softplan_jax.planning._engine.run_lanes`
    jitted (the curve rollout's XLA options) and compiled with the warm start's fallback trip
    bound set to ``trips`` on every platform (``FALLBACK_TRIPS`` and ``CPU_FALLBACK_TRIPS``; a
    huge value: a chunk of 8 at every width). The bound is read at trace time, so it is set
    around ``lower`` and restored after."""
    import functools

    from softplan_jax.geometry import _warm_start as ws
    from softplan_jax.planning._engine import run_lanes
    from softplan_jax.planning._options import rollout_compiler_options

    fn = jax.jit(functools.partial(run_lanes, options=opts, max_steps=max_steps, lanes=lanes),
                 compiler_options=rollout_compiler_options("curve"))

    def compile_(*a, **kw):
        saved = ws.FALLBACK_TRIPS, ws.CPU_FALLBACK_TRIPS
        ws.FALLBACK_TRIPS = ws.CPU_FALLBACK_TRIPS = trips
        try:
            t0 = time.perf_counter()
            c = fn.lower(*a, **kw).compile()
            return c, time.perf_counter() - t0
        finally:
            ws.FALLBACK_TRIPS, ws.CPU_FALLBACK_TRIPS = saved

    return compile_


def compile_timed(jitted, *args):
    """(compiled executable, lower + compile seconds) of a jitted function."""
    t0 = time.perf_counter()
    compiled = jitted.lower(*args).compile()
    return compiled, time.perf_counter() - t0


class ProgressBar:
    """A one-line text progress bar on stderr (``[#####-----] 3/10 label 12.3 s``)."""

    def __init__(self, total: int, label: str = "", width: int = 30, stream=None):
        self.total, self.label, self.width = max(1, int(total)), label, width
        self.stream = stream or sys.stderr
        self.t0 = time.perf_counter()
        self.done = 0
        self._draw()

    def update(self, k: int = 1, note: str = "") -> None:
        self.done = min(self.total, self.done + k)
        self._draw(note)

    def _draw(self, note: str = "") -> None:
        fill = int(round(self.width * self.done / self.total))
        bar = "#" * fill + "-" * (self.width - fill)
        elapsed = time.perf_counter() - self.t0
        eta = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        eta_s = f", eta {eta:.0f} s" if self.done and self.done < self.total else ""
        self.stream.write(
            f"\r{self.label} [{bar}] {self.done}/{self.total} chunks, {elapsed:.1f} s{eta_s} {note}".rstrip()
            + " " * 4
        )
        if self.done >= self.total:
            self.stream.write("\n")
        self.stream.flush()


def run_fresh(code: str, argv: list, path: str, timeout: float = 3600, env: dict | None = None) -> dict:
    """Run ``code`` (a Python program that prints one JSON object on its last line) in a fresh
    process with the package of checkout ``path`` first on its path and the persistent
    compilation cache off (``env``: more environment variables); returns that object. A
    RuntimeError with the end of its stderr if it fails."""
    import subprocess

    env = dict(os.environ, **(env or {}), SOFTPLAN_JAX_NO_CACHE="1", PYTHONPATH=path)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    proc = subprocess.run([sys.executable, "-c", code, *map(str, argv)], env=env, cwd=path, capture_output=True,
                          text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"the worker failed for {path}:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def write_results(prefix: str, report: dict, markdown: str) -> None:
    """Write ``prefix.json`` and ``prefix.md``."""
    os.makedirs(os.path.dirname(os.path.abspath(prefix)), exist_ok=True)
    with open(prefix + ".json", "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1, default=_json_default)
    with open(prefix + ".md", "w", encoding="utf-8") as fh:
        fh.write(markdown)


def _json_default(x):
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, np.ndarray) or hasattr(x, "__array__"):  # NumPy and jax arrays
        return np.asarray(x).tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def json_float(x):
    """A float for JSON (inf/nan as None)."""
    x = float(x)
    return x if np.isfinite(x) else None


def bar_figure(values: dict, path: str, xlabel: str, title: str) -> None:
    """A horizontal bar chart on a log axis: ``values`` {case: {version: seconds}}, one bar per
    version and case, written to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(values)
    versions = list(dict.fromkeys(v for n in names for v in values[n]))
    fig, ax = plt.subplots(figsize=(8, 0.6 * len(names) + 1.5))
    y = np.arange(len(names))
    for i, v in enumerate(versions):
        ax.barh(y + 0.4 * i, [values[n].get(v, np.nan) for n in names], height=0.38, label=v)
    ax.set_yticks(y + 0.2 * (len(versions) - 1), names, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.legend()
    ax.set_title(title)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def held_out_parser(doc: str, train_steps: str, max_steps: str):
    """The argument parser of a train-then-hold-out comparison (science.py, tuning.py and its
    ``--tuners`` part), with their common flags: --quick, the training and held-out seeds and
    sizes, and the rollout steps of each (``train_steps``, ``max_steps``: their help texts)."""
    import argparse

    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (small sizes) into results/quick/")
    ap.add_argument("--train-seed", type=int, default=0)
    ap.add_argument("--eval-seed", type=int, default=1)
    ap.add_argument("--n-train", type=int, default=None, help="training scenes (default 64; quick 8)")
    ap.add_argument("--n-eval", type=int, default=None, help="held-out scenes (default 1024; quick 16)")
    ap.add_argument("--train-steps", type=int, default=None, help=train_steps)
    ap.add_argument("--max-steps", type=int, default=None, help=max_steps)
    return ap
