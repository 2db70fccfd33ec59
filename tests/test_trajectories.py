"""Timed trajectories (softplan_jax.time_parametrize) checked from their files alone: every
sample within every limit by finite differences of the file (divided differences and
numpy.gradient), every configuration on the planned path (the polyline, or the spline
rebuilt from the file's waypoints), no contact by the dense brute force, and the duration
against TOPP-RA run directly (toppra's own spline through the actuator lengths, its own
grid). Also the certificate's fallback, a tracked run's time stamps, the arm's limits, and
bad input. The plan is test_planner's (the tree padded to 5 slots, 200 steps: one program)."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_allclose

import softplan_jax as sp
from softplan_jax import actuators as A
from softplan_jax.planning._planner import make_options
from softplan_jax.testing import oracle_actuators as O

PAD = dict(curve_slots=5, degree=2)
RATE = 20.0  # samples per second: coarse enough for the brute-force check, dense enough to test the rule
LIMITS = dict(max_speed=0.02, max_acceleration=0.05)


@pytest.fixture(scope="module")
def tree():
    return sp.paper_scenario("tree", **PAD)


@pytest.fixture(scope="module")
def plan(tree):
    r = sp.plan(tree, max_steps=200)
    assert r.status == "reached"
    return r


@pytest.fixture(scope="module")
def layout():
    return A.actuator_layout("tendon", 3, 3, radius=0.03)


@pytest.fixture(scope="module")
def timed(tree, plan, layout):
    lim = A.actuator_limits(**LIMITS)
    return {path: sp.time_parametrize(plan, layout, lim, tree, path=path, rate=RATE) for path in ("smooth", "linear")}


@pytest.fixture(scope="module")
def files(timed, tmp_path_factory):
    out = {}
    for path, traj in timed.items():
        folder = tmp_path_factory.mktemp(path)
        sp.save_trajectory(traj, folder / "t.csv")
        sp.save_trajectory(traj, folder / "t.json")
        out[path] = folder
    return out


def read_file(folder):
    """The CSV's columns by name and the JSON, read with numpy and json only."""
    with open(folder / "t.csv") as fh:
        header = fh.readline().strip().split(",")
    table = np.loadtxt(folder / "t.csv", delimiter=",", skiprows=1)
    with open(folder / "t.json") as fh:
        meta = json.load(fh)
    return {name: table[:, j] for j, name in enumerate(header)}, meta


def columns(cols, prefix, n, k):
    return np.stack([cols[f"{prefix}_{i}_{m}"] for i in range(n) for m in range(k)], axis=1)


@pytest.mark.parametrize("path", ["smooth", "linear"])
def test_every_sample_within_every_limit(files, path):
    cols, meta = read_file(files[path])
    t = cols["t"]
    lengths = columns(cols, "tendon", 3, 3)
    vmax, amax = meta["limits"]["max_speed"], meta["limits"]["max_acceleration"]
    assert (vmax, amax) == (LIMITS["max_speed"], LIMITS["max_acceleration"])
    assert np.all(np.diff(t) > 0) and t[0] == 0
    forward = np.diff(lengths, axis=0) / np.diff(t)[:, None]
    second = 2 * np.diff(forward, axis=0) / (t[2:] - t[:-2])[:, None]
    gradient = np.gradient(lengths, t, axis=0)
    for name, v, limit in (("speed", forward, vmax), ("acceleration", second, amax), ("gradient speed", gradient, vmax),
                           ("gradient acceleration", np.gradient(gradient, t, axis=0), amax)):
        assert np.max(np.abs(v)) <= limit, (path, name, np.max(np.abs(v)) / limit)
    # The limits bind: the trajectory is as fast as they allow somewhere.
    assert max(np.max(np.abs(forward)) / vmax, np.max(np.abs(second)) / amax) > 0.99
    # The file's speed columns are the lengths' rates: a central difference of the lengths agrees.
    speeds = columns(cols, "speed_tendon", 3, 3)
    mid = 0.5 * (speeds[1:] + speeds[:-1])
    assert np.max(np.abs(mid - forward)) < 0.05 * vmax
    # The lengths are those of the configurations: the sampled oracle at a few rows.
    q = np.stack([cols[f"{x}_{i}"] for i in range(3) for x in ("L", "theta", "phi")], axis=1).reshape(-1, 3, 3)
    radius, angles = np.array(meta["actuators"]["radius"]), np.array(meta["actuators"]["angles"])
    for j in np.linspace(0, t.shape[0] - 1, 4).astype(int):
        assert_allclose(lengths[j].reshape(3, 3), O.tendon_lengths_sampled(q[j], radius, angles, 2000), rtol=1e-6)


