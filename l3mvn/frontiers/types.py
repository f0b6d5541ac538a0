"""The typed record of one scored frontier (its settings are ``l3mvn.config.FrontierConfig``).

A ``Frontier`` crosses three boundaries: extraction fills the geometry and cost-utility fields, the
global policy fills the language fields, and step events carry it (via ``to_dict``) to the dashboard
and the recorder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np



@dataclass
class Frontier:
    """One frontier cluster and its candidate goal cell.

    ``cells`` are (row, col) map cells; ``center`` is a cell of the cluster; ``distance_m`` is the
    geodesic distance from the agent to the centre; ``utility`` and ``cost`` are the two terms of
    S_CU = utility - lambda * cost and ``s_cu`` is S_CU min-max normalised over the returned frontiers.
    The language fields stay empty until the agent attaches a language policy's scores (``LanguageScore``).
    """

    id: int
    cells: np.ndarray
    center: tuple[int, int]
    size: int
    distance_m: float
    utility: float
    cost: float
    s_cu: float
    objects: tuple[str, ...] = ()
    queries: dict[str, str] = field(default_factory=dict)
    llm_scores: dict[str, float] = field(default_factory=dict)
    s_llm: float | None = None
    fused: float | None = None
    reason: str = ""

    def to_dict(self, cells: bool = False) -> dict[str, Any]:
        """JSON-friendly summary; the cells shrink to ``bbox`` = [row_min, col_min, row_max, col_max]
        (inclusive) unless ``cells`` asks for the full (row, col) list."""
        rows, cols = self.cells[:, 0], self.cells[:, 1]
        out: dict[str, Any] = {
            "id": self.id,
            "center": [int(self.center[0]), int(self.center[1])],
            "size": int(self.size),
            "bbox": [int(rows.min()), int(cols.min()), int(rows.max()), int(cols.max())],
            "distance_m": float(self.distance_m),
            "utility": float(self.utility),
            "cost": float(self.cost),
            "s_cu": float(self.s_cu),
            "objects": list(self.objects),
            "queries": dict(self.queries),
            "llm_scores": {k: float(v) for k, v in self.llm_scores.items()},
            "s_llm": None if self.s_llm is None else float(self.s_llm),
            "fused": None if self.fused is None else float(self.fused),
            "reason": self.reason,
        }
        if cells:
            out["cells"] = self.cells.tolist()
        return out
