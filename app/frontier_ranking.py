"""How the dashboard ranks frontiers: one score per frontier, and which few the map labels.

The map's marker colours, its labels and the Frontiers table all rank by the same score, so a
frontier labelled on the map is always near the top of the table.
"""

from __future__ import annotations

from l3mvn_studio.state import FrontierMarker

TOP_LABELS = 3  # frontiers labelled on the map (the best by score, plus the chosen one)


def frontier_score(f: FrontierMarker) -> float:
    """What a frontier's colour shows: the fused score where the policy fuses, else cost-utility."""
    return f.fused if f.fused is not None else f.s_cu


def labelled_frontiers(frontiers: tuple[FrontierMarker, ...]) -> set[int]:
    """Ids of the frontiers labelled on the map: the chosen one and the best ``TOP_LABELS`` by score."""
    best = sorted(frontiers, key=frontier_score, reverse=True)[:TOP_LABELS]
    return {f.id for f in best} | {f.id for f in frontiers if f.chosen}
