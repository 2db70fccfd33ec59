"""The browser view without a browser (softplan_jax.viewer, ``softplan view``): the meshes
against independent geometry (the distance of every tube vertex to the polyline, volumes by the
divergence theorem, outward faces, closed surfaces, frames that do not twist), what is drawn
against the NumPy oracle (backbones, moving curves) and dense sampling (closest points and
clearance), the warm replanning of a dragged goal (nothing compiled), the panel, the slider, the
fallback offered where a plan stopped short, saved trajectories read back, and the command's
robustness: bad input exits 2 before any server starts, a port in use is skipped with a message,
Ctrl-C exits 130. The real browser is tests/test_viewer_browser.py.
"""

from __future__ import annotations

import json
import logging
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request

import jax
import numpy as np
import pytest
from session import REPO, subprocess_env

import softplan_jax as sp
from softplan_jax.cli import main
from softplan_jax.cli.trajectory import read_trajectory, trajectory_record, write_trajectory
from softplan_jax.testing import oracle_geometry as og
from softplan_jax.viewer import _meshes as meshes
from softplan_jax.viewer._live import ARM_SAMPLES, LivePlanner, shown_plan

viser = pytest.importorskip("viser", reason="the viewer extra (viser) is not installed: pip install '.[viewer]'")

MAX_STEPS = 200
STALLS = np.array([1.5, 1.5, 1.0])  # a goal of the tree the local planner leaves at max_steps (200 steps)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---------------------------------------------------------------------------------------------
# Meshes, against independent geometry.


def _polyline_distance(x, pts):
    """Distance from each point of x (V, 3) to the polyline pts (N, 3): brute force over its segments."""
    a, b = pts[:-1], pts[1:]
    ab = b - a
    t = np.clip(np.einsum("vsk,sk->vs", x[:, None] - a[None], ab) / np.maximum(np.sum(ab * ab, -1), 1e-300), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.min(np.linalg.norm(x[:, None] - closest, axis=-1), axis=1)


def _volume(v, f):
    """Signed volume of a closed triangle mesh (divergence theorem): positive when faces point out."""
    v = v.astype(np.float64)
    return float(np.sum(np.einsum("fk,fk->f", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])))) / 6.0


def _closed_and_consistent(f) -> bool:
    """Every directed edge appears once and its reverse once: a closed, consistently wound surface."""
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    return len(directed) == len(edges) and all((b, a) in directed for a, b in directed)


def _helix(n=240, turns=1.5, radius=0.4, pitch=0.5):
    u = np.linspace(0.0, 2 * np.pi * turns, n)
    return np.stack([radius * np.cos(u), radius * np.sin(u), pitch * u / (2 * np.pi)], -1)


def test_tube_of_a_straight_line_is_the_exact_prism():
    pts = np.stack([np.zeros(5), np.zeros(5), np.linspace(0.0, 2.0, 5)], -1) @ np.array(
        [[0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [-0.8, 0.0, 0.6]])  # a tilted straight line, length 2
    r, k = 0.1, 12
    v, f = meshes.tube_mesh(pts, r, sides=k)
    assert v.dtype == np.float32 and f.dtype == np.uint32 and v.shape == (5 * k + 2, 3)
    assert _closed_and_consistent(f)
    prism = 0.5 * k * r * r * np.sin(2 * np.pi / k) * 2.0  # the regular k-gon's area times the length
    assert _volume(v, f) == pytest.approx(prism, rel=1e-5)
    np.testing.assert_allclose(_polyline_distance(v[: 5 * k], pts), r, rtol=1e-5)


def test_tube_of_a_helix_lies_on_its_surface_and_faces_out():
    pts = _helix()
    r, k = 0.05, 16
    v, f = meshes.tube_mesh(pts, r, sides=k)
    d = _polyline_distance(v[:-2].astype(np.float64), pts)
    assert np.all(d <= r * (1 + 1e-5)) and np.all(d >= r * (1 - 2e-3)), (d.min(), d.max())
    assert _closed_and_consistent(f)
    length = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    assert _volume(v, f) == pytest.approx(0.5 * k * r * r * np.sin(2 * np.pi / k) * length, rel=2e-3)
    # Every side face's normal points away from the centre line (the caps: along the ends' tangents).
    side = f[: 2 * (len(pts) - 1) * k].astype(int)
    tri = v[side].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = tri.mean(axis=1)
    nearest_ring = side[:, 0] // k
    assert np.all(np.einsum("fk,fk->f", normal, centre - pts[nearest_ring]) > 0)


def test_frames_do_not_twist():
    """Rotation-minimizing frames: on a planar curve one frame vector stays the plane's normal;
    on a helix the normal turns about the tangent by about nothing (a Frenet frame turns by the
    torsion tau per unit length)."""
    u = np.linspace(0.0, 2.5, 80)
    plane = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])  # a tilted plane
    arc = np.stack([np.cos(u), np.sin(u)], -1) @ plane
    n, b = meshes.tube_frames(arc)
    normal = np.cross(plane[0], plane[1])
    assert np.allclose(np.abs(b @ normal), 1.0, atol=1e-9) or np.allclose(np.abs(n @ normal), 1.0, atol=1e-9)
    pts = _helix()
    n, b = meshes.tube_frames(pts)
    t = np.cross(n, b)
    assert np.allclose(np.einsum("ik,ik->i", n, b), 0, atol=1e-12) and np.allclose(np.linalg.norm(t, axis=1), 1)
    twist = np.sum(np.einsum("ik,ik->i", np.diff(n, axis=0), 0.5 * (b[1:] + b[:-1])))
    radius, c = 0.4, 0.5 / (2 * np.pi)
    tau = c / (radius**2 + c**2)  # the helix's torsion
    length = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    assert abs(twist) < 1e-3 * tau * length, (twist, tau * length)


