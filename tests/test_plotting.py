"""The animations' shared frame-and-writer loop (softplan_jax.plotting._animation), on
hand-made results: no planning, no rollout compile.

What a GIF shows is read off the writer: every frame it grabs is recorded with the
figure's caption at that moment, so the steps chosen (at most ``max_frames``, evenly
spaced, the first and the last always), the frames held at the end, the title prefix
and the status at the last step are checked exactly. The argument checks of
``animate`` and ``animate_tracking`` are checked with their messages, and no figure
is left open, whether the GIF was written or an error was raised.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

import softplan_jax as sp

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
pytest.importorskip("PIL")

import matplotlib.animation  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

from softplan_jax import plotting  # noqa: E402
from softplan_jax.plotting import _animation as animation  # noqa: E402


def _plan_result(scenario, steps):
    """A PlanResult-shaped trajectory: the arm bends a little more at every step."""
    q0 = np.asarray(scenario.q0)
    qs = np.stack([q0 + np.array([0.0, 0.1 * k, 0.0]) for k in range(steps + 1)])
    tips = np.stack([np.asarray(sp.tip_position(q)) for q in qs])
    clearance = np.linspace(0.5, 0.1, steps + 1)[:, None]
    return sp.PlanResult(reached=False, iterations=steps, collided=False, min_clearance=0.1, q=qs, tip=tips,
                         status="max_steps", clearance=clearance, final_error=1.0)


def _track_result(steps):
    """A TrackResult-shaped run of the swaying tree: the arm bends, the goal drifts along x."""
    moving = sp.moving_scenario("tree_sway")
    q0 = np.asarray(moving.scene.q0)
    qs = np.stack([q0 + np.array([0.0, 0.1 * k, 0.0]) for k in range(steps + 1)])
    tips = np.stack([np.asarray(sp.tip_position(q)) for q in qs])
    goal = np.asarray(moving.scene.goal)[None] + np.outer(np.arange(steps + 1), [0.01, 0.0, 0.0])
    return types.SimpleNamespace(moving=moving, time=0.5 * np.arange(steps + 1), goal=goal, q=qs, tip=tips,
                                 error=np.linalg.norm(goal - tips, axis=1), iterations=steps, status="reached")


@pytest.fixture(scope="module")
def scenario():
    return sp.make_scenario([1.0, 0.5, 1.5], [sp.line_segment([1.0, -1.0, 0.5], [1.0, 1.0, 2.5], radius=0.1)],
                            arm_radius=0.04)


@pytest.fixture(scope="module")
def track_result():
    return _track_result(7)


@pytest.fixture
def captions(monkeypatch):
    """The caption of every frame the GIF writer grabs, in order."""
    seen = []

    class Recorder(matplotlib.animation.PillowWriter):
        def grab_frame(self, **kw):
            seen.append(self.fig._suptitle.get_text())
            super().grab_frame(**kw)

    monkeypatch.setattr(matplotlib.animation, "PillowWriter", Recorder)
    return seen


def _gif_frames(path):
    from PIL import Image

    with Image.open(path) as im:
        return im.n_frames


@pytest.mark.parametrize("iterations, max_frames, shown", [
    (10, 4, [0, 3, 7, 10]),
    (10, 2, [0, 10]),
    (3, 200, [0, 1, 2, 3]),  # fewer steps than max_frames: every step
    (0, 5, [0]),
])
def test_animate_shows_evenly_spaced_steps_and_holds_the_last(scenario, captions, tmp_path, iterations, max_frames,
                                                              shown):
    result = _plan_result(scenario, iterations)
    gif = tmp_path / "plan.gif"
    written = plotting.animate(scenario, result, gif, fps=5, max_frames=max_frames, hold=0.4, title="sim", dpi=30)
    assert written == str(gif)
    expected = [f"sim\niteration {s} / {iterations}" + (" — max_steps" if s == iterations else "") for s in shown]
    assert captions == expected + [expected[-1]] * 2  # hold * fps = 2 frames more
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    assert plt.get_fignums() == []


def test_animate_without_title_or_hold(scenario, captions, tmp_path):
    gif = tmp_path / "plan.gif"
    plotting.animate(scenario, _plan_result(scenario, 4), gif, fps=5, max_frames=3, hold=0.0, dpi=30)
    assert captions == ["iteration 0 / 4", "iteration 2 / 4", "iteration 4 / 4 — max_steps"]
    assert _gif_frames(gif) == 3  # the arm moves: three different frames


def test_animate_tracking_frames(track_result, captions, tmp_path):
    gif = tmp_path / "sway.gif"
    r = track_result
    assert plotting.animate_tracking(r, gif, fps=4, max_frames=4, hold=0.5, title="sway", dpi=30) == str(gif)
    shown = [0, 2, 5, 7]
    expected = [f"sway\nt = {r.time[s]:.1f} s, step {s} / 7, |goal - tip| = {r.error[s]:.3f}"
                + (" — reached" if s == 7 else "") for s in shown]
    assert captions == expected + [expected[-1]] * 2
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    assert plt.get_fignums() == []


def test_animate_tracking_draws_what_moves(track_result, tmp_path, monkeypatch):
    """The goal marker follows the goal and the tip path grows, frame by frame."""
    goals, paths = [], []
    show_tip_path = animation._show_tip_path

    def spy(line, tips, step):
        show_tip_path(line, tips, step)
        paths.append(np.asarray(line.get_data_3d()).T.copy())
        goal = next(ln for ln in line.axes.get_lines() if ln.get_label() == "goal")
        goals.append(np.asarray(goal.get_data_3d())[:, 0].copy())

    monkeypatch.setattr(animation, "_show_tip_path", spy)
    r = track_result
    plotting.animate_tracking(r, tmp_path / "sway.gif", max_frames=3, hold=0.0, dpi=30)
    # FuncAnimation may draw the first frame more than once (init and save): the frames' last visits
    shown = [0, 4, 7]
    assert len(paths) >= len(shown)
    for path, goal, s in zip(paths[-len(shown):], goals[-len(shown):], shown, strict=True):
        np.testing.assert_array_equal(path, r.tip[: s + 1])
        np.testing.assert_array_equal(goal, r.goal[s])


@pytest.mark.parametrize("name", ["animate", "animate_tracking"])
@pytest.mark.parametrize("kw, message", [
    (dict(path="motion.png"), r"{name} writes GIF files; the path must end in \.gif, got '.*motion\.png'"),
    (dict(fps=0), r"fps must be > 0, got 0"),
    (dict(fps=float("nan")), r"fps must be > 0, got nan"),
    (dict(max_frames=1), r"max_frames must be >= 2, got 1"),
    (dict(view=(10.0,)), r"view must be \(elevation, azimuth\) in degrees, got \(10\.0,\)"),
])
def test_animation_arguments(name, kw, message, scenario, track_result, tmp_path):
    kw = dict(kw)
    path = tmp_path / kw.pop("path", "motion.gif")
    with pytest.raises(ValueError, match=message.format(name=name)):
        if name == "animate":
            plotting.animate(scenario, _plan_result(scenario, 2), path, **kw)
        else:
            plotting.animate_tracking(track_result, path, **kw)
    assert not path.exists()
    assert plt.get_fignums() == []


def test_the_path_is_checked_before_the_result(scenario, track_result, tmp_path):
    with pytest.raises(ValueError, match=r"animate_tracking writes GIF files"):
        plotting.animate_tracking(_plan_result(scenario, 2), tmp_path / "x.png")
    with pytest.raises(ValueError, match=r"result must be a TrackResult \(from softplan_jax\.track\); "
                                         r"PlanResult has no 'moving'"):
        plotting.animate_tracking(_plan_result(scenario, 2), tmp_path / "x.gif")
    with pytest.raises(ValueError, match=r"animate writes GIF files"):
        plotting.animate(scenario, track_result, tmp_path / "x.png")
    assert plt.get_fignums() == []


def test_the_package_exports_the_same_names():
    assert sorted(plotting.__all__) == sorted([
        "plot_snapshots", "plot_snapshot_panels", "plot_snapshots_with_clearance", "plot_clearance", "plot_tracking",
        "animate", "animate_tracking", "plot_cloud_fit", "plot_benchmark", "plot_actuators"])
    for name in plotting.__all__:
        assert callable(getattr(plotting, name))
