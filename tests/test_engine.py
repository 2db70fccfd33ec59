"""The rollout engine (softplan_jax.planning._engine): its drivers give the same arrays, a
finished rollout's records are frozen, a batch's refilled lanes give every scene
its own rollout (checked against a Python loop of single rollouts), the lanes and the
single plan's device by platform, the safe step's scale against its formula, and the
sizes' bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.planning._engine import (
    ACCELERATOR_LANES,
    DEFAULT_LANES,
    DEFAULT_QUANTUM,
    TRACK_LANES,
    check_engine_sizes,
    default_lanes,
    run,
    run_lanes,
)
from softplan_jax.planning._options import rollout_compiler_options
from softplan_jax.planning._planner import make_options, plan_device
from softplan_jax.planning._programs import batch_keys, rollout, rollout_jit
from softplan_jax.planning._step import safe_scale

PAD = dict(curve_slots=5, degree=2)  # test_planner's shape: its programs are shared (conftest SHARED)
STEPS = 200


@pytest.fixture(scope="module")
def paper():
    return {name: sp.paper_scenario(name, **PAD) for name in ("sim1", "sim2", "tree")}


@pytest.fixture(scope="module")
def five(paper):
    """Five scenes of one shape: the paper's three, the tree with a goal beyond reach (it stalls
    and escapes, so its random walks depend on its key), and sim2 with the tree's goal."""
    far = paper["tree"]._replace(goal=jnp.array([2.5, 2.5, 0.4]))
    other = paper["sim2"]._replace(goal=paper["tree"].goal)
    return [paper["sim1"], paper["sim2"], paper["tree"], far, other]


def _fields(r):
    return {f: np.asarray(v) for f, v in r._asdict().items() if v is not None}


@pytest.fixture(scope="module")
def scan_driver(paper):
    """The tree's rollout by the fixed-length scan driver (every step of the horizon)."""
    g = sp.default_gains()
    return jax.device_get(jax.jit(lambda s, k: rollout(s, g, make_options("curve"), STEPS, k, driver="scan"),
                                  compiler_options=rollout_compiler_options("curve"))(paper["tree"],
                                                                                      jax.random.PRNGKey(0)))


# The default chunk (8) is test_planner's program; another chunk is another program, so the
# second chunk runs with the slow tests.
@pytest.mark.parametrize("chunk", [8, pytest.param(5, marks=pytest.mark.slow)])
def test_chunks_driver_equals_scan_driver(paper, scan_driver, chunk):
    """rollout_jit (the "chunks" driver: stops after the chunk in which the rollout ended) gives
    the fixed-length scan's arrays bit for bit, whatever the chunk (neither 8 nor 5 divides the
    201 records)."""
    r = rollout_jit(paper["tree"], sp.default_gains(), make_options("curve", step_chunk=chunk), STEPS, 0)
    for f, x in _fields(scan_driver).items():
        np.testing.assert_array_equal(np.asarray(getattr(r, f)), x, err_msg=f"{f}, step_chunk {chunk}")


def test_records_frozen_after_the_end(paper):
    r = jax.device_get(rollout_jit(paper["tree"], sp.default_gains(), make_options("curve"), STEPS, 0))
    it = int(r.iterations)
    assert sp.planning.status_name(r.status) == "reached" and it < STEPS - 10
    for f in ("q", "tip", "clearance", "converged"):
        x = getattr(r, f)
        np.testing.assert_array_equal(x[it + 1:], np.broadcast_to(x[it], x[it + 1:].shape), err_msg=f)
    # No motion after the end: the between-step clearance is the clearance; no events.
    np.testing.assert_array_equal(r.between[it + 1:], np.broadcast_to(r.clearance[it], r.between[it + 1:].shape))
    assert np.all(r.step_scale[it:] == 0) and np.all(r.step_scale[:it] > 0)
    assert np.all(r.fallbacks[it + 1:] == 0) and not np.any(r.between_searched[it + 1:])
    assert float(r.final_error) == float(np.linalg.norm(np.asarray(paper["tree"].goal) - r.tip[it]))