def test_sphere_and_helpers():
    v, f = meshes.sphere_mesh(0.3, rings=10, sides=16)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 0.3, rtol=1e-6)
    assert _closed_and_consistent(f)
    vol = _volume(v, f)
    assert 0.9 * 4 / 3 * np.pi * 0.3**3 < vol < 4 / 3 * np.pi * 0.3**3  # inscribed: a little less
    assert meshes.polyline_segments(np.zeros((1, 3))).shape == (0, 2, 3)
    np.testing.assert_array_equal(meshes.polyline_segments(np.eye(3))[1], [[0, 1, 0], [0, 0, 1]])
    mv, mf = meshes.merge_meshes([(v, f), (v + 1, f)])
    assert mv.shape == (2 * len(v), 3) and mf.max() == 2 * len(v) - 1
    for bad in (lambda: meshes.tube_mesh(np.zeros((1, 3)), 0.1), lambda: meshes.tube_mesh(np.eye(3), 0.0),
                lambda: meshes.tube_mesh([[0, 0, 0], [np.nan, 0, 0]], 0.1), lambda: meshes.sphere_mesh(-1.0)):
        with pytest.raises(ValueError):
            bad()
    # A polyline with repeated points (an arm segment of theta = 0 sampled twice) still gives a finite tube.
    v, _ = meshes.tube_mesh([[0, 0, 0], [0, 0, 0], [0, 0, 1], [0, 0, 1]], 0.1)
    assert np.all(np.isfinite(v))


# ---------------------------------------------------------------------------------------------
# What is drawn, against the oracle.


@pytest.fixture(scope="module")
def tree():
    return sp.paper_scenario("tree")


@pytest.fixture(scope="module")
def planner(tree):
    return LivePlanner(tree, max_steps=MAX_STEPS)


def test_backbone_matches_the_oracle(planner):
    rng = np.random.default_rng(3)
    for q in (np.asarray(planner.scene.q0), np.column_stack([rng.uniform(0.7, 1.3, 3), [0.0, 0.9, -0.4],
                                                             rng.uniform(-3, 3, 3)])):
        got = planner.backbone(q)
        s = np.arange(1, ARM_SAMPLES + 1) / ARM_SAMPLES
        want = np.concatenate([np.zeros((1, 3))] + [og.segment_points(q, i, s) for i in range(3)])
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_closest_points_match_dense_sampling(planner, tree):
    from scipy.spatial import cKDTree

    q = np.array([[1.0, 0.5, 0.3], [1.0, 0.6, 2.0], [1.0, -0.2, 2.4]])
    a, o, c = planner.closest(q)
    arm = np.concatenate([og.segment_points(q, i, np.linspace(0.0, 1.0, 5001)) for i in range(3)])
    arm_tree = cKDTree(arm)
    coeffs, u_range = np.asarray(tree.curves.coeffs), np.asarray(tree.curves.u_range)
    radius = np.asarray(tree.curves.radius)
    for j, slot in enumerate(planner.real_slots):
        pts = og.OPoly(coeffs[slot], *u_range[slot]).point(np.linspace(*u_range[slot], 10001))
        coarse = float(np.min(arm_tree.query(pts[::50])[0]))  # then only the points that may beat it
        brute = float(np.min(arm_tree.query(pts, distance_upper_bound=coarse + 1e-9)[0]))
        brute -= float(tree.arm_radius) + radius[slot]
        assert c[j] <= brute + 1e-9 and c[j] == pytest.approx(brute, abs=1e-4)
        assert np.linalg.norm(a[j] - o[j]) == pytest.approx(c[j] + float(tree.arm_radius) + radius[slot], abs=1e-9)
        assert cKDTree(pts).query(o[j])[0] < 1e-3 and arm_tree.query(a[j])[0] < 1e-3  # on the curve, on the arm


