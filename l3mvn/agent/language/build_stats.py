"""``l3mvn language build-stats``: regenerate the shipped co-occurrence statistics."""

from __future__ import annotations

from pathlib import Path

from l3mvn.agent.language.cooccurrence import (
    BUILD_COMMAND,
    DEFAULT_ALPHA,
    DEFAULT_LIST_SIZE,
    DEFAULT_MIN_ROOMS,
    MAPPABLE_OBJECTS,
    STATS_PATH,
    CooccurrenceStats,
    build_stats,
    save_stats,
)
from l3mvn.agent.language.rooms import default_gibson_rooms_path, default_thor_metadata_path, load_rooms


def build_stats_file(
    gibson_rooms: str | Path | None = None,
    thor_metadata: str | Path | None = None,
    out: str | Path = STATS_PATH,
    candidates: tuple[str, ...] = MAPPABLE_OBJECTS,
    alpha: float = DEFAULT_ALPHA,
    min_rooms: int = DEFAULT_MIN_ROOMS,
    list_size: int = DEFAULT_LIST_SIZE,
) -> CooccurrenceStats:
    """Load both room sources, count, and write the JSON (with the command and sources in it)."""
    gibson = Path(gibson_rooms) if gibson_rooms else default_gibson_rooms_path()
    thor = Path(thor_metadata) if thor_metadata else default_thor_metadata_path()
    rooms = load_rooms(gibson_rooms, thor_metadata)
    sources = sorted({r.source for r in rooms})
    provenance = {
        "command": BUILD_COMMAND
        + (f" --alpha {alpha}" if alpha != DEFAULT_ALPHA else "")
        + (f" --min-rooms {min_rooms}" if min_rooms != DEFAULT_MIN_ROOMS else ""),
        "sources": {
            "gibson-3dsg": "shared/data/room_objects/gibson_3dsg_rooms.jsonl (Gibson 3D scene graphs; no tv class)"
            if "gibson-3dsg" in sources and gibson.exists()
            else None,
            "ai2thor": "procthor==0.0.1.dev2 databases/ai2thor-object-metadata.json "
            "(120 iTHOR rooms; RoboTHOR apartments left out)"
            if "ai2thor" in sources and thor
            else None,
        },
        "entropy": "natural log over the 6 goals",
    }
    stats = build_stats(rooms, candidates, alpha, min_rooms, list_size, provenance)
    save_stats(stats, out)
    return stats
