"""Ctrl-C in a real ``softplan run``: exit code 130, one line on stderr, no output file.

SIGINT is sent while the planner is being traced and while XLA compiles it (the
phase where an interrupt used to end in a segmentation fault, after the
"interrupted" line). The compilation caches are off in the child, so that it
really compiles.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from session import subprocess_env


def _interrupted_run(tmp_path, delay: float):
    """``softplan run sim1 --out run.json`` interrupted ``delay`` s after it says it compiles."""
    env = subprocess_env()
    for k in ("JAX_COMPILATION_CACHE_DIR",):
        env.pop(k, None)
    env.update(JAX_ENABLE_COMPILATION_CACHE="false", SOFTPLAN_COMPILATION_CACHE="0")
    out = tmp_path / "run.json"
    p = subprocess.Popen([sys.executable, "-m", "softplan_jax.cli", "run", "sim1", "--out", str(out)], cwd=tmp_path,
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = p.stderr.readline()  # "softplan: compiling the planner ..."
        assert first.startswith("softplan: compiling"), first + p.stderr.read()
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
        assert not out.exists() and os.listdir(d) == []
        interrupted += 1
    assert interrupted >= 3


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
    """main() called in-process (as the tests do) leaves Python's SIGINT handler and wakeup fd as they were."""
    from softplan_jax.cli import main

    def wakeup_fd():
        fd = signal.set_wakeup_fd(-1)
        signal.set_wakeup_fd(fd)
        return fd

    before = signal.getsignal(signal.SIGINT), wakeup_fd()
    assert main(["scenarios", "--json"]) == 0
    assert (signal.getsignal(signal.SIGINT), wakeup_fd()) == before
