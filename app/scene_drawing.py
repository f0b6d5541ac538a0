"""The 3D view: a snapshot's map drawn on viser's shared scene, and what a click on it points at.

The map is a textured plane with the agent, its goals and the frontiers on top; on demand, the
scene's ground truth lies over it, labelled as such. The cameras are fitted to the map when an
episode starts, and again whenever the map outgrows the view (while auto-fit is on).

Scene frame: map cell (row, col) -> (x, y) = ((col + 0.5) res, -(row + 0.5) res), z up toward the
camera, so the top-down view shows the map the way its image is stored (row 0 on top).
"""

from __future__ import annotations

import math

import numpy as np
import viser

from l3mvn.core.errors import L3MVNError
from l3mvn.run.session import EpisodeSession
from l3mvn_studio.frontier_ranking import frontier_score, labelled_frontiers
from l3mvn_studio.map_image import ground_truth_layer, score_color
from l3mvn_studio.state import Cell, MapView, Snapshot

MARKER_RADIUS_M = 0.22
_FARTHEST_CELL = 1e9  # farther from the origin than any map (a 48 m map has about 1,000 cells a side)


def cell_to_xy(cell: Cell, res: float) -> tuple[float, float]:
    return (cell[1] + 0.5) * res, -(cell[0] + 0.5) * res


def xy_to_cell(x: float, y: float, res: float) -> Cell:
    return int(math.floor(-y / res)), int(math.floor(x / res))


def ray_to_cell(origin, direction, res: float) -> Cell | None:
    """Where a click ray meets the map plane (z = 0); None when it runs parallel, away, or so far
    off that no map reaches there (a finite 1e308 would overflow as a cell index)."""
    oz, dz = float(origin[2]), float(direction[2])
    if abs(dz) < 1e-9 or -oz / dz < 0:
        return None
    t = -oz / dz
    x, y = float(origin[0]) + t * float(direction[0]), float(origin[1]) + t * float(direction[1])
    if not (abs(x / res) < _FARTHEST_CELL and abs(y / res) < _FARTHEST_CELL):  # NaN and inf fail too
        return None
    return xy_to_cell(x, y, res)


def clicked_cell(view: MapView, origin, direction) -> Cell:
    """The cell a click (a ray of finite numbers) points at on ``view``: the frontier whose marker it
    hits, else the map cell under it; a click beside the map is refused."""
    cell = ray_to_cell(origin, direction, view.resolution_m)
    rows, cols = view.cells
    r0, c0 = view.origin
    if cell is None or not (r0 <= cell[0] < r0 + rows and c0 <= cell[1] < c0 + cols):
        raise L3MVNError("that click is outside the map: click on the map or a frontier")
    reach = (MARKER_RADIUS_M * 1.5 / view.resolution_m) ** 2
    near = [(float((f.cell[0] - cell[0]) ** 2 + (f.cell[1] - cell[1]) ** 2), f.cell) for f in view.frontiers]
    near = [n for n in near if n[0] <= reach]
    return min(near)[1] if near else cell


