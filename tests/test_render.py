"""The renderer as a depth camera: analytic depths, per-pixel categories, conventions, and the
image helpers that show its output."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_world import two_rooms

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import centre_pixels
from l3mvn.core.types import Pose
from l3mvn.run.viz import category_palette, colorize_depth, colorize_semantic, legend, side_by_side
from l3mvn.world.sim.render import Renderer
from l3mvn.world.sim.world import build_world

RES = 0.05
ODD = (121, 161)  # odd sizes put the centre pixel exactly on the optical axis
CY, CX = 60, 80
BED_ID, TOILET_ID = 1, 2


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    cfg = SimConfig()
    return Renderer(build_world(two_rooms(), cfg), cfg)


def at(row: float, col: float, heading: float) -> Pose:
    return Pose((col + 0.5) * RES, (row + 0.5) * RES, heading)


def test_frame_has_the_configured_size_and_dtypes(renderer):
    frame = renderer.render(at(45, 30, 0.0), 0.0)
    assert frame.rgb.shape == (480, 640, 3) and frame.rgb.dtype == np.uint8
    assert frame.depth.shape == (480, 640) and frame.depth.dtype == np.float32
    assert frame.semantic.shape == (480, 640) and frame.semantic.dtype == np.int32


def test_ray_straight_at_a_wall_returns_its_distance_as_depth(renderer):
    frame = renderer.render(at(45, 30, 0.0), 0.0, *ODD)
    expected = 56 * RES - 30.5 * RES  # the one-cell wall's west face is at column 56
    assert frame.depth[CY, CX] == pytest.approx(expected, abs=1e-4)
    # z-depth, not ray length: a wall facing the camera has one depth across the image row.
    assert frame.depth[CY, CX + 20] == pytest.approx(expected, abs=1e-4)
    assert frame.semantic[CY, CX] == 0


def test_camera_pitched_down_at_the_bed_sees_the_bed_category_at_the_expected_depth(renderer):
    frame = renderer.render(at(35, 20, -math.pi / 2), math.radians(-30), *ODD)
    assert frame.semantic[CY, CX] == BED_ID
    horizontal = 35.5 * RES - 20 * RES  # to the bed's south face at row 20
    assert frame.depth[CY, CX] == pytest.approx(horizontal / math.cos(math.radians(30)), abs=1e-4)
    assert frame.rgb[CY, CX].max() > 0


def test_depth_beyond_max_or_nearer_than_min_is_zero_but_still_drawn(renderer):
    far = renderer.render(at(30, 8, 0.0), 0.0, *ODD)  # through the door to the far east wall, 5.4 m
    assert far.depth[CY, CX] == 0.0 and far.rgb[CY, CX].max() > 0
    near = renderer.render(at(45, 52, 0.0), 0.0, *ODD)  # 0.18 m from the wall
    assert near.depth[CY, CX] == 0.0 and near.rgb[CY, CX].max() > 0


def test_camera_pitched_down_sees_the_floor_nearer_in_lower_rows(renderer):
    frame = renderer.render(at(45, 30, math.pi), math.radians(-30), *ODD)
    column = frame.depth[3 * ODD[0] // 4 :, CX]
    valid = column[column > 0]
    assert valid.size > 10
    assert np.all(np.diff(valid) < 0)


def test_turning_left_brings_what_was_on_the_left_to_the_centre(renderer):
    camera = (44, 70)  # the toilet lies straight along +x from here
    heading = math.radians(-30)
    before = renderer.render(at(*camera, heading), 0.0, *ODD).semantic
    after = renderer.render(at(*camera, heading + math.radians(30)), 0.0, *ODD).semantic
    cols_before = np.nonzero(before == TOILET_ID)[1]
    cols_after = np.nonzero(after == TOILET_ID)[1]
    assert cols_before.size and cols_after.size
    assert cols_before.mean() < CX - 30
    assert abs(cols_after.mean() - CX) < 5


def test_frames_match_embree_ray_casting_pixel_for_pixel(renderer):
    """Intel Embree (through trimesh) is an independent ray caster: same world, same rays."""
    world = renderer.world
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("embreex", reason="embreex (Embree's Python wheel) is not installed")
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    caster = RayMeshIntersector(trimesh.Trimesh(world.vertices, world.triangles, process=False))
    cfg = renderer.cfg
    for pose, tilt in ((at(35, 20, -1.2), -0.5), (at(44, 70, 2.0), 0.5), (at(30, 8, 0.1), 0.0)):
        frame = renderer.render(pose, tilt, 60, 80)
        dirs = renderer.ray_directions(60, 80, pose, tilt).reshape(-1, 3)
        origin = np.broadcast_to([pose.x, pose.y, cfg.camera_height_m], dirs.shape)
        tri, ray, where = caster.intersects_id(origin, dirs, multiple_hits=False, return_locations=True)
        t = np.full(len(dirs), np.inf)
        ids = np.full(len(dirs), world.num_triangles)
        # Directions have unit length along the optical axis, so distance / |direction| is z-depth.
        t[ray] = np.linalg.norm(where - origin[ray], axis=1) / np.linalg.norm(dirs[ray], axis=1)
        ids[ray] = tri
        t, ids = t.reshape(60, 80), ids.reshape(60, 80)
        depth = np.where((t >= cfg.min_depth_m) & (t <= cfg.max_depth_m), t, 0.0)
        semantic = np.where(ids < world.num_triangles, world.tri_category[np.minimum(ids, world.num_triangles - 1)], 0)
        assert np.mean(np.abs(depth - frame.depth) < 1e-3) > 0.999
        assert np.mean(semantic == frame.semantic) > 0.999


# Poses that see both rooms' objects near and far, looking level, down and up.
VIEWS = (
    (at(35, 20, -1.2), -0.5),
    (at(44, 70, 2.0), 0.5),
    (at(30, 8, 0.1), 0.0),
    (at(45, 30, math.pi), math.radians(-30)),
    (at(35, 20, -math.pi / 2), math.radians(-30)),
)


@pytest.mark.parametrize("size", [(480, 640), (121, 161), (60, 80)])
def test_strided_pixels_rendered_alone_equal_those_of_the_whole_frame(renderer, size):
    """The mapper's pixels are rasterised alone, with the whole frame's arithmetic: same values."""
    for pose, tilt in VIEWS:
        whole = renderer.render(pose, tilt, *size)
        for step in (2, 3, 4):
            lone = renderer.frame(pose, tilt, *size)
            depth, semantic = lone.strided(step)
            assert np.array_equal(depth, centre_pixels(whole.depth, step))
            assert np.array_equal(semantic, centre_pixels(whole.semantic, step))
            assert lone.strided(step)[0] is depth  # made once


def test_category_counts_without_the_whole_frame_equal_the_whole_frames(renderer):
    """Counting one category rasterises only the box its triangles cover, as the whole frame does."""
    labels = range(0, len(two_rooms().categories) + 2)  # background and an absent id included
    for size in ((480, 640), ODD):
        for pose, tilt in VIEWS:
            whole = renderer.render(pose, tilt, *size)
            for label in labels:
                expected = int(np.count_nonzero((whole.semantic == label) & (whole.depth > 0)))
                assert renderer.frame(pose, tilt, *size).count(label) == expected
                assert whole.count(label) == expected


def test_a_frame_renders_only_what_is_read_and_reports_the_time(renderer):
    frame = renderer.frame(at(30, 8, 0.1), 0.0, 480, 640)
    frame.strided(4)
    assert frame.take_render_seconds() > 0.0
    assert frame.take_render_seconds() == 0.0  # claimed once
    rgb = frame.rgb  # the colours need the whole frame: made now, then kept
    assert rgb.shape == (480, 640, 3) and frame.rgb is rgb
    assert np.array_equal(frame.depth, renderer.render(at(30, 8, 0.1), 0.0, 480, 640).depth)
    assert frame.take_render_seconds() > 0.0


def test_bad_tilt_or_frame_size_is_rejected(renderer):
    with pytest.raises(L3MVNError, match="tilt"):
        renderer.render(at(45, 30, 0.0), math.pi / 2)
    with pytest.raises(L3MVNError, match="frame size"):
        renderer.render(at(45, 30, 0.0), 0.0, 0, 10)


def test_palette_colours_follow_the_category_name_not_its_position():
    a = category_palette(("bed", "chair", "spaceship"))
    b = category_palette(("spaceship", "chair", "bed"))
    assert a.shape == (4, 3) and a.dtype == np.uint8
    assert (a[1] == b[3]).all() and (a[2] == b[2]).all() and (a[3] == b[1]).all()
    assert (a[0] == b[0]).all()
    assert len({tuple(c) for c in category_palette(("chair", "couch", "potted plant", "bed", "toilet", "tv"))}) == 7
    assert legend(("bed",)) == [("bed", tuple(int(v) for v in a[1]))]


def test_colorized_images_mark_invalid_depth_black_and_keep_the_input_size():
    depth = np.array([[0.0, 1.0], [4.0, np.nan]], np.float32)
    img = colorize_depth(depth, 5.0)
    assert img.shape == (2, 2, 3) and img.dtype == np.uint8
    assert (img[0, 0] == 0).all() and (img[1, 1] == 0).all() and img[0, 1].any() and not (img[0, 1] == img[1, 0]).all()
    sem = colorize_semantic(np.array([[0, 2]]), ("bed", "toilet"))
    assert (sem[0, 1] == category_palette(("bed", "toilet"))[2]).all()
    with pytest.raises(L3MVNError, match="semantic ids"):
        colorize_semantic(np.array([[3]]), ("bed", "toilet"))
    both = side_by_side(img, np.zeros((2, 5), np.uint8))
    assert both.shape[0] == 2 and both.dtype == np.uint8
    with pytest.raises(L3MVNError, match="one height"):
        side_by_side(img, np.zeros((3, 3, 3), np.uint8))
