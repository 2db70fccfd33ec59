"""The viewer's control panel (viser GUI): the plan's outcome (status, iterations, minimum
clearance, tip error, planner, time to plan), the fallback button of a plan that stopped short,
the time slider and play button, the goal as numbers, the obstacle model (curve or N points)
and the toggles for the closest points, the tip path and shadows."""

from __future__ import annotations

from ._live import ShownPlan

__all__ = ["Panel", "outcome_text"]


def outcome_text(shown: ShownPlan, scene_label: str, method: str, plan_time: float | None, number: int,
                 warm: bool = True) -> str:
    """The panel's Markdown account of a plan (the ``number``-th shown; ``warm``: its planner was
    compiled before it)."""
    status = f"**{shown.status}**" + (f" ({shown.reason.replace('_', ' ')})" if shown.reason else "")
    if not shown.succeeded:
        status += " &mdash; the goal is not reached"
    planner = {"local": "local (potential field, paper eq. 9)", "global": "global search (plan_fallback)",
               "search": "guided by the global search (track_fallback)"}.get(shown.planner, shown.planner)
    lines = [f"{scene_label} &middot; {method} &middot; plan {number}", f"status: {status}",
             f"iterations: {shown.iterations}",
             f"min clearance: {shown.min_clearance:.4f}" + (" (collided)" if shown.collided else ""),
             f"final tip error: {shown.final_error:.4f}", f"planner: {planner}"]
    if shown.source not in ("plan", "fallback"):
        lines.append(f"from: {shown.source}")
    elif plan_time is not None and shown.source == "plan":
        lines.append(f"planned in {plan_time * 1e3:.0f} ms" + ("" if warm else " (compiling or loading its planner)"))
    return "  \n".join(lines)


class Panel:
    """The GUI of one :class:`~softplan_jax.viewer._app.Viewer` (built on its server)."""

    def __init__(self, viewer):
        self.viewer = viewer
        gui = viewer.server.gui
        planner = viewer.planner
        self.plan_time, self.plan_warm = None, True
        self._quiet = False
        self.label = getattr(viewer, "scene_label", "scene")
        self.outcome = gui.add_markdown("starting ...")
        self.fallback = gui.add_button("Fallback: global search", disabled=True,
                                       hint="reachability, then the certified search (plan_fallback / track_fallback)")
        self.fallback.on_click(lambda _: viewer.fall_back())
        self.slider = gui.add_slider("step", min=0, max=1, step=1, initial_value=0)
        self.slider.on_update(self._on_slider)
        self.clock = gui.add_markdown("")
        self.play_button = gui.add_button("Play")
        self.play_button.on_click(lambda _: viewer.play(self.play_button.label == "Play"))
        self.goal = gui.add_vector3("goal", initial_value=tuple(float(x) for x in planner.goal), step=0.01)
        self.goal.on_update(self._on_goal)
        self.method = gui.add_dropdown("obstacle model", ("curve", "points"), initial_value=planner.method)
        self.n_points = gui.add_number("N points", initial_value=planner.n_points, min=1, max=1000, step=1,
                                       visible=planner.method == "points")
        self.method.on_update(self._on_method)
        self.n_points.on_update(self._on_method)
        self.closest = gui.add_checkbox("closest points", initial_value=False,
                                        hint="the exact closest points and clearance segments at the step shown")
        self.closest.on_update(lambda _: viewer.draw(viewer.step))
        self.path = gui.add_checkbox("tip path", initial_value=True)
        self.path.on_update(self._on_path)
        self.shadows = gui.add_checkbox("shadows", initial_value=False,
                                        hint="shadows on the ground (slow to draw in a browser without a GPU)")
        self.shadows.on_update(lambda _: viewer.server.scene.configure_default_lights(True, bool(self.shadows.value)))
        viewer.drawing.show_model(planner.method, planner.n_points)

    @property
    def show_closest(self) -> bool:
        return bool(self.closest.value)

    @property
    def show_path(self) -> bool:
        return bool(self.path.value)

    def say(self, text: str) -> None:
        """A line of news (compiling, searching, an error) in place of the outcome."""
        self.outcome.content = text

    def new_plan(self, shown: ShownPlan) -> None:
        """The outcome of a new plan, its slider range and its goal (as numbers)."""
        method = self.viewer.planner.method
        if method == "points":
            method += f" (N = {self.viewer.planner.n_points})"
        self.outcome.content = outcome_text(shown, self.label, method, self.plan_time, self.viewer.plans,
                                            self.plan_warm)
        self.fallback.disabled = not self.viewer.planner.can_fall_back(shown)
        self._quiet = True
        try:
            self.slider.max = max(shown.q.shape[0] - 1, 1)
            self.slider.value = shown.q.shape[0] - 1
            self.goal.value = tuple(float(x) for x in self.viewer.planner.goal)
        finally:
            self._quiet = False

    def at_step(self, k: int) -> None:
        """The clock line of step k."""
        shown = self.viewer.shown
        t = "" if shown.time is None else f", t = {shown.time[k]:.2f} s"
        self.clock.content = f"step {k} of {shown.q.shape[0] - 1}{t}"

    def set_step(self, k: int) -> None:
        """Move the slider to step k (which draws it)."""
        if self.slider.value == k:
            self.viewer.draw(k)
        else:
            self.slider.value = k

    def playing(self, on: bool) -> None:
        self.play_button.label = "Pause" if on else "Play"

    def _on_slider(self, _) -> None:
        if not self._quiet:
            self.viewer.draw(int(self.slider.value))

    def _on_goal(self, _) -> None:
        if self._quiet:
            return
        try:
            self.viewer.set_goal(self.goal.value)
        except ValueError as err:
            self.say(f"goal: {err}")

    def _on_method(self, _) -> None:
        method, n = self.method.value, int(self.n_points.value)
        self.n_points.visible = method == "points"
        try:
            self.viewer.planner.set_method(method, n)
        except ValueError as err:
            self.say(f"obstacle model: {err}")
            return
        self.viewer.drawing.show_model(method, n)
        self.say("compiling the planner for this obstacle model (once), or loading it from the cache ...")
        self.viewer.replan()

    def _on_path(self, _) -> None:
        if self.viewer.drawing.path is not None:
            self.viewer.drawing.path.visible = self.show_path
