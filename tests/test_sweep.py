"""Sweeps at scale (:mod:`softplan_jax.sweeps`, ``softplan sweep``).

References: :func:`softplan_jax.plan_batch` on the same scenes with the same keys
(the sweep's table must hold its per-scene outcomes), a plain loop over the tips
for path lengths, ``jax.random.fold_in`` for the keys, the benchmarks' own Wilson
interval (benchmarks/_stats.py), and an uninterrupted run for a killed and resumed one.

Every planning run shares one compiled program: chunks of 3 scenes padded to 5
curve slots (degree 2), 200 steps, default options, float64 -- the program of
test_cli's ``softplan batch`` run, so a warm persistent cache holds it. The
fallback's programs are test_reach's (the same scene shape and ReachOptions).
"""

from __future__ import annotations

import gc
import json
import os
import shutil
import signal
import subprocess
import sys
import tracemalloc

import jax
import numpy as np
import pytest
from _stats import wilson
from session import REPO, free_port, one_device_env, subprocess_env

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.sweeps import load_trajectory, read_table, sweep, sweep_keys, sweep_scenarios, wilson_interval

SUITE = dict(obstacles=(1, 5), slots=5)
ARGS = dict(chunk=3, max_steps=200, **SUITE)  # one compiled program for every test
SEED, N, KEEP = 1, 12, 4  # seed 1: scene 1 is left at max_steps by the local planner (the fallback's case)
CLI_ARGS = ["--seed", "1", "--chunk", "3", "--max-steps", "200", "--obstacles", "1", "5", "--slots", "5"]


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    """An uninterrupted sweep of 12 scenes in 4 chunks, keeping the first 4 paths."""
    d = tmp_path_factory.mktemp("sweep") / "full"
    return d, sweep(N, d, SEED, trajectories=KEEP, progress=False, **ARGS)


@pytest.fixture(scope="module")
def reference():
    """plan_batch on the same scenes with the same keys, in the same chunks."""
    scenes = sweep_scenarios(SEED, 0, N, **SUITE)
    r = sp.plan_batch(scenes, max_steps=200, seed=sweep_keys(SEED, 0, N), chunk=3)
    return scenes, jax.tree_util.tree_map(np.asarray, r)


def test_table_holds_plan_batch_outcomes(full, reference):
    d, s = full
    _, r = reference
    t = read_table(d)
    np.testing.assert_array_equal(t["index"], np.arange(N))
    np.testing.assert_array_equal(t["chunk"], np.arange(N) // 3)
    assert list(t["status"]) == [sp.planning.status_name(c) for c in r.status]
    for col in ("iterations", "local_iterations"):
        np.testing.assert_array_equal(t[col], r.iterations)
    for col in ("reached", "escapes", "min_clearance", "final_error"):
        np.testing.assert_array_equal(t[col], getattr(r, col), err_msg=col)
    for i in range(N):  # tip path length, a plain loop
        tips = r.tip[i, : r.iterations[i] + 1]
        length = sum(float(np.linalg.norm(tips[k + 1] - tips[k])) for k in range(len(tips) - 1))
        assert t["path_length"][i] == pytest.approx(length, rel=1e-12, abs=1e-15)
    assert list(t["planner"]) == ["local" if x else "none" for x in r.reached]
    assert set(t["reason"]) == {""}
    # The summary from the table.
    assert sum(s["status_counts"].values()) == N and s["reached"] == s["reached_local"] == int(r.reached.sum())
    assert s["reached_global"] == 0 and s["steps_taken"] == int(r.iterations.sum())
    assert s["success_rate"] == pytest.approx(r.reached.mean())
    assert s["success_ci95"] == pytest.approx(list(wilson(int(r.reached.sum()), N)))
    assert s["min_clearance"] == pytest.approx(float(r.min_clearance.min()))
    assert s["chunks"] == 4 and s["resumed_chunks"] == 0 and s["sessions"] == 1
    assert s["compile_s"] > 0 and s["run_s"] > 0 and s["scenes_per_s"] == pytest.approx(N / s["run_s"])
    with open(d / "chunks.csv", encoding="utf-8") as fh:
        assert len(fh.read().splitlines()) == 1 + 4
    header = json.loads((d / "sweep.json").read_text())
    assert header["seed"] == SEED and header["n"] == N and header["chunk"] == 3 and header["dtype"] == "float64"
    assert set(header["versions"]) >= {"softplan_jax", "jax", "numpy"} and header["gains"]["preset"] == "default"


def test_scenes_and_keys_do_not_depend_on_n(reference):
    scenes, _ = reference
    first = sweep_scenarios(SEED, 0, 5, **SUITE)
    across = sweep_scenarios(SEED, 62, 66, **SUITE)  # blocks 0 and 1 (64 scenes each)
    second = sweep_scenarios(SEED, 64, 65, **SUITE)
    for a, b, c, d in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(scenes),
                          jax.tree_util.tree_leaves(across), jax.tree_util.tree_leaves(second), strict=True):
        np.testing.assert_array_equal(a, b[:5])
        np.testing.assert_array_equal(c[2:3], d)
    assert not np.array_equal(across.goal[1], across.goal[2])
    keys = sweep_keys(SEED, 0, N)
    np.testing.assert_array_equal(sweep_keys(SEED, 3, 5), keys[3:5])
    np.testing.assert_array_equal(keys[7], np.asarray(jax.random.fold_in(jax.random.PRNGKey(SEED), 7)))


