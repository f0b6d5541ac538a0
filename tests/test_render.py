"""The renderer as a depth camera: analytic depths, per-pixel categories, conventions, and the
image helpers that show its output."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest
from test_world import two_rooms

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import centre_pixels
from l3mvn.core.types import Pose
from l3mvn.run.viz import category_palette, colorize_depth, colorize_semantic, legend, side_by_side
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.sim import render
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


# -- the rasteriser's skipping of hidden triangles, against drawing them all ----------------------


@nb.njit
def _rasterise_in_index_order(vertices, triangles, origin, basis, focal, near, h, w, row0, col0, step, ids, depth):
    """The renderer's rasteriser as it was before hidden triangles were skipped: every triangle on
    screen drawn in index order, the first of equal depths kept."""
    out_h, out_w = ids.shape
    m = triangles.shape[0]
    cam = render._to_camera(vertices, origin, basis)
    cx, cy = w / 2.0, h / 2.0
    # Per triangle: clipped, projected polygon (<= 4 vertices) and its inverse-depth plane.
    poly = np.empty((m, 4, 2))
    count = np.zeros(m, np.int32)
    plane = np.empty((m, 3))
    rows = np.empty((m, 2), np.int32)
    for t in range(m):
        n, xmin, xmax, ymin, ymax, _ = render._project(cam, triangles, t, near, focal, cx, cy, poly[t])
        if n < 3 or xmax < 0.5 or xmin > w - 0.5 or ymax < 0.5 or ymin > h - 0.5:
            continue  # behind the camera or off screen
        i0, i1, i2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e1f, e1r, e1u = cam[i1, 0] - cam[i0, 0], cam[i1, 1] - cam[i0, 1], cam[i1, 2] - cam[i0, 2]
        e2f, e2r, e2u = cam[i2, 0] - cam[i0, 0], cam[i2, 1] - cam[i0, 1], cam[i2, 2] - cam[i0, 2]
        nf = e1r * e2u - e1u * e2r
        nr = e1u * e2f - e1f * e2u
        nu = e1f * e2r - e1r * e2f
        c = nf * cam[i0, 0] + nr * cam[i0, 1] + nu * cam[i0, 2]
        if abs(c) < 1e-12 * (abs(nf) + abs(nr) + abs(nu)):
            continue  # the plane passes through the camera: seen edge-on
        r0 = max(0, int(math.ceil(ymin - 0.5)))
        r1 = min(h - 1, int(math.floor(ymax - 0.5)))
        # ... as sampled rows: row0 + k * step for k in [r0, r1]
        r0 = max(0, -((row0 - r0) // step))
        r1 = min(out_h - 1, (r1 - row0) // step)
        if r0 > r1:
            continue
        # 1/z = (nf + nr * u + nu * v) / c with u = (sx - cx) / f, v = (cy - sy) / f.
        plane[t, 0] = (nf - nr * cx / focal + nu * cy / focal) / c
        plane[t, 1] = nr / (focal * c)
        plane[t, 2] = -nu / (focal * c)
        rows[t, 0] = r0
        rows[t, 1] = r1
        count[t] = n
    # Sampled columns from a column span [j0, j1]: first_col[j0] .. last_col[j1].
    first_col = np.empty(w, np.int64)
    last_col = np.empty(w, np.int64)
    for j in range(w):
        first_col[j] = max(0, -((col0 - j) // step))
        last_col[j] = min(out_w - 1, (j - col0) // step)
    invz = np.zeros(ids.shape)
    ids[:, :] = m
    for t in range(m):
        n = count[t]
        if n == 0:
            continue
        for row in range(rows[t, 0], rows[t, 1] + 1):
            yc = row0 + row * step + 0.5
            xl, xr = 1e30, -1e30
            for k in range(n):
                ax, ay = poly[t, k, 0], poly[t, k, 1]
                bx, by = poly[t, (k + 1) % n, 0], poly[t, (k + 1) % n, 1]
                if (ay - yc) * (by - yc) <= 0.0 and ay != by:
                    x = ax + (yc - ay) * (bx - ax) / (by - ay)
                    xl = min(xl, x)
                    xr = max(xr, x)
            j0 = max(0, int(math.ceil(xl - 0.5 - 1e-7)))
            j1 = min(w - 1, int(math.floor(xr - 0.5 + 1e-7)))
            base = plane[t, 0] + plane[t, 2] * yc
            slope = plane[t, 1]
            if j0 > j1:
                continue
            c0 = first_col[j0]
            x = col0 + c0 * step + 0.5  # the pixel centre, exact in floating point
            for col in range(c0, last_col[j1] + 1):
                iz = base + slope * x
                x += step
                if iz > invz[row, col]:
                    invz[row, col] = iz
                    ids[row, col] = t
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            iz = invz[i, j]
            depth[i, j] = 1.0 / iz if iz > 0.0 else np.inf


def test_skipping_hidden_triangles_changes_no_pixel_of_any_frame():
    """Triangles are drawn nearest first and skipped when hidden; the result must be exactly that of
    drawing every triangle in index order (same triangle ids, same depths), level, tilted, whole and
    strided, in a furnished house where most walls hide behind others."""
    cfg = SimConfig()
    house = generate_house(3)
    world = build_world(house, cfg)
    r = Renderer(world, cfg)
    rng = np.random.default_rng(0)
    cells = np.argwhere(house.navigable)
    skipped = 0
    for k in range(24):
        row, col = cells[rng.integers(len(cells))]
        x, y = house.cell_center(int(row), int(col))
        pose, tilt = Pose(x, y, float(rng.uniform(-math.pi, math.pi))), math.radians([0.0, -30.0, 30.0, -12.5][k % 4])
        for shape, corner, step, size in (((480, 640), (2, 2), 4, (120, 160)), ((121, 161), (0, 0), 1, (121, 161))):
            origin, basis, focal = r._camera(pose, tilt, shape[1])
            args = (r._vertices, r._triangles, origin, basis, focal, render._NEAR_M, *shape, *corner, step)
            ids, depth = np.empty(size, np.int32), np.empty(size, np.float32)
            expected_ids, expected_depth = np.empty(size, np.int32), np.empty(size, np.float32)
            render._rasterise(*args, ids, depth)
            _rasterise_in_index_order(*args, expected_ids, expected_depth)
            assert np.array_equal(ids, expected_ids)
            assert np.array_equal(depth, expected_depth)
            skipped += len(np.setdiff1d(np.arange(world.num_triangles), ids))
    assert skipped > 0


def test_equal_depths_keep_the_lower_triangle_index_whichever_is_drawn_first():
    """Two floor triangles on one plane, the later one nearer (so drawn first): where both cover a
    pixel their depths are equal to the bit, and the earlier triangle must keep it, as drawing in
    index order would. Edges along the axes make every plane coefficient exact."""
    vertices = np.array(
        [[1.0, 2.0, 0.0], [5.0, 2.0, 0.0], [1.0, -2.0, 0.0], [0.5, 1.0, 0.0], [2.5, 1.0, 0.0], [0.5, -1.0, 0.0]]
    )
    triangles = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    camera = (np.array([-2.0, 0.0, 0.88]), render.camera_basis(0.0, 0.0), 40.0, 0.01)
    args = (vertices, triangles, *camera, 60, 80, 0, 0, 1)
    ids, depth = np.empty((60, 80), np.int32), np.empty((60, 80), np.float32)
    expected_ids, expected_depth = np.empty((60, 80), np.int32), np.empty((60, 80), np.float32)
    render._rasterise(*args, ids, depth)
    _rasterise_in_index_order(*args, expected_ids, expected_depth)
    assert (ids == 0).sum() > 0 and (ids == 1).sum() > 0  # both show where the other does not
    assert np.array_equal(ids, expected_ids)
    assert np.array_equal(depth, expected_depth)
