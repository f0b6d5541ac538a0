"""What the dashboard shows, as plain typed records: the controller builds them, the views draw them.

A ``Snapshot`` is complete and immutable: a browser tab that connects late, or a view that skips
frames because the agent is faster than the page, only ever needs the latest one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from l3mvn.agent.frontiers import Fusion
from l3mvn.run.events import StepEvent

Cell = tuple[int, int]


@dataclass(frozen=True)
class FrontierMarker:
    """One frontier as the dashboard lists it (scores are None until the policy fills them)."""

    id: int
    cell: Cell
    size: int
    distance_m: float
    s_cu: float
    s_llm: float | None
    fused: float | None
    objects: tuple[str, ...]
    queries: dict[str, str]
    reason: str
    chosen: bool
    llm_scores: dict[str, float] = field(default_factory=dict)  # p(goal | frontier) for every goal
    expected_m: dict[str, float] = field(default_factory=dict)  # a distance head's metres to every goal
    score_name: str = "LLM"  # what ``s_llm`` holds: a language model's score, or PONI's potential ("pot")

    @property
    def label(self) -> str:
        llm = "-" if self.s_llm is None else f"{self.s_llm:.2f}"
        fused = "-" if self.fused is None else f"{self.fused:.2f}"
        return f"F{self.id}  {self.score_name} {llm} | CU {self.s_cu:.2f} | fused {fused}"


@dataclass(frozen=True, eq=False)
class MapView:
    """The map as an image cropped to what matters, plus everything drawn on top of it, in cells.

    ``image`` covers grid cells ``origin .. origin + image.shape[:2] / scale``; all cells are in the
    grid of ``source``: the agent's own map, or the scene's ground-truth grid for policies that keep
    no map (then nothing here is what the agent knows).
    """

    image: np.ndarray
    origin: Cell
    scale: int
    grid_shape: Cell
    resolution_m: float
    source: str  # "agent map" | "ground truth"
    agent_cell: Cell
    agent_heading: float
    long_term_goal: Cell | None = None
    short_term_goal: Cell | None = None
    goal_kind: str = ""
    override: str | None = None
    frontiers: tuple[FrontierMarker, ...] = ()
    legend: tuple[tuple[str, tuple[int, int, int]], ...] = ()  # the categories the image shows
    target: str = ""  # the goal category, ringed on the image
    world_origin: tuple[float, float] = (0.0, 0.0)  # world (x, y) of cell (0, 0)'s centre; +col = +x, +row = +y
    fusion: Fusion | None = None  # the language rule of the last frontier choice, with its numbers

    @property
    def cells(self) -> Cell:
        return self.image.shape[0] // self.scale, self.image.shape[1] // self.scale

    def contains(self, cell: Cell) -> bool:
        return 0 <= cell[0] < self.grid_shape[0] and 0 <= cell[1] < self.grid_shape[1]


@dataclass(frozen=True)
class Metrics:
    """Running totals over this server session. SR and SPL cover only the episodes a policy ran by
    itself (``policies`` names them): an episode a person steered measures the person, so it is only
    counted, in ``steered``."""

    episodes: int = 0
    successes: int = 0
    spl_sum: float = 0.0
    steered: int = 0
    policies: tuple[str, ...] = ()

    @property
    def finished(self) -> int:
        return self.episodes + self.steered

    @property
    def sr(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0

    @property
    def spl(self) -> float:
        return self.spl_sum / self.episodes if self.episodes else 0.0

    def add(self, result: dict, policy: str) -> Metrics:
        return replace(
            self,
            episodes=self.episodes + 1,
            successes=self.successes + int(bool(result.get("success"))),
            spl_sum=self.spl_sum + float(result.get("spl", 0.0)),
            policies=self.policies if policy in self.policies else self.policies + (policy,),
        )

    def add_steered(self) -> Metrics:
        return replace(self, steered=self.steered + 1)


@dataclass(frozen=True)
class Frames:
    """Display-sized camera frames (RGB, colour-mapped depth, colour-mapped semantics)."""

    rgb: np.ndarray
    depth: np.ndarray
    semantic: np.ndarray


@dataclass(frozen=True, eq=False)
class Snapshot:
    """Everything on the page after one step (or reset, or control change)."""

    seq: int
    policy: str
    running: bool
    steps_per_second: float
    metrics: Metrics
    event: StepEvent | None = None
    episode_id: int | None = None
    scene: str | None = None
    frames: Frames | None = None
    map: MapView | None = None
    manual_goal: Cell | None = None
    segment_note: str = ""
    error: str | None = None
    note: str = ""
    busy: str = ""  # what the worker is doing that holds the page's controls (a reset, a model load)
    run_queued: bool = False  # Run was pressed during a reset: it starts when the reset ends
    stepped_at: float = 0.0  # time.time() when the step's event arrived (latency measurements)
    achieved_steps_per_second: float | None = None  # what the current Run gets (None when not running)


@dataclass(frozen=True)
class Notice:
    """A message for one browser tab (``client_id``) or, when None, for every tab."""

    text: str
    level: str = "info"  # "info" | "warning" | "error"
    client_id: int | None = None
    details: dict = field(default_factory=dict)
    sticky: bool = False  # stays until dismissed (outcomes, failures): a user away for a minute still sees it
    title: str = ""  # empty: one by level ("L3MVN", "Request refused", "Error")