def _polyline_distance(x, way):
    """Distance of x (d,) to the polyline through way (K+1, d)."""
    a, b = way[:-1], way[1:]
    d = b - a
    u = np.clip(np.sum((x - a) * d, axis=1) / np.sum(d * d, axis=1), 0, 1)
    return float(np.min(np.linalg.norm(a + u[:, None] * d - x, axis=1)))


def _spline_distance(x, spline, s_grid, values):
    """Distance of x to the spline: the nearest grid point, refined by Newton on |q(s) - x|^2."""
    s = s_grid[np.argmin(np.linalg.norm(values - x, axis=1))]
    for _ in range(8):
        r, d1, d2 = spline(s) - x, spline(s, 1), spline(s, 2)
        s = np.clip(s - (r @ d1) / (d1 @ d1 + r @ d2), s_grid[0], s_grid[-1])
    return float(np.linalg.norm(spline(s) - x))


@pytest.mark.parametrize("path", ["smooth", "linear"])
def test_every_configuration_on_the_planned_path(files, plan, path):
    """Linear: on the plan's polyline. Smooth: on the cubic spline (not-a-knot, parameter the
    polyline's length in q) through the file's waypoints, which are the plan's steps."""
    from scipy.interpolate import CubicSpline

    cols, meta = read_file(files[path])
    q = np.stack([cols[f"{x}_{i}"] for i in range(3) for x in ("L", "theta", "phi")], axis=1)
    way = np.array(meta["plan"]["waypoints"]).reshape(-1, 9)
    assert_allclose(way, plan.q.reshape(-1, 9), rtol=0, atol=0)  # the tree's plan has no repeated step
    assert meta["plan"]["path"] == path and meta["plan"]["status"] == "reached"
    if path == "linear":
        dist = [_polyline_distance(x, way) for x in q]
        assert max(dist) < 1e-12
        assert len(meta["plan"]["stops"]) == way.shape[0] - 2  # at rest at every corner
    else:
        s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(way, axis=0), axis=1))])
        spline = CubicSpline(s, way, bc_type="not-a-knot", axis=0)
        grid = np.linspace(0, s[-1], 20001)
        values = spline(grid)
        dist = [_spline_distance(x, spline, grid, values) for x in q]
        assert max(dist) < 1e-9, max(dist)
        assert meta["plan"]["stops"] == [] and meta["plan"]["linear_spans"] == []
    # The trajectory passes every waypoint at its recorded time (each one is a sample).
    times = np.array(meta["plan"]["waypoint_times"])
    rows = np.searchsorted(cols["t"], times)
    assert np.all(cols["t"][rows] == times) and np.all(np.diff(times) > 0)
    assert_allclose(q[rows], way, rtol=0, atol=1e-9)


@pytest.mark.parametrize("path", ["smooth", "linear"])
def test_no_contact_by_the_dense_brute_force(files, tree, path):
    cols, _ = read_file(files[path])
    q = np.stack([cols[f"{x}_{i}"] for i in range(3) for x in ("L", "theta", "phi")], axis=1).reshape(-1, 3, 3)
    dense = np.asarray(sp.geometry.dense_trajectory_clearance(jnp.asarray(q), tree, substeps=1, arm_samples=30,
                                                              curve_samples=400))
    assert dense.min() > 0.04, dense.min()  # the plan's own minimum is 0.058


