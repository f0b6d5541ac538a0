"""The episode videos a report embeds: found in a folder by the name ``l3mvn eval --video`` and
``l3mvn export`` give them (``result_video_name``), failures first, at most a given number.

The page is one file that opens without a server, so each video travels inside it as a data: URI;
the choice is capped and its size is said, since every embedded megabyte is a megabyte of HTML.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from itertools import zip_longest
from pathlib import Path

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.result_videos import result_video_name
from l3mvn.world.task.scoring import FAILURE_CAUSES
from l3mvn_studio.report_data import Run

MAX_VIDEOS = 12
# The exporter writes VP9 in WebM, under the same stem, where the installed PyAV lacks libx264.
_TYPES = {".mp4": "video/mp4", ".webm": "video/webm"}


@dataclass(frozen=True)
class Video:
    run: int  # index of its run in the report
    row: dict
    name: str
    mime: str
    data: bytes

    def data_uri(self) -> str:
        return f"data:{self.mime};base64,{base64.b64encode(self.data).decode('ascii')}"


@dataclass
class VideoChoice:
    """The videos embedded, and the counts the page states about the rest."""

    folder: Path | None
    limit: int = MAX_VIDEOS
    embedded: list[Video] = field(default_factory=list)
    found: int = 0  # rows with a video in the folder
    missing: int = 0  # rows without one
    problems: list[str] = field(default_factory=list)  # videos found but not readable

    @property
    def left_out(self) -> int:
        return self.found - len(self.embedded) - len(self.problems)

    @property
    def size(self) -> int:
        return sum(len(v.data) for v in self.embedded)


def choose_videos(runs: list[Run], folder: str | Path | None, max_videos: int = MAX_VIDEOS) -> VideoChoice:
    """Up to ``max_videos`` videos of the runs' rows from ``folder``: failures before successes
    (failures by cause, in the order the task scores them), taking the runs in turn so every run is
    shown; None: no folder was given."""
    if folder is None:
        return VideoChoice(None)
    path = Path(folder)
    if not path.is_dir():
        raise L3MVNError(f"videos folder {path} not found (give the folder `l3mvn eval --video` or `export` wrote)")
    if max_videos < 0:
        raise L3MVNError(f"--max-videos must be 0 or more, got {max_videos}")
    choice = VideoChoice(path, max_videos)
    failures: list[list[tuple[int, dict, Path]]] = []
    successes: list[list[tuple[int, dict, Path]]] = []
    for i, run in enumerate(runs):
        found = []
        for row in sorted(run.rows, key=_outcome_order):
            video = _video_file(path, row)
            if video is None:
                choice.missing += 1
            else:
                found.append((i, row, video))
        choice.found += len(found)
        failures.append([f for f in found if f[1]["success"] != 1])
        successes.append([f for f in found if f[1]["success"] == 1])
    for i, row, video in (_in_turn(failures) + _in_turn(successes))[:max_videos]:
        try:
            data = video.read_bytes()
        except OSError as exc:
            choice.problems.append(f"{video.name}: {exc.strerror or exc}")
            continue
        choice.embedded.append(Video(i, row, video.name, _TYPES[video.suffix], data))
    return choice


def _outcome_order(row: dict) -> tuple[int, str]:
    cause = row["failure"]
    rank = FAILURE_CAUSES.index(cause) if cause != "success" else len(FAILURE_CAUSES)
    return rank, row["key"]


def _video_file(folder: Path, row: dict) -> Path | None:
    """The row's video in ``folder`` (MP4, else the WebM the exporter falls back to), when it is a file."""
    stem = Path(result_video_name(row)).stem
    for suffix in _TYPES:
        candidate = folder / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def _in_turn(per_run: list[list[tuple[int, dict, Path]]]) -> list[tuple[int, dict, Path]]:
    """One item of each run in turn, so the first runs' videos do not crowd out the others'."""
    return [item for group in zip_longest(*per_run) for item in group if item is not None]
