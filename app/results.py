"""The results browser's data: eval result files in a folder, their episodes, filters, summaries,
recordings read back frame by frame, a headless re-run of one result line, and the episode of a line
as the live session loads it (its scene, stored config and policy, and its recording's poses).

The browser only offers files found in the ``--results`` folder (nothing typed in the page), and every
bad file or line becomes a one-line problem beside what could be read, never an exception in a view.
"""

from __future__ import annotations

import dataclasses
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.types import Pose
from l3mvn.run.eval.job import EvalJob
from l3mvn.run.eval.results import episode_lines
from l3mvn.run.recording.catalogue import TIMELINE, find_recording, open_recording, recording_path, unique_tag
from l3mvn.run.recording.drawing import VideoOptions, frames
from l3mvn.run.recording.entities import WORLD_AGENT, reader_path
from l3mvn.run.recording.recorded import read_episode
from l3mvn.run.registry import check_policy
from l3mvn.world.datasets import load_episode_set
from l3mvn_studio.compare import EpisodeSource
from l3mvn_studio.map_image import png_bytes
from l3mvn_studio.session_worker import EpisodeStart

ALL, FAILURES, SUCCESSES = "all", "failures", "successes"
SORT_KEYS = ("row", "scene", "goal", "success", "spl", "dtg", "steps", "failure", "coverage")
FRAME_HEIGHT = 320  # pixels of the recording's camera and map panels (drawn over the main view: readable)
MAX_ROWS = 100_000  # episodes one file shows (ten times Gibson val for every policy of the paper)


@dataclass(frozen=True)
class EpisodeRow:
    """One episode line of a result file, as the table shows it (``raw`` is the whole line)."""

    index: int  # 1-based line number in the file
    scene: str
    episode_id: int
    goal: str
    policy: str
    success: bool
    spl: float | None
    dtg: float | None
    steps: int
    failure: str
    coverage: float | None
    raw: dict

    @property
    def label(self) -> str:
        return f"{self.index}: {self.scene} #{self.episode_id} {self.goal} ({'ok' if self.success else self.failure})"


@dataclass(frozen=True)
class ResultFile:
    """The readable episodes of one file and a one-line problem per line that was left out."""

    path: Path
    rows: tuple[EpisodeRow, ...]
    problems: tuple[str, ...]


def list_result_files(folder: str | Path) -> list[Path]:
    """The regular ``*.jsonl`` files directly in ``folder``, by name (an absent folder has none; a
    FIFO, device or folder named like one is not offered: reading it could block)."""
    p = Path(folder)
    if not p.is_dir():
        return []
    return sorted(path for path in p.glob("*.jsonl") if path.is_file())


def load_result_file(path: str | Path) -> ResultFile:
    """Every valid episode line of ``path`` (at most ``MAX_ROWS``); error rows and malformed lines
    become problems naming their line. A file with no episode line at all is an L3MVNError (it is
    not a result file)."""
    p = Path(path)
    read = episode_lines(p, limit=MAX_ROWS)
    rows = []
    for n, row in read.rows:
        extra = row.get("extra") if isinstance(row.get("extra"), dict) else {}
        coverage = extra.get("coverage")
        rows.append(
            EpisodeRow(
                n,
                row["scene"],
                row["episode_id"],
                row["goal"],
                row["policy"],
                row["success"] == 1,
                row["spl"],
                row["dtg"],
                row["steps"],
                row["failure"],
                coverage if _is_number(coverage) else None,
                row,
            )
        )
    if not rows:
        raise L3MVNError(
            f"{p.name} is not an eval result file: no episode line"
            + (f" ({read.problems[0]})" if read.problems else "")
        )
    return ResultFile(p, tuple(rows), tuple(read.problems))


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def filter_choices(rows: tuple[EpisodeRow, ...]) -> tuple[str, ...]:
    """all / failures / successes, then ``cause: X`` per failure cause and ``goal: X`` per category present."""
    causes = sorted({r.failure for r in rows if not r.success})
    goals = sorted({r.goal for r in rows})
    return (ALL, FAILURES, SUCCESSES, *(f"cause: {c}" for c in causes), *(f"goal: {g}" for g in goals))


