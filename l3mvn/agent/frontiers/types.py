"""The typed record of one scored frontier (its settings are ``l3mvn.core.config.FrontierConfig``).

A ``Frontier`` crosses three boundaries: extraction fills the geometry and cost-utility fields, the
global policy fills the language fields, and step events carry it (via ``to_dict``) to the dashboard
and the recorder. ``Fusion`` is the language policy's rule with the numbers it used, so a viewer can
say why a frontier won without re-running the policy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

POTENTIALS_RULE = "potentials"  # PONI's rule (l3mvn.agent.potentials.policy)


def prior_score_name(fusion: Fusion | None) -> str:
    """What a frontier's prior score (``s_llm``) is, in one word for labels and plots: PONI's potential
    ("pot") or a language model's score ("LLM")."""
    return "pot" if fusion is not None and fusion.rule == POTENTIALS_RULE else "LLM"


@dataclass(frozen=True)
class Fusion:
    """How a language policy turned its frontier scores into a choice, with every number it compared.

    Tuples follow the frontier list (``ids[k]`` names frontier k, as ``F<id>``). ``branch`` is the
    case of ``rule`` that fired: paper ``language`` (max S_LLM above B), ``exploration`` (below B) or
    ``fused`` (inside B); official_code ``language``, ``first above 0.1`` or ``utility``; expected
    and potentials ``least total`` (potentials is PONI's: ``s_llm`` holds the goal's object
    potential, ``explore`` the area potential, ``bonus_m`` the area and size bonus, ``exploration``
    which bonuses). ``compared`` is what the rule ranked by: paper the fused score, official_code
    S_LLM with the no-object stand-in, expected and potentials the total metres (least wins).
    ``choice`` is the rule's pick, which the agent's commitment may overrule in favour of the
    frontier it already pursues.
    """

    rule: str
    branch: str
    choice: int
    ids: tuple[int, ...]
    s_llm: tuple[float, ...]
    explore: tuple[float, ...]
    compared: tuple[float, ...]
    exploration: str = "cost-utility"
    bound: tuple[float, float] | None = None  # paper
    threshold: float | None = None  # official_code
    cost_m: tuple[float, ...] = ()  # expected: travel cost to each frontier
    bonus_m: tuple[float, ...] = ()  # expected: size bonus U / lambda
    expected_m: tuple[float, ...] = ()  # expected: the head's metres on from each frontier to the goal
    scorer: str = ""  # what gave the S_LLM scores: the scorer, and its model where it has one
    words: str = ""  # potentials with a map head: the embedder whose reading of the window adds metres

    @property
    def _words(self) -> str:
        return f" and the {self.words} words of the frontier's window" if self.words else ""

    @property
    def least_wins(self) -> bool:
        """Whether ``compared`` ranks least first (the rules that compare metres) or highest first."""
        return self.rule in ("expected", POTENTIALS_RULE)

    @property
    def max_s_llm(self) -> float:
        return max(self.s_llm) if self.s_llm else 0.0

    def describe(self) -> str:
        """The rule in one line with its numbers, ending with the winner against the runner-up."""
        name = "S_CU" if self.exploration == "cost-utility" else "nearness"
        if self.rule == "expected":
            return (
                "expected: least metres to the frontier - size bonus + expected metres on to the goal: "
                + self._versus(self.compared, least=True, fmt=self._total)
            )
        if self.rule == POTENTIALS_RULE:
            return (
                f"PONI: least metres to the frontier - bonus ({self.exploration}) + expected metres on to the "
                f"goal (from the object potential{self._words}): "
                + self._versus(self.compared, least=True, fmt=self._total)
            )
        if self.rule == "official_code":  # S_LLM as compared: a frontier without objects counts 0.1 + 0.1 U / max U
            head = f"official code: max S_LLM {max(self.compared):.2f}"
            if self.branch == "language":
                return f"{head} > {self.threshold:g}, so the highest S_LLM: " + self._versus(self.compared)
            if self.branch == "first above 0.1":
                k = self.choice
                return (
                    f"{head} <= {self.threshold:g}, so the first frontier by {name} with S_LLM > 0.1: "
                    f"F{self.ids[k]} ({name} {self.explore[k]:.2f}, S_LLM {self.compared[k]:.2f})"
                )
            return f"{head} <= {self.threshold:g}, so the best {name}: " + self._versus(self.explore)
        assert self.bound is not None  # the paper's rule always has its bound
        lo, hi = self.bound
        head = f"bound B = [{lo:.2f}, {hi:.2f}]; max S_LLM {self.max_s_llm:.2f}"
        if self.branch == "language":
            return f"{head} is above B, so language alone decides: " + self._versus(self.s_llm)
        if self.branch == "exploration":
            return f"{head} is below B, so {name} alone decides: " + self._versus(self.explore)
        return f"{head} is inside B, so fused = max(S_LLM, {lo:.2f} + {hi - lo:.2f} x {name}): " + self._versus(
            self.compared
        )

    def _total(self, k: int) -> str:
        return f"{self.cost_m[k]:.1f} - {self.bonus_m[k]:.1f} + {self.expected_m[k]:.1f} = {self.compared[k]:.1f} m"

    def _versus(
        self, values: tuple[float, ...], *, least: bool = False, fmt: Callable[[int], str] | None = None
    ) -> str:
        """``F<choice> <value> beats F<runner-up> <value>`` (the best other frontier by ``values``)."""
        show = fmt or (lambda k: f"{values[k]:.2f}")
        k = self.choice
        others = [j for j in range(len(values)) if j != k]
        if not others:
            return f"F{self.ids[k]} {show(k)} (the only frontier)"
        j = min(others, key=lambda o: values[o]) if least else max(others, key=lambda o: values[o])
        return f"F{self.ids[k]} {show(k)} beats F{self.ids[j]} {show(j)}"

    def to_dict(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["bound"] = None if self.bound is None else list(self.bound)
        out.update({k: list(v) for k, v in out.items() if isinstance(v, tuple)})
        out["line"] = self.describe()
        return out


@dataclass
class Frontier:
    """One frontier cluster and its candidate goal cell.

    ``cells`` are (row, col) map cells; ``center`` is a cell of the cluster; ``distance_m`` is the
    geodesic distance from the agent to the centre; ``utility`` and ``cost`` are the two terms of
    S_CU = utility - lambda * cost and ``s_cu`` is S_CU min-max normalised over the returned frontiers.
    The language fields stay empty until the agent attaches a language policy's scores (``LanguageScore``):
    ``expected_m`` holds a distance-predicting head's metres from the frontier to each goal, and
    ``fusion`` the rule of the selection that scored it (one object shared by that selection's frontiers).
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
    expected_m: dict[str, float] = field(default_factory=dict)
    fusion: Fusion | None = None

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
            "expected_m": {k: float(v) for k, v in self.expected_m.items()},
            "fusion": None if self.fusion is None else self.fusion.to_dict(),
        }
        if cells:
            out["cells"] = self.cells.tolist()
        return out
