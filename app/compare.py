"""Two policies (or two configs) on one episode, step by step: run both, read both recordings back,
and find the first step where their decisions part.

Each side runs through ``l3mvn eval``'s own path (an ``EvalJob`` and ``run_one``: same episode set,
seed and episode key, so a side is exactly what eval would score) and is recorded; everything shown
is then read back from the two recordings, so a comparison of two stored recordings (the Results
panel's) and of two fresh runs is one code path. A side's recording goes to
``<recordings>/compare/<config hash>/``: two configs of one policy would otherwise share a file name.
"""

from __future__ import annotations

import bisect
import math
import re
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.eval.job import EvalJob
from l3mvn.run.recording.catalogue import recording_path, unique_tag
from l3mvn.run.recording.drawing import FONT, PANEL_BG, TEXT_RGB, VideoOptions, fit_text, frames
from l3mvn.run.recording.recorded import RecordedEpisode, read_episode
from l3mvn.run.registry import PolicySpec, policies
from l3mvn_studio.map_image import png_bytes, png_rgb

PICTURE_HEIGHT = 400  # pixels of a side's map panel: the map is what is compared, so it leads
CAMERA_SCALE = 0.6  # the camera frame under it, at this share of the map panel's height
_GAP = 12
_CAPTION = 40
_BAND = 78
_DIM = (175, 175, 175)
_DIFF_RGB = (255, 200, 40)
_ENDED_RGB = (120, 120, 120)
_RUNNING = threading.Lock()
# The recorder's decision line: "<action> [<goal kind>] F<chosen frontier> <reason> ...".
_DECISION = re.compile(r"^(?P<action>[a-z_]+)(?: \[(?P<kind>[a-z]+)\])?(?: F(?P<frontier>\d+)(?=\s|$))?")


@dataclass(frozen=True)
class EpisodeSource:
    """The episode set both sides run on, as ``l3mvn eval`` / ``serve`` flags name it."""

    dataset: str | None
    split: str
    houses: int
    episodes_per_house: int
    seed: int
    scenes: str | None = None


@dataclass(frozen=True)
class Contender:
    """One side: a policy under a config tree."""

    policy: str
    config: Config


@dataclass(frozen=True)
class StepDecision:
    """What a side decided at one step, as its recording stores it."""

    step: int
    action: str
    goal_kind: str
    frontier: int | None  # the chosen frontier's id
    goal_cell: tuple[int, int] | None  # the long-term goal (row, col)
    line: str  # the whole decision line, reason included

    @property
    def key(self) -> tuple:
        """What two decisions must share to count as the same decision (the reason's words may differ)."""
        return self.action, self.goal_kind, self.frontier, self.goal_cell

    @property
    def words(self) -> str:
        goal = "no goal" if self.goal_cell is None else f"goal {self.goal_kind or '-'} at {self.goal_cell}"
        chosen = "" if self.frontier is None else f" (F{self.frontier})"
        return f"{self.action}, {goal}{chosen}"


@dataclass(frozen=True)
class Side:
    """One run read back: a PNG per step (map over camera, decision under them) and its decisions."""

    label: str  # "A: frontier"
    recording: Path
    pictures: tuple[bytes, ...]
    decisions: tuple[StepDecision, ...]
    success: bool | None  # None: the recording holds no result (cut short)
    result: str  # one line: outcome, SPL, DTG, steps

    @property
    def last_step(self) -> int:
        return self.decisions[-1].step

    def index_at(self, step: int) -> int:
        """The picture shown at ``step``: the last one recorded at or before it (its own, or the last
        one once this side has ended)."""
        return max(bisect.bisect_right([d.step for d in self.decisions], step) - 1, 0)

    def picture(self, step: int) -> np.ndarray:
        return png_rgb(self.pictures[self.index_at(step)])

    def decision_line(self, step: int) -> str:
        if step > self.last_step:
            return f"{self.label}: ended at step {self.last_step} ({self.result})"
        d = self.decisions[self.index_at(step)]
        return f"{self.label}, step {d.step}: {d.line}"


