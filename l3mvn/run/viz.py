"""Pure image helpers shared by the CLI, the dashboard and recordings.

Category colours are keyed by category *name*, never by index, so "bed" has the same colour in a
Gibson house, a procedural house and every recording.
"""

from __future__ import annotations

import zlib

import numpy as np

from l3mvn.core.errors import L3MVNError

BACKGROUND_RGB = (40, 40, 40)
# Cells the agent's failed forward steps blocked (walls to its planner); violet, far from every category.
COLLISION_RGB = (90, 0, 225)

# The map's one colour scheme: the live map, the Compare and Results pictures, rerun recordings and
# exported videos all draw with these, so a colour means the same thing wherever a map is shown.
# Dark unexplored space makes the light explored floor the figure, and the category colours and
# the frontier colormap read on both.
UNEXPLORED_RGB = (28, 30, 36)
FREE_RGB = (226, 226, 220)
GLIMPSED_RGB = (170, 170, 160)  # explored only from afar: what the agent may go look at
OBSTACLE_RGB = (112, 112, 124)
GUESSED_RGB = (70, 72, 88)  # an obstacle only guessed from depth too near to read
TRAJECTORY_RGB = (10, 10, 10)  # the walked path lies on explored floor: black reads best there
AGENT_RGB = (230, 30, 40)
GOAL_RGB = (255, 0, 200)  # the long-term goal
SHORT_TERM_GOAL_RGB = (255, 150, 0)
TARGET_RGB = (0, 0, 0)  # boxes and rings round the target category: no category colour is black
UNSCORED_RGB = (150, 150, 150)  # a frontier without a finite score
# Frontier score colormap, low -> high (viridis anchors): ordered in lightness, so it reads in grey too.
SCORE_ANCHORS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], np.float32)
SCORE_SCALE = "min-max"  # what the legends say the colours span

# Hand-picked, mutually distinct colours for the categories people look at most.
_NAMED_RGB: dict[str, tuple[int, int, int]] = {
    "chair": (230, 120, 40),
    "couch": (60, 110, 220),
    "potted plant": (50, 180, 70),
    "bed": (200, 60, 200),
    "toilet": (60, 220, 230),
    "tv": (240, 220, 40),
    "dining table": (150, 90, 40),
    "oven": (230, 50, 50),
    "sink": (120, 170, 255),
    "refrigerator": (170, 230, 140),
    "book": (255, 150, 170),
    "clock": (255, 255, 150),
    "vase": (120, 60, 160),
    "cup": (255, 200, 120),
    "bottle": (0, 140, 130),
    # The other categories of the procedural houses, each picked greedily as far as possible (CIELAB)
    # from every colour above and from the map's greys, so no two swatches read alike.
    "bathtub": (0, 0, 255),
    "shower": (0, 255, 0),
    "towel": (120, 15, 60),
    "dresser": (255, 0, 135),
    "side table": (30, 75, 0),
    "desk": (15, 0, 165),
    "coffee table": (135, 135, 0),
    "tv stand": (255, 165, 255),
    "shelving unit": (180, 255, 75),
    "counter": (0, 15, 75),
    "lamp": (195, 0, 255),
    "microwave": (0, 255, 195),
    "toaster": (120, 0, 0),
    "coffee machine": (0, 255, 120),
    "garbage can": (0, 90, 150),
    "laptop": (135, 90, 255),
    "laundry hamper": (120, 150, 90),
}

# For names not listed: the next colours of the same greedy pick (a hue from a name hash gives
# dozens of near-identical blues and greens).
_SPARE_RGB: tuple[tuple[int, int, int], ...] = (
    (180, 90, 150),
    (195, 165, 210),
    (15, 165, 210),
    (240, 165, 0),
    (180, 255, 225),
    (195, 15, 75),
    (135, 180, 0),
    (90, 60, 105),
    (75, 30, 15),
    (165, 105, 105),
    (75, 195, 150),
    (0, 0, 105),
    (0, 75, 60),
    (180, 135, 255),
    (0, 195, 0),
    (225, 105, 90),
)

# Turbo-like anchor colours (near, ..., far) for depth.
_DEPTH_ANCHORS = np.array(
    [
        [48, 18, 59],
        [70, 107, 227],
        [40, 188, 235],
        [50, 242, 152],
        [164, 252, 60],
        [237, 208, 58],
        [251, 128, 34],
        [210, 48, 5],
        [122, 4, 3],
    ],
    dtype=np.float32,
)


def category_color(name: str) -> tuple[int, int, int]:
    """A fixed colour for a category name; names not listed get a spare distinct colour by name hash."""
    key = name.strip().lower().replace("_", " ").replace("-", " ")
    if key in _NAMED_RGB:
        return _NAMED_RGB[key]
    return _SPARE_RGB[zlib.crc32(key.encode()) % len(_SPARE_RGB)]