_CHILD = """
import sys, jax
jax.config.update("jax_enable_x64", True)
from softplan_jax.sweeps import sweep

def progress(info):
    if info["chunks_done"] == 2:
        print("two chunks written", flush=True)
        sys.stdin.readline()  # the parent kills this process here, chunk 2 on its way

sweep(12, sys.argv[1], 1, chunk=3, max_steps=200, obstacles=(1, 5), slots=5, trajectories=4, progress=progress)
print("finished", flush=True)
"""


def test_killed_sweep_resumes_to_the_same_table(full, tmp_path):
    d = tmp_path / "killed"
    p = subprocess.Popen([sys.executable, "-c", _CHILD, str(d)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=subprocess_env(), cwd=REPO)
    try:
        line = p.stdout.readline()
        assert line.strip() == "two chunks written", p.stderr.read()[-3000:]
        os.kill(p.pid, signal.SIGKILL)
    finally:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=60)
        p.stdout.close()
        p.stderr.close()
        p.stdin.close()
    assert p.returncode == -signal.SIGKILL
    assert sorted(os.listdir(d / "chunks")) == ["000000.csv", "000000.json", "000001.csv", "000001.json"]
    assert not (d / "scenes.csv").exists() and not (d / "summary.json").exists()
    # A kill in the middle of chunk 2's commit: its timing written, a half-written table and shard.
    (d / "chunks" / "000002.json").write_text('{"chunk": 2}')
    (d / "chunks" / ".000002.csv.tmp.99999").write_text("index,chunk\n6,")
    (d / "trajectories" / ".000002.npz.tmp.99999").write_bytes(b"PK")
    s = sweep(N, d, SEED, trajectories=KEEP, progress=False, **ARGS)
    assert s["resumed_chunks"] == 2 and s["sessions"] == 2
    assert (d / "scenes.csv").read_bytes() == (full[0] / "scenes.csv").read_bytes()
    for name in ("000000.npz", "000001.npz"):
        with np.load(d / "trajectories" / name) as a, np.load(full[0] / "trajectories" / name) as b:
            assert sorted(a.files) == sorted(b.files)
            for k in a.files:
                np.testing.assert_array_equal(a[k], b[k])
    leftovers = [f for sub in ("chunks", "trajectories") for f in os.listdir(d / sub) if ".tmp." in f]
    assert leftovers == []
    assert {k: v for k, v in s.items() if k not in _TIMES} == {k: v for k, v in full[1].items() if k not in _TIMES}