@dataclass(frozen=True)
class Comparison:
    """Both sides of one episode, step-synchronised (step k of A beside step k of B)."""

    episode_key: str
    goal: str
    a: Side
    b: Side
    first_difference: int | None  # the first step whose decisions differ; None: identical throughout

    @property
    def steps(self) -> int:
        """Steps on the slider: the longer side's."""
        return max(self.a.last_step, self.b.last_step) + 1

    @property
    def difference_line(self) -> str:
        k = self.first_difference
        if k is None:
            return f"decisions identical for all {self.steps} steps"
        return f"decisions first differ at step {k}: A <{_words_at(self.a, k)}>; B <{_words_at(self.b, k)}>"

    def picture(self, step: int) -> np.ndarray:
        """A and B at ``step`` side by side, each captioned; a side that has ended holds its last picture
        under an "ended at step n" banner; the first differing step is flagged on both."""
        step = min(max(int(step), 0), self.steps - 1)
        sides = [_captioned(s, step, step == self.first_difference) for s in (self.a, self.b)]
        h = max(p.shape[0] for p in sides)
        out = np.full((h, sides[0].shape[1] + _GAP + sides[1].shape[1], 3), PANEL_BG, np.uint8)
        out[: sides[0].shape[0], : sides[0].shape[1]] = sides[0]
        out[: sides[1].shape[0], sides[0].shape[1] + _GAP :] = sides[1]
        return out


def _words_at(side: Side, step: int) -> str:
    if step > side.last_step:
        return f"ended at step {side.last_step}"
    return side.decisions[side.index_at(step)].words


# --- the first difference --------------------------------------------------------------------


def first_difference(a: Sequence[StepDecision], b: Sequence[StepDecision]) -> int | None:
    """The first step at which the two decision lists differ (action, goal kind, chosen frontier or
    long-term goal cell), or where only one of them still has a decision; None when they agree on
    every step and end together. Lists are in step order; a step only one list holds differs."""
    by_step_b = {d.step: d for d in b}
    steps = sorted({d.step for d in a} | set(by_step_b))
    by_step_a = {d.step: d for d in a}
    for step in steps:
        da, db = by_step_a.get(step), by_step_b.get(step)
        if da is None or db is None or da.key != db.key:
            return step
    return None


def parse_decision(step: int, line: str, goal_xy: np.ndarray | None) -> StepDecision:
    """A decision from the recorder's decision line (``Recorder._log_decision``) and the long-term goal
    marker's position that step (``map/goal``, map pixels x = col + 0.5, y = row + 0.5)."""
    m = _DECISION.match(line)
    cell = None if goal_xy is None or not len(goal_xy) else (math.floor(goal_xy[0][1]), math.floor(goal_xy[0][0]))
    if m is None:  # no decision logged this step: only the goal marker can tell the two sides apart
        return StepDecision(step, "", "", None, cell, line)
    frontier = m.group("frontier")
    return StepDecision(
        step, m.group("action"), m.group("kind") or "", None if frontier is None else int(frontier), cell, line
    )


# --- choices and runs --------------------------------------------------------------------------


def comparable_policies() -> tuple[str, ...]:
    """Policy names a comparison can run (aliases left out: they would run the same policy twice)."""
    return tuple(name for name, spec in policies().items() if _excluded(spec) is None and spec.same_as is None)


def excluded_policies() -> dict[str, str]:
    """The policies a comparison cannot run, each with why."""
    return {name: why for name, spec in policies().items() if (why := _excluded(spec)) is not None}


def check_contender(policy: str) -> str:
    spec = policies().get(policy)
    if spec is None:
        raise L3MVNError(f"unknown policy {policy!r}; choose one of {', '.join(comparable_policies())}")
    if (why := _excluded(spec)) is not None:
        raise L3MVNError(
            f"policy {policy!r} cannot be compared: {why}; choose one of {', '.join(comparable_policies())}"
        )
    return policy


def _excluded(spec: PolicySpec) -> str | None:
    """Why a policy cannot take part in a comparison, or None."""
    if spec.driven:
        return "it is driven by hand and cannot run by itself"
    return None if spec.map_based else "it keeps no map, so there is no map or frontier to compare"


def episode_job(source: EpisodeSource, contender: Contender, key: str, record_dir: str | Path | None) -> EvalJob:
    """The eval job that runs ``contender`` on ``source``; L3MVNError naming valid keys when ``key`` is
    not one of its episodes."""
    job = _job(source, contender, record_dir)
    keys = job.keys()
    if key not in keys:
        shown = ", ".join(keys[:8]) + (f", ... ({len(keys)} in all)" if len(keys) > 8 else "")
        raise L3MVNError(f"episode {key!r} is not in this episode set; valid episodes: {shown}")
    return job


