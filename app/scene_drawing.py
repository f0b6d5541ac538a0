"""The 3D view: a snapshot's map drawn on viser's shared scene, and what a click on it points at.

The map is a textured plane with the agent, its goals and the frontiers on top; on demand, the
scene's ground truth lies over it, labelled as such. The cameras are fitted to the map when an
episode starts, and again whenever the map outgrows the view (while auto-fit is on).

Frontier spheres are coloured on the score scale fitted to the step's scores and sized so no two
touch (a click picks the nearest). Their labels, and the long-term goal's, are sized in metres for
the zoom of the most zoomed-out page at each draw and placed apart (``label_placement``), so no
label covers another, a marker or the agent; a label moved off its point has a leader line.
The map's picture is re-sent only now and then; the cells changed since are drawn over it as
points, which the page draws in the frame they arrive in (``map_patches``).

Scene frame: map cell (row, col) -> (x, y) = ((col + 0.5) res, -(row + 0.5) res), z up toward the
camera, so the top-down view shows the map the way its image is stored (row 0 on top).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import viser

from l3mvn.core.errors import L3MVNError
from l3mvn.run.session import EpisodeSession
from l3mvn.run.viz import AGENT_RGB, GOAL_RGB, SHORT_TERM_GOAL_RGB
from l3mvn_studio.frontier_ranking import frontier_score, labelled_frontiers
from l3mvn_studio.label_placement import Box, LabelRequest, PlacedLabel, place_labels
from l3mvn_studio.map_image import frontier_colors, ground_truth_layer
from l3mvn_studio.map_patches import CellPicture, PicturePatches
from l3mvn_studio.state import Cell, FrontierMarker, MapView, Snapshot

MARKER_RADIUS_M = 0.22  # a lone frontier's sphere; crowded ones get smaller (never under the minimum)
MIN_MARKER_RADIUS_M = 0.06
LABEL_PX = 13.0  # a map label's em on screen, in CSS pixels, at the zoom the labels were last placed for
_AGENT_HALF_M = 0.25  # the agent's arrow is 0.4 m long: labels keep off a square this size round it
_GOAL_RING_M = 0.06  # the long-term goal's ring round a point with no frontier (a manual goal): its hole
_FIT_FOV = math.radians(75)  # what _fit_pose assumes of a page's camera before any page reports its own
_FIT_MARGIN = 1.1  # a fitted map leaves a tenth of the canvas around it: its edge frontiers' labels fit
_FIT_HEIGHT_PX = 900
_LEADER_RGB = (235, 235, 235)  # frontiers border unexplored space: a light line reads there
# Labels lie on the map (drawn over everything all the same): one held above it would be seen off
# its place by a camera not straight above it, and placement works in the map's plane.
_LABEL_Z = 0.01
_LABEL_POOL = 16  # frontier labels made with the scene; more are made when a map has more frontiers
_GLYPHS = "★F0123456789.-() abcdefghijklmnopqrstuvwxyz"
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
        # The cells changed since the picture was sent, drawn over it (see map_patches).
        self.map_patch = scene.add_point_cloud(
            "/map_patch",
            np.zeros((1, 3), np.float32),
            np.zeros((1, 3), np.uint8),
            point_size=0.05,
            point_shape="square",
            point_shading="flat",  # each cell one colour, as in the picture under it
            precision="float32",
            visible=False,
        )
        # Every glyph the map's labels use, drawn once at a size nothing shows, so the page has them
        # all before the first label: glyphs drawn later arrive a few per frame and a label could
        # stay blank until the next update.
        scene.add_label(
            "/labels/glyphs", _GLYPHS, position=(0.0, 0.0, -1.0), font_size_mode="scene", font_scene_height=1e-4
        )
        self.map_note = scene.add_label(
            "/map_note",
            "Press Reset (or Run) to start an episode",
            position=(0, 0, 0.2),
            font_screen_scale=1.4,
            anchor="center-center",  # on the canvas's centre, whatever its width between the panels
        )
        self.agent = scene.add_mesh_simple("/agent", *_arrow_mesh(), color=AGENT_RGB, visible=False)
        # A flat ring round the frontier it marks: on the map, seen in its place from any camera.
        self.ltg = scene.add_mesh_simple("/goal/long_term", *_ring_mesh(0.2, 0.26), color=GOAL_RGB, visible=False)
        self._ring = (0.2, 0.26)
        self.ltg_label = _add_map_label(scene, "/labels/long_term_goal")
        self.stg = scene.add_icosphere("/goal/short_term", 0.08, SHORT_TERM_GOAL_RGB, visible=False)
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
        self.leaders = scene.add_line_segments(
            "/labels/leaders", np.zeros((1, 2, 3), np.float32), _LEADER_RGB, thickness=2.0, thickness_units="screen"
        )
        self.leaders.visible = False
        self._markers: list[viser.IcosphereHandle] = []
        # Made up front, outside any atomic batch: a label made and shown in one batch may stay blank.
        self._labels = [_add_map_label(scene, f"/labels/{i}") for i in range(_LABEL_POOL)]
        self._ltg_text = ""
        self._patches = PicturePatches()
        self._patch_cells: np.ndarray | None = None  # the cells the patch shows now
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

    def shown_labels(self) -> list[viser.LabelHandle]:
        """The map's labels shown now: the long-term goal's and the frontiers' (what a page sees)."""
        return [h for h in (self.ltg_label, *self._labels) if h.visible and h.text]

    def fit_camera(self, camera, view: MapView) -> None:
        """Point ``camera`` straight down at ``view``'s map, all of it in sight on that page's canvas."""
        x, y, z = _fit_pose(view, *_page_view(camera))
        camera.up_direction = (0.0, 1.0, 0.0)
        camera.position = (x, y, z)  # moves look_at along with it: set look_at after
        camera.look_at = (x, y, 0.0)

    def _draw_map(self, view: MapView, snap: Snapshot, session: EpisodeSession | None, auto_fit: bool) -> None:
        res = view.resolution_m
        self._draw_picture(view)
        ax, ay = cell_to_xy(view.agent_cell, res)
        self.agent.position = (ax, ay, 0.05)
        self.agent.wxyz = (math.cos(-view.agent_heading / 2), 0.0, 0.0, math.sin(-view.agent_heading / 2))
        self.agent.visible = True
        self._draw_long_term_goal(view, snap.manual_goal)
        _place(self.stg, view.short_term_goal, res, 0.0)
        self.map_note.text = (
            "" if view.source == "agent map" else f"ground-truth floor plan: policy {snap.policy!r} keeps no map"
        )
        rows, cols = view.cells
        x0, y0 = cell_to_xy((view.origin[0], view.origin[1] + cols // 2), res)
        self.map_note.position = (x0, y0 + 0.4, 0.2)  # centred above the map's top edge
        self._draw_ground_truth(view, snap, session)
        crop = (view.origin[0], view.origin[1], view.origin[0] + rows, view.origin[1] + cols)
        key = (snap.event.episode_key if snap.event else None, view.source)
        fitted = self._fitted is None or key != self._fitted[0] or (auto_fit and not _inside(crop, self._fitted[1]))
        if fitted:
            self._fitted = (key, crop)
            self._fit_all(view)
        self._draw_frontiers(view, self._em_m(view, fitted))

    def _draw_picture(self, view: MapView) -> None:
        """The map's picture when it is due, and the cells changed since drawn over it as points."""
        res, k = view.resolution_m, view.scale
        patch = self._patches.update(CellPicture(view.image[k // 2 :: k, k // 2 :: k], view.origin, res))
        if patch.send_picture:
            _place_plane(self.map_plane, view.image, view.origin, view.cells, res, 0.0)
        self.map_plane.visible = True
        if not len(patch.cells):
            self.map_patch.visible = False
            return
        shown = np.concatenate([patch.cells, patch.colours], axis=1)
        if self._patch_cells is None or not np.array_equal(shown, self._patch_cells):
            rows, cols = patch.cells[:, 0], patch.cells[:, 1]
            points = np.stack([(cols + 0.5) * res, -(rows + 0.5) * res, np.full(len(rows), 0.004)], axis=1)
            self.map_patch.points = points.astype(np.float32)
            self.map_patch.colors = np.ascontiguousarray(patch.colours, np.uint8)
            self.map_patch.point_size = res * 1.05  # squares overlap a little: no seam between cells
            self._patch_cells = shown
        self.map_patch.visible = True

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
        on its next step), or nothing once a manual goal is cleared. Its label is placed with the
        frontiers' (``_draw_frontiers``)."""
        res, z = view.resolution_m, 0.02
        if manual is not None and manual != view.long_term_goal:
            _place(self.ltg, manual, res, z)
            self._ltg_text = "manual goal (from the next step)"
        elif view.goal_kind == "manual" and manual is None:
            _place(self.ltg, None, res, z)
            self._ltg_text = ""
        else:
            _place(self.ltg, view.long_term_goal, res, z)
            self._ltg_text = (
                "manual goal" if view.goal_kind == "manual" else f"long-term goal ({view.goal_kind or '-'})"
            )

    def _em_m(self, view: MapView, fitted: bool) -> float:
        """A label's em in metres: ``LABEL_PX`` pixels on the most zoomed-out page now (after a fit,
        at the fitted view), so labels placed apart in metres are apart on every page."""
        per_px = []
        heights = []
        for client in self._server.get_clients().values():
            cam = client.camera
            height = int(getattr(cam, "image_height", 0) or 0)
            heights.append(height)
            if fitted:  # the camera was just told to move: the page has not reported its new pose yet
                depth = _fit_pose(view, *_page_view(cam))[2]
            else:
                depth = float(np.linalg.norm(np.asarray(cam.position) - np.asarray(cam.look_at)))
            if height > 0 and depth > 0 and 0 < cam.fov < math.pi:
                per_px.append(LABEL_PX * 2 * depth * math.tan(cam.fov / 2) / height)
        return max(per_px) if per_px else fitted_em_m(view, min((h for h in heights if h > 0), default=_FIT_HEIGHT_PX))

    def _draw_frontiers(self, view: MapView, em_m: float) -> None:
        """A sphere per frontier in its fitted score colour, sized apart from its neighbours; then
        the labels placed apart (``map_labels``)."""
        while len(self._markers) < len(view.frontiers):
            i = len(self._markers)
            self._markers.append(self._server.scene.add_icosphere(f"/frontiers/{i}", MARKER_RADIUS_M, (150, 150, 150)))
        goal = None
        if self.ltg.visible and self._ltg_text:
            goal = (self._ltg_text, (float(self.ltg.position[0]), float(self.ltg.position[1])))
        layout = map_labels(view, goal, em_m)
        colors = frontier_colors(view.frontiers)
        for i, sphere in enumerate(self._markers):
            if i >= len(view.frontiers):
                sphere.visible = False
                continue
            x, y = cell_to_xy(view.frontiers[i].cell, view.resolution_m)
            sphere.position = (x, y, 0.0)  # centred on the map: its outline, seen from above, is where it is
            sphere.radius = layout.radii[i]
            sphere.color = colors[i]
            sphere.visible = True
        if goal is not None and layout.goal_ring != self._ring:
            self.ltg.vertices = _ring_mesh(*layout.goal_ring)[0]
            self._ring = layout.goal_ring
        self._show_labels(layout.placed, em_m)

    def _show_labels(self, placed: list[PlacedLabel | None], em_m: float) -> None:
        """``placed`` (the goal's label first) onto the label handles (made as needed), the rest
        hidden; leader lines for the labels moved off their point."""
        while len(self._labels) < len(placed) - 1:
            self._labels.append(_add_map_label(self._server.scene, f"/labels/{len(self._labels)}"))
        handles = [self.ltg_label, *self._labels]
        leaders = []
        for i, handle in enumerate(handles):
            p = placed[i] if i < len(placed) else None
            if p is None:
                handle.visible = False
                continue
            handle.text = p.text
            handle.font_scene_height = em_m
            handle.anchor = p.anchor
            handle.position = (p.at[0], p.at[1], _LABEL_Z)
            handle.visible = True
            if p.leader is not None:
                leaders.append([(*p.leader[0], _LABEL_Z), (*p.leader[1], _LABEL_Z)])
        if leaders:
            self.leaders.points = np.asarray(leaders, np.float32)
            self.leaders.colors = np.broadcast_to(np.asarray(_LEADER_RGB, np.uint8), (len(leaders), 2, 3)).copy()
        self.leaders.visible = bool(leaders)

    def _hide_map(self, note: str) -> None:
        for handle in (
            self.map_plane,
            self.map_patch,
            self.agent,
            self.ltg,
            self.stg,
            self.ltg_label,
            self.leaders,
            *self._markers,
        ):
            handle.visible = False
        for label in self._labels:
            label.visible = False
        self.map_note.text = note
        x, y, _ = self._server.initial_camera.look_at  # where the last map was fitted: the canvas's centre
        self.map_note.position = (float(x), float(y), 0.2)

    def _fit_all(self, view: MapView) -> None:
        for client in self._server.get_clients().values():
            self.fit_camera(client.camera, view)
        x, y, z = _fit_pose(view)
        self._server.initial_camera.position = (x, y, z)
        self._server.initial_camera.look_at = (x, y, 0.0)


@dataclass(frozen=True)
class MapLabels:
    """Where the frontier spheres and the map's labels go at one zoom."""

    radii: list[float]  # each frontier's sphere, in ``view.frontiers`` order
    goal_ring: tuple[float, float]  # the long-term goal's ring: inner and outer radius
    placed: list[PlacedLabel | None]  # the goal's label first (None when none), then the frontiers' by importance


def fitted_em_m(view: MapView, height_px: int) -> float:
    """A label's em in metres for ``LABEL_PX`` pixels on a page ``height_px`` tall showing the fitted view."""
    return LABEL_PX * 2 * _fit_pose(view)[2] * math.tan(_FIT_FOV / 2) / height_px


def map_labels(view: MapView, goal: tuple[str, tuple[float, float]] | None, em_m: float) -> MapLabels:
    """The spheres sized apart, and the labels placed apart at one em = ``em_m``: the long-term
    goal's (``goal``: its text and scene point), the chosen frontier's, then by score (the best few
    with their score, the rest with their id only); none covers a sphere, the goal or the agent."""
    res = view.resolution_m
    xy = [cell_to_xy(f.cell, res) for f in view.frontiers]
    radii = marker_radii(xy)
    markers = [Box.around(x, y, r) for (x, y), r in zip(xy, radii)]
    markers.append(Box.around(*cell_to_xy(view.agent_cell, res), _AGENT_HALF_M))
    requests: list[LabelRequest] = []
    goal_ring = (_GOAL_RING_M, 2 * _GOAL_RING_M)
    if goal is not None:
        goal_ring = _goal_ring(goal[1], xy, radii, res)
        markers.append(Box.around(*goal[1], goal_ring[1]))
        requests.append(LabelRequest(goal[0], goal[1], goal_ring[1]))
    top = labelled_frontiers(view.frontiers)
    order = sorted(range(len(view.frontiers)), key=lambda i: _importance(view.frontiers[i], top))
    requests += [LabelRequest(frontier_text(view.frontiers[i], top), xy[i], radii[i]) for i in order]
    rows, cols = view.cells
    (x0, y1), (x1, y0) = cell_to_xy(view.origin, res), cell_to_xy((view.origin[0] + rows, view.origin[1] + cols), res)
    margin = 4 * em_m
    placed = place_labels(
        requests, em_m=em_m, markers=markers, bounds=Box(x0 - margin, y0 - margin, x1 + margin, y1 + margin)
    )
    return MapLabels(radii, goal_ring, placed if goal is not None else [None, *placed])


def marker_radii(xy: list[tuple[float, float]]) -> list[float]:
    """Each frontier sphere's radius: ``MARKER_RADIUS_M``, or under half the distance to its nearest
    neighbour where frontiers crowd (so no two touch and a click can pick each), never under
    ``MIN_MARKER_RADIUS_M``."""
    if len(xy) < 2:
        return [MARKER_RADIUS_M] * len(xy)
    p = np.asarray(xy, np.float64)
    d = np.sqrt(((p[:, None] - p[None]) ** 2).sum(axis=2))
    np.fill_diagonal(d, np.inf)
    return [float(min(MARKER_RADIUS_M, max(MIN_MARKER_RADIUS_M, 0.45 * n))) for n in d.min(axis=1)]


def _goal_ring(
    at: tuple[float, float], xy: list[tuple[float, float]], radii: list[float], res: float
) -> tuple[float, float]:
    """The long-term goal's ring: just round the sphere of the frontier it marks (or a small hole on
    a bare point), a third as wide again (``MIN_MARKER_RADIUS_M`` at least)."""
    below = max((r for p, r in zip(xy, radii) if math.dist(at, p) <= res), default=0.0)
    inner = below + 0.02 if below else _GOAL_RING_M
    return inner, inner + max(MIN_MARKER_RADIUS_M, inner / 3)


def _ring_mesh(inner: float, outer: float, segments: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A flat annulus round the origin, its faces wound to face +z (the camera above)."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a), np.zeros(segments)], axis=1)
    vertices = np.concatenate([ring * inner, ring * outer]).astype(np.float32)
    i = np.arange(segments)
    j = (i + 1) % segments
    faces = np.concatenate([np.stack([i, segments + i, j], 1), np.stack([j, segments + i, segments + j], 1)])
    return vertices, faces.astype(np.uint32)


def frontier_text(f: FrontierMarker, top: set[int]) -> str:
    """A frontier's map label: its id, with the score its colour shows for the best few and the
    chosen one (starred); every score is in the Frontiers table."""
    if f.id not in top:
        return f"F{f.id}"
    return f"{'★' if f.chosen else ''}F{f.id} {frontier_score(f):.2f}"


def _importance(f: FrontierMarker, top: set[int]) -> tuple:
    """Sort key, most important first: the chosen frontier, the scored few, then by score."""
    score = frontier_score(f)
    return (not f.chosen, f.id not in top, -score if math.isfinite(score) else math.inf, f.id)


def _add_map_label(scene, name: str) -> viser.LabelHandle:
    """A label sized in scene metres (``font_scene_height`` set at each draw), centred on its position."""
    return scene.add_label(
        name, "", position=(0.0, 0.0, _LABEL_Z), font_size_mode="scene", anchor="center-center", visible=False
    )


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


def _fit_pose(view: MapView, aspect: float = 1.0, fov: float = _FIT_FOV) -> tuple[float, float, float]:
    """Camera above the map centre, high enough that a page's view (vertical ``fov``, width / height
    ``aspect``) shows all of the crop with a margin: the canvas lies between the page's panels, so
    centred on it is centred on the map, and on a canvas taller than wide the map's width limits."""
    res = view.resolution_m
    rows, cols = view.cells
    x, y = cell_to_xy((view.origin[0] + rows // 2, view.origin[1] + cols // 2), res)
    half_height = max(rows * res, cols * res / aspect) / 2
    return x, y, _FIT_MARGIN * half_height / math.tan(fov / 2)


def _page_view(camera) -> tuple[float, float]:
    """(aspect, vertical fov) a page reported of its camera; the defaults before it reported them."""
    aspect, fov = float(getattr(camera, "aspect", 0) or 0), float(getattr(camera, "fov", 0) or 0)
    ok = math.isfinite(aspect) and 0.1 < aspect < 10 and math.isfinite(fov) and 0 < fov < math.pi
    return (aspect, fov) if ok else (1.0, _FIT_FOV)


def _inside(crop: tuple[int, int, int, int], fitted: tuple[int, int, int, int]) -> bool:
    """Whether map crop (r0, c0, r1, c1) lies within the crop the cameras were fitted to."""
    return fitted[0] <= crop[0] and fitted[1] <= crop[1] and crop[2] <= fitted[2] and crop[3] <= fitted[3]


def _arrow_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A flat arrowhead pointing along +x (the agent's heading), 0.4 m long."""
    v = np.array([[0.25, 0, 0], [-0.15, 0.14, 0], [-0.07, 0, 0], [-0.15, -0.14, 0]], np.float32)
    return v, np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