_TIMES = {"out", "resumed_chunks", "sessions", "generation_s", "compile_s", "run_s", "fallback_s", "scenes_per_s",
          "steps_per_s"}


@pytest.mark.parametrize("change, field", [
    (dict(max_steps=100), "max_steps"), (dict(seed=2), "seed"), (dict(chunk=4), "chunk"), (dict(n=13), "n"),
    (dict(fallback=True), "fallback"), (dict(trajectories=None), "trajectories"), (dict(slots=6), "slots"),
    (dict(gains="paper"), "gains"), (dict(goal_tolerance=0.02), "options"),
])
def test_other_arguments_into_a_sweep_folder_are_refused(full, change, field):
    d, _ = full
    before = (d / "scenes.csv").read_bytes(), (d / "sweep.json").read_bytes()
    kw = dict(n=N, out=d, seed=SEED, trajectories=KEEP, progress=False, **ARGS) | change
    with pytest.raises(ValueError, match=rf"other arguments: .*\b{field} \("):
        sweep(**kw)
    assert ((d / "scenes.csv").read_bytes(), (d / "sweep.json").read_bytes()) == before


@pytest.mark.parametrize("kw, match", [
    (dict(n=0), "n must be an int >= 1"), (dict(n=2.5), "n must be"), (dict(chunk=0), "chunk must"),
    (dict(seed=-1), "seed must"), (dict(max_steps=0), "max_steps must"), (dict(trajectories="some"), "trajectories"),
    (dict(trajectories=0), "trajectories must"), (dict(obstacles=(3, 1)), "obstacles"),
    (dict(obstacles=(1, 6)), "obstacles"),
    (dict(gains="nope"), "gains: unknown preset"), (dict(dtype=np.int32), "dtype"), (dict(progress="yes"), "progress"),
    (dict(method="lines"), "method"), (dict(fallback="yes"), "fallback"), (dict(devices="global"), "devices"),
    (dict(devices=64), "devices"), (dict(stall_windw=3), "unknown planner option"), (dict(out=None), "out"),
])
def test_bad_arguments_write_nothing(tmp_path, kw, match):
    out = tmp_path / "new"
    with pytest.raises(ValueError, match=match):
        sweep(**(dict(n=3, out=out, progress=False, **ARGS) | kw))
    assert not out.exists()


def test_folders_that_are_not_a_new_or_same_sweep(full, tmp_path):
    d, _ = full
    with pytest.raises(ValueError, match="holds a sweep; pass resume=True"):
        sweep(N, d, SEED, trajectories=KEEP, progress=False, resume=False, **ARGS)
    a_file = tmp_path / "file.txt"
    a_file.write_text("keep me")
    with pytest.raises(ValueError, match="out: .* is not a folder"):
        sweep(3, a_file, progress=False, **ARGS)
    with pytest.raises(ValueError, match="out: cannot create"):
        sweep(3, a_file / "sub", progress=False, **ARGS)
    with pytest.raises(ValueError, match="no sweep.json"):
        sweep(3, tmp_path, progress=False, **ARGS)
    assert a_file.read_text() == "keep me"


def test_trajectories_only_when_asked(full, reference):
    d, _ = full
    scenes, r = reference
    t = read_table(d)
    assert sorted(os.listdir(d / "trajectories")) == ["000000.npz", "000001.npz"]  # scenes 0-2, 3
    for i in range(KEEP):
        tr = load_trajectory(d, i)
        it = t["iterations"][i]
        np.testing.assert_array_equal(tr["q"], r.q[i, : it + 1])
        np.testing.assert_array_equal(tr["tip"], r.tip[i, : it + 1])
        np.testing.assert_array_equal(tr["q"][0], scenes.q0[i])
        assert np.linalg.norm(tr["tip"][-1] - scenes.goal[i]) == pytest.approx(t["final_error"][i], rel=1e-9)
        assert (tr["status"], tr["planner"]) == (t["status"][i], t["planner"][i])
    with pytest.raises(ValueError, match="was not kept"):
        load_trajectory(d, KEEP)
    with pytest.raises(ValueError, match="index must be"):
        load_trajectory(d, N)


