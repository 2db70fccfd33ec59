"""The 3-D scene of the view in viser: the obstacles as tubes along their curves (point sets as
spheres), the arm as a tube of its radius with its segment boundaries marked, the goal as a
draggable handle, the tip path, and the exact closest points with their clearance segments;
each drawn from NumPy meshes (:mod:`._meshes`) and updated in place as the step changes."""

from __future__ import annotations

import numpy as np

from ._live import ARM_SAMPLES, LivePlanner, ShownPlan
from ._meshes import merge_meshes, polyline_segments, sphere_mesh, tube_mesh

__all__ = ["COLORS", "display_radii", "SceneDrawing"]

COLORS = {
    "arm": [(66, 133, 244), (25, 90, 190)],  # segments alternate
    "arm_failed": [(230, 110, 80), (190, 70, 50)],  # a plan that did not reach its goal
    "joint": (40, 40, 40),
    "curve": (140, 90, 43),  # branch brown
    "points": (107, 68, 35),
    "model": (250, 250, 250),  # the N points of the N-point model
    "goal": (242, 183, 5),
    "path": (68, 68, 68),
    "path_global": (27, 158, 119),  # the part found by the global search
    "clear": (0, 150, 136),
    "contact": (220, 30, 30),
}


def display_radii(planner: LivePlanner) -> tuple[float, float]:
    """``(arm radius, thinnest obstacle radius)`` as drawn: the scene's radii, or where a radius
    is 0 (a backbone, a wire), 1 % (arm) and 0.6 % (obstacles) of the arm's length, so that it shows."""
    length = float(np.sum(np.asarray(planner.scene.q0)[:, 0]))
    arm = float(planner.scene.arm_radius)
    return (arm if arm > 0 else 0.01 * length), 0.006 * length