def _job(source: EpisodeSource, contender: Contender, record_dir: str | Path | None) -> EvalJob:
    check_contender(contender.policy)
    return EvalJob.create(
        source.dataset,
        source.split,
        houses=source.houses,
        episodes_per_house=source.episodes_per_house,
        seed=source.seed,
        config=contender.config,
        policy=contender.policy,
        record_dir=record_dir,
        scenes=source.scenes,
    )


def side_folder(record_dir: str | Path, config_hash: str) -> Path:
    return Path(record_dir) / "compare" / config_hash[:12]


def run_side(source: EpisodeSource, key: str, contender: Contender, record_dir: str | Path) -> Path:
    """Run episode ``key`` with ``contender`` as ``l3mvn eval`` would, recorded; the recording's path."""
    folder = side_folder(record_dir, _job(source, contender, None).config_hash)  # creating a job loads nothing
    job = episode_job(source, contender, key, folder)
    tag = unique_tag("compare")
    row = job.run_one(key, record_tag=tag)
    if "error" in row:
        raise L3MVNError(f"running {key} with {contender.policy} failed: {first_line(str(row['error']))}")
    if row.get("recording_error"):
        raise L3MVNError(f"running {key} with {contender.policy}: {row['recording_error']}")
    found = recording_path(folder, job.load().name, row["scene"], int(row["episode_id"]), contender.policy, tag)
    if not found.is_file():
        raise L3MVNError(f"running {key} with {contender.policy} wrote no recording in {folder}")
    return found


def run_comparison(
    source: EpisodeSource,
    key: str,
    a: Contender,
    b: Contender,
    record_dir: str | Path,
    progress: Callable[[str], None] = lambda text: None,
) -> Comparison:
    """Run ``key`` with A, then with B (same episode, same seed), and compare their recordings."""
    for c in (a, b):
        check_contender(c.policy)
    with _RUNNING:  # eval jobs keep one warm state per process: one comparison at a time
        return _run_both(source, key, a, b, record_dir, progress)


def _run_both(
    source: EpisodeSource, key: str, a: Contender, b: Contender, record_dir: str | Path, progress: Callable[[str], None]
) -> Comparison:
    progress(f"running A ({a.policy}) on {key}")
    path_a = run_side(source, key, a, record_dir)
    progress(f"running B ({b.policy}) on {key}")
    path_b = run_side(source, key, b, record_dir)
    progress("reading both recordings")
    return compare_recordings(path_a, path_b, key)


def compare_recordings(path_a: str | Path, path_b: str | Path, key: str) -> Comparison:
    """The comparison of two recordings of one episode (one-line L3MVNError for a bad recording)."""
    ep_a, ep_b = read_episode(path_a), read_episode(path_b)
    if (ep_a.scene, ep_a.episode_id) != (ep_b.scene, ep_b.episode_id):
        raise L3MVNError(
            f"{Path(path_a).name} and {Path(path_b).name} record different episodes "
            f"({ep_a.scene} #{ep_a.episode_id} vs {ep_b.scene} #{ep_b.episode_id})"
        )
    _share_crop(ep_a, ep_b)
    a, b = _side("A", ep_a), _side("B", ep_b)
    goal = ep_a.steps[0].goal if ep_a.steps else "?"
    return Comparison(key, goal, a, b, first_difference(a.decisions, b.decisions))


def _share_crop(ep_a: RecordedEpisode, ep_b: RecordedEpisode) -> None:
    """Both maps cut to one crop (the union of each side's), so a cell lies at the same place in both
    pictures and one scale reads both; only when both maps share a frame (the agent starts on the same
    map pixel at its first mapped step: same episode, same map size), else each keeps its own."""
    starts = [
        next((tuple(np.round(s.agent[0], 3)) for s in ep.steps if s.agent is not None), None) for ep in (ep_a, ep_b)
    ]
    if starts[0] is None or starts[0] != starts[1]:
        return
    (r0, r1, c0, c1), (s0, s1, d0, d1) = ep_a.box, ep_b.box
    ep_a.box = ep_b.box = (min(r0, s0), max(r1, s1), min(c0, d0), max(c1, d1))