class MapScene:
    """Builds the scene's handles once; ``draw`` brings them up to date with a snapshot.

    Drawn from one thread at a time (the dashboard's draw loop); ``fit_camera`` only moves a camera.
    """

    def __init__(self, server: viser.ViserServer) -> None:
        self._server = server
        scene = server.scene
        scene.set_up_direction("+y")
        scene.add_light_ambient("/light", intensity=1.0)
        self.map_plane = scene.add_image(
            "/map",
            np.zeros((8, 8, 3), np.uint8),
            1.0,
            1.0,
            format="png",
            cast_shadow=False,
            receive_shadow=False,
            visible=False,
        )
        self.map_note = scene.add_label(
            "/map_note", "Press Reset (or Run) to start an episode", position=(0, 0, 0.2), font_screen_scale=1.4
        )
        self.agent = scene.add_mesh_simple("/agent", *_arrow_mesh(), color=(230, 30, 40), visible=False)
        # Above the frontier spheres (a top-down camera sees it in front of the chosen one).
        self.ltg = scene.add_icosphere("/goal/long_term", 0.16, (220, 20, 60), visible=False)
        self.ltg_label = scene.add_label(
            "/goal/long_term/label", "long-term goal", position=(0.0, -0.3, 0.1), anchor="top-center"
        )
        self.stg = scene.add_icosphere("/goal/short_term", 0.08, (255, 150, 0), visible=False)
        self.gt_plane = scene.add_image(
            "/ground_truth",
            np.zeros((8, 8, 4), np.uint8),
            1.0,
            1.0,
            format="png",
            cast_shadow=False,
            receive_shadow=False,
            visible=False,
        )
        self.gt_label = scene.add_label("/ground_truth_label", "", position=(0, 0, 0.3), visible=False)
        self._markers: list[tuple[viser.IcosphereHandle, viser.LabelHandle]] = []
        self._fitted: tuple | None = None  # (episode, source, crop in cells) the cameras were fitted to
        self._gt_key: tuple | None = None  # what the ground-truth layer was last built for

    def draw(self, snap: Snapshot, *, session: EpisodeSession | None, ground_truth: bool, auto_fit: bool) -> None:
        """Draw ``snap``'s map (the ground truth over it when ``ground_truth`` is on and ``session`` still
        runs its episode), or hide the map while its episode has none yet."""
        if snap.event is not None and snap.event.step == 0:
            self._fitted = None  # a new episode (the same one again too): fit its first map
        if snap.map is not None:
            self._draw_map(snap.map, snap, session if ground_truth else None, auto_fit)
        elif snap.event is not None:
            self._hide_map("the agent's map appears after the first step")

    def fit_camera(self, camera, view: MapView) -> None:
        """Point ``camera`` straight down at ``view``'s map, all of it in sight."""
        x, y, z = _fit_pose(view)
        camera.up_direction = (0.0, 1.0, 0.0)
        camera.position = (x, y, z)  # moves look_at along with it: set look_at after
        camera.look_at = (x, y, 0.0)

    def _draw_map(self, view: MapView, snap: Snapshot, session: EpisodeSession | None, auto_fit: bool) -> None:
        res = view.resolution_m
        _place_plane(self.map_plane, view.image, view.origin, view.cells, res, 0.0)
        ax, ay = cell_to_xy(view.agent_cell, res)
        self.agent.position = (ax, ay, 0.05)
        self.agent.wxyz = (math.cos(-view.agent_heading / 2), 0.0, 0.0, math.sin(-view.agent_heading / 2))
        self.agent.visible = True
        self._draw_long_term_goal(view, snap.manual_goal)
        _place(self.stg, view.short_term_goal, res, 0.08)
        self.map_note.text = (
            "" if view.source == "agent map" else f"ground-truth floor plan: policy {snap.policy!r} keeps no map"
        )
        x0, y0 = cell_to_xy(view.origin, res)
        self.map_note.position = (x0, y0 + 0.4, 0.2)
        self._draw_frontiers(view)
        self._draw_ground_truth(view, snap, session)
        rows, cols = view.cells
        crop = (view.origin[0], view.origin[1], view.origin[0] + rows, view.origin[1] + cols)
        key = (snap.event.episode_key if snap.event else None, view.source)
        if self._fitted is None or key != self._fitted[0] or (auto_fit and not _inside(crop, self._fitted[1])):
            self._fitted = (key, crop)
            self._fit_all(view)

    def _draw_ground_truth(self, view: MapView, snap: Snapshot, session: EpisodeSession | None) -> None:
        """The scene's truth under the agent's knowledge, labelled as such, while ``session`` runs the
        snapshot's episode; otherwise nothing."""
        event = snap.event
        if event is None or session is None or session.episode is None or session.episode.key != event.episode_key:
            self.gt_plane.visible = self.gt_label.visible = False
            return
        key = (event.episode_key, event.goal, view.source, view.world_origin, view.scale)
        if key != self._gt_key:
            task = session.task
            layer = ground_truth_layer(view, task.scene, task.region(event.goal).region, event.goal)
            res = view.resolution_m
            _place_plane(self.gt_plane, layer.image, layer.origin, layer.cells, res, 0.02)
            where = layer.goal_cell if layer.goal_cell is not None else view.agent_cell
            gx, gy = cell_to_xy(where, res)
            self.gt_label.position = (gx, gy, 0.3)
            self.gt_label.text = (
                f"GROUND TRUTH: {event.goal} (not known to the agent)"
                if layer.goal_cell
                else f"GROUND TRUTH: no {event.goal} in this scene"
            )
            self._gt_key = key
        self.gt_plane.visible = self.gt_label.visible = True

    def _draw_long_term_goal(self, view: MapView, manual: Cell | None) -> None:
        """The policy's long-term goal, or a manual goal as soon as it is set (the agent takes it
        on its next step), or nothing once a manual goal is cleared."""
        res, z = view.resolution_m, 2 * MARKER_RADIUS_M + 0.16
        if manual is not None and manual != view.long_term_goal:
            _place(self.ltg, manual, res, z)
            self.ltg_label.text = "manual goal (from the next step)"
        elif view.goal_kind == "manual" and manual is None:
            _place(self.ltg, None, res, z)
            self.ltg_label.text = ""
        else:
            _place(self.ltg, view.long_term_goal, res, z)
            self.ltg_label.text = (
                "manual goal" if view.goal_kind == "manual" else f"long-term goal ({view.goal_kind or '-'})"
            )

    def _draw_frontiers(self, view: MapView) -> None:
        """A sphere per frontier coloured by its score; labels on the best few only (the rest are
        in the Frontiers table), so labels do not pile up on each other."""
        res = view.resolution_m
        while len(self._markers) < len(view.frontiers):
            i = len(self._markers)
            sphere = self._server.scene.add_icosphere(f"/frontiers/{i}", MARKER_RADIUS_M, (150, 150, 150))
            label = self._server.scene.add_label(
                f"/frontiers/{i}/label", "", position=(0.0, 0.3, 0.0), font_screen_scale=0.75, anchor="bottom-center"
            )
            self._markers.append((sphere, label))
        labelled = labelled_frontiers(view.frontiers)
        for i, (sphere, label) in enumerate(self._markers):
            if i >= len(view.frontiers):
                sphere.visible = False
                continue
            f = view.frontiers[i]
            x, y = cell_to_xy(f.cell, res)
            sphere.position = (x, y, MARKER_RADIUS_M)
            sphere.color = score_color(frontier_score(f))
            label.text = (("★ " if f.chosen else "") + f.label) if f.id in labelled else ""
            sphere.visible = True

    def _hide_map(self, note: str) -> None:
        for handle in (self.map_plane, self.agent, self.ltg, self.stg, *(s for s, _ in self._markers)):
            handle.visible = False
        self.ltg_label.text = ""
        self.map_note.text = note

    def _fit_all(self, view: MapView) -> None:
        for client in self._server.get_clients().values():
            self.fit_camera(client.camera, view)
        x, y, z = _fit_pose(view)
        self._server.initial_camera.position = (x, y, z)
        self._server.initial_camera.look_at = (x, y, 0.0)