def _suspensions(held_steps, lanes, quantum):
    """The scenes run_lanes suspends, in order, for scenes that hold a lane for ``held_steps``
    steps each (iterations + 1: the last step judges): its queue in plain Python."""
    queue = list(range(lanes, len(held_steps)))
    lane = [[b, 0, 0] for b in range(lanes)]  # scene, steps it has taken, steps held in this lane
    left, suspended = list(held_steps), []
    while any(b is not None for b, _, _ in lane):
        for ln in lane:
            if ln[0] is not None:
                ln[1] += 1
                ln[2] += 1
        done = [ln[0] is not None and ln[1] == left[ln[0]] for ln in lane]
        spare = len(queue) - sum(done)
        due = [ln[0] is not None and not d and ln[2] >= quantum for ln, d in zip(lane, done, strict=True)]
        suspend = [d and sum(due[: i + 1]) <= spare for i, d in enumerate(due)]
        for ln, s in zip(lane, suspend, strict=True):
            if s:
                left[ln[0]] -= ln[1]
                queue.append(ln[0])
                suspended.append(ln[0])
        for ln, d, s in zip(lane, done, suspend, strict=True):
            if d or s:
                ln[:] = [queue.pop(0) if queue else None, 0, 0]
    return suspended


def test_lanes_refill_matches_single_rollouts(five):
    """Five scenes on two lanes (refills, scenes suspended after DEFAULT_QUANTUM steps and
    resumed, one idle lane at the end): bit for bit the rollouts of a lane per scene (no refill,
    no suspension: two chunks of three scenes on three lanes, test_planner's compiled batch of
    the paper scenes), and against a Python loop of single rollouts with the same keys: the same
    status, steps and escapes, and q to rounding (a vmapped program rounds differently). The
    scene beyond reach escapes at random (its key and walk follow it through its suspensions):
    there a near-tie amplifies the rounding difference from about step 46 on (1e-14 to 1e-2 by
    the end), so its q is compared over the first 40 steps; the others over the whole horizon."""
    stack = sp.scenarios.stack_scenarios(five)
    two = jax.device_get(sp.plan_batch(stack, max_steps=STEPS, lanes=2, devices=1))
    each = jax.device_get(sp.plan_batch(stack, max_steps=STEPS, chunk=3, devices=1))  # 3 lanes for 3 scenes
    for f, x in _fields(each).items():
        np.testing.assert_array_equal(np.asarray(getattr(two, f)), x, err_msg=f)
    # The two lanes did suspend scenes, among them the escaping one: the check above covers it.
    assert 3 in _suspensions([int(i) + 1 for i in two.iterations], 2, DEFAULT_QUANTUM)
    keys = batch_keys(0, len(five))
    assert int(two.escapes[3]) > 0
    for b, sc in enumerate(five):
        one = jax.device_get(rollout_jit(sc, sp.default_gains(), make_options("curve"), STEPS, keys[b]))
        assert int(two.status[b]) == int(one.status), b
        assert int(two.iterations[b]) == int(one.iterations), b
        assert int(two.escapes[b]) == int(one.escapes), b
        horizon = 40 if b == 3 else STEPS + 1
        np.testing.assert_allclose(two.q[b, :horizon], one.q[:horizon], atol=1e-9, err_msg=f"scene {b}")
    assert [sp.planning.status_name(s) for s in two.status[:3]] == ["reached"] * 3
    # Another key for the escaping scene changes its walks (the keys follow the scenes into their lanes).
    other = jax.device_get(rollout_jit(five[3], sp.default_gains(), make_options("curve"), STEPS, keys[2]))
    assert np.abs(other.q - two.q[3]).max() > 1e-2


def test_default_lanes_by_platform():
    """A batch's lanes when none are given: on a CPU 128 when planning and up to 1,024 when
    tracking (a tracked scene holds its lane to the horizon), the whole share (up to 16,384)
    on an accelerator, where a wide vmapped step costs little more than a narrow one."""
    assert default_lanes("cpu") == DEFAULT_LANES == 128
    assert default_lanes("cpu", tracking=True) == TRACK_LANES == 1024
    for tracking in (False, True):
        assert default_lanes("gpu", tracking) == default_lanes("cuda", tracking) == ACCELERATOR_LANES == 16384
        assert default_lanes("tpu", tracking) == ACCELERATOR_LANES
    assert default_lanes() == default_lanes(jax.default_backend())