def _side(letter: str, ep: RecordedEpisode) -> Side:
    options = VideoOptions(height=PICTURE_HEIGHT, title_s=0.0)
    h0, w0 = cv2.imdecode(np.frombuffer(ep.steps[0].rgb_png, np.uint8), cv2.IMREAD_UNCHANGED).shape[:2]
    camera_w = round(PICTURE_HEIGHT * w0 / h0)
    decisions = tuple(
        parse_decision(s.step, s.decision or "(no decision logged)", None if s.goal_mark is None else s.goal_mark.xy)
        for s in ep.steps
    )
    label = f"{letter}: {ep.policy}"
    pictures = []
    for frame, d in zip(frames(ep, options, title_frames=0), decisions):
        pictures.append(png_bytes(_restack(frame, camera_w, d, ep.steps[-1].step)))
    return Side(label, ep.path, tuple(pictures), decisions, _success(ep), _result_line(ep))


def _restack(frame: np.ndarray, camera_w: int, d: StepDecision, last: int) -> np.ndarray:
    """The export frame (camera | map, text band) as one side of a comparison: the map on top at full
    size, the camera under it smaller, then the step and the decision in large type."""
    h = PICTURE_HEIGHT
    camera, map_panel = frame[:h, :camera_w], frame[:h, camera_w + 6 :]
    ch, cw = round(h * CAMERA_SCALE), round(camera_w * CAMERA_SCALE)
    small = cv2.resize(camera, (cw, ch), interpolation=cv2.INTER_AREA)
    width = max(map_panel.shape[1], cw)
    out = np.full((h + 4 + ch + _BAND, width, 3), PANEL_BG, np.uint8)
    out[:h, : map_panel.shape[1]] = map_panel
    out[h + 4 : h + 4 + ch, :cw] = small
    y = h + 4 + ch
    cv2.putText(out, f"step {d.step}/{last}", (8, y + 24), FONT, 0.65, TEXT_RGB, 1, cv2.LINE_AA)
    for i, line in enumerate(_wrap(d.line, width - 16, 0.5)[:2]):
        cv2.putText(out, line, (8, y + 48 + 22 * i), FONT, 0.5, _DIM, 1, cv2.LINE_AA)
    return out


def _captioned(side: Side, step: int, differs: bool) -> np.ndarray:
    body = side.picture(step)
    out = np.full((_CAPTION + body.shape[0], body.shape[1], 3), PANEL_BG, np.uint8)
    out[_CAPTION:] = body
    cv2.putText(out, side.label, (8, 28), FONT, 0.8, TEXT_RGB, 2, cv2.LINE_AA)
    if step > side.last_step:
        text = f"ended at step {side.last_step} ({_outcome_word(side)})"
        cv2.rectangle(out, (0, _CAPTION), (out.shape[1] - 1, _CAPTION + 44), _ENDED_RGB, -1)
        cv2.putText(
            out, fit_text(text, out.shape[1] - 16, 0.7), (8, _CAPTION + 30), FONT, 0.7, (255, 255, 255), 2, cv2.LINE_AA
        )
    elif differs:
        cv2.rectangle(out, (1, 1), (out.shape[1] - 2, out.shape[0] - 2), _DIFF_RGB, 3)
        tw = cv2.getTextSize("first difference", FONT, 0.6, 2)[0][0]
        cv2.putText(out, "first difference", (out.shape[1] - tw - 10, 27), FONT, 0.6, _DIFF_RGB, 2, cv2.LINE_AA)
    return out


def _outcome_word(side: Side) -> str:
    return side.result.split(":", 1)[0]


def _success(ep: RecordedEpisode) -> bool | None:
    if not ep.result:
        return None
    return ep.outcome == "success"


def _result_line(ep: RecordedEpisode) -> str:
    """``SUCCESS: SPL 0.71, DTG 0.40 m, 52 steps`` or ``FAILURE timeout: ...`` from the recorded result."""
    r = ep.result
    if not r:
        return "NO RESULT (recording cut short)"
    head = "SUCCESS" if ep.outcome == "success" else f"FAILURE {r.get('failure', '?')}"
    return f"{head}: SPL {_num(r.get('spl'))}, DTG {_num(r.get('dtg'))} m, {r.get('steps', '?')} steps"


def _num(v) -> str:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return "-"
    return f"{f:.2f}" if math.isfinite(f) else "-"


def _wrap(text: str, width: int, scale: float) -> list[str]:
    lines, line = [], ""
    for word in text.split():
        trial = f"{line} {word}".strip()
        if line and cv2.getTextSize(trial, FONT, scale, 1)[0][0] > width:
            lines.append(line)
            line = word
        else:
            line = trial
    lines.append(line)
    if len(lines) > 2:
        lines[1] = fit_text(lines[1] + " " + " ".join(lines[2:]), width, scale)
    return lines
