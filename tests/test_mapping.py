"""Semantic mapping: hand-made depth frames must land on the map cells geometry predicts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage as ndi

from l3mvn.agent.mapping import SemanticMapper
from l3mvn.core.camera import CameraIntrinsics, depth_to_points, downsample_frame
from l3mvn.core.config import MapConfig, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Pose
from l3mvn.world.sim.simulator import BuiltinSimulator

H, W = 120, 160
SIM = SimConfig()
INTR = CameraIntrinsics.from_sim(SIM, H, W)  # 79 deg HFOV, camera 0.88 m up
CATS = ("chair", "couch", "tv")
CENTRE = 480  # 48 m map at 5 cm
START = Pose(3.3, -1.2, 0.0)


def _mapper(cfg: MapConfig | None = None, start: Pose = START) -> SemanticMapper:
    mapper = SemanticMapper(
        cfg or MapConfig(), INTR, CATS, max_depth_m=SIM.max_depth_m, body_radius_m=SIM.agent_radius_m
    )
    mapper.reset(start)
    return mapper


def _ray_cast(pose: Pose, tilt: float, planes: list[tuple[int, float]]) -> np.ndarray:
    """z-depth of axis-aligned planes ``(axis, value)`` (0: x = value, 1: y, 2: z); 0 where none is hit.

    Rays are ``forward + a * right + b * up``: their forward component is 1, so the ray parameter of a
    hit is its z-depth directly.
    """
    f = (W / 2) / math.tan(math.radians(79.0) / 2)
    a = (np.arange(W) + 0.5 - W / 2) / f
    b = (H / 2 - np.arange(H) - 0.5) / f
    ch, sh, ct, st = math.cos(pose.heading), math.sin(pose.heading), math.cos(tilt), math.sin(tilt)
    forward = np.array([ch * ct, sh * ct, st])
    right = np.array([sh, -ch, 0.0])
    up = np.array([-ch * st, -sh * st, ct])
    rays = forward + a[None, :, None] * right + b[:, None, None] * up
    origin = np.array([pose.x, pose.y, 0.88])
    depth = np.full((H, W), np.inf)
    for axis, value in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (value - origin[axis]) / rays[..., axis]
        depth = np.where((t > 0) & (t < depth), t, depth)
    return np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)


def _wall(distance: float) -> np.ndarray:
    """A wall facing the camera (tilt 0) at ``distance``: constant z-depth."""
    return np.full((H, W), distance, dtype=np.float32)


def _cells(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.nonzero(grid)


def _outside_footprint(smap) -> np.ndarray:
    return smap.explored & ~smap.current


# --- geometry ---------------------------------------------------------------------------------
def test_start_pose_maps_to_map_centre_with_heading_kept():
    start = Pose(3.3, -1.2, 0.7)
    smap = _mapper(start=start).map
    assert smap.size == 960
    assert smap.agent_cell == (CENTRE, CENTRE)
    assert smap.world_to_cell(3.3, -1.2) == (CENTRE, CENTRE)
    assert smap.cell_to_world(CENTRE, CENTRE) == pytest.approx((3.325, -1.175))
    assert smap.agent_heading == 0.7
    assert list(zip(*_cells(smap.visited))) == [(CENTRE, CENTRE)]
    assert smap.explored[CENTRE, CENTRE] and smap.current[CENTRE, CENTRE]
    assert not smap.obstacle.any()


@pytest.mark.parametrize(
    ("heading_deg", "axis", "wall_index"),
    [(0, 1, CENTRE + 40), (90, 0, CENTRE + 40), (180, 1, CENTRE - 41)],
)
def test_wall_ahead_lands_obstacles_on_the_cells_ahead_for_each_heading(heading_deg, axis, wall_index):
    # A wall 2.02 m ahead: heading 0 -> x + 2.02 (col 400), 90 -> y + 2.02 (row 400), 180 -> x - 2.02.
    pose = Pose(START.x, START.y, math.radians(heading_deg))
    smap = _mapper().update(_wall(2.02), None, pose, 0.0)
    cells = _cells(smap.obstacle)
    along, across = cells[axis], cells[1 - axis]
    assert set(along.tolist()) == {wall_index}
    # Half width of the view at 2.02 m: 2.02 * tan(39.5 deg) = 1.665 m = 33.3 cells each side.
    assert across.min() in (CENTRE - 34, CENTRE - 33) and across.max() in (CENTRE + 33, CENTRE + 32)


@pytest.mark.parametrize(("heading_deg", "left_is"), [(0, "rows above centre"), (90, "cols below centre")])
def test_left_half_of_the_image_maps_to_the_agents_left(heading_deg, left_is):
    # Counter-clockwise headings: facing +x the left is +y (higher rows); facing +y the left is -x.
    semantic = np.zeros((H, W), dtype=np.int32)
    semantic[:, : W // 2 - 4] = 1
    pose = Pose(START.x, START.y, math.radians(heading_deg))
    rows, cols = _cells(_mapper().update(_wall(2.02), semantic, pose, 0.0).category("chair"))
    assert len(rows) > 0
    if left_is == "rows above centre":
        assert rows.min() >= CENTRE
    else:
        assert cols.max() < CENTRE


def test_floor_points_mark_explored_but_not_obstacle():
    smap = _mapper().update(_ray_cast(START, 0.0, [(2, 0.0)]), None, START, 0.0)
    assert not smap.obstacle.any()
    assert _outside_footprint(smap).sum() > 500


def test_explored_at_looks_up_world_points_and_reads_off_map_points_as_unexplored():
    smap = _mapper().update(_ray_cast(START, 0.0, [(2, 0.0)]), None, START, 0.0)
    rows, cols = np.nonzero(smap.explored)
    xs, ys = zip(*(smap.cell_to_world(int(r), int(c)) for r, c in zip(rows[:50], cols[:50])))
    assert smap.explored_at(np.array(xs), np.array(ys)).all()
    behind = smap.explored_at(np.array([START.x - 3.0]), np.array([START.y]))  # the camera looks along +x
    far = smap.explored_at(np.array([START.x + 100.0]), np.array([START.y]))
    assert not behind[0] and not far[0]


def test_points_above_the_obstacle_band_are_ignored():
    # A ceiling at 2.6 m > 0.88 + 0.5 m: neither obstacle nor explored (beyond the agent's footprint).
    smap = _mapper().update(_ray_cast(START, 0.0, [(2, 2.6)]), None, START, 0.0)
    assert not smap.obstacle.any()
    assert not _outside_footprint(smap).any()


def test_tilting_down_30_degrees_moves_the_nearest_floor_hit_closer():
    # Lowest pixel ray: atan(59.5 / f) = 31.5 deg below the axis -> floor at 0.88 / tan(31.5) = 1.43 m;
    # tilted 30 deg down it points 61.5 deg down -> 0.48 m.
    def nearest_floor_m(tilt: float) -> float:
        smap = _mapper(MapConfig(free_space_bins=0)).update(_ray_cast(START, tilt, [(2, 0.0)]), None, START, tilt)
        rows, cols = _cells(_outside_footprint(smap))
        return float(np.hypot(rows - CENTRE + 0.5, cols - CENTRE + 0.5).min() * 0.05)

    assert nearest_floor_m(0.0) == pytest.approx(1.43, abs=0.08)
    assert nearest_floor_m(math.radians(-30)) == pytest.approx(0.48, abs=0.08)


def test_free_space_between_camera_and_wall_is_explored_but_not_beyond_it():
    smap = _mapper().update(_wall(2.02), None, START, 0.0)
    ahead = smap.explored[CENTRE, CENTRE + 10 : CENTRE + 38]  # 0.5-1.9 m ahead: below the lowest ray
    assert ahead.all()
    assert not smap.explored[CENTRE, CENTRE + 45 :].any()  # behind the wall at 2.02 m
    blind = _mapper(MapConfig(free_space_bins=0)).update(_wall(2.02), None, START, 0.0)
    assert not blind.explored[CENTRE, CENTRE + 10 : CENTRE + 25].all()


def test_only_what_was_seen_from_within_the_look_distance_counts_as_looked_at():
    # A wall 4.5 m ahead: the floor and the wall are explored all the way, looked at up to 2.5 m.
    smap = _mapper().update(_wall(4.5), None, START, 0.0)
    cols = CENTRE + np.arange(12, 88)  # 0.6-4.4 m ahead
    row = CENTRE
    assert smap.explored[row, cols].all()
    near = (cols - CENTRE + 0.5) * 0.05 <= MapConfig().look_distance_m
    assert smap.looked[row, cols[near]].all() and not smap.looked[row, cols[~near]].any()
    assert not (smap.looked & ~smap.explored).any()
    farther = _mapper(MapConfig(look_distance_m=5.0)).update(_wall(4.5), None, START, 0.0)
    assert farther.looked[row, cols].all()


def test_depth_at_or_beyond_max_range_is_dropped():
    smap = _mapper().update(_wall(5.0), None, START, 0.0)
    assert not smap.obstacle.any() and not _outside_footprint(smap).any()


def _sensed(depth: np.ndarray) -> np.ndarray:
    """What the sensor reports: 0 below its minimum range and at or beyond its maximum."""
    return np.where((depth >= SIM.min_depth_m) & (depth < SIM.max_depth_m), depth, 0.0).astype(np.float32)


def _ranged_mapper() -> SemanticMapper:
    mapper = SemanticMapper(
        MapConfig(),
        INTR,
        CATS,
        max_depth_m=SIM.max_depth_m,
        body_radius_m=SIM.agent_radius_m,
        min_depth_m=SIM.min_depth_m,
    )
    mapper.reset(START)
    return mapper


@pytest.mark.parametrize("tilt_deg", [0.0, -30.0])
def test_a_wall_nearer_than_the_sensor_minimum_is_an_obstacle_no_farther_than_that(tilt_deg):
    # A wall 0.3 m ahead: level, every reading lies below the 0.5 m minimum and reads 0; looking
    # down, the rays that meet it lowest travel just over 0.5 m and read true.
    tilt = math.radians(tilt_deg)
    depth = _sensed(_ray_cast(START, tilt, [(2, 0.0), (0, START.x + 0.3)]))
    assert (depth == 0).mean() > 0.8
    blind = _mapper().update(depth, None, START, tilt)
    smap = _ranged_mapper().update(depth, None, START, tilt)
    rows, cols = _cells(smap.obstacle & ~blind.obstacle)
    assert len(rows) > 10
    ahead_m = (cols - CENTRE) * 0.05
    assert (ahead_m > 0.2).all() and (ahead_m <= 0.5).all()
    assert (np.abs(rows - CENTRE) * 0.05 <= 0.5).all()
    # The inference marks no floor: what is free is what the valid readings showed. Nor does it
    # explore: a frontier behind a guess stays a frontier.
    assert not ((smap.explored & ~smap.obstacle) & ~(blind.explored & ~blind.obstacle)).any()
    assert not smap.explored[rows, cols].any()
    if tilt_deg == 0.0:
        assert not blind.obstacle.any()  # without the minimum range the wall does not exist


def test_a_guessed_obstacle_never_lands_on_seen_floor_and_seen_floor_takes_it_back():
    # Round a door frame the farthest place a too-near obstacle can be is floor: the guess must give
    # way to what the map has seen, before or after.
    near_wall = _sensed(_ray_cast(START, 0.0, [(2, 0.0), (0, START.x + 0.3)]))
    open_floor = _sensed(_ray_cast(START, 0.0, [(2, 0.0), (0, START.x + 4.0)]))
    seen_first = _ranged_mapper()
    seen_first.update(open_floor, None, START, 0.0)
    assert not seen_first.update(near_wall, None, START, 0.0).obstacle[:, CENTRE : CENTRE + 60].any()

    guessed_first = _ranged_mapper()
    guessed = guessed_first.update(near_wall, None, START, 0.0).obstacle.copy()
    assert guessed.any()
    after = guessed_first.update(open_floor, None, START, 0.0)
    assert not (after.obstacle & guessed).any()
    assert after.explored[guessed].all()


def test_an_obstacle_seen_where_one_was_guessed_stays():
    near_wall = _sensed(_ray_cast(START, 0.0, [(2, 0.0), (0, START.x + 0.32)]))
    mapper = _ranged_mapper()
    guessed = mapper.update(near_wall, None, START, 0.0).obstacle.copy()
    back = Pose(START.x - 1.0, START.y, 0.0)  # 1.32 m from the wall: every reading valid
    seen = mapper.update(_sensed(_ray_cast(back, 0.0, [(2, 0.0), (0, START.x + 0.32)])), None, back, 0.0)
    wall_col = CENTRE + 6  # x = START.x + 0.32
    assert seen.obstacle[:, wall_col].any()
    # The floor seen in front of the wall took back the guesses lying on it; those behind it stay.
    assert not (seen.obstacle & guessed)[:, :wall_col].any()
    assert (seen.obstacle & guessed)[:, wall_col + 1 :].any()


def test_invalid_rays_that_may_have_seen_nothing_mark_nothing():
    # Open floor: rays near the horizon meet it beyond the 5 m range, rays above it meet nothing.
    depth = _sensed(_ray_cast(START, 0.0, [(2, 0.0)]))
    assert (depth == 0).sum() > H * W / 2
    smap = _ranged_mapper().update(depth, None, START, 0.0)
    assert not smap.obstacle.any()
    assert smap.explored.sum() == _mapper().update(depth, None, START, 0.0).explored.sum()


def test_the_minimum_range_must_lie_below_the_maximum():
    with pytest.raises(L3MVNError, match="min_depth_m"):
        SemanticMapper(MapConfig(), INTR, CATS, max_depth_m=5.0, body_radius_m=0.18, min_depth_m=5.0)


# --- categories -------------------------------------------------------------------------------
def _labelled_column(n: int, label: int = 2) -> np.ndarray:
    """``n`` pixels of one image column near the centre row; at 2.02 m they share one map cell."""
    semantic = np.zeros((H, W), dtype=np.int32)
    semantic[60 : 60 + n, 82] = label
    return semantic


def test_a_category_cell_needs_five_points():
    four = _mapper().update(_wall(2.02), _labelled_column(4), START, 0.0)
    assert not four.categories.any()
    five = _mapper().update(_wall(2.02), _labelled_column(5), START, 0.0)
    assert list(zip(*_cells(five.category("couch")))) == [(CENTRE - 2, CENTRE + 40)]
    assert not five.category("chair").any() and not five.category("tv").any()


def test_category_threshold_is_configurable():
    smap = _mapper(MapConfig(category_point_threshold=2)).update(_wall(2.02), _labelled_column(2), START, 0.0)
    assert smap.category("couch").sum() == 1


def test_category_counts_accumulate_across_frames():
    mapper = _mapper()
    mapper.update(_wall(2.02), _labelled_column(4), START, 0.0)
    assert not mapper.map.categories.any()
    one_more = np.zeros((H, W), dtype=np.int32)
    one_more[64, 82] = 2
    assert mapper.update(_wall(2.02), one_more, START, 0.0).category("couch").sum() == 1


def test_objects_below_the_obstacle_band_still_register():
    # A labelled object lying on the floor is not an obstacle, but its category channel must fill.
    semantic = np.full((H, W), 3, dtype=np.int32)
    smap = _mapper().update(_ray_cast(START, 0.0, [(2, 0.0)]), semantic, START, 0.0)
    assert not smap.obstacle.any()
    assert smap.category("tv").sum() > 100


# --- trajectory and bounds --------------------------------------------------------------------
def test_visited_draws_a_continuous_line_between_poses():
    mapper = _mapper()
    empty = np.zeros((H, W), dtype=np.float32)
    smap = mapper.update(empty, None, Pose(START.x + 0.82, START.y - 0.53, 0.0), 0.0)
    end = (CENTRE - 11, CENTRE + 16)
    assert smap.agent_cell == end
    rows, cols = _cells(smap.visited)
    assert len(rows) == 17
    assert smap.visited[CENTRE, CENTRE] and smap.visited[end]
    _, components = ndi.label(smap.visited, structure=np.ones((3, 3)))
    assert components == 1


def test_pose_off_the_map_raises_and_leaves_the_map_untouched():
    mapper = _mapper()
    before = mapper.map.copy()
    with pytest.raises(L3MVNError, match="off the 48 m map"):
        mapper.update(_wall(2.02), None, Pose(START.x + 24.5, START.y, 0.0), 0.0)
    after = mapper.map
    assert after.agent_cell == before.agent_cell
    assert np.array_equal(after.explored, before.explored) and np.array_equal(after.visited, before.visited)


def test_world_to_cell_off_the_map_raises():
    with pytest.raises(L3MVNError, match="off the 960x960 map"):
        _mapper().map.world_to_cell(START.x, START.y - 24.1)


def test_local_window_is_half_size_centred_on_the_agent_and_clamped_to_the_map():
    cfg = MapConfig(map_size_m=4.0)
    mapper = _mapper(cfg)
    window = mapper.map.local_window()
    assert window.bounds == (20, 60, 20, 60) and window.agent_cell == (20, 20)
    empty = np.zeros((H, W), dtype=np.float32)
    window = mapper.update(empty, None, Pose(START.x + 1.92, START.y - 1.92, 0.0), 0.0).local_window()
    assert window.bounds == (0, 40, 40, 80)
    assert window.agent_cell == (1, 38)
    assert window.visited.shape == (40, 40) and window.categories.shape == (3, 40, 40)


def test_map_sizes_follow_the_config():
    assert MapConfig().map_cells == 960 and MapConfig().local_cells == 480
    assert MapConfig(map_size_m=36.0).map_cells == 720


# --- bad inputs -------------------------------------------------------------------------------
def test_update_before_reset_raises():
    with pytest.raises(L3MVNError, match="reset"):
        SemanticMapper(MapConfig(), INTR, CATS, max_depth_m=SIM.max_depth_m, body_radius_m=SIM.agent_radius_m).update(
            _wall(2.0), None, START, 0.0
        )


def test_depth_of_the_wrong_shape_raises():
    with pytest.raises(L3MVNError, match="intrinsics expect"):
        _mapper().update(np.ones((480, 640), dtype=np.float32), None, START, 0.0)


def test_semantic_ids_beyond_the_categories_raise():
    semantic = np.full((H, W), 4, dtype=np.int32)
    with pytest.raises(L3MVNError, match=r"0\.\.3"):
        _mapper().update(_wall(2.0), semantic, START, 0.0)


def test_unknown_category_raises():
    with pytest.raises(L3MVNError, match="valid: chair, couch, tv"):
        _mapper().map.category("sofa")


def test_map_size_must_be_an_even_number_of_cells():
    with pytest.raises(L3MVNError, match="even whole number"):
        MapConfig(map_size_m=36.02)


# --- projection -------------------------------------------------------------------------------
def test_depth_to_points_drops_invalid_depth_and_carries_labels():
    depth = _wall(2.0)
    depth[0, :] = 0.0
    depth[1, 0] = np.nan
    semantic = np.zeros((H, W), dtype=np.int32)
    semantic[H - 1, W - 1] = 3
    cloud = depth_to_points(depth, INTR, Pose(0.0, 0.0, 0.0), 0.0, semantic)
    assert cloud.points.shape == (H * W - W - 1, 3) and cloud.points.dtype == np.float32
    assert np.allclose(cloud.points[:, 0], 2.0)
    assert cloud.labels[-1] == 3 and cloud.labels[:-1].max() == 0
    # Bottom-right pixel: below the camera and to the right (-y when facing +x).
    assert cloud.points[-1, 1] < 0 and cloud.points[-1, 2] < 0.88


def test_downsample_frame_keeps_the_centre_pixel_of_each_block():
    depth = np.arange(480 * 640, dtype=np.float32).reshape(480, 640)
    small, sem = downsample_frame(depth, depth.astype(np.int32), 4)
    assert small.shape == (120, 160) and sem.shape == (120, 160)
    assert small[1, 1] == depth[6, 6]


class _ArraySplat(SemanticMapper):
    """The mapper with the whole-array ``_splat`` the compiled pass replaced: its reference."""

    def _splat(self, points, labels, x, y):
        cfg, size = self.cfg, self.cfg.map_cells
        half = size // 2
        cols = np.floor(points[:, 0] / cfg.resolution_m).astype(np.int64) + half
        rows = np.floor(points[:, 1] / cfg.resolution_m).astype(np.int64) + half
        z = points[:, 2]
        keep = (rows >= 0) & (rows < size) & (cols >= 0) & (cols < size) & (z >= cfg.floor_min_height_m)
        flat, z, labels = rows[keep] * size + cols[keep], z[keep], labels[keep]
        near = np.hypot(points[keep, 0] - x, points[keep, 1] - y) <= cfg.look_distance_m
        below_top, high = z <= self.obstacle_max_height_m, z >= cfg.obstacle_min_height_m
        self._explored.reshape(-1)[flat[below_top]] = True
        self._looked.reshape(-1)[flat[below_top & near]] = True
        self._obstacle.reshape(-1)[flat[below_top & high]] = True
        labelled = (labels > 0) & (z <= cfg.category_max_height_m)
        if labelled.any():
            cells, hits = np.unique(
                (labels[labelled].astype(np.int64) - 1) * size * size + flat[labelled], return_counts=True
            )
            counts = self._counts.reshape(-1)
            total = np.minimum(counts[cells].astype(np.int64) + hits, cfg.category_point_threshold)
            counts[cells] = total
            self._categories.reshape(-1)[cells[total >= cfg.category_point_threshold]] = True
        return flat[below_top & high], flat[~high]


def test_the_compiled_splat_maps_what_the_array_code_maps(tiny_scene):
    """A walk round both rooms of the two-room house, level and tilted: after every frame each grid
    (obstacles, guesses, explored, looked, categories and their point counts) is the reference's."""
    sim = SimConfig().with_frame(H, W)
    env = BuiltinSimulator(tiny_scene, sim)
    start = Pose(2.5, 2.0, 0.0)
    mappers = [cls.for_sim(MapConfig(), sim, H, W, tiny_scene.categories) for cls in (SemanticMapper, _ArraySplat)]
    for mapper in mappers:
        mapper.reset(start)
    rng = np.random.default_rng(3)
    walkable = np.argwhere(tiny_scene.walkable)
    for k in range(20):
        x, y = tiny_scene.cell_center(*walkable[rng.integers(len(walkable))])
        pose = Pose(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
        tilt = (0.0, -math.pi / 6)[k % 2]
        depth, semantic = env.renderer.render(pose, tilt).strided(1)
        for mapper in mappers:
            mapper.update(depth, semantic, pose, tilt)
        compiled, reference = mappers
        for name in ("_obstacle", "_inferred", "_explored", "_looked", "_categories", "_counts"):
            assert np.array_equal(getattr(compiled, name), getattr(reference, name)), (k, name)
    assert compiled._categories.any() and compiled._obstacle.any()
