"""Batches: the LAPACK-free small solve, plan_batch in chunks with progress,
and plan_batch sharded over 2 host devices.

* :func:`softplan_jax.base._numerics.solve_small` (the planner's and the swept
  check's 3x3 solves): backward stable against NumPy's LAPACK solve over
  condition numbers up to 1e12, pivots, differentiable; no LAPACK custom call
  left in a lowered rollout or collision check. (jaxlib's batched LAPACK
  kernels split a large batch over XLA's intra-op thread pool and wait for it:
  a batch sharded over as many CPU devices as the pool has threads deadlocked.)
* ``plan_batch(chunk=...)``: the same statuses, iterations and trajectories (to
  rounding: a vmapped program's rounding depends on its batch size) as one
  call; equal chunk shapes compile once; ``progress=True`` writes to stderr.
* 2 host devices (``XLA_FLAGS=--xla_force_host_platform_device_count=2``, in a
  subprocess: the device count is fixed when jax starts): the sharded
  plan_batch, collision checks included, finishes and gives the statuses and
  iterations of the 1-device run, trajectories to rounding (see
  :func:`test_two_host_devices_match_one`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from session import free_port, one_device_env, subprocess_env

import softplan_jax as sp
from softplan_jax.base._numerics import evaluate_where, solve_small, tie
from softplan_jax.planning import apply_collision_checks
from softplan_jax.planning._planner import make_options
from softplan_jax.planning._programs import rollout_jit

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAD = dict(curve_slots=5, degree=2)


# ----------------------------------------------------------------------------
# solve_small


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_solve_small_backward_stable(n):
    rng = np.random.default_rng(n)
    for cond in (1.0, 1e4, 1e8, 1e12):
        U, _ = np.linalg.qr(rng.normal(size=(200, n, n)))
        V, _ = np.linalg.qr(rng.normal(size=(200, n, n)))
        A = (U * np.logspace(0, -np.log10(cond), n)[None, None, :]) @ V.transpose(0, 2, 1)
        B = rng.normal(size=(200, n, 4))
        X = np.asarray(jax.vmap(solve_small)(jnp.asarray(A), jnp.asarray(B)))
        # Backward error |A X - B| / (|A| |X|) at rounding level, whatever the conditioning.
        res = np.linalg.norm(A @ X - B, axis=(1, 2)) / (np.linalg.norm(A, axis=(1, 2)) * np.linalg.norm(X, axis=(1, 2)))
        assert res.max() < 1e-15, (cond, res.max())
        # Forward error within conditioning of LAPACK's answer.
        Xr = np.linalg.solve(A, B)
        rel = np.linalg.norm(X - Xr, axis=(1, 2)) / np.linalg.norm(Xr, axis=(1, 2))
        assert rel.max() < 100 * cond * np.finfo(np.float64).eps, (cond, rel.max())
        # A vector right-hand side.
        x = np.asarray(solve_small(jnp.asarray(A[0]), jnp.asarray(B[0, :, 0])))
        assert np.linalg.norm(A[0] @ x - B[0, :, 0]) < 1e-15 * np.linalg.norm(A[0]) * np.linalg.norm(x)


def test_solve_small_pivots_and_singular():
    # A zero leading entry needs a row exchange.
    P = jnp.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(np.asarray(solve_small(P, jnp.array([1.0, 2.0, 3.0]))), [3.0, 1.0, 2.0])
    # Exactly singular: not finite (as LAPACK's solve), never a silent wrong number.
    assert not np.all(np.isfinite(np.asarray(solve_small(jnp.zeros((3, 3)), jnp.ones(3)))))
    with pytest.raises(ValueError, match="solve_small"):
        solve_small(jnp.zeros((3, 2)), jnp.ones(3))
    # Larger systems fall back to jnp.linalg.solve.
    A = jnp.eye(6) * 2.0
    np.testing.assert_allclose(np.asarray(solve_small(A, jnp.ones(6))), 0.5)


# ----------------------------------------------------------------------------
# tie and evaluate_where (loop carries and skipped work under vmap)


@pytest.mark.parametrize("ref", [jnp.array([np.nan, 1.0]), jnp.array([3, 0]), jnp.array([True]), jnp.zeros((0,))])
def test_tie_changes_no_value(ref):
    """tie returns every leaf unchanged (NaN, inf, integers, bools, uint32 keys), whatever
    ref holds (a NaN, a zero, an empty array), eagerly, jitted and under vmap."""
    tree = (jnp.array([np.nan, -np.inf, 1.5]), jnp.array(7, jnp.int32), jnp.array([True, False]),
            jax.random.PRNGKey(3))
    for fn in (tie, jax.jit(tie)):
        out = fn(tree, ref)
        for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(tree), strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    if ref.size:
        refs = jnp.stack([ref, ref])
        out = jax.vmap(lambda r: tie(tree, r))(refs)
        for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(tree), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.broadcast_to(np.asarray(b), a.shape))


@pytest.mark.parametrize("chunk", [1, 3])
def test_evaluate_where_matches_a_python_loop(chunk):
    """evaluate_where fills exactly the flagged entries with fn's values, for chunk 1
    (no vmap) and larger chunks, and under vmap with different flags per member."""
    fill = (jnp.full((5,), -1.0), jnp.zeros((5, 2), jnp.int32))

    def fn(p):
        return (jnp.sin(p.astype(jnp.float64)), jnp.stack([p, 2 * p]).astype(jnp.int32))

    todos = np.array([[True, False, True, True, False], [False] * 5, [True] * 5])
    for todo in todos:
        out = evaluate_where(jnp.asarray(todo), fn, chunk, fill)
        want = tuple(np.array(f) for f in fill)
        for p in range(5):
            if todo[p]:
                want[0][p], want[1][p] = np.sin(p), [p, 2 * p]
        for a, b in zip(out, want, strict=True):
            np.testing.assert_array_equal(np.asarray(a), b)
    batched = jax.vmap(lambda t: evaluate_where(t, fn, chunk, fill))(jnp.asarray(todos))
    for k, todo in enumerate(todos):
        single = evaluate_where(jnp.asarray(todo), fn, chunk, fill)
        for a, b in zip(batched, single, strict=True):
            np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b))


def test_solve_small_gradient_matches_linalg_solve():
    rng = np.random.default_rng(7)
    A = jnp.asarray(rng.normal(size=(3, 3))) + 3.0 * jnp.eye(3)
    B = jnp.asarray(rng.normal(size=(3, 5)))

    def loss(solve):
        return lambda A, B: jnp.sum(jnp.sin(solve(A, B)))

    for argnum in (0, 1):
        g = jax.grad(loss(solve_small), argnum)(A, B)
        ref = jax.grad(loss(jnp.linalg.solve), argnum)(A, B)
        np.testing.assert_allclose(np.asarray(g), np.asarray(ref), rtol=1e-12, atol=1e-14)


def test_no_lapack_call_in_rollouts_and_checks():
    """The deadlock's cause, checked at the source: no LAPACK custom call (jaxlib's
    ``lapack_*_ffi``, whose batched kernels wait on XLA's intra-op pool) in the
    lowered checked rollout (the planner's pseudo-inverses and the swept check) or in the
    post-hoc checks."""
    sc = sp.paper_scenario("tree", **PAD)
    gains = sp.default_gains()
    texts = [rollout_jit.lower(sc, gains, make_options("curve"), 20).as_text()]
    r = jax.eval_shape(lambda s: sp.planning.rollout(s, gains, make_options("curve", check_collisions=False), 20), sc)
    r = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), r)
    texts.append(jax.jit(lambda r, s: apply_collision_checks(r, s, make_options("curve"))).lower(r, sc).as_text())
    for text in texts:
        assert "lapack" not in text.lower()
    # The test can fail: jnp.linalg.solve lowers to a LAPACK call on CPU.
    A = jnp.eye(3)[None].repeat(4, 0)
    assert "lapack" in jax.jit(jax.vmap(jnp.linalg.solve)).lower(A, A).as_text().lower()


# ----------------------------------------------------------------------------
# plan_batch: arguments


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(chunk=0), "chunk"),
        (dict(chunk=-2), "chunk"),
        (dict(chunk=1.5), "chunk"),
        (dict(chunk=True), "chunk"),
        (dict(devices=0), "devices"),
        (dict(devices=10**6), "devices"),
        (dict(devices=True), "devices"),
        (dict(devices="cpu"), "devices"),
        (dict(devices=[]), "devices"),
        (dict(devices=[0]), "devices"),
        (dict(devices=[jax.devices()[0], jax.devices()[0]]), "twice"),
        (dict(progress="yes"), "progress"),
        (dict(progres=True), "unknown planner option"),
    ],
)
def test_plan_batch_bad_arguments(kwargs, match):
    batch = sp.scenarios.stack_scenarios([sp.paper_scenario("sim1", **PAD)] * 2)
    with pytest.raises(ValueError, match=match):
        sp.plan_batch(batch, max_steps=5, **kwargs)


# ----------------------------------------------------------------------------
# 2 host devices (a subprocess: the device count is fixed when jax starts)

TWO_DEVICES = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import softplan_jax as sp

    assert len(jax.local_devices()) == 2, jax.local_devices()
    PAD = dict(curve_slots=5, degree=2)
    batch = sp.scenarios.stack_scenarios([sp.paper_scenario(n, **PAD) for n in ("sim1", "sim2", "tree")])
    one = sp.plan_batch(batch, max_steps=200, devices=1)
    two = sp.plan_batch(batch, max_steps=200)  # every local device: 3 scenarios padded to 4
    compiled = sp.planning.rollout_batch.cache_size()
    # The chunked path over the mesh (one chunk of 4, shown with progress): the same program.
    again = sp.plan_batch(batch, max_steps=200, chunk=4, progress=True)
    # No cross-device communication in the partitioned program (jit's automatic partitioning
    # of the same vmapped rollout all-reduces the warm start's while-loop predicate instead).
    text = sp.planning.rollout_batch.lower(batch, sp.default_gains(), sp.make_options("curve"), 200).compile().as_text()
    collectives = [op for op in ("all-reduce", "all-gather", "all-to-all", "collective-permute", "reduce-scatter")
                   if op + "(" in text or op + "-start(" in text]
    out = dict(
        shape=list(two.q.shape),
        sharding=str(two.q.sharding) if hasattr(two.q, "sharding") else "",
        status=[np.asarray(one.status).tolist(), np.asarray(two.status).tolist()],
        iterations=[np.asarray(one.iterations).tolist(), np.asarray(two.iterations).tolist()],
        dq=float(np.max(np.abs(np.asarray(one.q) - np.asarray(two.q)))),
        dclear=float(np.max(np.abs(np.asarray(one.min_clearance) - np.asarray(two.min_clearance)))),
        chunked_equal=all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
                          for a, b in zip(jax.tree_util.tree_leaves(two), jax.tree_util.tree_leaves(again),
                                          strict=True)),
        recompiled=sp.planning.rollout_batch.cache_size() - compiled,
        collectives=collectives,
        partitions=text.count("num_partitions=2") + text.count("mesh['batch'=2]"),
    )
    print(json.dumps(out))
    """
)