def select(rows: tuple[EpisodeRow, ...], how: str, sort: str = "row", descending: bool = False) -> list[EpisodeRow]:
    """The rows ``how`` keeps (one of ``filter_choices``), sorted by ``sort`` (missing values last)."""
    if how == ALL:
        kept = list(rows)
    elif how == FAILURES:
        kept = [r for r in rows if not r.success]
    elif how == SUCCESSES:
        kept = [r for r in rows if r.success]
    elif how.startswith("cause: "):
        kept = [r for r in rows if not r.success and r.failure == how[7:]]
    elif how.startswith("goal: "):
        kept = [r for r in rows if r.goal == how[6:]]
    else:
        raise L3MVNError(f"unknown filter {how!r}; choose one of {', '.join(filter_choices(rows))}")
    if sort not in SORT_KEYS:
        raise L3MVNError(f"unknown sort key {sort!r}; choose one of {', '.join(SORT_KEYS)}")
    attr = "index" if sort == "row" else sort
    present = [r for r in kept if getattr(r, attr) is not None]
    missing = [r for r in kept if getattr(r, attr) is None]
    return sorted(present, key=lambda r: getattr(r, attr), reverse=descending) + missing


def summaries(rows: list[EpisodeRow], by: str = "goal") -> tuple[dict[str, tuple[int, float, float]], dict[str, int]]:
    """Per ``by`` (goal or scene): (episodes, SR, mean SPL); and episodes per failure cause (``success`` included)."""
    groups: dict[str, list[EpisodeRow]] = defaultdict(list)
    for r in rows:
        groups[getattr(r, by)].append(r)
    per_group = {
        g: (len(rs), float(np.mean([r.success for r in rs])), float(np.mean([r.spl or 0.0 for r in rs])))
        for g, rs in sorted(groups.items())
    }
    causes: dict[str, int] = defaultdict(int)
    for r in rows:
        causes[r.failure] += 1
    return per_group, dict(sorted(causes.items(), key=lambda kv: -kv[1]))


def solved_by_one(a: tuple[EpisodeRow, ...], b: tuple[EpisodeRow, ...]) -> tuple[list[EpisodeRow], list[EpisodeRow]]:
    """Episodes (matched by key) that ``a`` solved and ``b`` did not, and the reverse."""
    in_b = {r.raw["key"]: r for r in b}
    in_a = {r.raw["key"]: r for r in a}
    only_a = [r for r in a if r.success and r.raw["key"] in in_b and not in_b[r.raw["key"]].success]
    only_b = [r for r in b if r.success and r.raw["key"] in in_a and not in_a[r.raw["key"]].success]
    return only_a, only_b


def recording_of(recordings_dir: str | Path, row: EpisodeRow) -> Path | None:
    return find_recording(recordings_dir, row.scene, row.episode_id, row.policy)


def recording_frames(path: str | Path) -> tuple[list[bytes], list[str]]:
    """One picture per recorded step (camera, map with frontiers and scores, the decision under them)
    as a PNG (``png_rgb`` reads it: raw, a 500-step episode's pictures would take ~0.5 GB) and that
    step's decision line; one-line L3MVNError when the file is not a readable recording."""
    ep = read_episode(path)
    pictures = [png_bytes(p) for p in frames(ep, VideoOptions(height=FRAME_HEIGHT, title_s=0.0), title_frames=0)]
    return pictures, [f"step {s.step}: {s.decision or '(no decision logged)'}" for s in ep.steps]


def recorded_poses(path: str | Path) -> dict[int, Pose]:
    """The agent's pose at each step of a recording (its world transform); one-line L3MVNError when the
    file is not a readable recording."""
    p = Path(path)
    reader = open_recording(p)
    poses: dict[int, Pose] = {}
    try:
        for chunk in reader.stream(store=reader.recordings()[0]):
            if chunk.entity_path != reader_path(WORLD_AGENT):
                continue
            batch = chunk.to_record_batch()
            names = set(batch.schema.names)
            if not {TIMELINE, _TRANSLATION, _ROTATION} <= names:
                continue
            for step, xyz, turn in zip(
                batch.column(TIMELINE).to_pylist(),
                batch.column(_TRANSLATION).to_pylist(),
                batch.column(_ROTATION).to_pylist(),
                strict=True,
            ):
                if step is not None and xyz and turn:
                    poses[int(step)] = Pose(float(xyz[0][0]), float(xyz[0][1]), float(turn[0]["angle"]))
    except (RuntimeError, ValueError, OSError, KeyError, TypeError, IndexError, L3MVNError) as exc:
        raise L3MVNError(f"{p.name} is not a readable rerun recording: {first_line(exc)}") from None
    return poses


_TRANSLATION, _ROTATION = "Transform3D:translation", "Transform3D:rotation_axis_angle"