def _place(handle, cell: Cell | None, res: float, z: float) -> None:
    if cell is None:
        handle.visible = False
        return
    x, y = cell_to_xy(cell, res)
    handle.position = (x, y, z)
    handle.visible = True


def _place_plane(plane, image: np.ndarray, origin: Cell, cells: Cell, res: float, z: float) -> None:
    """Show ``image`` on ``plane`` over map cells ``origin .. origin + cells``, at height ``z``."""
    rows, cols = cells
    (x0, y0), (x1, y1) = cell_to_xy(origin, res), cell_to_xy((origin[0] + rows - 1, origin[1] + cols - 1), res)
    plane.image = image[::-1]  # viser's image plane has row 0 at -y; our row 0 is on top
    plane.render_width, plane.render_height = cols * res, rows * res
    plane.position = ((x0 + x1) / 2, (y0 + y1) / 2, z)
    plane.visible = True


def _fit_pose(view: MapView) -> tuple[float, float, float]:
    """Camera above the map centre, high enough that a 75 deg view shows all of the crop."""
    res = view.resolution_m
    rows, cols = view.cells
    x, y = cell_to_xy((view.origin[0] + rows // 2, view.origin[1] + cols // 2), res)
    extent = max(rows, cols) * res
    # Shifted right so the map sits left of the control panel.
    return x + 0.2 * extent, y, 0.62 * extent / math.tan(math.radians(75) / 2)


def _inside(crop: tuple[int, int, int, int], fitted: tuple[int, int, int, int]) -> bool:
    """Whether map crop (r0, c0, r1, c1) lies within the crop the cameras were fitted to."""
    return fitted[0] <= crop[0] and fitted[1] <= crop[1] and crop[2] <= fitted[2] and crop[3] <= fitted[3]


def _arrow_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A flat arrowhead pointing along +x (the agent's heading), 0.4 m long."""
    v = np.array([[0.25, 0, 0], [-0.15, 0.14, 0], [-0.07, 0, 0], [-0.15, -0.14, 0]], np.float32)
    return v, np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
