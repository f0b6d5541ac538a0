"""Render a World into RGB, z-depth and per-pixel category ids, on the CPU, in a few milliseconds.

A z-buffer rasteriser compiled with numba, sampling every pixel at its centre exactly as a ray
caster would: per pixel it keeps the nearest triangle by the exact plane depth, so depth is the
analytic z-depth of a pinhole camera and the semantic id is the hit triangle's category.
Embree (Open3D's RaycastingScene) gives the same frames (``tests/test_render.py`` checks it) but
spends ~100 ns per ray in overhead alone, i.e. >= 40 ms at 480x640 on two cores; rasterising the
few thousand boundary quads of a floor costs a fraction of that. It runs on one thread: the agent
shares the two cores, and numba's thread pool degrades badly when they are oversubscribed.
Shading is one fused pass: a precomputed shaded colour per triangle, a floor checker from the hit
point, mild distance fog.

Most of a house's walls hide behind nearer ones; the rasteriser draws triangles nearest first and
skips those that small tiles of pixels already show to be behind (see ``_rasterise``), keeping the
result of drawing all of them in order bit for bit.

A frame is made as far as it is read (``l3mvn.core.frames``): the pixels an agent maps (the centre
of every k x k block) are rasterised alone, with the very arithmetic of the whole frame (pixel
centres, spans, the depth plane), so they hold the same values as the whole frame's; the whole
depth and semantic images, and the colour image after them, are made on first read.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame
from l3mvn.core.types import Pose
from l3mvn.world.sim.world import World

# Wrapped Lambert: every axis-aligned face direction gets its own brightness, so room corners and
# box edges read under a single fixed light.
_LIGHT = np.array([0.35, 0.6, 0.72]) / np.linalg.norm([0.35, 0.6, 0.72])
_AMBIENT = 0.45
_DIFFUSE = 0.55
_FOG_RGB = (128.0, 128.0, 135.0)
_FOG_MAX = 0.45  # fog fraction at _FOG_RANGE_M and beyond
_FOG_RANGE_M = 12.0
_TILE_M = 0.5  # floor checker: a metric cue for how far the floor runs
_TILE_DARK = 0.86
_NEAR_M = 0.01
_TILE_PX = 8  # side of the pixel tiles whose nearest surfaces let hidden triangles be skipped


class Renderer:
    """Renders a World from a pinhole camera ``cfg.camera_height_m`` above the agent's pose."""

    def __init__(self, world: World, cfg: SimConfig) -> None:
        self.world = world
        self.cfg = cfg
        m = world.num_triangles
        self._vertices = np.ascontiguousarray(world.vertices, np.float64)
        self._triangles = np.ascontiguousarray(world.triangles, np.int32)
        # Index m is the "no hit" sentinel: black, background, not floor.
        shade = _AMBIENT + _DIFFUSE * (0.5 + 0.5 * world.tri_normal.astype(np.float64) @ _LIGHT)
        self._color = np.zeros((m + 1, 3), np.float32)
        self._color[:m] = np.clip(world.tri_color * shade[:, None], 0.0, 1.0) * 255.0
        self._category = np.zeros(m + 1, np.int32)
        self._category[:m] = world.tri_category
        z = world.vertices[world.triangles][:, :, 2]
        self._floor = np.zeros(m + 1, np.bool_)
        self._floor[:m] = (world.tri_normal[:, 2] > 0.5) & (np.abs(z).max(axis=1) < 1e-6)
        self._by_category = {
            int(c): np.ascontiguousarray(self._triangles[world.tri_category == c])
            for c in np.unique(world.tri_category)
        }

    def render(self, pose: Pose, tilt: float, height: int | None = None, width: int | None = None) -> CameraFrame:
        """The whole frame, every image made."""
        frame = self.frame(pose, tilt, height, width)
        frame.rgb  # noqa: B018 - made now: the caller wants the whole frame
        return frame

    def frame(self, pose: Pose, tilt: float, height: int | None = None, width: int | None = None) -> CameraFrame:
        """The frame from ``pose`` at ``tilt``, its images made when first read."""
        h = self.cfg.frame_height if height is None else int(height)
        w = self.cfg.frame_width if width is None else int(width)
        if h <= 0 or w <= 0:
            raise L3MVNError(f"frame size must be positive, got {h}x{w}")
        if not math.isfinite(tilt) or abs(tilt) >= math.pi / 2:
            raise L3MVNError(f"tilt must be a finite angle in (-pi/2, pi/2) radians, got {tilt}")
        return RenderedFrame(self, pose, tilt, (h, w))

    def _camera(self, pose: Pose, tilt: float, width: int) -> tuple[np.ndarray, np.ndarray, float]:
        focal = (width / 2.0) / math.tan(math.radians(self.cfg.hfov_deg) / 2.0)
        origin = np.array([pose.x, pose.y, self.cfg.camera_height_m], np.float64)
        return origin, camera_basis(pose.heading, tilt), focal

    def _sampled(
        self, pose: Pose, tilt: float, shape: tuple[int, int], corner: tuple[int, int], step: int, size: tuple[int, int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(triangle ids, z-depth, depth, semantic) of ``size`` pixels of a frame of ``shape``: rows
        corner[0] + i * step, columns corner[1] + j * step."""
        origin, basis, focal = self._camera(pose, tilt, shape[1])
        ids = np.empty(size, np.int32)
        z = np.empty(size, np.float32)
        _rasterise(
            self._vertices, self._triangles, origin, basis, focal, _NEAR_M, *shape, corner[0], corner[1], step, ids, z
        )
        depth = np.empty(size, np.float32)
        semantic = np.empty(size, np.int32)
        _label(ids, z, self._category, self.cfg.min_depth_m, self.cfg.max_depth_m, depth, semantic)
        return ids, z, depth, semantic

    def _shaded(self, pose: Pose, tilt: float, ids: np.ndarray, z: np.ndarray) -> np.ndarray:
        origin, basis, focal = self._camera(pose, tilt, ids.shape[1])
        rgb = np.empty((*ids.shape, 3), np.uint8)
        _shade(ids, z, origin, basis, focal, self._color, self._floor, rgb)
        return rgb

    def count(self, pose: Pose, tilt: float, shape: tuple[int, int], label: int) -> int:
        """Pixels of the frame that show category ``label`` with valid depth. Only the box on screen
        of that category's triangles within the depth range is rasterised (every pixel showing one of
        them lies in it), as the whole frame would rasterise it."""
        triangles = self._by_category.get(label)
        if triangles is None:
            return 0
        origin, basis, focal = self._camera(pose, tilt, shape[1])
        box = np.empty(4, np.int64)
        if not _screen_box(
            self._vertices, triangles, origin, basis, focal, _NEAR_M, shape[0], shape[1], self.cfg.max_depth_m, box
        ):
            return 0
        r0, r1, c0, c1 = (int(v) for v in box)
        _, _, depth, semantic = self._sampled(pose, tilt, shape, (r0, c0), 1, (r1 - r0 + 1, c1 - c0 + 1))
        return int(np.count_nonzero((semantic == label) & (depth > 0)))

    def ray_directions(self, height: int, width: int, pose: Pose, tilt: float) -> np.ndarray:
        """(H, W, 3) world ray directions with unit length along the optical axis (hit t = z-depth)."""
        focal = (width / 2.0) / math.tan(math.radians(self.cfg.hfov_deg) / 2.0)
        u = (np.arange(width) + 0.5 - width / 2.0) / focal
        v = (height / 2.0 - np.arange(height) - 0.5) / focal
        f, r, up = camera_basis(pose.heading, tilt)
        return f + u[None, :, None] * r + v[:, None, None] * up


def camera_basis(heading: float, tilt: float) -> np.ndarray:
    """Rows: forward, right, up in world coordinates (heading CCW from +x, tilt positive up)."""
    ch, sh, ct, st = math.cos(heading), math.sin(heading), math.cos(tilt), math.sin(tilt)
    return np.array([[ct * ch, ct * sh, st], [sh, -ch, 0.0], [-st * ch, -st * sh, ct]], np.float64)


class RenderedFrame(CameraFrame):
    """A frame of the built-in renderer: strided pixels alone, the whole images on first read."""

    def __init__(self, renderer: Renderer, pose: Pose, tilt: float, shape: tuple[int, int]) -> None:
        super().__init__(shape)
        self._renderer, self._pose, self._tilt = renderer, pose, tilt
        self._ids: np.ndarray | None = None
        self._z: np.ndarray | None = None

    def _make_full(self) -> tuple[np.ndarray, np.ndarray]:
        self._ids, self._z, depth, semantic = self._renderer._sampled(
            self._pose, self._tilt, self.shape, (0, 0), 1, self.shape
        )
        return depth, semantic

    def _make_rgb(self) -> np.ndarray:
        self.depth  # noqa: B018 - the colours shade the whole frame's triangles and depths
        assert self._ids is not None and self._z is not None
        return self._renderer._shaded(self._pose, self._tilt, self._ids, self._z)

    def _make_strided(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        start = step // 2
        size = (len(range(start, self.shape[0], step)), len(range(start, self.shape[1], step)))
        _, _, depth, semantic = self._renderer._sampled(self._pose, self._tilt, self.shape, (start, start), step, size)
        return depth, semantic

    def _make_count(self, label: int) -> int:
        return self._renderer.count(self._pose, self._tilt, self.shape, label)


@nb.njit(cache=True)
def _project(cam, triangles, t, near, focal, cx, cy, poly):
    """Clip triangle ``t`` (camera coordinates ``cam``) at the near plane and project it into
    ``poly``: (vertex count, xmin, xmax, ymin, ymax, nearest forward distance)."""
    n = 0
    xmin, xmax, ymin, ymax, fmin = 1e30, -1e30, 1e30, -1e30, 1e30
    for e in range(3):
        a = triangles[t, e]
        b = triangles[t, (e + 1) % 3]
        a_in = cam[a, 0] >= near
        for k in range(2):
            if k == 0:
                if not a_in:
                    continue
                pf, pr, pu = cam[a, 0], cam[a, 1], cam[a, 2]
            else:
                if a_in == (cam[b, 0] >= near):
                    continue
                s = (near - cam[a, 0]) / (cam[b, 0] - cam[a, 0])
                pf = near
                pr = cam[a, 1] + s * (cam[b, 1] - cam[a, 1])
                pu = cam[a, 2] + s * (cam[b, 2] - cam[a, 2])
            sx = cx + focal * pr / pf
            sy = cy - focal * pu / pf
            poly[n, 0] = sx
            poly[n, 1] = sy
            xmin = min(xmin, sx)
            xmax = max(xmax, sx)
            ymin = min(ymin, sy)
            ymax = max(ymax, sy)
            fmin = min(fmin, pf)
            n += 1
    return n, xmin, xmax, ymin, ymax, fmin


@nb.njit(cache=True)
def _to_camera(vertices, origin, basis):
    nv = vertices.shape[0]
    cam = np.empty((nv, 3))
    for i in range(nv):
        dx = vertices[i, 0] - origin[0]
        dy = vertices[i, 1] - origin[1]
        dz = vertices[i, 2] - origin[2]
        for k in range(3):
            cam[i, k] = basis[k, 0] * dx + basis[k, 1] * dy + basis[k, 2] * dz
    return cam


@nb.njit(cache=True)
def _outcodes(cam, near, focal, cx, cy, w, h):
    """Per vertex: bit 1 behind the near plane; in front of it, bits 2-16 for beyond the left,
    right, top and bottom pixel centres, in ``_project``'s own arithmetic. A triangle whose three
    vertices share a bit is one ``_project`` would find off screen, so it is skipped unprojected."""
    codes = np.zeros(cam.shape[0], np.int32)
    for i in range(cam.shape[0]):
        pf = cam[i, 0]
        if not pf >= near:
            codes[i] = 1
            continue
        sx = cx + focal * cam[i, 1] / pf
        sy = cy - focal * cam[i, 2] / pf
        horizontal = (2 if sx < 0.5 else 0) | (4 if sx > w - 0.5 else 0)
        codes[i] = horizontal | (8 if sy < 0.5 else 0) | (16 if sy > h - 0.5 else 0)
    return codes


@nb.njit(cache=True)
def _rasterise(vertices, triangles, origin, basis, focal, near, h, w, row0, col0, step, ids, depth):
    """Fill ``ids`` (triangle index, or len(triangles) for none) and ``depth`` (z, inf for none) at
    the pixels (row0 + i * step, col0 + j * step) of an h x w frame.

    Each pixel keeps the largest inverse depth of the triangles covering it, the lowest index among
    equals: a rule that does not depend on the order triangles are drawn in. So they are drawn
    nearest first, and a triangle is skipped when every tile of pixels its box touches already
    holds nearer surfaces than any it could show there (a bound on its plane over the box, with
    room for rounding), which is what most walls behind walls are."""
    out_h, out_w = ids.shape
    m = triangles.shape[0]
    cam = _to_camera(vertices, origin, basis)
    cx, cy = w / 2.0, h / 2.0
    # Sampled columns from a column span [j0, j1]: first_col[j0] .. last_col[j1].
    first_col = np.empty(w, np.int64)
    last_col = np.empty(w, np.int64)
    for j in range(w):
        first_col[j] = max(0, -((col0 - j) // step))
        last_col[j] = min(out_w - 1, (j - col0) // step)
    # Per triangle on screen: clipped, projected polygon (<= 4 vertices), its inverse-depth plane,
    # its box of sampled pixels and a bound on the inverse depth it computes inside that box.
    poly = np.empty((m, 4, 2))
    count = np.zeros(m, np.int32)
    plane = np.empty((m, 3))
    box = np.empty((m, 4), np.int64)
    codes = _outcodes(cam, near, focal, cx, cy, w, h)
    reach = np.empty(m)
    nearest = np.empty(m)
    shown = np.empty(m, np.int64)
    n_shown = 0
    for t in range(m):
        i0, i1, i2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        if codes[i0] & codes[i1] & codes[i2]:
            continue  # wholly behind the camera or beyond one side of the screen
        n, xmin, xmax, ymin, ymax, fmin = _project(cam, triangles, t, near, focal, cx, cy, poly[t])
        if n < 3 or xmax < 0.5 or xmin > w - 0.5 or ymax < 0.5 or ymin > h - 0.5:
            continue  # behind the camera or off screen
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
        # Every pixel a row's span covers lies within the polygon's columns (the same tolerance).
        j0 = max(0, int(math.ceil(xmin - 0.5 - 1e-7)))
        j1 = min(w - 1, int(math.floor(xmax - 0.5 + 1e-7)))
        if r0 > r1 or j0 > j1 or first_col[j0] > last_col[j1]:
            continue
        # 1/z = (nf + nr * u + nu * v) / c with u = (sx - cx) / f, v = (cy - sy) / f.
        p0 = (nf - nr * cx / focal + nu * cy / focal) / c
        p1 = nr / (focal * c)
        p2 = -nu / (focal * c)
        plane[t, 0], plane[t, 1], plane[t, 2] = p0, p1, p2
        box[t, 0], box[t, 1], box[t, 2], box[t, 3] = r0, r1, first_col[j0], last_col[j1]
        xa, xb = col0 + box[t, 2] * step + 0.5, col0 + box[t, 3] * step + 0.5
        ya, yb = row0 + r0 * step + 0.5, row0 + r1 * step + 0.5
        # The plane is linear: its largest value over the box is at a corner. Each pixel's value is
        # three rounded operations from the exact one; the allowance is thousands of times that.
        top = p0 + max(p1 * xa, p1 * xb) + max(p2 * ya, p2 * yb)
        reach[t] = top + 1e-12 * (abs(p0) + abs(p1) * max(abs(xa), abs(xb)) + abs(p2) * max(abs(ya), abs(yb)))
        nearest[t] = fmin
        count[t] = n
        shown[n_shown] = t
        n_shown += 1
    shown = shown[:n_shown]
    shown = shown[np.argsort(nearest[shown], kind="mergesort")]
    invz = np.zeros(ids.shape)
    ids[:, :] = m
    tiles_h = (out_h + _TILE_PX - 1) // _TILE_PX
    tiles_w = (out_w + _TILE_PX - 1) // _TILE_PX
    tile_floor = np.zeros((tiles_h, tiles_w))  # least inverse depth in the tile, where not stale
    stale = np.zeros((tiles_h, tiles_w), np.bool_)
    for t in shown:
        tr0, tr1 = box[t, 0] // _TILE_PX, box[t, 1] // _TILE_PX
        tc0, tc1 = box[t, 2] // _TILE_PX, box[t, 3] // _TILE_PX
        hidden = True
        for tr in range(tr0, tr1 + 1):
            for tc in range(tc0, tc1 + 1):
                if stale[tr, tc]:
                    least = np.inf
                    for row in range(tr * _TILE_PX, min((tr + 1) * _TILE_PX, out_h)):
                        for col in range(tc * _TILE_PX, min((tc + 1) * _TILE_PX, out_w)):
                            least = min(least, invz[row, col])
                    tile_floor[tr, tc] = least
                    stale[tr, tc] = False
                if not reach[t] < tile_floor[tr, tc]:
                    hidden = False
                    break
            if not hidden:
                break
        if hidden:
            continue
        stale[tr0 : tr1 + 1, tc0 : tc1 + 1] = True
        n = count[t]
        for row in range(box[t, 0], box[t, 1] + 1):
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
                held = invz[row, col]
                if iz > held or (iz == held and iz > 0.0 and t < ids[row, col]):
                    invz[row, col] = iz
                    ids[row, col] = t
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            iz = invz[i, j]
            depth[i, j] = 1.0 / iz if iz > 0.0 else np.inf


@nb.njit(cache=True)
def _label(ids, z, category, dmin, dmax, depth, semantic):
    """Per pixel: the hit triangle's category, and its depth where the sensor's range keeps it
    (0 elsewhere, and where nothing was hit)."""
    h, w = ids.shape
    for i in range(h):
        for j in range(w):
            semantic[i, j] = category[ids[i, j]]
            d = z[i, j]
            depth[i, j] = d if math.isfinite(d) and dmin <= d <= dmax else 0.0


@nb.njit(cache=True)
def _shade(ids, z, origin, basis, focal, color, floor, rgb):
    """Per pixel: shaded colour with floor checker and fog; black where nothing was hit."""
    h, w = ids.shape
    cx, cy = w / 2.0, h / 2.0
    for i in range(h):
        v = (cy - i - 0.5) / focal
        for j in range(w):
            t = ids[i, j]
            d = z[i, j]
            if not math.isfinite(d):
                rgb[i, j, 0] = 0
                rgb[i, j, 1] = 0
                rgb[i, j, 2] = 0
                continue
            fog = min(d * (_FOG_MAX / _FOG_RANGE_M), _FOG_MAX)
            gain = 1.0 - fog
            if floor[t]:
                u = (j + 0.5 - cx) / focal
                x = origin[0] + d * (basis[0, 0] + u * basis[1, 0] + v * basis[2, 0])
                y = origin[1] + d * (basis[0, 1] + u * basis[1, 1] + v * basis[2, 1])
                if (math.floor(x / _TILE_M) + math.floor(y / _TILE_M)) % 2 != 0:
                    gain *= _TILE_DARK
            rgb[i, j, 0] = np.uint8(min(color[t, 0] * gain + fog * _FOG_RGB[0], 255.0))
            rgb[i, j, 1] = np.uint8(min(color[t, 1] * gain + fog * _FOG_RGB[1], 255.0))
            rgb[i, j, 2] = np.uint8(min(color[t, 2] * gain + fog * _FOG_RGB[2], 255.0))


@nb.njit(cache=True)
def _screen_box(vertices, triangles, origin, basis, focal, near, h, w, dmax, box):
    """Pixel box (first row, last row, first column, last column) into ``box`` holding every pixel
    that ``triangles`` cover nearer than ``dmax`` (depth over a triangle is least at a vertex of its
    clipped polygon); False when none is on screen."""
    cam = _to_camera(vertices, origin, basis)
    cx, cy = w / 2.0, h / 2.0
    codes = _outcodes(cam, near, focal, cx, cy, w, h)
    poly = np.empty((4, 2))
    found = False
    for t in range(triangles.shape[0]):
        if codes[triangles[t, 0]] & codes[triangles[t, 1]] & codes[triangles[t, 2]]:
            continue
        n, xmin, xmax, ymin, ymax, fmin = _project(cam, triangles, t, near, focal, cx, cy, poly)
        if n < 3 or xmax < 0.5 or xmin > w - 0.5 or ymax < 0.5 or ymin > h - 0.5:
            continue
        if fmin > dmax * (1.0 + 1e-6) + 1e-6:
            continue
        r0 = max(0, int(math.ceil(ymin - 0.5)))
        r1 = min(h - 1, int(math.floor(ymax - 0.5)))
        c0 = max(0, int(math.ceil(xmin - 0.5 - 1e-7)))
        c1 = min(w - 1, int(math.floor(xmax - 0.5 + 1e-7)))
        if r0 > r1 or c0 > c1:
            continue
        if not found:
            box[0], box[1], box[2], box[3] = r0, r1, c0, c1
            found = True
        else:
            box[0], box[1] = min(box[0], r0), max(box[1], r1)
            box[2], box[3] = min(box[2], c0), max(box[3], c1)
    return found