def test_moving_curves_move_as_the_oracle(tree):
    moving = sp.moving_scenario("tree_sway")
    live = LivePlanner(moving, max_steps=MAX_STEPS)
    motion = moving.motion
    coeffs, u_range = np.asarray(tree.curves.coeffs), np.asarray(tree.curves.u_range)
    for t in (0.0, 0.7, 2.3):
        R, p = live.curve_poses(t)
        for k in range(coeffs.shape[0]):
            rest = og.OPoly(coeffs[k], *u_range[k]).point(np.linspace(*u_range[k], 7))
            m = {f: np.asarray(getattr(motion, f))[k] for f in motion._fields}
            want = og.moving_curve_points(coeffs[k], u_range[k], m, t, 7)
            np.testing.assert_allclose(rest @ R[k].T + p[k], want, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# The viewer, served but without a browser.


@pytest.fixture(scope="module")
def viewer(planner):
    from softplan_jax.viewer._app import Viewer

    v = Viewer(planner, host="127.0.0.1", port=0, label="tree")
    assert v.wait_idle(600), "the first plan did not finish"
    yield v
    v.stop()


def _check_arm(v, q):
    """The arm's meshes on show are the tubes around the oracle's backbone of q."""
    r = v.drawing.arm_radius
    for i, verts in enumerate(v.arm_vertices):
        centre = og.segment_points(q, i, np.linspace(0.0, 1.0, 4 * ARM_SAMPLES + 1))
        d = _polyline_distance(verts[:-2].astype(np.float64), centre)
        np.testing.assert_allclose(d, r, rtol=5e-3)


def test_first_plan_is_shown(viewer, tree):
    shown = viewer.shown
    assert shown.status == "reached" and shown.iterations > 0 and viewer.plans == 1
    np.testing.assert_allclose(shown.goal[-1], np.asarray(tree.goal))
    assert np.linalg.norm(shown.tip[-1] - np.asarray(tree.goal)) < 0.01
    assert viewer.panel.slider.max == shown.iterations and viewer.panel.slider.value == shown.iterations
    text = viewer.panel.outcome.content
    assert "**reached**" in text and f"iterations: {shown.iterations}" in text
    assert f"min clearance: {shown.min_clearance:.4f}" in text
    assert viewer.panel.fallback.disabled
    _check_arm(viewer, shown.q[-1])
    assert viewer.url == f"http://127.0.0.1:{viewer.port}" and not viewer.port_in_use
    with urllib.request.urlopen(viewer.url, timeout=30) as page:  # the page is served
        assert page.status == 200 and b"<html" in page.read(2000).lower()


def test_dragging_the_goal_replans_warm(viewer, caplog):
    """A new goal runs the compiled rollout again: nothing compiles from the goal's update to the
    new arm's meshes (plan, backbone, meshes, closest points), and the arm reaches the new goal."""
    viewer.panel.closest.value = True  # the closest points' program too
    goals = np.asarray(viewer.planner.goal) + np.array([[0.0, 0.05, 0.0], [0.05, 0.1, -0.05], [-0.05, 0.05, 0.0]])
    plans = viewer.plans
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        for g in goals:
            viewer.set_goal(g)
            assert viewer.wait_idle(120)
            assert viewer.shown.status == "reached", viewer.shown.status
            np.testing.assert_allclose(viewer.shown.goal[-1], g)
            assert np.linalg.norm(viewer.shown.tip[-1] - g) < 0.01
            _check_arm(viewer, viewer.shown.q[-1])
    compiled = [r.getMessage() for r in caplog.records if "ompil" in r.getMessage()]
    assert not compiled, compiled
    assert viewer.plans == plans + 3 and len(viewer.latencies) >= 3
    np.testing.assert_allclose(viewer.drawing.gizmo.position, goals[-1])
    viewer.panel.closest.value = False


def test_slider_draws_each_step_and_play_runs_to_the_end(viewer):
    shown = viewer.shown
    viewer.panel.slider.value = 0
    _check_arm(viewer, shown.q[0])
    assert viewer.panel.clock.content == f"step 0 of {shown.iterations}"
    k = shown.iterations // 2
    viewer.panel.slider.value = k
    _check_arm(viewer, shown.q[k])
    viewer.play(True)
    deadline = time.time() + 60
    while viewer.panel.play_button.label == "Pause" and time.time() < deadline:
        time.sleep(0.05)
    assert viewer.step == shown.iterations and viewer.panel.play_button.label == "Play"


def test_a_plan_that_stops_short_offers_the_fallback(viewer):
    viewer.set_goal(STALLS)
    assert viewer.wait_idle(120)
    assert viewer.shown.status == "max_steps" and not viewer.shown.succeeded
    assert not viewer.panel.fallback.disabled
    assert "the goal is not reached" in viewer.panel.outcome.content
    from softplan_jax.viewer._drawing import COLORS

    assert tuple(viewer.drawing.segments[0].color) == COLORS["arm_failed"][0]
    viewer.set_goal([1.0, 1.0, 1.2])  # on the trunk: proven unreachable at once, nothing to fall back on
    assert viewer.wait_idle(120)
    assert viewer.shown.status == "unreachable" and viewer.shown.reason == "goal_in_obstacle"
    assert viewer.panel.fallback.disabled


def test_a_port_in_use_is_skipped(planner):
    from softplan_jax.viewer._app import Viewer

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        v = Viewer(planner, sp.viewer.shown_plan(
            {"q": np.asarray(planner.scene.q0)[None], "tip": np.zeros((1, 3)), "clearance": np.zeros((1, 5)),
             "goal": planner.goal, "status": "reached", "iterations": 0}), port=port)
        try:
            assert v.port_in_use and v.port != port and v.plans == 1
        finally:
            v.stop()


# ---------------------------------------------------------------------------------------------
# Saved trajectories and bad input.


def _record(result, tree):
    summary = dict(scenario="tree", method="curve", n_points=None, repulsion="khatib", dtype="float64",
                   max_steps=MAX_STEPS, goal_tolerance=0.01, compile_time_s=0.0, run_time_s=0.0, gains="default",
                   gains_file=None, gain_values={"k_att": 1.0, "rep_max": None})
    return trajectory_record(result, tree, summary)


@pytest.mark.parametrize("ext", [".json", ".npz"])
def test_saved_trajectories_are_read_back(planner, tree, tmp_path, ext):
    planner.set_goal(np.asarray(tree.goal))
    planner.plan()
    record = _record(planner._result, tree)
    path = str(tmp_path / f"run{ext}")
    write_trajectory(path, record)
    back = read_trajectory(path)
    for key in ("q", "tip", "clearance", "goal"):
        np.testing.assert_array_equal(back[key], record[key])
    assert back["status"] == record["status"] and back["scenario"] == "tree" and back["time"] is None
    shown = shown_plan(back, source=path)
    assert shown.goal.shape == (shown.q.shape[0], 3) and shown.source == path


def test_bad_trajectory_files_name_the_field(tmp_path):
    good = {"format": "softplan-trajectory/1", "q": [[[1.0, 0.0, 0.0]]], "tip": [[0.0, 0.0, 1.0]],
            "clearance": [[0.5]], "goal": [0.0, 0.0, 1.0], "status": "reached", "scenario": "tree"}
    for change, field in (({"format": "softplan-scenario/1"}, "format"), ({"q": [[1.0, 0.0]]}, "q"),
                          ({"tip": [[0.0, 1.0]]}, "tip"), ({"goal": [1.0, 2.0]}, "goal"),
                          ({"clearance": [[0.5], [0.5]]}, "clearance"), ({"scenario": 3}, "scenario")):
        path = tmp_path / "bad.json"
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(ValueError, match=f"field {field}"):
            read_trajectory(str(path))


def test_view_rejects_bad_input_before_serving(monkeypatch):
    workers = sum(t.name == "softplan-viewer" for t in threading.enumerate())
    for kwargs, match in (({"scene": None}, "scene must be"), ({"scene": "nosuch"}, "unknown scene"),
                          ({"scene": "tree", "port": 70000}, "port"), ({"scene": "tree", "host": ""}, "host"),
                          ({"scene": "tree", "method": "nearest"}, "method"),
                          ({"scene": "tree", "result": {"q": np.zeros((2, 4, 3)), "tip": np.zeros((2, 3)),
                                                        "clearance": np.zeros((2, 5)), "goal": np.zeros(3),
                                                        "status": "reached", "iterations": 1}}, "shape")):
        with pytest.raises(ValueError, match=match):
            sp.view(**kwargs)
    monkeypatch.setitem(sys.modules, "viser", None)  # viser not installed: the extra is named
    with pytest.raises(ImportError, match=r"pip install 'softplan_jax\[viewer\]'"):
        sp.view("tree")
    assert sum(t.name == "softplan-viewer" for t in threading.enumerate()) == workers  # no view started


def test_command_bad_input_exits_2_before_serving(tmp_path, capsys, monkeypatch):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "softplan-scenario/1", "goal": [1, 2]}')
    traj = tmp_path / "run.json"
    traj.write_text(json.dumps({"format": "softplan-trajectory/1", "q": [[[1.0, 0.0, 0.0]] * 3],
                                "tip": [[0.0, 0.0, 3.0]], "clearance": [[0.5]], "goal": [0.0, 0.0, 3.0],
                                "status": "reached", "scenario": "gone.json"}))
    port = _free_port()
    workers = sum(t.name == "softplan-viewer" for t in threading.enumerate())
    for argv, message in (([str(bad)], "field goal"), (["nosuch"], "unknown scenario"),
                          ([str(traj)], "field scenario"), (["tree", "--port", "70000"], "--port"),
                          (["tree", "--n-points", "0"], "--n-points")):
        assert main(["view", *argv, "--port", str(port)] if "--port" not in argv else ["view", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("softplan: error:") and message in err[0], err
    monkeypatch.setitem(sys.modules, "viser", None)  # viser not installed
    assert main(["view", "tree", "--port", str(port)]) == 2
    assert "pip install 'softplan_jax[viewer]'" in capsys.readouterr().err
    assert sum(t.name == "softplan-viewer" for t in threading.enumerate()) == workers  # no view started
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))  # nothing took the port