def episode_start(row: dict, source: EpisodeSource, recording: Path | None = None) -> EpisodeStart:
    """The episode of a result line as the live session loads it: its scene and episode from the episode
    set the eval ran (built with the line's stored config, as ``rerun`` does), its policy and config,
    and the poses of ``recording`` (when given) to check the replay against."""
    cfg = config_of(row)
    policy = check_policy(str(row.get("policy")))
    s = source
    episodes = load_episode_set(
        s.dataset,
        s.split,
        houses=s.houses,
        episodes_per_house=s.episodes_per_house,
        seed=s.seed,
        cfg=cfg,
        scenes_dir=s.scenes,
    )
    key = str(row.get("key"))
    episode = next((ep for ep in episodes.episodes if ep.key == key), None)
    if episode is None:
        raise L3MVNError(
            f"episode {key} is not in this dashboard's episode set; start serve with the eval's "
            "--dataset/--houses/--episodes-per-house/--seed"
        )
    return EpisodeStart(
        episodes.name,
        episodes.scene_of(episode),
        episode,
        policy,
        cfg,
        str(row.get("config_hash") or ""),
        {} if recording is None else recorded_poses(recording),
    )


def config_of(row: dict) -> Config:
    """The config tree stored in a result line; a line without one or with unknown fields is an error."""
    stored = row.get("config")
    if not isinstance(stored, dict):
        raise L3MVNError("this result line stores no config: it cannot be re-run")
    base = Config()
    sections = {}
    for name, values in stored.items():
        section = getattr(base, name, None)
        if section is None or not dataclasses.is_dataclass(section) or not isinstance(values, dict):
            raise L3MVNError(f"the stored config has an unknown section {name!r}: it cannot be re-run")
        try:
            sections[name] = dataclasses.replace(
                section, **{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
            )
        except TypeError as exc:
            raise L3MVNError(
                f"the stored config's {name} section does not fit this version: {first_line(exc)}"
            ) from None
    return base.replace(**sections)


@dataclass(frozen=True)
class Rerun:
    """A re-run of a result line: its new line and whether it reproduced the stored metrics."""

    row: dict
    same_config: bool  # the config hash (config, policy, seed) equals the stored one
    reproduced: bool  # success, SPL, DTG, steps and failure cause all equal the stored ones
    recording: Path  # the new recording (a file of its own: no other recording is touched)

    @property
    def summary(self) -> str:
        new = self.row
        verdict = "same result as stored" if self.reproduced else "DIFFERENT result from stored"
        seed = "" if self.same_config else " (config hash differs: another seed or config made the stored line)"
        return (
            f"re-run {new.get('key')}: success {new.get('success')}, SPL {new.get('spl')}, steps "
            f"{new.get('steps')}, {new.get('failure')}: {verdict}{seed}"
        )


def rerun(row: dict, source: EpisodeSource, record_dir: str | Path) -> Rerun:
    """Run the line's episode again, exactly as ``l3mvn eval`` did (same job path, its stored config and
    policy, this dashboard's episode set and seed), recorded under a name of its own in ``record_dir``
    (``unique_tag``), so a re-run never replaces a recording and concurrent re-runs never share a file."""
    cfg = config_of(row)
    job = EvalJob.create(
        source.dataset,
        source.split,
        houses=source.houses,
        episodes_per_house=source.episodes_per_house,
        seed=source.seed,
        config=cfg,
        policy=str(row.get("policy")),
        record_dir=record_dir,
    )
    key = str(row.get("key"))
    if key not in set(job.keys()):
        raise L3MVNError(
            f"episode {key} is not in this dashboard's episode set; start serve with the eval's "
            "--dataset/--houses/--episodes-per-house/--seed"
        )
    tag = unique_tag("rerun")
    new = job.run_one(key, record_tag=tag)
    if "error" in new:
        raise L3MVNError(f"re-running {key} failed: {first_line(str(new['error']))}")
    if new.get("recording_error"):
        raise L3MVNError(f"re-running {key}: {new['recording_error']}")
    fields = ("success", "spl", "dtg", "steps", "failure")
    recording = recording_path(record_dir, job.load().name, new["scene"], new["episode_id"], job.policy, tag)
    if not recording.is_file():
        raise L3MVNError(f"re-running {key} wrote no recording at {recording}")
    return Rerun(
        new, job.config_hash == row.get("config_hash"), all(new.get(f) == row.get(f) for f in fields), recording
    )
