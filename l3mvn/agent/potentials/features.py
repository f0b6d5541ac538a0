"""The network's input: the map around the agent, pooled to the network's cells.

One function serves training (maps revealed from full houses) and the running agent (its
``SemanticMap``), so both read the same channels in the same order: explored (the share of the cell's
map cells explored), obstacle (any), then one channel per SemExp category (any). A window that runs
off the map is padded with zeros, as unexplored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError

CHANNELS: tuple[str, ...] = ("explored", "obstacle", *GIBSON_CATEGORIES)
OUTPUTS: tuple[str, ...] = ("area", *GOAL_CATEGORIES)


@dataclass(frozen=True)
class WindowGrid:
    """Where the network's window lies on a map: ``factor`` map cells per network cell a side, the
    window's top-left map cell ``origin`` and its ``cells`` a side."""

    factor: int
    origin: tuple[int, int]
    cells: int

    @classmethod
    def around(cls, center: tuple[int, int], map_cell_m: float, cfg: PotentialConfig) -> WindowGrid:
        ratio = cfg.cell_m / map_cell_m
        factor = round(ratio)
        if factor < 1 or abs(ratio - factor) > 1e-6:
            raise L3MVNError(
                f"poni.cell_m ({cfg.cell_m} m) must be a whole multiple of the map's cell ({map_cell_m} m)"
            )
        half = cfg.window_cells * factor // 2
        return cls(factor, (int(center[0]) - half, int(center[1]) - half), cfg.window_cells)

    def to_window(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Network cells of map cells, and which of them fall inside the window."""
        wr = (np.asarray(rows) - self.origin[0]) // self.factor
        wc = (np.asarray(cols) - self.origin[1]) // self.factor
        inside = (wr >= 0) & (wr < self.cells) & (wc >= 0) & (wc < self.cells)
        return wr, wc, inside

    def flat_cells(self, cells: np.ndarray) -> np.ndarray:
        """The distinct network cells, as flat indices into a window, of the (K, 2) map ``cells``
        that fall inside it: where a frontier is read (its best cell) and, in training, labelled."""
        wr, wc, inside = self.to_window(cells[:, 0], cells[:, 1])
        return np.unique(wr[inside] * self.cells + wc[inside])


def window_features(
    explored: np.ndarray,
    obstacle: np.ndarray,
    categories: np.ndarray,
    category_names: tuple[str, ...],
    grid: WindowGrid,
) -> np.ndarray:
    """(len(CHANNELS), cells, cells) float32 input for the window ``grid`` of a map whose bool layers
    are ``explored``, ``obstacle`` (H, W) and ``categories`` (K, H, W) named ``category_names``; a
    SemExp category the map lacks stays zero."""
    f, n = grid.factor, grid.cells
    side = n * f
    index = {name: k for k, name in enumerate(category_names)}
    layers = [explored, obstacle] + [categories[index[c]] if c in index else None for c in GIBSON_CATEGORIES]
    out = np.zeros((len(CHANNELS), n, n), dtype=np.float32)
    h, w = explored.shape
    r0, c0 = grid.origin
    sr, sc = slice(max(r0, 0), min(r0 + side, h)), slice(max(c0, 0), min(c0 + side, w))
    if sr.start >= sr.stop or sc.start >= sc.stop:
        return out
    dr, dc = sr.start - r0, sc.start - c0
    block = np.zeros((side, side), dtype=np.float32)
    for k, layer in enumerate(layers):
        if layer is None:
            continue
        crop = layer[sr, sc]
        if not crop.any():
            continue
        block[:] = 0.0
        block[dr : dr + crop.shape[0], dc : dc + crop.shape[1]] = crop
        pooled = block.reshape(n, f, n, f)
        out[k] = pooled.mean(axis=(1, 3)) if k == 0 else pooled.max(axis=(1, 3))
    return out


def objects_hot(object_lists: list[tuple[str, ...]]) -> np.ndarray:
    """(len(object_lists), len(GIBSON_CATEGORIES)) bool: which SemExp categories each frontier's
    window holds (its ``Frontier.objects``); a name outside them has no column, as it has no channel."""
    index = {name: k for k, name in enumerate(GIBSON_CATEGORIES)}
    out = np.zeros((len(object_lists), len(GIBSON_CATEGORIES)), dtype=bool)
    for row, names in enumerate(object_lists):
        out[row, [index[n] for n in names if n in index]] = True
    return out