def test_fallback_reports_local_and_global_shares(full, tmp_path):
    d = tmp_path / "fallback"
    s = sweep(3, d, SEED, fallback=True, trajectories="all", progress=False, **ARGS)
    t, local = read_table(d), read_table(full[0])
    left = [i for i in range(3) if local["status"][i] in ("stalled", "max_steps")]
    assert left == [1]  # the case this seed was chosen for
    for i in range(3):
        assert t["local_iterations"][i] == local["iterations"][i]
        if i not in left:  # the same row as the local planner's (scene i is scene i of every sweep of this seed)
            assert all(t[c][i] == local[c][i] for c in t if c != "chunk")
    for i in left:
        assert t["planner"][i] in ("global", "none") and t["planner"][i] == ("global" if t["reached"][i] else "none")
        if t["reached"][i]:
            assert t["status"][i] == "reached" and t["reason"][i] == ""
            tr = load_trajectory(d, i)
            goal = sweep_scenarios(SEED, i, i + 1, **SUITE).goal[0]
            assert np.linalg.norm(tr["tip"][-1] - goal) < 1e-2 and tr["q"].shape[0] == t["iterations"][i] + 1
            length = sum(float(np.linalg.norm(tr["tip"][k + 1] - tr["tip"][k])) for k in range(len(tr["tip"]) - 1))
            assert t["path_length"][i] == pytest.approx(length, rel=1e-9)
        else:
            assert t["status"][i] in ("unreachable", "stalled", "max_steps") and t["reason"][i]
    # The shares add up, each over all scenes, with its Wilson interval.
    k_local, k_global = int(np.sum(t["planner"] == "local")), int(np.sum(t["planner"] == "global"))
    assert (s["reached_local"], s["reached_global"]) == (k_local, k_global)
    assert s["reached"] == k_local + k_global == int(t["reached"].sum()) and sum(s["status_counts"].values()) == 3
    assert k_local == 2
    for name, k in (("success", k_local + k_global), ("local", k_local), ("global", k_global)):
        assert s[f"{name}_rate"] == pytest.approx(k / 3)
        assert s[f"{name}_ci95"] == pytest.approx(list(wilson(k, 3)))
    assert s["fallback"] and s["fallback_s"] > 0


def test_memory_is_flat_in_n(full, tmp_path):
    """Nothing per scene outlives its chunk: after every chunk (the next one on its way), the
    live jax arrays are the same bytes, and Python's allocations (NumPy's included) do not
    grow by a chunk's rollouts."""
    samples = []

    def progress(info):
        gc.collect()  # garbage of earlier tests (freed whenever the collector runs) is not the sweep's
        samples.append((sum(x.nbytes for x in jax.live_arrays()), tracemalloc.get_traced_memory()[0]))

    tracemalloc.start()
    try:
        sweep(18, tmp_path / "18", SEED, progress=progress, **ARGS)  # 6 chunks
    finally:
        tracemalloc.stop()
    live, python = [a for a, _ in samples[:-1]], [b for _, b in samples[:-1]]  # the last: nothing on its way
    assert live == [live[0]] * 5, live
    one_chunk = 3 * 201 * (9 + 3) * 8  # q and tip of a chunk's rollouts, copied to the host
    assert (python[-1] - python[1]) / 3 < one_chunk / 2, python


def test_wilson_interval():
    for k, n in ((0, 1), (0, 12), (3, 12), (12, 12), (517, 1000)):
        assert wilson_interval(k, n) == pytest.approx(wilson(k, n), abs=1e-15)
    assert wilson_interval(0, 12)[0] == 0.0 and wilson_interval(12, 12)[1] == 1.0
    assert all(np.isnan(wilson_interval(0, 0)))