def category_palette(categories: tuple[str, ...]) -> np.ndarray:
    """(K + 1, 3) uint8: row 0 is background, row k + 1 is ``categories[k]``."""
    return np.array([BACKGROUND_RGB, *(category_color(c) for c in categories)], dtype=np.uint8)


def legend(categories: tuple[str, ...]) -> list[tuple[str, tuple[int, int, int]]]:
    return [(c, category_color(c)) for c in categories]


def fitted_scores(scores) -> np.ndarray:
    """(N,) scores -> (N,) positions in [0, 1] on the colormap: min-max over the scores given.

    Min-max rather than rank: fused scores crowd into a narrow band (a fixed 0..1 scale paints them
    one colour), and min-max spreads that band over the whole colormap while keeping the gaps
    between scores (two near-equal frontiers get near-equal colours; a rank would make a 0.001
    difference look as large as any other). Frontiers that all score alike sit mid-scale; NaN stays NaN.
    """
    s = np.asarray(scores, np.float64).reshape(-1)
    finite = np.isfinite(s)
    if not finite.any():
        return np.full(s.shape, np.nan)
    lo, hi = float(s[finite].min()), float(s[finite].max())
    if hi - lo < 1e-9:
        return np.where(finite, 0.5, np.nan)
    return (s - lo) / (hi - lo)


def colormap(t) -> np.ndarray:
    """(N,) positions in [0, 1] -> (N, 3) uint8 score colours; NaN is ``UNSCORED_RGB``."""
    t = np.asarray(t, np.float64).reshape(-1)
    nan = ~np.isfinite(t)
    x = np.clip(np.where(nan, 0.0, t), 0.0, 1.0) * (len(SCORE_ANCHORS) - 1)
    lo = np.minimum(x.astype(np.int64), len(SCORE_ANCHORS) - 2)
    frac = (x - lo)[:, None]
    rgb = np.round(SCORE_ANCHORS[lo] * (1.0 - frac) + SCORE_ANCHORS[lo + 1] * frac).astype(np.uint8)
    rgb[nan] = UNSCORED_RGB
    return rgb


def score_colors(scores) -> np.ndarray:
    """(N,) scores -> (N, 3) uint8 colours fitted to the scores present (``fitted_scores``)."""
    return colormap(fitted_scores(scores))


def colorize_semantic(semantic: np.ndarray, categories: tuple[str, ...]) -> np.ndarray:
    """(H, W) ids (0 background, k + 1 = categories[k]) -> (H, W, 3) uint8."""
    sem = np.asarray(semantic)
    if sem.ndim != 2:
        raise L3MVNError(f"semantic image must be 2-D (H, W), got shape {sem.shape}")
    if sem.size and (sem.min() < 0 or sem.max() > len(categories)):
        raise L3MVNError(f"semantic ids must lie in 0..{len(categories)}, got {sem.min()}..{sem.max()}")
    return category_palette(categories)[sem]


def colorize_depth(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """(H, W) metres -> (H, W, 3) uint8 with a turbo-like map (near blue, far red); 0 / invalid black."""
    d = np.asarray(depth, dtype=np.float32)
    if d.ndim != 2:
        raise L3MVNError(f"depth image must be 2-D (H, W), got shape {d.shape}")
    if not max_depth > 0:
        raise L3MVNError(f"max_depth must be positive, got {max_depth}")
    valid = np.isfinite(d) & (d > 0)
    s = np.clip(np.where(valid, d, 0.0) / max_depth, 0.0, 1.0) * (len(_DEPTH_ANCHORS) - 1)
    lo = np.minimum(s.astype(np.int32), len(_DEPTH_ANCHORS) - 2)
    frac = (s - lo)[..., None]
    rgb = _DEPTH_ANCHORS[lo] * (1.0 - frac) + _DEPTH_ANCHORS[lo + 1] * frac
    out = rgb.astype(np.uint8)
    out[~valid] = 0
    return out


def side_by_side(*images: np.ndarray, gap: int = 4) -> np.ndarray:
    """Concatenate same-height images left to right with a thin black gap; gray images become RGB."""
    if not images:
        raise L3MVNError("side_by_side needs at least one image")
    rgb = [np.repeat(im[..., None], 3, axis=2) if im.ndim == 2 else im for im in map(np.asarray, images)]
    heights = {im.shape[0] for im in rgb}
    if len(heights) != 1:
        raise L3MVNError(f"side_by_side needs images of one height, got heights {sorted(heights)}")
    if any(im.ndim != 3 or im.shape[2] != 3 for im in rgb):
        raise L3MVNError("side_by_side takes (H, W) or (H, W, 3) images")
    spacer = np.zeros((rgb[0].shape[0], gap, 3), np.uint8)
    parts: list[np.ndarray] = []
    for i, im in enumerate(rgb):
        if i:
            parts.append(spacer)
        parts.append(im.astype(np.uint8, copy=False))
    return np.concatenate(parts, axis=1)