def _toppra_duration(points_s, lengths, vmax, amax):
    """TOPP-RA run directly: toppra's SplineInterpolator through the actuator lengths sampled along
    the path, toppra's own grid, rest to rest."""
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as tc

    path = toppra.SplineInterpolator(points_s, lengths)
    dof = lengths.shape[1]
    cons = [tc.JointVelocityConstraint(np.full(dof, vmax)),
            tc.JointAccelerationConstraint(np.full(dof, amax), discretization_scheme=tc.DiscretizationType.Interpolation)]
    traj = algo.TOPPRA(cons, path, solver_wrapper="seidel", gridpt_min_nb_points=400).compute_trajectory(0, 0)
    return float(traj.duration)


def _lengths_along(q_rows, layout):
    f = jax.jit(jax.vmap(lambda q: A.tendon_lengths(q, layout.radius, layout.angles).reshape(-1)))
    return np.asarray(f(jnp.asarray(q_rows.reshape(-1, 3, 3))))


@pytest.mark.parametrize("path", ["smooth", "linear"])
def test_duration_within_two_percent_of_toppra(files, layout, path):
    from scipy.interpolate import CubicSpline

    cols, meta = read_file(files[path])
    way = np.array(meta["plan"]["waypoints"]).reshape(-1, 9)
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(way, axis=0), axis=1))])
    vmax, amax = LIMITS["max_speed"], LIMITS["max_acceleration"]
    if path == "smooth":
        dense = np.linspace(0, s[-1], 3000)
        q = CubicSpline(s, way, bc_type="not-a-knot", axis=0)(dense)
        ref = _toppra_duration(dense, _lengths_along(q, layout), vmax, amax)
    else:  # rest to rest along every straight motion
        ref = 0.0
        for k in range(way.shape[0] - 1):
            u = np.linspace(0, 1, 40)
            q = way[k] + u[:, None] * (way[k + 1] - way[k])
            ref += _toppra_duration(u * (s[k + 1] - s[k]), _lengths_along(q, layout), vmax, amax)
    mine = cols["t"][-1]
    assert meta["plan"]["duration"] == mine
    assert abs(mine / ref - 1) < 0.02, (path, mine, ref)


def test_smooth_is_faster_and_loads_back(timed, files):
    smooth, linear = timed["smooth"], timed["linear"]
    assert smooth.path == "smooth" and linear.path == "linear"
    assert smooth.duration < 0.85 * linear.duration  # the stops at the corners cost most of the difference
    for path, traj in timed.items():
        for name in ("t.csv", "t.json"):
            back = sp.load_trajectory(files[path] / name)
            for field in ("t", "q", "lengths", "speeds", "tip", "waypoints", "waypoint_times", "stops"):
                np.testing.assert_array_equal(getattr(back, field), getattr(traj, field), err_msg=f"{path} {name}")
            assert back.layout.kind == "tendon" and back.status == "reached" and back.report.ok
            np.testing.assert_array_equal(np.asarray(back.layout.angles), np.asarray(traj.layout.angles))