@pytest.mark.slow  # a 2-device subprocess compiling its own partitioned program (~27 s)
def test_two_host_devices_match_one():
    """plan_batch sharded over 2 host devices, collision checks included (the default),
    on the paper scenes: it finishes (it used to hang: see solve_small), gives the
    1-device run's statuses and iterations, trajectories to rounding. Not bit for bit:
    XLA compiles a partitioned program (num_partitions = 2) through its SPMD pipeline,
    whose early CSE lets the algebraic simplifier rewrite a different graph (measured:
    68 dot ops left against 89 in the 1-device program), and the rollout amplifies the
    1e-16 differences. The chunked path over the mesh reuses the program bit for bit, and
    the compiled program has no collective (jit's automatic partitioning of the same
    vmapped rollout puts an all-reduce in the warm start's fallback while loop, whose
    predicate is an "any" over the batch: every iteration would synchronise the devices)."""
    env = subprocess_env()
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    env["XLA_FLAGS"] = " ".join(flags + ["--xla_force_host_platform_device_count=2"])
    p = subprocess.run([sys.executable, "-c", TWO_DEVICES], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["shape"] == [3, 201, 3, 3]
    assert out["status"][0] == out["status"][1] == [int(sp.Status.REACHED)] * 3, out
    assert out["iterations"][0] == out["iterations"][1], out
    assert out["dq"] < 1e-9 and out["dclear"] < 1e-9, out  # close, not bit for bit (see above)
    assert out["chunked_equal"] and out["recompiled"] == 0, out
    assert out["partitions"] > 0 and out["collectives"] == [], out  # the 2-device program, no collectives
    assert "plan_batch: 1/1 chunks, 3/3 scenarios on 2 devices" in p.stderr


def test_batch_keys_per_scenario():
    from softplan_jax.planning._programs import batch_keys

    keys = jax.random.split(jax.random.PRNGKey(4), 5)
    np.testing.assert_array_equal(np.asarray(batch_keys(4, 5)), np.asarray(keys))
    # A share of a suite keeps the suite's keys.
    np.testing.assert_array_equal(np.asarray(batch_keys(keys[2:4], 2)), np.asarray(keys[2:4]))
    typed = jax.random.split(jax.random.key(4), 3)
    assert batch_keys(typed, 3) is typed
    assert batch_keys(jax.random.key(4), 3).shape == (3,)
    batch = sp.scenarios.stack_scenarios([sp.paper_scenario("sim1", **PAD)] * 2)
    with pytest.raises(ValueError, match="3 keys for a batch of 2"):
        sp.plan_batch(batch, max_steps=5, seed=jax.random.split(jax.random.PRNGKey(0), 3))


DISTRIBUTED = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2, process_id=int(sys.argv[2]))
    import numpy as np
    from jax.experimental import multihost_utils
    import softplan_jax as sp

    # The README's recipe: every process builds the same suite and keys, plans its own share.
    n = 6
    suite = sp.random_scenarios(0, n)
    keys = jax.random.split(jax.random.PRNGKey(0), n)
    share = np.array_split(np.arange(n), jax.process_count())[jax.process_index()]
    mine = jax.tree_util.tree_map(lambda x: x[share], suite)
    r = sp.plan_batch(mine, max_steps=100, seed=keys[share])
    summary = np.stack([np.asarray(r.status), np.asarray(r.iterations)], axis=1)
    gathered = np.asarray(multihost_utils.process_allgather(summary)).reshape(-1, 2)
    local = sp.plan_batch(suite, max_steps=100, devices=1)  # the whole suite, here, for comparison
    print(json.dumps(dict(process=jax.process_index(), count=jax.process_count(),
                          devices=len(jax.devices()), local_devices=len(jax.local_devices()),
                          gathered=gathered.tolist(),
                          whole=np.stack([np.asarray(local.status), np.asarray(local.iterations)], 1).tolist())))
    jax.distributed.shutdown()
    """
)


@pytest.mark.slow
def test_distributed_two_processes_one_host():
    """The README's jax.distributed recipe, run as 2 processes on this machine (CPU,
    1 device each): every process plans its share, the summaries are gathered, and
    they are the whole suite's (statuses and iterations). Not a test on real
    multi-host hardware."""
    port, env = free_port(), one_device_env()
    procs = [subprocess.Popen([sys.executable, "-c", DISTRIBUTED, f"localhost:{port}", str(i)], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=900)
        assert p.returncode == 0, stderr[-3000:]
        outs.append(json.loads(stdout.strip().splitlines()[-1]))
    for out in outs:
        assert (out["count"], out["devices"], out["local_devices"]) == (2, 2, 1), out
        assert out["gathered"] == outs[0]["whole"], out


@pytest.mark.slow
def test_batch_command_on_two_processes_is_the_sharded_run(tmp_path):
    """``softplan batch --coordinator ... --num-processes 2 --process-id I`` (the same command
    on every host; here 2 processes of 1 CPU device each) runs the SAME shard_map program as
    one process sharded over 2 host devices: a global mesh, each process computing its own
    devices' shards, the results gathered. Process 0 writes --out; the per-scenario results
    equal the one-process run's bit for bit. Not a test on real multi-host hardware."""
    env = one_device_env()
    common = ["-m", "softplan_jax.cli", "batch", "--n", "6", "--max-steps", "40", "--chunk", "4", "--no-progress"]
    port = free_port()
    procs = [subprocess.Popen([sys.executable, *common, "--coordinator", f"localhost:{port}", "--num-processes", "2",
                               "--process-id", str(i), "--json", "--out", str(tmp_path / f"p{i}.npz")],
                              cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    outs = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=900)
        assert p.returncode == 0, stderr[-3000:]
        outs.append(stdout)
    # jax's CPU collectives (gloo) print one "[Gloo] Rank i is connected ..." line on stdout.
    def ours(text):
        return "\n".join(line for line in text.splitlines() if not line.startswith("[Gloo]"))

    summary = json.loads(ours(outs[0]))
    assert (summary["processes"], summary["devices"], summary["chunk"]) == (2, 2, 4), summary
    assert ours(outs[1]).strip() == "" and not (tmp_path / "p1.npz").exists()  # only process 0 reports
    env2 = dict(env, XLA_FLAGS=(env["XLA_FLAGS"] + " --xla_force_host_platform_device_count=2").strip())
    one = subprocess.run([sys.executable, *common, "--out", str(tmp_path / "one.npz")],
                         cwd=ROOT, env=env2, capture_output=True, text=True, timeout=900)
    assert one.returncode == 0, one.stderr[-3000:]
    a, b = np.load(tmp_path / "p0.npz"), np.load(tmp_path / "one.npz")
    assert a["status"].shape == (6,)
    for key in ("status", "iterations", "min_clearance", "final_error", "escapes"):
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_global_mesh_in_one_process():
    """devices="global" without jax.distributed is every local device: no mesh for one
    device, and a plan_batch equal to devices=None's."""
    from softplan_jax.planning._batching import batch_mesh, is_global

    mesh = batch_mesh("global")
    assert mesh is None if len(jax.devices()) == 1 else mesh.size == len(jax.devices())
    assert not is_global(mesh)
    with pytest.raises(ValueError, match='"global"'):
        batch_mesh("everywhere")
    # test_plan_batch_matches_single's batch: its program (found in the compilation cache).
    batch = sp.scenarios.stack_scenarios([sp.paper_scenario(name, **PAD) for name in ("sim1", "sim2", "tree")])
    a = sp.plan_batch(batch, max_steps=200, devices="global")
    b = sp.plan_batch(batch, max_steps=200)
    np.testing.assert_array_equal(np.asarray(a.q), np.asarray(b.q))