@pytest.mark.parametrize("entry", ["plan_batch", "track_batch"])
def test_batch_entry_points_default_lanes(entry, monkeypatch):
    """plan_batch and track_batch without ``lanes`` hand the engine the CPU's width for their
    mode: at most 128 lanes when planning, the whole batch (up to 1,024) when tracking. Caught at the
    engine's door (run_lanes replaced), so nothing compiles."""
    from softplan_jax.planning import _programs as programs

    seen = {}

    class Caught(Exception):
        pass

    def spy(worlds, gains, options, max_steps, keys, **kw):
        seen.update(kw, batch=keys.shape[0])
        raise Caught

    monkeypatch.setattr(programs, "run_lanes", spy)
    if entry == "plan_batch":
        batch = sp.random_scenarios(7, 70)
        call = lambda: sp.plan_batch(batch, max_steps=13)  # noqa: E731
    else:
        batch = sp.moving.random_moving_scenarios(7, 70)
        call = lambda: sp.track_batch(batch, max_steps=13)  # noqa: E731
    with pytest.raises(Caught):
        call()
    want = DEFAULT_LANES if entry == "plan_batch" else TRACK_LANES
    assert seen["batch"] == 70 and seen["lanes"] == (want if jax.default_backend() == "cpu" else ACCELERATOR_LANES)


def test_plan_device(paper, monkeypatch):
    """plan(device=...): a named device runs the same rollout (here the one CPU, jax's default
    device: the same compiled program, bit for bit);
    bad values are refused before anything compiles; with an accelerator as the default
    backend, one scene goes to the host CPU."""
    cpu = jax.devices("cpu")[0]
    ref = sp.plan(paper["tree"], max_steps=STEPS)
    compiled = sp.planning.rollout_jit.cache_size()
    on_cpu = sp.plan(paper["tree"], max_steps=STEPS, device=cpu)
    # The default device already: the same compiled program (no device context, no device_put).
    assert sp.planning.rollout_jit.cache_size() == compiled
    assert on_cpu.status == ref.status == "reached" and on_cpu.iterations == ref.iterations
    np.testing.assert_array_equal(np.asarray(on_cpu.q), np.asarray(ref.q))
    assert plan_device("default") is None and plan_device(cpu) is cpu
    assert plan_device(None) is None  # the default backend is this CPU
    before = sp.planning.rollout_jit.cache_size()
    for bad in ("gpu", 3, [cpu]):
        with pytest.raises(ValueError, match="device"):
            sp.plan(paper["tree"], max_steps=STEPS, device=bad)
    assert sp.planning.rollout_jit.cache_size() == before
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert plan_device(None) == cpu


def test_safe_scale_against_its_formula():
    q = jnp.array([[1.0, 0.3, 0.2], [0.9, -0.5, 1.0]])
    q_t = q + jnp.array([[0.05, 0.2, -0.1], [0.0, 0.3, 0.2]])
    B = float(sp.geometry.motion_bound(q, q_t)[-1])
    c = jnp.array([0.3, 0.05, jnp.inf])
    floor, f = 2e-6, 0.8

    def formula(budgets):
        return min(1.0, max(min(budgets), 0.0) / B)

    alpha, too_fast = safe_scale(q, q_t, c, floor, f)
    assert float(alpha) == pytest.approx(formula([f * (0.05 - floor)]), rel=1e-14) and not bool(too_fast)
    travel = jnp.array([0.01, 0.02, 0.0])
    alpha, too_fast = safe_scale(q, q_t, c, floor, f, travel)
    assert float(alpha) == pytest.approx(formula([f * (0.3 - floor) - 0.01, f * (0.05 - floor) - 0.02]), rel=1e-14)
    assert not bool(too_fast)
    # An obstacle that travels farther than the budget: even standing still is not proven safe.
    alpha, too_fast = safe_scale(q, q_t, c, floor, f, jnp.array([0.0, 0.05, 0.0]))
    assert bool(too_fast) and float(alpha) == 0.0
    # The cap of the global search's path steps; no obstacle; no motion; NaN.
    assert float(safe_scale(q, q_t, c, floor, f, cap=1e-3)[0]) == pytest.approx(1e-3 / B, rel=1e-14)
    assert float(safe_scale(q, q_t, jnp.full((2,), jnp.inf), floor, f)[0]) == 1.0
    assert float(safe_scale(q, q, c, floor, f)[0]) == 1.0
    assert np.isnan(float(safe_scale(q, q_t, jnp.array([jnp.nan, 1.0]), floor, f)[0]))


