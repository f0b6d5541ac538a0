"""The 3D world built from a map: where walls go, how objects stand, how big the mesh is."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import GIBSON, needs_gibson
from scipy import ndimage as ndi

from l3mvn.core.config import SimConfig
from l3mvn.core.grid import disk
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.world import build_world, category_profile, wall_grids

# Two rooms split by a one-cell wall at column 56 with a door in rows 23..36, a bed against the
# north wall, a free-standing toilet, and a one-cell map speck in the west room.
H, W = 60, 120
WALL_COL = 56
BED = (slice(4, 20), slice(10, 30))
TOILET = (slice(40, 48), slice(90, 98))
SPECK = (40, 40)
CATEGORIES = ("bed", "toilet")


def two_rooms(categories: tuple[str, ...] = CATEGORIES, extra: dict | None = None) -> SceneMap:
    """Navmesh drawn directly, so the free floor (navmesh + 2 cells) has known straight edges."""
    nav = np.zeros((H, W), bool)
    nav[6:54, 6:54] = True  # west room: free floor rows/cols 4..55
    nav[6:54, 59:114] = True  # east room: free floor cols 57..115
    nav[25:35, 53:60] = True  # door through the wall at column 56
    objects = np.zeros((len(categories), H, W), bool)
    masks = {"bed": BED, "toilet": TOILET, **(extra or {})}
    for k, name in enumerate(categories):
        objects[k][masks[name]] = True
    # Real maps erode the navmesh by ~4 cells around objects; the map noise is a hole in it.
    nav &= ~ndi.binary_dilation(objects.any(0), disk(4))
    hole = np.zeros((H, W), bool)
    hole[SPECK] = True
    nav &= ~ndi.binary_dilation(hole, disk(3))
    return SceneMap(name="TwoRooms", floor=0, categories=categories, navigable=nav, objects=objects)


def test_walls_never_cover_free_floor_or_object_footprints():
    scene = two_rooms()
    world = build_world(scene, SimConfig())
    assert not (world.walls & scene.free).any()
    assert not (world.walls & scene.object_any).any()
    assert not (world.furniture & (scene.free | scene.object_any)).any()


def test_ring_between_object_and_free_floor_is_floor_not_wall():
    scene = two_rooms()
    walls, _ = wall_grids(scene)
    toilet = np.zeros((H, W), bool)
    toilet[TOILET] = True
    ring = ndi.binary_dilation(toilet, disk(3)) & ~toilet
    assert (ring & ~scene.free).any(), "the test map must have an eroded ring to clean"
    assert not (walls & ring).any()


def test_real_wall_behind_an_object_is_kept():
    walls, _ = wall_grids(two_rooms())
    assert walls[0:4, BED[1]].all()


def test_an_object_deep_in_the_eroded_margin_gets_a_view_corridor_to_the_floor():
    # A plant in a niche: its navmesh stays 8 cells away (4 more than the usual margin).
    scene = two_rooms(("bed", "toilet", "potted plant"), {"potted plant": (slice(8, 12), slice(40, 44))})
    nav = scene.navigable & ~ndi.binary_dilation(scene.category_mask("potted plant"), disk(8))
    scene = SceneMap(name="Niche", floor=0, categories=scene.categories, navigable=nav, objects=scene.objects)
    walls, _ = wall_grids(scene)
    plant = scene.category_mask("potted plant")
    corridor = ndi.binary_dilation(plant, np.ones((3, 3), bool)) & ~plant & ~walls
    assert corridor.any(), "the plant is walled in"
    assert walls[0:4, 40:44].all(), "the outer wall behind the plant must stay"


def test_a_toilet_in_a_room_the_navmesh_lost_shows_through_a_door_wide_opening():
    # The navmesh lost the bathroom: the toilet sits 12 cells (0.6 m) south of the west room's
    # floor, walled in on every side but the narrow margin band.
    toilet = (slice(45, 53), slice(20, 28))
    scene = two_rooms(("bed", "toilet"), {"toilet": toilet})
    nav = scene.navigable.copy()
    nav[32:, :54] = False
    scene = SceneMap(name="Lost", floor=0, categories=scene.categories, navigable=nav, objects=scene.objects)
    free_edge = int(np.flatnonzero(scene.free[:, 24]).max())
    assert 45 - free_edge > 10, "the test map must put the toilet well away from the floor"
    walls, _ = wall_grids(scene)
    mid = (free_edge + 45) // 2
    opening = np.flatnonzero(~walls[mid, :54])
    assert opening.size >= 10 and opening.min() <= 20 and opening.max() >= 27, "narrower than the toilet's face"
    assert walls[mid, :8].all() and walls[mid, 44:54].all(), "the opening spreads beyond a door"
    assert walls[56:, 20:28].all(), "the wall behind the toilet must stay"


def test_unlabelled_furniture_stays_below_the_camera():
    # A cabinet-sized block (1 m2, 0.5 m thick) in the east room: furniture, built to table height,
    # so the camera at 0.88 m sees the objects behind it.
    nav = two_rooms().navigable.copy()
    nav[20:44, 70:94] = False
    base = two_rooms()
    scene = SceneMap(name="Cabinet", floor=0, categories=base.categories, navigable=nav, objects=base.objects)
    walls, furniture = wall_grids(scene)
    assert furniture.any() and not walls[30, 80]
    world = build_world(scene, SimConfig())
    tops = world.vertices[world.triangles[world.tri_category == 0]][..., 2]
    heights = np.unique(np.round(tops, 3))
    assert 0.75 in heights and not ((heights > 0.75) & (heights < SimConfig().wall_height_m)).any()
    assert 0.75 < SimConfig().camera_height_m


def test_one_cell_speck_is_removed_but_one_cell_wall_between_rooms_is_kept():
    scene = two_rooms()
    assert not scene.free[SPECK] and not scene.object_any[SPECK], "the map must contain the speck"
    walls, _ = wall_grids(scene)
    assert not walls[SPECK]
    assert walls[4:23, WALL_COL].all() and walls[37:56, WALL_COL].all()
    assert not walls[6:54, WALL_COL - 1].any() and not walls[6:54, WALL_COL + 1].any()  # one cell thick
    assert not walls[23:37, WALL_COL].any()  # the door


def test_mesh_triangles_are_typed_and_categories_follow_scene_order():
    scene = two_rooms()
    world = build_world(scene, SimConfig())
    m = world.num_triangles
    assert world.vertices.dtype == np.float32 and world.vertices.shape[1] == 3
    assert world.triangles.shape == (m, 3) and world.triangles.max() < len(world.vertices)
    assert world.tri_category.shape == (m,) and world.tri_color.shape == (m, 3)
    assert 0.0 <= world.tri_color.min() and world.tri_color.max() <= 1.0
    assert set(np.unique(world.tri_category)) == {0, 1, 2}
    bed_z = world.vertices[world.triangles[world.tri_category == 1]][..., 2]
    assert bed_z.min() == 0.0 and bed_z.max() == pytest.approx(0.6)
    assert world.vertices[:, 2].max() == pytest.approx(SimConfig().wall_height_m)


def test_small_items_sit_on_the_furniture_below_them_and_unknown_names_get_a_default_height():
    table = (slice(40, 50), slice(20, 40))
    cup = (slice(44, 46), slice(24, 26))
    gadget = (slice(10, 14), slice(80, 84))
    scene = two_rooms(("dining-table", "cup", "gadget"), {"dining-table": table, "cup": cup, "gadget": gadget})
    world = build_world(scene, SimConfig())
    z = lambda cat: world.vertices[world.triangles[world.tri_category == cat]][..., 2]  # noqa: E731
    assert z(1).max() == pytest.approx(0.75)
    assert z(2).min() == pytest.approx(0.75) and z(2).max() == pytest.approx(0.75 + category_profile("cup").height)
    assert z(3).max() == pytest.approx(0.8)
    assert category_profile("Dining_Table") == category_profile("dining-table")


def test_overlapping_floor_standing_categories_keep_one_box_per_cell():
    chair = (slice(42, 46), slice(36, 44))  # pushed half under the table
    table = (slice(40, 50), slice(20, 40))
    scene = two_rooms(("dining-table", "chair"), {"dining-table": table, "chair": chair})
    world = build_world(scene, SimConfig())
    tops = world.tri_normal[:, 2] > 0.5
    tri = world.vertices[world.triangles]
    table_top_area = _area(tri[tops & (world.tri_category == 1)])
    chair_top_area = _area(tri[tops & (world.tri_category == 2)])
    res2 = 0.05**2
    assert chair_top_area == pytest.approx(4 * 8 * res2, rel=1e-4)
    assert table_top_area == pytest.approx((10 * 20 - 4 * 4) * res2, rel=1e-4)


def _area(tris: np.ndarray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum())


@needs_gibson
def test_every_gibson_floor_builds_compactly_and_no_walkable_camera_is_inside_a_wall():
    from l3mvn.core.types import Pose
    from l3mvn.world.scenes.semexp import load_split
    from l3mvn.world.sim.render import Renderer

    cfg = SimConfig(min_depth_m=1e-3)
    rng = np.random.default_rng(0)
    for floors in load_split(GIBSON, "train").values():
        for scene in floors.values():
            world = build_world(scene, cfg)
            assert not (world.walls | world.furniture)[scene.walkable].any(), scene.key
            assert world.num_triangles < 100_000, (scene.key, world.num_triangles)
            renderer = Renderer(world, cfg)
            cells = np.argwhere(scene.walkable)
            for r, c in cells[rng.choice(len(cells), 8)]:
                x, y = scene.cell_center(int(r), int(c))
                for heading in (0.0, 1.6, 3.2, 4.7):
                    pose = Pose(x, y, heading)
                    z = renderer.render(pose, 0.0, 3, 32).depth[1]
                    ray_m = z * np.linalg.norm(renderer.ray_directions(3, 32, pose, 0.0)[1], axis=-1)
                    # Inside a solid every ray hits a back face within a cell; a walkable cell
                    # centre is at least half a cell from any wall face.
                    assert ((z == 0) | (ray_m >= 0.02)).all(), (scene.key, int(r), int(c))


@needs_gibson
def test_no_goal_object_of_the_gibson_houses_is_walled_in():
    from l3mvn.world.scenes.semexp import load_split

    walled = []
    for name, floors in load_split(GIBSON, "train").items():
        for scene in floors.values():
            walls, furniture = wall_grids(scene)
            open_cells = ~walls & ~furniture
            for goal in scene.present_goals():
                labels, n = ndi.label(scene.category_mask(goal), structure=np.ones((3, 3)))
                for k in range(1, n + 1):
                    comp = labels == k
                    ring = ndi.binary_dilation(comp, np.ones((3, 3), bool)) & ~comp
                    far = ndi.distance_transform_edt(~scene.free)[comp].min() > 20  # > 1 m from any floor
                    if not (ring & open_cells).any() and not far:
                        walled.append((name, goal, k))
    assert walled == []


def _pixels(scene: SceneMap, category: str, row: int, col: int, heading: float) -> int:
    """Pixels of ``category`` seen from the cell (row, col) at camera height, tilt 0, 120x160."""
    from l3mvn.core.types import Pose
    from l3mvn.world.sim.render import Renderer

    assert scene.walkable[row, col], "the viewpoint must be a standing pose"
    x, y = scene.cell_center(row, col)
    frame = Renderer(build_world(scene, SimConfig()), SimConfig()).render(Pose(x, y, heading), 0.0, 120, 160)
    return int(np.count_nonzero(frame.semantic == scene.categories.index(category) + 1))


def test_a_toilet_drawn_inside_an_oven_footprint_keeps_every_cell_and_shows_from_the_floor():
    # A map may draw a toilet inside an oven's footprint; tallest-wins would build only the oven.
    oven = (slice(4, 20), slice(76, 96))
    toilet = (slice(6, 14), slice(82, 90))
    scene = two_rooms(("oven", "toilet"), {"oven": oven, "toilet": toilet})
    world = build_world(scene, SimConfig())
    tri = world.vertices[world.triangles]
    tops = world.tri_normal[:, 2] > 0.5
    assert _area(tri[tops & (world.tri_category == 2)]) == pytest.approx(8 * 8 * 0.05**2, rel=1e-4)
    assert _area(tri[tops & (world.tri_category == 1)]) == pytest.approx((16 * 20 - 64) * 0.05**2, rel=1e-4)
    assert _pixels(scene, "toilet", 36, 86, -np.pi / 2) >= 30


def test_a_plant_behind_a_taller_sink_shows_over_it():
    sink = (slice(10, 18), slice(66, 100))
    plant = (slice(4, 10), slice(80, 86))
    scene = two_rooms(("sink", "potted plant"), {"sink": sink, "potted plant": plant})
    gap = ndi.distance_transform_edt(~scene.free)[plant].min()
    assert gap > 2, "the plant must stand behind the sink, away from the floor"
    assert category_profile("sink").height > SimConfig().camera_height_m > category_profile("potted plant").height
    assert _pixels(scene, "potted plant", 36, 83, -np.pi / 2) >= 30
    world = build_world(scene, SimConfig())
    sink_z = world.vertices[world.triangles[world.tri_category == 1]][..., 2]
    assert sink_z.max() == pytest.approx(0.9)  # only the part in the plant's corridor is cut down


def test_a_small_item_drawn_over_a_goal_object_neither_stacks_on_it_nor_rings_it():
    # A vase footprint covering and surrounding a potted plant would bury it in a ring stacked on its top.
    vase = (slice(26, 40), slice(76, 90))
    plant = (slice(30, 36), slice(80, 86))
    scene = two_rooms(("vase", "potted plant"), {"vase": vase, "potted plant": plant})
    world = build_world(scene, SimConfig())
    plant_z = world.vertices[world.triangles[world.tri_category == 2]][..., 2]
    assert plant_z.max() == pytest.approx(category_profile("potted plant").height)
    assert _pixels(scene, "potted plant", 50, 83, -np.pi / 2) >= 30