def _wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) (w, x, y, z) of rotation matrices (..., 3, 3) (viser's transforms)."""
    from viser.transforms import SO3

    return np.asarray(SO3.from_matrix(R).wxyz, np.float64)


class SceneDrawing:
    """The scene nodes of one view and their updates (call under the viewer's lock)."""

    def __init__(self, server, planner: LivePlanner, goal, backbone: np.ndarray):
        self.server, self.planner = server, planner
        self.arm_radius, self.min_radius = display_radii(planner)
        self.n = planner.scene.n_segments
        scene = server.scene
        scene.set_up_direction("+z")
        # Lights instead of viser's image-based environment map, and no shadows unless asked
        # for (the panel): in a browser without a GPU (software WebGL) each multiplies the time
        # to draw a frame (the documentation's viewer page has the measurements).
        scene.configure_environment_map(None)
        scene.configure_default_lights(True, cast_shadow=False)
        scene.add_light_ambient("/light/ambient", intensity=0.6)
        scene.add_light_hemisphere("/light/sky", intensity=0.8)
        scene.add_grid("/ground", width=6.0, height=6.0, cell_size=0.25, section_size=1.0, position=(0.0, 0.0, 0.0))
        self.curves = {}  # slot -> mesh handle of a polynomial curve (moves in a moving scene)
        self.models = []  # the N-point model's spheres, one mesh per curve
        self._add_obstacles()
        self.segments = [scene.add_mesh_simple(f"/arm/segment_{i}", *self._segment(backbone, i),
                                               color=COLORS["arm"][i % 2]) for i in range(self.n)]
        jv, jf = sphere_mesh(1.35 * self.arm_radius)
        self.joints = scene.add_batched_meshes_simple(
            "/arm/joints", jv, jf, batched_wxyzs=np.tile([1.0, 0, 0, 0], (self.n + 1, 1)),
            batched_positions=backbone[::ARM_SAMPLES], batched_colors=COLORS["joint"], lod="off")
        self.gizmo = scene.add_transform_controls("/goal", scale=0.35, disable_rotations=True, depth_test=False,
                                                  position=tuple(np.asarray(goal, float)))
        gv, gf = sphere_mesh(2.0 * self.arm_radius)
        self.goal_marker = scene.add_mesh_simple("/goal_now", gv, gf, color=COLORS["goal"],
                                                 position=tuple(np.asarray(goal, float)))
        self.path = None
        self._add_closest(len(planner.real_slots))

    def _add_closest(self, k: int) -> None:
        """Hidden nodes for the closest pairs of k obstacles: segments, points and labels (none if k = 0)."""
        self.closest = self.closest_points = None
        self.labels = []
        if k == 0:
            return
        scene = self.server.scene
        self.closest = scene.add_line_segments("/closest/segments", np.zeros((k, 2, 3)), COLORS["clear"],
                                               thickness=0.4 * self.arm_radius, visible=False)
        pv, pf = sphere_mesh(0.8 * self.arm_radius, rings=6, sides=8)
        self.closest_points = scene.add_batched_meshes_simple(
            "/closest/points", pv, pf, batched_wxyzs=np.tile([1.0, 0, 0, 0], (2 * k, 1)),
            batched_positions=np.zeros((2 * k, 3)), batched_colors=COLORS["clear"], lod="off", visible=False)
        self.labels = [scene.add_label(f"/closest/label_{j}", "", visible=False, font_screen_scale=0.8)
                       for j in range(k)]

    def _add_obstacles(self) -> None:
        """Tubes along the curves (rest pose; a moving scene's curves are moved by their node's
        pose) and one mesh of spheres per point set."""
        scene = self.server.scene
        for ob in self.planner.obstacles:
            r = max(ob["radius"], self.min_radius)
            slot = ob["slot"]
            if ob["kind"] == "curve":
                v, f = tube_mesh(ob["pts"], r)
                h = scene.add_mesh_simple(f"/obstacles/curve_{slot}", v, f, color=COLORS["curve"])
                if slot < self.planner.curve_slots:
                    self.curves[slot] = h
            else:
                sv, sf = sphere_mesh(r, rings=6, sides=10)
                v, f = merge_meshes([(sv + p.astype(np.float32), sf) for p in ob["pts"]])
                scene.add_mesh_simple(f"/obstacles/points_{slot}", v, f, color=COLORS["points"])

    def show_model(self, method: str, n_points: int) -> None:
        """The N points of each curve under the N-point model (method "points"; paper §3: N = 1
        the middle of the range, N >= 2 both ends included), drawn as small spheres; none for
        the curve method."""
        for h in self.models:
            h.remove()
        self.models = []
        if method != "points":
            return
        sv, sf = sphere_mesh(1.6 * self.min_radius, rings=4, sides=6)
        for ob in self.planner.obstacles:
            if ob["kind"] != "curve":
                continue
            pts = ob["pts"]
            idx = [len(pts) // 2] if n_points == 1 else np.round(np.linspace(0, len(pts) - 1, n_points)).astype(int)
            v, f = merge_meshes([(sv + pts[i].astype(np.float32), sf) for i in idx])
            self.models.append(self.server.scene.add_mesh_simple(f"/obstacles/curve_{ob['slot']}/model", v, f,
                                                                 color=COLORS["model"]))

    def new_plan(self, shown: ShownPlan, show_path: bool) -> None:
        """The tip path of a new plan (its global part in another colour) and the arm's colours."""
        seg = polyline_segments(shown.tip)
        colors = np.tile(np.asarray(COLORS["path"], np.uint8), (len(seg), 2, 1))
        if shown.global_start is not None:
            colors[shown.global_start:] = COLORS["path_global"]
        if len(seg) == 0:  # a plan of no step: an invisible dot
            seg, colors = np.repeat(shown.tip[:1, None], 2, axis=1).astype(np.float32), np.zeros((1, 2, 3), np.uint8)
        self.path = self.server.scene.add_line_segments("/tip_path", seg, colors, thickness=0.3 * self.arm_radius,
                                                        visible=show_path)
        palette = COLORS["arm" if shown.succeeded else "arm_failed"]
        for i, h in enumerate(self.segments):
            h.color = palette[i % 2]

    def _segment(self, backbone: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray]:
        """The tube mesh of segment i of a backbone (n * ARM_SAMPLES + 1, 3)."""
        return tube_mesh(backbone[i * ARM_SAMPLES:(i + 1) * ARM_SAMPLES + 1], self.arm_radius)

    def arm(self, backbone: np.ndarray) -> list[np.ndarray]:
        """Move the arm to a backbone (n * ARM_SAMPLES + 1, 3); returns the segments' vertices."""
        out = []
        for i, h in enumerate(self.segments):
            v = self._segment(backbone, i)[0]
            h.vertices = v
            out.append(v)
        self.joints.batched_positions = backbone[::ARM_SAMPLES].astype(np.float32)
        return out

    def obstacles_at(self, R: np.ndarray, p: np.ndarray) -> None:
        """A moving scene's curves at one instant: their rigid poses R (m_c, 3, 3), p (m_c, 3)."""
        if not self.curves:
            return
        q = _wxyz(R)
        for slot, h in self.curves.items():
            h.wxyz, h.position = q[slot], p[slot]

    def goal_at(self, goal) -> None:
        """The goal marker at the goal of the step shown (a moving goal moves)."""
        self.goal_marker.position = np.asarray(goal, np.float64)

    def closest_pairs(self, pairs, visible: bool) -> None:
        """The exact closest points and clearance segments (arm point -> obstacle point) with
        the clearance written beside each, or hidden; ``pairs`` from
        :meth:`~.live.LivePlanner.closest`."""
        if self.closest is None:
            return
        for h in (self.closest, self.closest_points, *self.labels):
            h.visible = visible
        if not visible or pairs is None:
            return
        a, o, c = pairs
        color = np.where((c <= 0)[:, None], COLORS["contact"], COLORS["clear"]).astype(np.uint8)
        self.closest.points = np.stack([a, o], axis=1).astype(np.float32)
        self.closest.colors = np.repeat(color[:, None], 2, axis=1)
        self.closest_points.batched_positions = np.concatenate([a, o]).astype(np.float32)
        self.closest_points.batched_colors = np.concatenate([color, color])
        for j, h in enumerate(self.labels):
            h.position = 0.5 * (a[j] + o[j])
            h.text = f"{c[j]:.3f}"

    def camera(self) -> None:
        """The initial camera: looking at the middle of the arm's reach and the goal, from the front right."""
        L = float(np.sum(np.asarray(self.planner.scene.q0)[:, 0]))
        centre = 0.5 * (np.array([0.0, 0.0, 0.5 * L]) + self.planner.goal)
        self.server.initial_camera.look_at = centre
        self.server.initial_camera.position = centre + L * np.array([0.55, -0.75, 0.3])
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
