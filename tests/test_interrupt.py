"""Ctrl-C in a real ``softplan run``: exit code 130, one line on stderr, no output file.

SIGINT is sent while the planner is being traced and while XLA compiles it (the
phase where an interrupt used to end in a segmentation fault, after the
"interrupted" line). The compilation caches are off in the child, so that it
really compiles.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from session import subprocess_env


def _interrupted_run(tmp_path, delay: float, after_output: bool = False):
    """``softplan run sim1 --out run.json`` interrupted ``delay`` s after it says it compiles
    (``after_output``: ``delay`` s after run.json appeared, the work done)."""
    env = subprocess_env()
    for k in ("JAX_COMPILATION_CACHE_DIR",):
        env.pop(k, None)
    env.update(JAX_ENABLE_COMPILATION_CACHE="false", SOFTPLAN_COMPILATION_CACHE="0")
    out = tmp_path / "run.json"
    p = subprocess.Popen([sys.executable, "-m", "softplan_jax.cli", "run", "sim1", "--out", str(out)], cwd=tmp_path,
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = p.stderr.readline()  # "softplan: preparing the planner ..."
        assert first.startswith("softplan: preparing the planner"), first + p.stderr.read()
        while after_output and not out.exists() and p.poll() is None:
            time.sleep(0.001)
        time.sleep(delay)
        t0 = time.perf_counter()
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
        elapsed = time.perf_counter() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.returncode, stdout, stderr, elapsed, out


@pytest.mark.parametrize("delay", [0.2, 2.5])  # tracing the rollout; XLA compiling it
def test_ctrl_c_exits_130_with_one_line_and_no_output(tmp_path, delay):
    rc, stdout, stderr, elapsed, out = _interrupted_run(tmp_path, delay)
    assert rc == 130, (rc, stderr)
    assert stderr.splitlines() == ["softplan: interrupted"], stderr
    assert stdout == ""
    assert not out.exists() and sorted(os.listdir(tmp_path)) == []  # no output, no temporary file
    assert elapsed < 10.0  # ends at once, not after the compilation


def test_ctrl_c_in_a_sweep_says_the_same_command_resumes(tmp_path):
    """``softplan sweep`` interrupted once its folder holds the sweep's header (planning under
    way): exit 130, "interrupted", then the line that says the same command resumes."""
    out = tmp_path / "sweep1"
    p = subprocess.Popen([sys.executable, "-m", "softplan_jax.cli", "sweep", "--n", "6", "--chunk", "3", "--out",
                          str(out)], cwd=tmp_path, env=subprocess_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.perf_counter()
        while not (out / "sweep.json").exists() and p.poll() is None and time.perf_counter() - t0 < 120:
            time.sleep(0.01)
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, stderr
    assert stderr.splitlines()[-2:] == [
        "softplan: interrupted",
        f"softplan: the same command again resumes the sweep in {out} after its last complete chunk"], stderr


@pytest.mark.slow
def test_ctrl_c_is_clean_every_time(tmp_path):
    """Several tries at spread delays: never a crash (a segfault is rc -11). An interrupted
    run exits 130 and leaves nothing; a run that finished before the signal came (a fast
    machine compiles and plans sim1 in under 5 s) exits 0 with its whole output. At least
    three of the five tries must be interrupted ones (those of up to 1.5 s leave no time to finish)."""
    interrupted = 0
    for k, delay in enumerate((0.0, 0.7, 1.5, 3.0, 5.0)):
        d = tmp_path / str(k)
        d.mkdir()
        rc, _, stderr, _, out = _interrupted_run(d, delay)
        if rc == 0:  # done before the signal: a complete run
            assert out.exists() and os.listdir(d) == ["run.json"] and "interrupted" not in stderr, (delay, stderr)
            continue
        assert rc == 130 and stderr.splitlines() == ["softplan: interrupted"], (delay, rc, stderr)
        _assert_nothing_partial(d, out)
        interrupted += 1
    assert interrupted >= 3


def _assert_nothing_partial(d, out):
    """After an interrupt: no temporary file, and run.json either absent or whole (a signal
    between its renaming into place and the command's end leaves the complete file)."""
    assert os.listdir(d) in ([], ["run.json"]), os.listdir(d)
    if out.exists():
        assert json.loads(out.read_text())["status"] == "reached"


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.0, 0.1])
def test_ctrl_c_while_the_process_exits_is_ignored(tmp_path, delay):
    """SIGINT once the output is written, while jax's exit handlers run and the interpreter
    finalizes: the run ends as it would have (0, its output, nothing more on stderr), not
    killed by the signal (-2) nor with a KeyboardInterrupt traceback from jax's exit handler,
    as it did before the console entry point left SIGINT ignored. (A signal in the short
    window before the command returns is an ordinary interrupt: 130 and the one line.)"""
    rc, _, stderr, _, out = _interrupted_run(tmp_path, delay, after_output=True)
    if rc == 130:
        assert stderr.splitlines() == ["softplan: interrupted"], stderr
        _assert_nothing_partial(tmp_path, out)
    else:
        assert (rc, stderr) == (0, ""), (rc, stderr)
        assert os.listdir(tmp_path) == ["run.json"] and json.loads(out.read_text())["status"] == "reached"


def test_atomic_output_leaves_nothing_on_error(tmp_path):
    from softplan_jax.cli.interrupt import atomic_output

    target = tmp_path / "x.json"
    with pytest.raises(RuntimeError):
        with atomic_output(str(target)) as tmp:
            with open(tmp, "w") as fh:
                fh.write("partial")
            raise RuntimeError("boom")
    assert os.listdir(tmp_path) == []
    with atomic_output(str(target)) as tmp:
        with open(tmp, "w") as fh:
            fh.write("whole")
    assert target.read_text() == "whole" and os.listdir(tmp_path) == ["x.json"]


def test_in_process_main_restores_the_handlers():
    """main() called in-process (as the tests do) leaves Python's SIGINT handler and wakeup fd
    as they were; console_main() (the process's entry point) leaves SIGINT ignored."""
    from softplan_jax.cli import main

    def wakeup_fd():
        fd = signal.set_wakeup_fd(-1)
        signal.set_wakeup_fd(fd)
        return fd

    before = signal.getsignal(signal.SIGINT), wakeup_fd()
    assert main(["scenarios", "--json"]) == 0
    assert (signal.getsignal(signal.SIGINT), wakeup_fd()) == before
    from softplan_jax.cli import console_main

    old_argv = sys.argv
    sys.argv = ["softplan", "scenarios", "--json"]
    try:
        assert console_main() == 0
        assert (signal.getsignal(signal.SIGINT), wakeup_fd()) == (signal.SIG_IGN, before[1])
    finally:
        sys.argv = old_argv
        signal.signal(signal.SIGINT, before[0])