def _main(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_command(full, tmp_path, capsys):
    d, s = full
    code, out, err = _main(capsys, "sweep", "--n", N, "--out", d, *CLI_ARGS, "--trajectories", KEEP, "--json",
                           "--no-progress")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["resumed_chunks"] == 4 and summary["status_counts"] == s["status_counts"]
    assert summary["success_ci95"] == pytest.approx(s["success_ci95"])
    code, out, err = _main(capsys, "sweep", "--n", N, "--out", d, *CLI_ARGS, "--trajectories", KEEP)
    assert code == 0 and "reached [95 % CI]" in out and "scenes/s" in out and "steps taken/s" in out
    assert "resuming" in err
    # Bad input: exit 2, one line naming the field.
    bad = [
        (["--n", 0, "--out", tmp_path / "x"], "--n must be >= 1"),
        (["--n", 3], "--out"),
        (["--n", N, "--out", d, *CLI_ARGS, "--trajectories", KEEP, "--max-steps", 100],
         "max_steps (200 there, 100 here)"),
        (["--n", 3, "--out", tmp_path / "x", "--trajectories", "some"], "--trajectories"),
        (["--n", 3, "--out", tmp_path / "x", "--obstacles", 1, 9], "--obstacles"),
        (["--n", 3, "--out", tmp_path / "x", "--n-points", 5], "--n-points"),
        (["--n", 3, "--out", d / "sweep.json"], "--out"),
    ]
    for argv, msg in bad:
        code, out, err = _main(capsys, "sweep", *argv)
        assert code == 2 and msg in err and err.startswith("softplan: error:"), (argv, err)
        assert len(err.strip().splitlines()) == 1
    # --force: the old sweep's files go, other files stay.
    copy = tmp_path / "copy"
    shutil.copytree(d, copy)
    (copy / "notes.txt").write_text("mine")
    code, out, err = _main(capsys, "sweep", "--n", 3, "--out", copy, *CLI_ARGS, "--force", "--json", "--no-progress")
    assert code == 0, err
    assert sorted(os.listdir(copy / "chunks")) == ["000000.csv", "000000.json"]
    assert not (copy / "trajectories").exists() and (copy / "notes.txt").read_text() == "mine"
    assert read_table(copy)["status"].tolist() == read_table(d)["status"][:3].tolist()


def _processes(tmp_path, out, extra=((), ())):
    """``softplan sweep`` as 2 processes of one CPU device each (jax.distributed on this
    machine); ``extra``: further flags of process 0 and 1. Returns [(rc, stdout, stderr)]."""
    env, port = one_device_env(), free_port()
    common = [sys.executable, "-m", "softplan_jax.cli", "sweep", "--n", str(N), "--out", str(out),
              *CLI_ARGS, "--json"]
    procs = [subprocess.Popen([*common, *extra[i], "--coordinator", f"localhost:{port}", "--num-processes", "2",
                               "--process-id", str(i)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    ours = lambda text: "\n".join(x for x in text.splitlines() if not x.startswith("[Gloo]"))  # noqa: E731
    return [(p.returncode, ours(o), e) for p, (o, e) in zip(procs, outs, strict=True)]


@pytest.mark.slow
def test_two_processes_write_the_one_process_table(full, tmp_path):
    """``softplan sweep --coordinator ... --num-processes 2 --process-id I`` on this machine:
    process i plans chunks c % 2 == i into one folder, process 0 merges and reports, and
    scenes.csv is byte for byte the uninterrupted one-process sweep's. The folder then
    resumes in one process with every chunk done. Not a test on real multi-host hardware."""
    d, s = full
    out = tmp_path / "two"
    (r0, o0, e0), (r1, o1, e1) = _processes(tmp_path, out, extra=(["--no-progress"], []))
    assert r0 == 0 and r1 == 0, (e0[-3000:], e1[-3000:])
    summary = json.loads(o0)
    assert summary["processes"] == 2 and summary["sessions"] == 2 and summary["status_counts"] == s["status_counts"]
    assert o1.strip() == ""  # process 1 prints no summary, only its progress lines
    assert "sweep[1/2]: 2/2 chunks" in e1, e1[-2000:]
    assert (out / "scenes.csv").read_bytes() == (d / "scenes.csv").read_bytes()
    chunks = (out / "chunks.csv").read_text().splitlines()[1:]
    sessions = [row.split(",")[3] for row in chunks]
    assert sessions[0] == sessions[2] != sessions[1] == sessions[3]  # chunks 0, 2 by one process; 1, 3 by the other
    again = sweep(N, out, SEED, progress=False, **ARGS)
    assert again["resumed_chunks"] == 4 and again["processes"] == 1 and again["status_counts"] == s["status_counts"]


@pytest.mark.slow
def test_processes_with_other_arguments_all_exit_2(tmp_path):
    """A process whose arguments differ from process 0's sweep: both processes exit 2,
    the field named, process 1's error reported by process 0 too; nothing is planned."""
    out = tmp_path / "mixed"
    (r0, _, e0), (r1, _, e1) = _processes(tmp_path, out, extra=([], ["--max-steps", "100"]))
    assert (r0, r1) == (2, 2), (e0[-3000:], e1[-3000:])
    assert "process 1 of 2" in e0 and "max_steps (200 there, 100 here)" in e0, e0[-2000:]
    assert "max_steps (200 there, 100 here)" in e1, e1[-2000:]
    assert not (out / "chunks").exists()


def test_batch_command_with_the_fallback(tmp_path, capsys):
    """``softplan batch --fallback``: the scenes the local planner reached keep its arrays
    bit for bit; the one it left at max_steps (scene 4 of seed 0, the case chosen) is taken by
    the fallback, and the summary's local and global shares add up to the npz's rows."""
    argv = ["batch", "--n", 6, "--seed", 0, "--chunk", 3, "--max-steps", 200, "--obstacles", 1, 5, "--slots", 5,
            "--json", "--no-progress"]
    code, out, err = _main(capsys, *argv, "--out", tmp_path / "local.npz")
    assert code == 0, err
    plain = json.loads(out)
    code, out, err = _main(capsys, *argv, "--fallback", "--out", tmp_path / "fallback.npz")
    assert code == 0, err
    s = json.loads(out)
    a, b = np.load(tmp_path / "local.npz"), np.load(tmp_path / "fallback.npz")
    left = np.nonzero(np.isin(a["status"], [sp.Status.STALLED, sp.Status.MAX_STEPS]))[0]
    assert left.tolist() == [4] and plain["reached_global"] == 0 and not plain["fallback"]
    kept = np.setdiff1d(np.arange(6), left)
    for key in ("status", "iterations", "min_clearance", "final_error", "escapes", "reached", "collided", "planner"):
        np.testing.assert_array_equal(a[key][kept], b[key][kept], err_msg=key)
    assert b["planner"].tolist() == [("global" if k in left else "local") if r else "none"
                                     for k, r in enumerate(b["reached"])]
    assert b["status"][4] in (sp.Status.REACHED, sp.Status.UNREACHABLE, sp.Status.MAX_STEPS)
    assert b["iterations"][4] >= a["iterations"][4] and b["escapes"][4] == a["escapes"][4]
    k_local, k_global = int(np.sum(b["planner"] == "local")), int(np.sum(b["planner"] == "global"))
    assert (s["reached_local"], s["reached_global"]) == (k_local, k_global) == (5, int(b["reached"][4]))
    assert s["success_rate"] == pytest.approx((k_local + k_global) / 6) and s["fallback"]
    assert s["success_ci95"] == pytest.approx(list(wilson(k_local + k_global, 6)))
    assert s["fallback_time_s"] > 0 and sum(s["status_counts"].values()) == 6
    # With --coordinator the fallback is refused (softplan sweep runs it per process).
    code, _, err = _main(capsys, *argv, "--fallback", "--coordinator", "localhost:1", "--num-processes", 2,
                         "--process-id", 0)
    assert code == 2 and "--fallback does not combine with --coordinator" in err
