"""The browser view (viser): :class:`Viewer` serves one scene, replans on a worker thread when
the goal moves (the latest goal wins: drags that arrive while a plan runs are merged into the
next one), and redraws the arm, the obstacles of a moving scene and the closest points at the
step of the time slider. The panel is :mod:`._panel`; the scene's nodes are :mod:`._drawing`."""

from __future__ import annotations

import contextlib
import io
import threading
import time

import numpy as np

from ._drawing import SceneDrawing
from ._live import LivePlanner, ShownPlan
from ._panel import Panel

__all__ = ["Viewer"]


class _Jobs:
    """The worker's queue: the latest goal (earlier ones dropped), a replan, a fallback."""

    def __init__(self):
        self.cond = threading.Condition()
        self.goal = None  # (goal, time posted)
        self.other = []  # "plan" | "fallback"
        self.busy = False
        self.closed = False

    def post(self, kind: str, goal=None) -> None:
        with self.cond:
            if kind == "goal":
                self.goal = (np.asarray(goal, np.float64), time.perf_counter())
            elif kind not in self.other:
                self.other.append(kind)
            self.cond.notify_all()

    def take(self):
        """The next job, ``(kind, goal, posted)``, waiting for one; None once closed."""
        with self.cond:
            while not self.closed and self.goal is None and not self.other:
                self.cond.wait()
            if self.closed:
                return None
            self.busy = True
            if self.goal is not None:
                (goal, posted), self.goal = self.goal, None
                if "plan" in self.other:
                    self.other.remove("plan")  # the goal's plan is the replan
                return "goal", goal, posted
            return self.other.pop(0), None, time.perf_counter()

    def done(self) -> None:
        with self.cond:
            self.busy = False
            self.cond.notify_all()

    def wait_idle(self, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: not self.busy and self.goal is None and not self.other, timeout)

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()


