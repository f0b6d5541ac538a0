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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
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


@dataclass(frozen=True)
class Frame:
    """rgb uint8 (H, W, 3); depth float32 metres (H, W), 0 where invalid; semantic int32 (H, W)."""

    rgb: np.ndarray
    depth: np.ndarray
    semantic: np.ndarray


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

    def render(self, pose: Pose, tilt: float, height: int | None = None, width: int | None = None) -> Frame:
        h = self.cfg.frame_height if height is None else int(height)
        w = self.cfg.frame_width if width is None else int(width)
        if h <= 0 or w <= 0:
            raise L3MVNError(f"frame size must be positive, got {h}x{w}")
        if not math.isfinite(tilt) or abs(tilt) >= math.pi / 2:
            raise L3MVNError(f"tilt must be a finite angle in (-pi/2, pi/2) radians, got {tilt}")
        focal = (w / 2.0) / math.tan(math.radians(self.cfg.hfov_deg) / 2.0)
        origin = np.array([pose.x, pose.y, self.cfg.camera_height_m], np.float64)
        basis = camera_basis(pose.heading, tilt)
        ids = np.empty((h, w), np.int32)
        depth = np.empty((h, w), np.float32)
        _rasterise(self._vertices, self._triangles, origin, basis, focal, _NEAR_M, ids, depth)
        rgb = np.empty((h, w, 3), np.uint8)
        semantic = np.empty((h, w), np.int32)
        _shade(
            ids,
            depth,
            origin,
            basis,
            focal,
            self._color,
            self._category,
            self._floor,
            self.cfg.min_depth_m,
            self.cfg.max_depth_m,
            rgb,
            semantic,
        )
        return Frame(rgb=rgb, depth=depth, semantic=semantic)

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


@nb.njit(cache=True)
def _rasterise(vertices, triangles, origin, basis, focal, near, ids, depth):
    """Fill ``ids`` (triangle index, or len(triangles) for none) and ``depth`` (z, inf for none)."""
    h, w = ids.shape
    m = triangles.shape[0]
    nv = vertices.shape[0]
    cam = np.empty((nv, 3))
    for i in range(nv):
        dx = vertices[i, 0] - origin[0]
        dy = vertices[i, 1] - origin[1]
        dz = vertices[i, 2] - origin[2]
        for k in range(3):
            cam[i, k] = basis[k, 0] * dx + basis[k, 1] * dy + basis[k, 2] * dz
    cx, cy = w / 2.0, h / 2.0
    # Per triangle: clipped, projected polygon (<= 4 vertices) and its inverse-depth plane.
    poly = np.empty((m, 4, 2))
    count = np.zeros(m, np.int32)
    plane = np.empty((m, 3))
    rows = np.empty((m, 2), np.int32)
    for t in range(m):
        n = 0
        xmin, xmax, ymin, ymax = 1e30, -1e30, 1e30, -1e30
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
                poly[t, n, 0] = sx
                poly[t, n, 1] = sy
                xmin = min(xmin, sx)
                xmax = max(xmax, sx)
                ymin = min(ymin, sy)
                ymax = max(ymax, sy)
                n += 1
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
        if r0 > r1:
            continue
        # 1/z = (nf + nr * u + nu * v) / c with u = (sx - cx) / f, v = (cy - sy) / f.
        plane[t, 0] = (nf - nr * cx / focal + nu * cy / focal) / c
        plane[t, 1] = nr / (focal * c)
        plane[t, 2] = -nu / (focal * c)
        rows[t, 0] = r0
        rows[t, 1] = r1
        count[t] = n
    invz = np.zeros((h, w))
    ids[:, :] = m
    for t in range(m):
        n = count[t]
        if n == 0:
            continue
        for i in range(rows[t, 0], rows[t, 1] + 1):
            yc = i + 0.5
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
            step = plane[t, 1]
            for j in range(j0, j1 + 1):
                iz = base + step * (j + 0.5)
                if iz > invz[i, j]:
                    invz[i, j] = iz
                    ids[i, j] = t
    for i in range(h):
        for j in range(w):
            iz = invz[i, j]
            depth[i, j] = 1.0 / iz if iz > 0.0 else np.inf


@nb.njit(cache=True)
def _shade(ids, depth, origin, basis, focal, color, category, floor, dmin, dmax, rgb, semantic):
    """Per pixel: category, shaded colour with floor checker and fog; depth outside range -> 0."""
    h, w = ids.shape
    cx, cy = w / 2.0, h / 2.0
    for i in range(h):
        v = (cy - i - 0.5) / focal
        for j in range(w):
            t = ids[i, j]
            z = depth[i, j]
            semantic[i, j] = category[t]
            if not math.isfinite(z):
                depth[i, j] = 0.0
                rgb[i, j, 0] = 0
                rgb[i, j, 1] = 0
                rgb[i, j, 2] = 0
                continue
            fog = min(z * (_FOG_MAX / _FOG_RANGE_M), _FOG_MAX)
            gain = 1.0 - fog
            if floor[t]:
                u = (j + 0.5 - cx) / focal
                x = origin[0] + z * (basis[0, 0] + u * basis[1, 0] + v * basis[2, 0])
                y = origin[1] + z * (basis[0, 1] + u * basis[1, 1] + v * basis[2, 1])
                if (math.floor(x / _TILE_M) + math.floor(y / _TILE_M)) % 2 != 0:
                    gain *= _TILE_DARK
            rgb[i, j, 0] = np.uint8(min(color[t, 0] * gain + fog * _FOG_RGB[0], 255.0))
            rgb[i, j, 1] = np.uint8(min(color[t, 1] * gain + fog * _FOG_RGB[1], 255.0))
            rgb[i, j, 2] = np.uint8(min(color[t, 2] * gain + fog * _FOG_RGB[2], 255.0))
            if z < dmin or z > dmax:
                depth[i, j] = 0.0