def test_unproven_spans_fall_back_to_the_straight_motions(tree, plan, layout):
    """Where the swept check cannot prove the spline clear (here: a contact tolerance just below the
    plan's clearance), those spans are timed along the plan's straight motions, with stops."""
    options = make_options(contact_tolerance=0.056)
    traj = sp.time_parametrize(plan, layout, A.actuator_limits(**LIMITS), tree, options=options, rate=RATE)
    assert traj.path == "mixed" and 0 < traj.linear_spans.size < plan.iterations
    assert traj.report.ok and len(traj.stops) >= traj.linear_spans.size
    for k in traj.linear_spans:  # samples within a linear span lie on its straight motion
        a, b = traj.waypoint_times[k], traj.waypoint_times[k + 1]
        rows = (traj.t >= a) & (traj.t <= b)
        for x in traj.q[rows].reshape(-1, 9):
            assert _polyline_distance(x, plan.q[k:k + 2].reshape(-1, 9)) < 1e-12
    everything = sp.time_parametrize(plan, layout, A.actuator_limits(**LIMITS), tree, rate=RATE,
                                     options=make_options(contact_tolerance=0.5))
    assert everything.path == "linear" and everything.duration == pytest.approx(
        sp.time_parametrize(plan, layout, A.actuator_limits(**LIMITS), tree, rate=RATE, path="linear").duration)


def test_tracked_run_keeps_its_time_and_reports_the_limits(layout):
    moving = sp.moving_scenario("tree_sway")
    r = sp.track(moving, max_steps=200)
    traj = sp.time_parametrize(r, layout, A.actuator_limits(**LIMITS))
    assert traj.path == "tracked"
    np.testing.assert_array_equal(traj.t, r.time - r.time[0])
    np.testing.assert_array_equal(traj.q, r.q)
    t = traj.t
    speed = np.abs(np.diff(traj.lengths, axis=0)) / np.diff(t)[:, None, None]
    second = 2 * np.abs(np.diff(np.diff(traj.lengths, axis=0) / np.diff(t)[:, None, None], axis=0)) / (
        t[2:] - t[:-2])[:, None, None]
    over_v = np.nonzero(np.any(speed > LIMITS["max_speed"] * (1 + 1e-9), axis=(1, 2)))[0]
    over_a = np.nonzero(np.any(second > LIMITS["max_acceleration"] * (1 + 1e-9), axis=(1, 2)))[0]
    assert not traj.report.ok and over_v.size > 0
    assert traj.report.violations["max_speed"] == over_v.size
    assert traj.report.violations["max_acceleration"] == over_a.size
    first_v, first_a = t[over_v[0]], t[over_a[0] + 1] if over_a.size else np.inf  # an acceleration: its middle sample
    name, when = ("max_speed", first_v) if first_v <= first_a else ("max_acceleration", first_a)
    assert traj.report.first.startswith(f"{name}: ") and f"at t = {when:.3f} s" in traj.report.first


def test_constrained_scene_and_extension(tree, layout):
    """A far goal stretches an arm with unbounded extension (the warning); actuator length limits
    become the scene's segment length limits."""
    far = tree._replace(goal=jnp.array([10.0, 10.0, 10.0]))
    r = sp.plan(far, max_steps=200)
    ext = sp.trajectories.extension(far, r.q)
    assert not ext["bounded"] and ext["stretch"] > 2 and ext["warn"]
    lim = A.actuator_limits(min_length=0.5, max_length=3.3, max_speed=0.02)
    c = sp.trajectories.constrain_scenario(tree, layout, lim)
    assert np.all(np.asarray(c.L_max) <= 3.3) and np.all(np.asarray(c.L_min) >= np.asarray(tree.L_min))
    assert sp.trajectories.extension(c, r.q)["bounded"]


# ----------------------------------------------------------------------------
# Bad input: a ValueError naming the field; nothing timed.


