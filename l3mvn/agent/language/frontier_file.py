"""Frontier data files (written by ``l3mvn language frontier-data``, read by ``l3mvn train-head``).

One choice = the frontiers an agent chose among at one re-selection in one house, each with the
objects its window saw and the ground-truth metres from it to every goal. The reader types the lines
into ``Choice`` records and refuses a malformed one in one line naming it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from l3mvn.agent.language.queries import feedforward_query
from l3mvn.agent.language.vocabulary import GOALS, canonical
from l3mvn.core.errors import L3MVNError


def frontier_query(objects: Sequence[str]) -> str:
    """The sentence a frontier-trained head reads: the paper's feed-forward string over *every*
    mapped category in the window, canonical names sorted (what ``Scorer.query_objects`` gives with
    ``object_filter="all"`` at run time, so training and run time read the same text)."""
    return feedforward_query(tuple(sorted({canonical(o) for o in objects})))


@dataclass(frozen=True)
class FrontierRecord:
    objects: tuple[str, ...]  # canonical, sorted
    cost: float  # the agent's travel cost to it (geodesic on its map + turning), metres
    utility: float  # cost-utility's U (cluster cells)
    s_cu: float
    goal_m: dict[str, float]  # ground-truth metres to the nearest instance; inf: no path / none in the house


@dataclass(frozen=True)
class Choice:
    house: str
    episode: str
    seed: int
    goal: str  # the episode's goal (the record labels every goal)
    mapped: frozenset[str]  # every category on the agent's map then: a goal in it was no search
    frontiers: tuple[FrontierRecord, ...]


def load_choices(path: str | Path) -> list[Choice]:
    """The choices of a frontier-data file, in file order (``done`` lines aside)."""
    path = Path(path)
    if not path.is_file():
        raise L3MVNError(f"frontier data {path} not found; make it with `l3mvn language frontier-data`")
    out: list[Choice] = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        try:
            row = json.loads(line)
            if "done" in row:
                continue
            frontiers = tuple(
                FrontierRecord(
                    tuple(sorted(canonical(o) for o in f["objects"])),
                    float(f["cost"]),
                    float(f["utility"]),
                    float(f["s_cu"]),
                    {g: math.inf if f["goal_m"].get(g) is None else float(f["goal_m"][g]) for g in GOALS},
                )
                for f in row["frontiers"]
            )
            out.append(
                Choice(
                    str(row["house"]),
                    str(row["episode"]),
                    int(row["seed"]),
                    str(row["goal"]),
                    frozenset(canonical(o) for o in row["mapped"]),
                    frontiers,
                )
            )
        except (json.JSONDecodeError, KeyError, TypeError, ValueError, AttributeError) as exc:
            raise L3MVNError(
                f"{path}:{n}: not a frontier-data line ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0][:80] if str(exc) else ''})"
            ) from None
    if not out:
        raise L3MVNError(f"{path}: no frontier choice in it")
    return out


__all__ = ["Choice", "FrontierRecord", "frontier_query", "load_choices"]
