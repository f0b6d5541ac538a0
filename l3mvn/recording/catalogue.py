"""Recording files: their names (dataset, scene, episode, policy), the catalogue of a folder, and
reading one back (which steps it holds, whether it is readable at all)."""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from rerun.chunk import RrdReader

from l3mvn.errors import L3MVNError

APPLICATION_ID = "l3mvn"
TIMELINE = "step"
_NAME_PART = re.compile(r"[^A-Za-z0-9.-]+")


def recording_path(recordings_dir: str | Path, dataset: str | Path, scene: str, episode_id: int,
                   policy: str) -> Path:
    """``<dir>/<dataset>_<scene>_<episode>_<policy>.rrd``; a dataset path contributes its folder name,
    and anything but letters, digits, '.' and '-' becomes '-' so the name parses back unambiguously."""
    parts = [_name_part(Path(str(dataset)).name or str(dataset)), _name_part(scene), str(int(episode_id)),
             _name_part(policy)]
    return Path(recordings_dir) / ("_".join(parts) + ".rrd")


@dataclass(frozen=True)
class RecordingInfo:
    """One ``.rrd`` on disk; the episode fields are None when the name does not follow the pattern."""

    path: Path
    dataset: str | None
    scene: str | None
    episode_id: int | None
    policy: str | None
    size_bytes: int
    mtime: float

    def to_dict(self) -> dict:
        return {"path": str(self.path), "name": self.path.name, "dataset": self.dataset, "scene": self.scene,
                "episode_id": self.episode_id, "policy": self.policy, "size_bytes": self.size_bytes,
                "mtime": self.mtime}


def parse_recording_name(path: str | Path) -> tuple[str, str, int, str] | None:
    """(dataset, scene, episode_id, policy) from a name made by ``recording_path``, else None."""
    p = Path(path)
    parts = p.stem.split("_") if p.suffix == ".rrd" else []
    if len(parts) != 4 or not parts[2].isdigit() or not all(parts):
        return None
    return parts[0], parts[1], int(parts[2]), parts[3]


def list_recordings(recordings_dir: str | Path) -> list[RecordingInfo]:
    """Every ``*.rrd`` directly in the folder, newest first (an absent folder has none)."""
    folder = Path(recordings_dir)
    if not folder.is_dir():
        return []
    out = []
    for path in folder.glob("*.rrd"):
        try:
            st = path.stat()
        except OSError:  # deleted while listing
            continue
        parsed = parse_recording_name(path)
        dataset, scene, episode_id, policy = parsed if parsed else (None, None, None, None)
        out.append(RecordingInfo(path, dataset, scene, episode_id, policy, st.st_size, st.st_mtime))
    return sorted(out, key=lambda r: (-r.mtime, r.path.name))


def _name_part(text: str) -> str:
    part = _NAME_PART.sub("-", str(text)).strip("-")
    if not part:
        raise L3MVNError(f"cannot name a recording after {text!r}: it needs a letter or digit")
    return part


@dataclass(frozen=True)
class RecordingSummary:
    """What a ``.rrd`` holds, read back with rerun's own reader."""

    path: Path
    application_id: str
    recording_id: str
    entity_paths: tuple[str, ...]
    steps: tuple[int, ...]  # distinct values on the ``step`` timeline, sorted


def open_recording(path: str | Path) -> RrdReader:
    """Rerun's reader for ``path``, or L3MVNError naming the file when it is missing or not a recording.

    A recording still being written (or cut off before its footer) is accepted: rerun falls back to
    scanning the file.
    """
    p = Path(path)
    if not p.is_file():
        raise L3MVNError(f"recording {p} not found" + ("" if not p.exists() else " (not a file)"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer": expected for a live or interrupted recording
            reader = RrdReader(p)
            recordings = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise L3MVNError(f"{p} is not a readable rerun recording: {one_line(exc)}") from None
    if not recordings:
        raise L3MVNError(f"{p} holds no rerun recording (only blueprints)")
    return reader


def read_recording(path: str | Path) -> RecordingSummary:
    """Entity paths and step numbers of the first recording in ``path`` (reads every chunk)."""
    reader = open_recording(path)
    entry = reader.recordings()[0]
    entities: set[str] = set()
    steps: set[int] = set()
    try:
        for chunk in reader.stream(store=entry):
            entities.add(chunk.entity_path)
            if TIMELINE in chunk.timeline_names:
                steps.update(chunk.to_record_batch().column(TIMELINE).to_pylist())
    except (RuntimeError, ValueError, OSError) as exc:
        raise L3MVNError(f"{path} is not a readable rerun recording: {one_line(exc)}") from None
    entities.discard("/__properties")
    return RecordingSummary(Path(path), entry.application_id, entry.recording_id, tuple(sorted(entities)),
                            tuple(sorted(s for s in steps if s is not None)))


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())