def test_bad_input(tree, plan, layout):
    lim = A.actuator_limits(**LIMITS)
    tp = sp.time_parametrize
    cases = [
        (lambda: tp(plan._replace(status="collided"), layout, lim, tree), r"result: the run ended 'collided'"),
        (lambda: tp(plan, layout, lim), r"scenario: path='smooth' proves the spline clear"),
        (lambda: tp(plan, A.actuator_layout("tendon", 2, 3), lim, tree), r"result.q has shape .* 2 segments"),
        (lambda: tp(plan, layout, A.actuator_limits(max_length=9.0), tree), r"limits: timing needs a finite max_speed"),
        (lambda: tp(plan, layout, lim, tree, rate=0.0), r"rate must be a finite number"),
        (lambda: tp(plan, layout, lim, tree, path="bezier"), r"path must be 'smooth' or 'linear'"),
        (lambda: tp(plan, layout, lim, tree, max_tip_speed=-1.0), r"max_tip_speed must be a finite number > 0"),
        (lambda: tp(plan, "tendons", lim, tree), r"layout must be an ActuatorLayout"),
        (lambda: tp(plan, layout, {"max_speed": 1}, tree), r"limits must be ActuatorLimits"),
        (lambda: tp(plan._replace(q=plan.q[:1], tip=plan.tip[:1]), layout, lim, tree, path="linear"),
         r"result: the plan does not move"),
        (lambda: tp(plan, layout, A.actuator_limits(max_length=2.9, max_speed=0.02), tree),
         r"limits: the plan leaves the actuators' length limits .*max_length: tendon \d of segment 2"),
        (lambda: tp(plan, A.actuator_layout("chamber", 3, 3, radius=0.7), lim, tree, path="linear"),
         r"layout: at step \d+ of the plan: radius: 0.7 is not inside segment \d's bending radius"),
    ]
    for fn, pattern in cases:
        with pytest.raises(ValueError, match=pattern):
            fn()


def test_bad_files(tmp_path, timed):
    traj = timed["linear"]
    with pytest.raises(ValueError, match=r"path: a timed trajectory is written as .csv or .json"):
        sp.save_trajectory(traj, tmp_path / "t.txt")
    sp.save_trajectory(traj, tmp_path / "t.json")
    with pytest.raises(ValueError, match=r"exists; pass overwrite=True"):
        sp.save_trajectory(traj, tmp_path / "t.json")
    with pytest.raises(ValueError, match=r"needs its JSON file"):
        sp.save_trajectory(traj, tmp_path / "u.csv") or sp.load_trajectory(tmp_path / "u.csv").t.shape
    d = json.loads((tmp_path / "t.json").read_text())
    for change, pattern in [
        (lambda d: d.update(format="softplan-trajectory/1"), r"format must be 'softplan-timed-trajectory/1'"),
        (lambda d: d["actuators"].update(kind="muscle"), r"actuators.kind must be one of"),
        (lambda d: d["actuators"].update(radius=[0.03, -1, 0.03]), r"radius must be finite and > 0"),
        (lambda d: d["limits"].update(max_speed=-1), r"limits.max_speed must be > 0"),
        (lambda d: d["samples"].update(t=d["samples"]["t"][::-1]), r"samples.t must hold two or more increasing"),
        (lambda d: d["samples"].update(tip=d["samples"]["tip"][:-1]), r"samples.tip has shape"),
        (lambda d: d["plan"].pop("waypoints"), r"missing field plan.waypoints"),
        (lambda d: d["plan"].update(path="wiggly"), r"plan.path must be one of"),
    ]:
        bad = json.loads(json.dumps(d))
        change(bad)
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=pattern):
            sp.load_trajectory(tmp_path / "bad.json")
    (tmp_path / "w.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"not valid JSON"):
        sp.load_trajectory(tmp_path / "w.json")
    assert math.isfinite(traj.duration)


def test_plot_actuators(timed):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = sp.plotting.plot_actuators(timed["smooth"])
    assert len(fig.axes) == 3  # lengths, speeds, accelerations (an acceleration limit is set)
    limit_lines = [ln for ln in fig.axes[1].get_lines() if np.ptp(ln.get_ydata()) == 0 and abs(ln.get_ydata()[0]) > 0]
    assert {round(abs(ln.get_ydata()[0]), 6) for ln in limit_lines} == {LIMITS["max_speed"]}
    plt.close(fig)
    with pytest.raises(ValueError, match=r"traj must be a Trajectory"):
        sp.plotting.plot_actuators(timed["smooth"].q)