def test_command_skips_a_busy_port_and_stops_on_ctrl_c(planner, tree, tmp_path):
    """``softplan view run.json`` (a saved trajectory of the tree) on a busy port: it says so,
    serves the next one, and Ctrl-C ends it with exit code 130 and one line, the port released."""
    planner.set_goal(np.asarray(tree.goal))
    planner.plan()
    saved = str(tmp_path / "run.json")
    write_trajectory(saved, _record(planner._result, tree))
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        proc = subprocess.Popen([sys.executable, "-m", "softplan_jax.cli", "view", saved, "--port", str(port),
                                 "--max-steps", str(MAX_STEPS)], cwd=REPO, env=subprocess_env(),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            url = _read_address(proc, timeout=240)
        except BaseException:
            proc.kill()
            raise
    served = int(url.rsplit(":", 1)[1])
    assert served != port
    with urllib.request.urlopen(url, timeout=30) as page:
        assert page.status == 200
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (out, err)
    assert err.strip().splitlines()[-1] == "softplan: interrupted", err
    assert f"port {port} is in use; serving on port {served} instead" in err + out
    with socket.socket() as s:
        s.bind(("127.0.0.1", served))  # released


def _read_address(proc, timeout: float) -> str:
    """The address of ``softplan view run.json`` (its stdout's line), waiting up to ``timeout`` s."""
    found = []

    def read():
        for line in proc.stdout:
            if "the view of run.json is at http://" in line:
                found.append(line.rsplit(" ", 1)[1].strip())
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    if not found:
        raise AssertionError(f"no address within {timeout} s (exit code {proc.poll()})")
    return found[0]