@pytest.mark.parametrize("kwargs, field", [
    (dict(lanes=0), "lanes"), (dict(lanes=2.5), "lanes"), (dict(lanes=True), "lanes"),
    (dict(max_steps=2.5), "max_steps"), (dict(max_steps=0), "max_steps"),
    (dict(step_chunk=0), "step_chunk"), (dict(step_chunk=1.5), "step_chunk"),
])
def test_bad_sizes_refused_before_compiling(paper, kwargs, field):
    before = sp.planning.rollout_batch.cache_size()
    with pytest.raises(ValueError, match=field):
        sp.plan_batch(sp.scenarios.stack_scenarios(list(paper.values())), **kwargs)
    assert sp.planning.rollout_batch.cache_size() == before
    if field != "lanes":
        with pytest.raises(ValueError, match=field):
            sp.plan(paper["tree"], **kwargs)
    with pytest.raises(ValueError, match="lanes"):
        check_engine_sizes(10, 8, "4")


@pytest.mark.parametrize("quantum", [0, 2.5, True, "64"])
def test_bad_quantum_refused_before_tracing(paper, quantum):
    stack = sp.scenarios.stack_scenarios(list(paper.values()))
    keys = batch_keys(0, 3)
    with pytest.raises(ValueError, match="quantum must be an int >= 1"):
        run_lanes(stack, sp.default_gains(), make_options("curve"), 10, keys, quantum=quantum)


def test_tracking_a_static_scene_plans_it_then_holds(paper):
    """The mode is the options': TrackOptions on a static scene hold the goal to the horizon. Up to
    the step where planning ends at the goal, the two rollouts are the same step bit for bit (the
    static attraction, no motion); tracking then holds the goal (status reached, held to the end)."""
    from softplan_jax.planning._tracking import make_track_options

    sc, g = paper["tree"], sp.default_gains()
    planned = jax.device_get(rollout_jit(sc, g, make_options("curve"), STEPS, 0))
    tracked = jax.device_get(rollout_jit(sc, g, make_track_options("curve"), STEPS, 0))
    it = int(planned.iterations)
    np.testing.assert_array_equal(tracked.q[: it + 1], planned.q[: it + 1])
    assert sp.planning.status_name(tracked.status) == "reached" and bool(tracked.held_to_end)
    assert int(tracked.reached_step) == it and int(tracked.iterations) == STEPS
    np.testing.assert_allclose(tracked.time, np.arange(STEPS + 1) * float(g.dt), rtol=1e-15)
    assert np.all(tracked.error[it:] <= 0.02)
    with pytest.raises(ValueError, match="TrackOptions"):
        run(sp.moving_scenario("tree_sway"), g, make_options("curve"), 5, jax.random.PRNGKey(0))


def test_default_lanes_follow_the_batch_and_its_horizon():
    """A CPU plans on ceil(scenes * LANE_STEPS / max_steps) lanes between MIN_LANES and
    DEFAULT_LANES; tracking and accelerators keep their widths; without the batch's size
    the CPU's default."""
    from softplan_jax.planning._engine import (
        ACCELERATOR_LANES,
        DEFAULT_LANES,
        LANE_STEPS,
        MIN_LANES,
        TRACK_LANES,
        default_lanes,
    )

    assert default_lanes("cpu") == DEFAULT_LANES
    assert default_lanes("cpu", scenes=1024, max_steps=600) == -(-1024 * LANE_STEPS // 600) == DEFAULT_LANES
    assert default_lanes("cpu", scenes=2048, max_steps=600) == DEFAULT_LANES
    assert default_lanes("cpu", scenes=256, max_steps=600) == -(-256 * LANE_STEPS // 600) == 32
    assert default_lanes("cpu", scenes=64, max_steps=600) == MIN_LANES
    assert default_lanes("cpu", scenes=64, max_steps=150) == 32
    assert default_lanes("cpu", scenes=100, max_steps=50) == DEFAULT_LANES
    assert default_lanes("cpu", tracking=True, scenes=64, max_steps=600) == TRACK_LANES
    assert default_lanes("gpu", scenes=64, max_steps=600) == ACCELERATOR_LANES