class Viewer:
    """An interactive 3-D view of one scene in the browser, served by viser.

    Args:
      planner: the scene and its planner (:class:`~softplan_jax.viewer._live.LivePlanner`).
      shown: a plan to show first (None: plan the scene's goal).
      host, port: where to serve; a port in use is skipped for the next free one (``port``
        then differs from the one asked for: :attr:`port_in_use`).
      label: the scene's name, in the panel.

    Attributes:
      server: the ``viser.ViserServer``. planner: the LivePlanner. shown: the ShownPlan on show.
      plans: how many plans have been shown. latencies: seconds from each goal update (a drag
        or :meth:`set_goal`) to its new arm's meshes handed to the server and flushed; of which
        plan_times: the plan's own seconds.
    """

    def __init__(self, planner: LivePlanner, shown: ShownPlan | None = None, *, host: str = "127.0.0.1",
                 port: int = 8080, label: str = "softplan"):
        import viser

        self.planner, self.requested_port, self.scene_label = planner, int(port), label
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: the caller prints the address
            self.server = viser.ViserServer(host=host, port=int(port), label=f"softplan: {label}", verbose=False)
        self.server.gui.configure_theme(control_width="medium", show_share_button=False)
        self._lock = threading.RLock()
        self._jobs = _Jobs()
        self.shown, self.plans, self.latencies, self.plan_times, self.step = None, 0, [], [], 0
        self.arm_vertices = []
        self._playing = threading.Event()
        q0 = np.asarray(planner.scene.q0, np.float64)
        self.drawing = SceneDrawing(self.server, planner, planner.goal, planner.backbone(q0))
        self.drawing.camera()
        self.drawing.gizmo.on_update(self._on_drag)
        self.panel = Panel(self)
        self._worker = threading.Thread(target=self._work, name="softplan-viewer", daemon=True)
        self._worker.start()
        threading.Thread(target=self._play_loop, name="softplan-viewer-play", daemon=True).start()
        if shown is None:
            self.panel.say("compiling the planner, or loading it from the cache (once per scene shape and "
                           "option set) ...")
            self._jobs.post("plan")
        else:
            self.show(shown)

    # --- the address --------------------------------------------------------------------------

    @property
    def port(self) -> int:
        """The port served (the next free one where the one asked for was in use)."""
        return self.server.get_port()

    @property
    def port_in_use(self) -> bool:
        """Whether the port asked for was in use, so another one is served."""
        return self.requested_port != 0 and self.port != self.requested_port

    @property
    def url(self) -> str:
        """The page's address (``localhost`` where the server listens on every interface)."""
        host = self.server.get_host()
        return f"http://{'localhost' if host in ('0.0.0.0', '::', '') else host}:{self.port}"

    # --- goals and plans ----------------------------------------------------------------------

    def _on_drag(self, event) -> None:
        """The goal handle moved in a browser: replan for its position."""
        self._jobs.post("goal", np.asarray(event.target.position, np.float64))

    def set_goal(self, goal) -> None:
        """Move the goal (3,) as a drag would: the handle moves in every browser and the scene is
        replanned on the worker thread (returns at once; :meth:`wait_idle` waits for the plan).
        ValueError for a goal that is not 3 finite numbers."""
        g = np.asarray(goal, np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"goal must be 3 finite numbers, got {goal!r}")
        self.drawing.gizmo.position = g
        self._jobs.post("goal", g)

    def replan(self) -> None:
        """Plan again with the current goal and method (on the worker thread)."""
        self._jobs.post("plan")

    def fall_back(self) -> None:
        """Run the global fallback on the current goal (on the worker thread)."""
        self._jobs.post("fallback")

    def wait_idle(self, timeout: float = 600.0) -> bool:
        """Wait until every posted plan is shown; False if ``timeout`` seconds passed first."""
        return self._jobs.wait_idle(timeout)

    def _work(self) -> None:
        while (job := self._jobs.take()) is not None:
            kind, goal, posted = job
            try:
                self._run(kind, goal, posted)
            except Exception as err:  # noqa: BLE001 - shown in the panel; the view goes on
                self.panel.say(f"error: {type(err).__name__}: {' '.join(str(err).split())}")
            finally:
                self._jobs.done()

    def _run(self, kind: str, goal, posted: float) -> None:
        if kind == "goal":
            self.planner.set_goal(goal)
        if kind == "fallback":
            self.panel.say("searching globally: reachability, then the certified search (their programs "
                           "compile on the first search, about a minute) ...")
            shown = self.planner.fallback()
        else:
            warm, t0 = self.planner.is_compiled, time.perf_counter()
            shown = self.planner.plan()
            self.panel.plan_time, self.panel.plan_warm = time.perf_counter() - t0, warm
        self.show(shown)
        if kind == "goal":
            self.latencies.append(time.perf_counter() - posted)
            self.plan_times.append(self.panel.plan_time)
        elif self.plans == 1:  # the closest points' program compiled before it is asked for
            self.planner.closest(shown.q[-1], 0.0 if shown.time is None else float(shown.time[-1]))

    def show(self, shown: ShownPlan) -> None:
        """Show a plan: its tip path, its last step, the panel's outcome (and flush to the browsers)."""
        with self._lock, self.server.atomic():
            self.shown = shown
            self.plans += 1
            self.drawing.new_plan(shown, self.panel.show_path)
            self.panel.new_plan(shown)
            self.draw(shown.q.shape[0] - 1)
        self.server.flush()

    # --- the step on show ---------------------------------------------------------------------

    def draw(self, k: int) -> list[np.ndarray]:
        """Draw step k of the plan on show (clipped to its steps): the arm, a moving scene's
        obstacles and goal, the closest points if on; returns the arm segments' vertices."""
        with self._lock:
            if self.shown is None:
                return []
            k = int(np.clip(k, 0, self.shown.q.shape[0] - 1))
            self.step = k
            t = 0.0 if self.shown.time is None else float(self.shown.time[k])
            verts = self.drawing.arm(self.planner.backbone(self.shown.q[k]))
            if self.planner.moving:
                self.drawing.obstacles_at(*self.planner.curve_poses(t))
            self.drawing.goal_at(self.shown.goal[k])
            pairs = self.planner.closest(self.shown.q[k], t) if self.panel.show_closest else None
            self.drawing.closest_pairs(pairs, self.panel.show_closest)
            self.panel.at_step(k)
            self.arm_vertices = verts
            return verts

    def play(self, on: bool = True) -> None:
        """Play the plan from its start (or from the step shown, if not at the end), or pause."""
        if on:
            if self.shown is not None and self.step >= self.shown.q.shape[0] - 1:
                self.panel.set_step(0)
            self._playing.set()
        else:
            self._playing.clear()
        self.panel.playing(on)

    def _play_loop(self, fps: float = 25.0) -> None:
        while True:
            self._playing.wait()
            time.sleep(1.0 / fps)
            if not self._playing.is_set():
                continue
            with self._lock:
                last = self.shown is None or self.step >= self.shown.q.shape[0] - 1
                if not last:
                    self.panel.set_step(self.step + 1)
            if last:
                self.play(False)

    # --- lifetime -----------------------------------------------------------------------------

    def wait(self) -> None:
        """Serve until Ctrl-C (then stop the server and return) or :meth:`stop`."""
        try:
            while not self._jobs.closed:
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def stop(self) -> None:
        """Stop the worker and the server (the page disconnects)."""
        if self._jobs.closed:
            return
        self._jobs.close()
        self._playing.clear()
        self.server.stop()
