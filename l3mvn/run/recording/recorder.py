"""The recorder: a step-event subscriber that writes one ``.rrd`` per episode."""

from __future__ import annotations

import errno
import fcntl
import logging
import math
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rerun as rr
from scipy import ndimage as ndi

from l3mvn.agent.decision import Decision
from l3mvn.agent.frontiers.types import prior_score_name
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.events import EventBus, StepEvent
from l3mvn.run.recording.catalogue import APPLICATION_ID, TIMELINE, recording_gap, recording_path
from l3mvn.run.recording.entities import (
    CAMERA,
    CAMERA_DEPTH,
    CAMERA_RGB,
    CAMERA_RGB_TARGET,
    CAMERA_SEMANTIC,
    CAMERA_SEMANTIC_TARGET,
    EPISODE,
    LANGUAGE_CHOSEN,
    LANGUAGE_CHOSEN_METRES,
    LOG_DECISIONS,
    LOG_EPISODE,
    LOG_FUSION,
    LOG_LANGUAGE,
    MAP,
    MAP_AGENT,
    MAP_COLLISION_MARKS,
    MAP_FRONTIER_CELLS,
    MAP_FRONTIERS,
    MAP_GOAL,
    MAP_SEMANTIC,
    MAP_SHORT_TERM_GOAL,
    MAP_TARGET,
    MAP_TRAJECTORY,
    METRICS_CHOSEN_FRONTIER,
    METRICS_FRONTIER_SCORES,
    METRICS_FRONTIERS,
    METRICS_GROUND_TRUTH,
    METRICS_TIMINGS_MS,
    WORLD_AGENT,
    WORLD_AGENT_BODY,
    WORLD_GOAL,
    WORLD_TRAJECTORY,
    language_by_goal,
)
from l3mvn.run.recording.layout import LABELLED_FRONTIERS, MapBounds, default_blueprint, map_view_bounds
from l3mvn.run.viz import (
    AGENT_RGB,
    BACKGROUND_RGB,
    COLLISION_RGB,
    FREE_RGB,
    GOAL_RGB,
    OBSTACLE_RGB,
    SHORT_TERM_GOAL_RGB,
    TARGET_RGB,
    TRAJECTORY_RGB,
    UNEXPLORED_RGB,
    category_color,
    category_palette,
    score_colors,
)
from l3mvn.world.episode import Episode

log = logging.getLogger(__name__)

SAVE_TIMEOUT_S = 20.0  # rerun opens a file in milliseconds; this long means its writer is stuck
MIN_FREE_BYTES = 8 << 20  # free disk a recording needs to start (a long 480x640 episode writes tens of MiB)
_GOAL_ARM_CELLS = 5.0  # half the size of the goal's cross on the map
_TARGET_MERGE_M = 0.5  # target fragments on the map closer than this share one box
_TARGET_MERGE_PX = 3  # and in the camera frame

# Map classes before the categories, in the map's one colour scheme (l3mvn.run.viz).
_MAP_CLASSES = (
    ("unexplored", UNEXPLORED_RGB),
    ("explored", FREE_RGB),
    ("obstacle", OBSTACLE_RGB),
    ("visited", TRAJECTORY_RGB),
)


class Recorder:
    """A StepEvent subscriber writing one episode to ``path`` (``entities`` describes the tree).

    It never raises into the loop: a failing step is logged once and skipped. The file is finished
    (flushed, footer written) on the ``done`` event or ``close()``; later events are ignored.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        dataset: str,
        scene: str,
        episode_id: int,
        policy: str,
        application_id: str = APPLICATION_ID,
    ) -> None:
        self.path = Path(path)
        self.meta = {"dataset": str(dataset), "scene": scene, "episode_id": int(episode_id), "policy": policy}
        _check_room(self.path)
        existed = self.path.exists()
        self._held = hold_exclusively(self.path)
        self._rec = rr.RecordingStream(application_id, send_properties=True)
        try:
            _start_file(self._rec, self.path)
        except L3MVNError:
            os.close(self._held)
            if not existed:  # no empty or header-only .rrd left behind to be listed as a recording
                self.path.unlink(missing_ok=True)
            raise
        self._rec.send_recording_name(f"{Path(str(dataset)).name} {scene} #{episode_id} {policy}")
        self._lock = threading.Lock()
        self._closed = False
        self._unsubscribe: Callable[[], None] | None = None
        self._errors = 0
        self._failure: str | None = None
        self._episode_key: str | None = None
        self._camera_categories: tuple[str, ...] | None = None
        self._map_categories: tuple[str, ...] | None = None
        self._last_map_ids: np.ndarray | None = None
        self._started = False
        self._segment = 0
        self._world_xyz: list[tuple[float, float, float]] = []
        self._map_xy: list[tuple[float, float]] = []
        self._last_queries: tuple = ()
        self._cleared: dict[str, bool] = {}
        self._last_event_t: float | None = None
        self._series: dict[str, list[str]] = {}
        self._map_box: tuple[int, int, int, int] | None = None  # rows r0..r1, cols c0..c1 ever mapped
        self._view: MapBounds | None = None
        self._resolution_m = 0.0
        self._last_target: tuple = ()
        self._last_fusion = None  # the Fusion record last written to LOG_FUSION
        self._last_marks: np.ndarray | None = None  # the collision marks last written (a new array per change)
        self.log_ms: list[float] = []  # this recorder's own cost per event, for budgets and benchmarks

    @classmethod
    def for_episode(
        cls, recordings_dir: str | Path, dataset: str | Path, episode: Episode, policy: str, tag: str | None = None
    ) -> Recorder:
        """A recorder writing to ``recording_path(recordings_dir, dataset, ..., tag)`` for ``episode``."""
        path = recording_path(recordings_dir, dataset, episode.scene, episode.episode_id, policy, tag)
        return cls(
            path,
            dataset=Path(str(dataset)).name or str(dataset),
            scene=episode.scene,
            episode_id=episode.episode_id,
            policy=policy,
        )

    def attach(self, bus: EventBus) -> Recorder:
        """Subscribe to ``bus``; the recorder unsubscribes itself when it closes."""
        self._unsubscribe = bus.subscribe(self)
        return self

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def errors(self) -> int:
        """Events that failed to record (each was skipped, never raised)."""
        return self._errors

    @property
    def failure(self) -> str | None:
        """Once closed: why the file on disk is not the whole recording (rerun writes in the
        background and reports no write error, so a full disk would otherwise pass unseen)."""
        return self._failure

    def _check_on_disk(self) -> str | None:
        """None when the whole recording is on disk; else why not, the file renamed ``*.rrd.partial``
        so that no listing offers it as a recording (what it holds stays readable)."""
        try:
            os.fsync(self._held)  # a full disk or a quota often reports only here
            gap = recording_gap(self.path)
        except OSError as exc:
            gap = f"did not reach the disk: {exc.strerror or exc}"
        if gap is None:
            return None
        partial = self.path.with_name(self.path.name + ".partial")
        try:
            os.replace(self.path, partial)
        except OSError:
            partial = self.path
        return f"recording {self.path} {gap} (is the disk full?); kept as {partial.name}"

    def __call__(self, event: StepEvent) -> None:
        with self._lock:
            if self._closed:
                return
            if self._episode_key is None:
                self._episode_key = event.episode_key
            elif event.episode_key != self._episode_key:
                return  # another episode on a shared bus: not ours
            t0 = time.perf_counter()
            try:
                self._log_event(event)
            except Exception:  # a recording problem must never end an episode
                self._errors += 1
                if self._errors == 1:
                    log.exception("recorder %s failed at step %d; later failures are counted", self.path, event.step)
            self.log_ms.append((time.perf_counter() - t0) * 1e3)
            if event.done:
                self._close_locked()

    def close(self) -> None:
        """Finish the file (idempotent)."""
        with self._lock:
            self._close_locked()

    def _close_locked(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._rec.flush()
            self._rec.disconnect()  # finalises the file sink: the footer makes the .rrd seekable
        except Exception as exc:  # the check below says what the file lacks
            log.warning("could not finish recording %s: %s", self.path, first_line(exc))
        self._failure = self._check_on_disk()
        if self._failure:
            log.error("%s", self._failure)
        if self._errors > 1:
            log.warning("recorder %s: %d steps failed to record", self.path, self._errors)
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        os.close(self._held)  # lets the next writer of this path in, now that the file is whole

    # --- one event ---------------------------------------------------------------------------
    def _log_event(self, ev: StepEvent) -> None:
        rec, obs = self._rec, ev.observation
        rec.set_time(TIMELINE, sequence=int(ev.step))
        if self._camera_categories != obs.categories:
            self._log_camera_context(obs.categories)
        if not self._started:
            self._log_episode_card(ev)
            self._started = True
        if ev.segment != self._segment:
            self._segment = ev.segment
            rec.log(LOG_EPISODE, rr.TextLog(f"segment {ev.segment}: target changed to {ev.goal}", level="WARN"))

        rec.log(CAMERA_RGB, rr.Image(obs.rgb))
        rec.log(CAMERA_DEPTH, rr.DepthImage(obs.depth, meter=1.0, colormap="turbo"))
        rec.log(CAMERA_SEMANTIC, rr.SegmentationImage(_small_ids(obs.semantic)))
        self._log_camera_target(obs, ev.goal)

        self._log_world(ev)
        self._log_metrics(ev)
        decision = ev.decision
        if decision is not None:
            if decision.map is not None:
                self._log_map(decision, ev.goal)
            self._log_decision(decision)
        if ev.done:
            self._log_result(ev)
            if self._map_box is not None:
                self._fit_view(self._map_box, self._resolution_m, final=True)

    def _log_camera_context(self, categories: tuple[str, ...]) -> None:
        palette = category_palette(categories)
        classes = [rr.ClassDescription(info=rr.AnnotationInfo(id=0, label="background", color=BACKGROUND_RGB))]
        classes += [
            rr.ClassDescription(info=rr.AnnotationInfo(id=k + 1, label=name, color=tuple(palette[k + 1])))
            for k, name in enumerate(categories)
        ]
        self._rec.log(CAMERA, rr.AnnotationContext(classes), static=True)
        self._camera_categories = categories

    def _log_map_context(self, names: tuple[str, ...]) -> None:
        palette = category_palette(names)
        n = len(_MAP_CLASSES)
        classes = [
            rr.ClassDescription(info=rr.AnnotationInfo(id=i, label=label, color=rgb))
            for i, (label, rgb) in enumerate(_MAP_CLASSES)
        ]
        classes += [
            rr.ClassDescription(info=rr.AnnotationInfo(id=n + k, label=name, color=tuple(palette[k + 1])))
            for k, name in enumerate(names)
        ]
        self._rec.log(MAP, rr.AnnotationContext(classes), static=True)
        self._map_categories = names

    def _log_episode_card(self, ev: StepEvent) -> None:
        m = self.meta
        text = (
            f"# {m['scene']} episode {m['episode_id']}\n\n"
            f"* dataset: `{m['dataset']}`\n* policy: `{m['policy']}`\n* goal: **{ev.goal}**\n"
            f"* episode key: `{ev.episode_key}`\n"
        )
        self._rec.log(EPISODE, rr.TextDocument(text, media_type="text/markdown"))
        self._rec.log(LOG_EPISODE, rr.TextLog(f"episode {ev.episode_key}: find {ev.goal} ({m['policy']})"))

    def _log_world(self, ev: StepEvent) -> None:
        rec, pose = self._rec, ev.pose
        if not self._world_xyz:
            rec.log(
                WORLD_AGENT_BODY,
                rr.Arrows3D(origins=[[0.0, 0.0, 0.3]], vectors=[[0.4, 0.0, 0.0]], colors=[AGENT_RGB]),
                static=True,
            )
        rec.log(
            WORLD_AGENT,
            rr.Transform3D(
                translation=[pose.x, pose.y, 0.0], rotation=rr.RotationAxisAngle(axis=[0, 0, 1], radians=pose.heading)
            ),
        )
        here = (pose.x, pose.y, 0.05)
        if not self._world_xyz or self._world_xyz[-1] != here:
            self._world_xyz.append(here)
            rec.log(WORLD_TRAJECTORY, rr.LineStrips3D([self._world_xyz], colors=[AGENT_RGB]))

    def _log_metrics(self, ev: StepEvent) -> None:
        now = time.perf_counter()
        timings = {} if self._last_event_t is None else {"loop": (now - self._last_event_t) * 1e3}
        self._last_event_t = now
        if self.log_ms:
            timings["recorder"] = self.log_ms[-1]
        if ev.decision is not None:
            timings.update(ev.decision.timings_ms)
            if ev.decision.map is not None:
                self._rec.log(METRICS_FRONTIERS, rr.Scalars([float(len(ev.decision.frontiers))]))
                self._log_frontier_scores(ev.decision)
        self._log_series(METRICS_GROUND_TRUTH, ev.ground_truth)
        self._log_series(METRICS_TIMINGS_MS, timings)

    def _log_frontier_scores(self, d) -> None:
        """Each frontier's score (the one its colour shows) as a line named like its map label, F<id>,
        and the chosen frontier's prior (LLM, or PONI's "pot"), CU and fused scores: how the decision
        margin evolves."""
        self._log_series(METRICS_FRONTIER_SCORES, {f"F{f.id}": _score(f) for f in d.frontiers})
        chosen = next((f for f in d.frontiers if f.id == d.chosen_frontier), None)
        parts = (
            {}
            if chosen is None
            else {prior_score_name(chosen.fusion): chosen.s_llm, "CU": chosen.s_cu, "fused": chosen.fused}
        )
        self._log_series(METRICS_CHOSEN_FRONTIER, {k: math.nan if v is None else v for k, v in parts.items()})
        if any(f.llm_scores for f in d.frontiers):
            self._log_language(d.frontiers, chosen)
        # The rule's line at each new choice, and a line when no frontier is the goal any more (the
        # target seen, a look goal, an escape): a replayed or exported step shows the rule in force.
        fusion = None if chosen is None else chosen.fusion
        if fusion is not self._last_fusion:
            self._rec.log(LOG_FUSION, rr.TextLog(fusion.describe() if fusion is not None else _no_rule(d.goal_kind)))
        self._last_fusion = fusion

    def _log_language(self, frontiers: list, chosen) -> None:
        """Why the prior preferred a frontier, over time: the chosen frontier's p(goal) per goal (and
        a distance head's metres to each goal) in the map's category colours, every frontier's p(goal)
        per goal as lines F<id>."""
        self._log_series(LANGUAGE_CHOSEN, {} if chosen is None else chosen.llm_scores, colors=category_color)
        if any(f.expected_m for f in frontiers):
            self._log_series(LANGUAGE_CHOSEN_METRES, {} if chosen is None else chosen.expected_m, colors=category_color)
        by_goal: dict[str, dict[str, float]] = {}
        for f in frontiers:
            for goal, p in f.llm_scores.items():
                by_goal.setdefault(goal, {})[f"F{f.id}"] = p
        for goal, values in by_goal.items():
            self._log_series(language_by_goal(goal), values)

    def _log_series(self, entity: str, values: dict[str, float], colors=None) -> None:
        """One entity, one named line per key: a key's line index never changes, a missing value is
        a gap (NaN), and a new key extends the names (one log call per group, not per value);
        ``colors(key)`` gives a line its colour (categories keep their map colour)."""
        keys = self._series.setdefault(entity, [])
        grown = [k for k in values if k not in keys]
        if grown:
            keys.extend(grown)
            self._rec.log(
                entity,
                rr.SeriesLines(names=keys, colors=None if colors is None else [colors(k) for k in keys]),
                static=True,
            )
        if keys:
            row = [float(values.get(k, math.nan)) for k in keys]
            self._rec.log(entity, rr.Scalars([v if math.isfinite(v) else math.nan for v in row]))

    def _log_map(self, d, goal: str) -> None:
        rec, m = self._rec, d.map
        if self._map_categories != tuple(m.category_names):
            self._log_map_context(tuple(m.category_names))
            self._last_map_ids = None
        ids, box = _map_ids(m)
        if self._last_map_ids is None or not np.array_equal(ids, self._last_map_ids):
            rec.log(MAP_SEMANTIC, rr.SegmentationImage(ids))
            self._last_map_ids = ids
        if box is not None:
            self._fit_view(box, m.resolution_m, final=False)
        self._log_target(m, goal)

        r, c = m.agent_cell
        here = (c + 0.5, r + 0.5)
        if not self._map_xy or self._map_xy[-1] != here:
            self._map_xy.append(here)
            rec.log(MAP_TRAJECTORY, rr.LineStrips2D([self._map_xy], colors=[TRAJECTORY_RGB], radii=[0.6]))
        heading = (math.cos(m.agent_heading) * 8.0, math.sin(m.agent_heading) * 8.0)
        rec.log(
            MAP_AGENT,
            rr.Points2D([here], colors=[AGENT_RGB], radii=[3.0]),
            rr.Arrows2D(origins=[here], vectors=[heading], colors=[AGENT_RGB]),
        )

        self._log_goal(d)
        self._log_collision_marks(d.collision_marks)
        self._log_point(MAP_SHORT_TERM_GOAL, d.short_term_goal, 2.0, SHORT_TERM_GOAL_RGB, None)
        self._log_frontiers(d.frontiers, d.chosen_frontier)
        if d.long_term_goal is not None:
            gx, gy = m.cell_to_world(*d.long_term_goal)
            rec.log(WORLD_GOAL, rr.Points3D([[gx, gy, 0.1]], colors=[GOAL_RGB], radii=[0.15]))

    def _fit_view(self, box: tuple[int, int, int, int], resolution_m: float, *, final: bool) -> None:
        """Fit the map view to what is mapped: re-sent when the mapped area outgrows the view, and
        once at the end, so a replay opens on the whole explored house, not the 48 m map frame."""
        self._resolution_m = resolution_m
        r0, r1, c0, c1 = box
        if self._map_box is not None:
            pr0, pr1, pc0, pc1 = self._map_box
            r0, r1, c0, c1 = min(r0, pr0), max(r1, pr1), min(c0, pc0), max(c1, pc1)
        self._map_box = (r0, r1, c0, c1)
        view = self._view
        if final or view is None or c0 < view.x0 or c1 > view.x1 or r0 < view.y0 or r1 > view.y1:
            self._view = map_view_bounds(self._map_box, resolution_m, final=final)
            self._rec.send_blueprint(default_blueprint(self._view), make_active=True, make_default=True)

    def _log_target(self, m, goal: str) -> None:
        """A box around every blob of the target category on the map (one label, the target's name)."""
        merge = int(round(_TARGET_MERGE_M / m.resolution_m))
        boxes = _blob_boxes(m.categories[m.category_names.index(goal)], merge) if goal in m.category_names else ()
        if boxes == self._last_target:
            return
        self._last_target = boxes
        if not boxes:
            self._clear(MAP_TARGET)
            return
        self._cleared[MAP_TARGET] = False
        mins = [(c0, r0) for r0, r1, c0, c1 in boxes]
        sizes = [(c1 - c0, r1 - r0) for r0, r1, c0, c1 in boxes]
        labels = [f"target: {goal}"] + [""] * (len(boxes) - 1)
        self._rec.log(
            MAP_TARGET,
            rr.Boxes2D(mins=mins, sizes=sizes, colors=[TARGET_RGB], radii=[0.8], labels=labels, show_labels=True),
        )

    def _log_camera_target(self, obs, goal: str) -> None:
        """The target's pixels boxed in the RGB and semantic frames (what the detector reports)."""
        mask = obs.semantic == obs.categories.index(goal) + 1 if goal in obs.categories else None
        boxes = () if mask is None else _blob_boxes(mask, _TARGET_MERGE_PX)
        for entity in (CAMERA_RGB_TARGET, CAMERA_SEMANTIC_TARGET):
            if not boxes:
                self._clear(entity)
                continue
            self._cleared[entity] = False
            self._rec.log(
                entity,
                rr.Boxes2D(
                    mins=[(c0, r0) for r0, r1, c0, c1 in boxes],
                    sizes=[(c1 - c0, r1 - r0) for r0, r1, c0, c1 in boxes],
                    colors=[TARGET_RGB],
                    radii=[1.0],
                    labels=[goal] + [""] * (len(boxes) - 1),
                    show_labels=True,
                ),
            )

    def _log_goal(self, d) -> None:
        """The long-term goal as a cross drawn above the frontiers (it sits on the chosen one), labelled
        with its kind unless it is that frontier (whose label says so)."""
        if d.long_term_goal is None:
            self._clear(MAP_GOAL)
            return
        self._cleared[MAP_GOAL] = False
        x, y = d.long_term_goal[1] + 0.5, d.long_term_goal[0] + 0.5
        arm = _GOAL_ARM_CELLS
        label = None if d.chosen_frontier is not None else f"goal ({d.goal_kind})"
        self._rec.log(
            MAP_GOAL,
            rr.Points2D([(x, y)], colors=[GOAL_RGB], radii=[1.2], draw_order=41, labels=[label] if label else None),
            rr.LineStrips2D(
                [[(x - arm, y - arm), (x + arm, y + arm)], [(x - arm, y + arm), (x + arm, y - arm)]],
                colors=[GOAL_RGB],
                radii=[0.8],
                draw_order=40,
            ),
        )

    def _log_collision_marks(self, marks: np.ndarray | None) -> None:
        """The cells the agent's failed steps blocked, written when they change: a replay shows what
        closed a passage the map shows free."""
        if marks is self._last_marks:
            return
        self._last_marks = marks
        if marks is None or not len(marks):
            self._clear(MAP_COLLISION_MARKS)
            return
        self._cleared[MAP_COLLISION_MARKS] = False
        self._rec.log(
            MAP_COLLISION_MARKS, rr.Points2D(marks[:, ::-1] + 0.5, colors=[COLLISION_RGB], radii=[0.5], draw_order=30)
        )

    def _log_point(self, entity: str, cell, radius: float, rgb, label: str | None) -> None:
        if cell is None:
            self._clear(entity)
            return
        self._cleared[entity] = False
        pos = [(cell[1] + 0.5, cell[0] + 0.5)]
        self._rec.log(entity, rr.Points2D(pos, colors=[rgb], radii=[radius], labels=[label] if label else None))

    def _log_frontiers(self, frontiers: list, chosen: int | None) -> None:
        if not frontiers:
            self._clear(MAP_FRONTIERS)
            self._clear(MAP_FRONTIER_CELLS)
            return
        self._cleared[MAP_FRONTIERS] = self._cleared[MAP_FRONTIER_CELLS] = False
        centers = np.array([(f.center[1] + 0.5, f.center[0] + 0.5) for f in frontiers], np.float32)
        scores = np.array([_score(f) for f in frontiers], np.float32)
        colors = score_colors(scores)
        radii = [4.0 if f.id == chosen else 2.5 for f in frontiers]
        top = set(np.argsort(-scores, kind="stable")[:LABELLED_FRONTIERS].tolist())
        labels = [
            _frontier_label(f, f.id == chosen) if i in top or f.id == chosen else "" for i, f in enumerate(frontiers)
        ]
        self._rec.log(
            MAP_FRONTIERS,
            rr.Points2D(centers, colors=colors, radii=radii, labels=labels, show_labels=True),
            rr.AnyValues(
                frontier_id=np.array([f.id for f in frontiers], np.int32),
                score_llm=_scores(frontiers, "s_llm"),
                score_cu=_scores(frontiers, "s_cu"),
                score_fused=_scores(frontiers, "fused"),
                chosen=np.array([f.id == chosen for f in frontiers]),
            ),
        )
        cells = np.concatenate([f.cells for f in frontiers])[:, ::-1].astype(np.float32) + 0.5
        cell_colors = np.repeat(colors, [len(f.cells) for f in frontiers], axis=0)
        self._rec.log(MAP_FRONTIER_CELLS, rr.Points2D(cells, colors=cell_colors, radii=[0.5]))
        queries = tuple((f.id, tuple(sorted(f.queries.items()))) for f in frontiers if f.queries)
        if queries and queries != self._last_queries:
            for f in frontiers:
                for name, query in f.queries.items():
                    score = f.llm_scores.get(name)
                    tail = "" if score is None else f" -> {score:.3f}"
                    self._rec.log(LOG_LANGUAGE, rr.TextLog(f"F{f.id} [{name}] {query}{tail}"))
        self._last_queries = queries

    def _log_decision(self, d: Decision) -> None:
        parts = [d.action.name.lower()]
        if d.goal_kind:
            parts.append(f"[{d.goal_kind}]")
        if d.chosen_frontier is not None:
            parts.append(f"F{d.chosen_frontier}")
        if d.reason:
            parts.append(d.reason)
        if d.override:
            parts.append(f"(override {d.override})")
        if d.stuck:
            parts.append("(stuck)")
        level = "WARN" if d.override or d.stuck else "INFO"
        self._rec.log(LOG_DECISIONS, rr.TextLog(" ".join(parts), level=level))

    def _log_result(self, ev: StepEvent) -> None:
        res = ev.result or {}
        keys = ("success", "spl", "dtg", "failure", "steps", "path_length_m", "shortest_path_m")
        summary = ", ".join(f"{k}={_fmt(res[k])}" for k in keys if k in res)
        self._rec.log(LOG_EPISODE, rr.TextLog(f"done: {summary}", level="INFO"))
        rows = "\n".join(f"| {k} | {_fmt(v)} |" for k, v in res.items() if not isinstance(v, (dict, list)))
        m = self.meta
        self._rec.log(
            EPISODE,
            rr.TextDocument(
                f"# {m['scene']} episode {m['episode_id']}\n\n* dataset: `{m['dataset']}`\n* policy: `{m['policy']}`\n"
                f"* goal: **{ev.goal}**\n\n| result | value |\n|---|---|\n{rows}\n",
                media_type="text/markdown",
            ),
        )

    def _clear(self, entity: str) -> None:
        if self._cleared.get(entity) is False:  # only once, and only after something was shown
            self._rec.log(entity, rr.Clear(recursive=False))
            self._cleared[entity] = True


def _start_file(rec: rr.RecordingStream, path: Path) -> None:
    """Point ``rec`` at ``path``. rerun's ``save`` can wait for ever when its writer thread dies on
    the first bytes (a file size limit, a quota), so it runs in a thread of its own that is given up
    on after ``SAVE_TIMEOUT_S``: the episode goes on unrecorded instead of hanging the run."""
    failed: list[BaseException] = []

    def save() -> None:
        try:
            rec.save(path, default_blueprint=default_blueprint())
        except (OSError, RuntimeError, ValueError) as exc:
            failed.append(exc)

    starter = threading.Thread(target=save, name=f"rerun-save-{path.name}", daemon=True)
    starter.start()
    starter.join(SAVE_TIMEOUT_S)
    if starter.is_alive():
        raise L3MVNError(
            f"cannot write recording {path}: rerun's writer did not start within {SAVE_TIMEOUT_S:g} s "
            "(a full disk or a file size limit?)"
        )
    if failed:
        raise L3MVNError(f"cannot write recording {path}: {first_line(failed[0])}")


def _check_room(path: Path) -> None:
    """Refuse to start a recording on a disk with less than ``MIN_FREE_BYTES`` free (creating its
    folder): rerun's file writer can block for ever on a disk with no room to start."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        disk = os.statvfs(path.parent)
    except OSError as exc:
        raise L3MVNError(f"cannot write recording {path}: {exc.strerror or exc}") from None
    free = disk.f_bavail * disk.f_frsize
    if free < MIN_FREE_BYTES:
        raise L3MVNError(
            f"cannot write recording {path}: only {free >> 10} KiB free on its disk (a recording "
            f"needs a few MiB; {MIN_FREE_BYTES >> 20} MiB are asked for)"
        )


def hold_exclusively(path: Path) -> int:
    """Open ``path`` (creating it, changing no byte) under an exclusive ``flock`` and return the
    descriptor that holds it. A second writer of the same path, in this process or another, is
    refused before it could truncate or interleave with the first; the kernel drops the lock with
    the holder, however it exits."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise L3MVNError(f"cannot write recording {path}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        os.close(fd)
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            raise L3MVNError(
                f"recording {path} is being written by another recorder; record into another "
                "folder or wait for it to finish"
            ) from None
        raise L3MVNError(f"cannot lock recording {path} ({exc.strerror or exc}): record to a local disk") from None
    return fd


def _small_ids(ids: np.ndarray) -> np.ndarray:
    return ids.astype(np.uint8) if ids.size and int(ids.max()) < 256 else ids.astype(np.uint16)


def _map_ids(m) -> tuple[np.ndarray, tuple[int, int, int, int] | None]:
    """(M, M) class ids of the map: unexplored 0, explored 1, obstacle 2, visited 3, category k at 4 + k;
    and the box painted (rows r0..r1, cols c0..c1, end exclusive; None while nothing is mapped).

    Only the bounding box of what is mapped is painted (views, no copies of the K x M x M stack), so
    a 720x720 map with 15 categories costs well under a millisecond.
    """
    n = len(_MAP_CLASSES)
    ids = np.zeros(m.explored.shape, np.uint8 if n + len(m.category_names) <= 256 else np.uint16)
    cat_rows = m.categories.any(axis=2)  # (K, M): cheap, reduces along contiguous rows
    present = np.flatnonzero(cat_rows.any(axis=1))
    rows = np.flatnonzero(m.explored.any(axis=1) | cat_rows.any(axis=0))
    if rows.size == 0:
        return ids, None
    r0, r1 = rows[0], rows[-1] + 1
    band = (slice(r0, r1),)
    cols = np.flatnonzero(m.explored[band].any(axis=0) | m.categories[:, r0:r1].any(axis=(0, 1)))
    c0, c1 = cols[0], cols[-1] + 1
    box = (slice(r0, r1), slice(c0, c1))
    window = ids[box]
    window[m.explored[box]] = 1
    window[m.obstacle[box]] = 2
    window[m.visited[box]] = 3
    for k in present:
        window[m.categories[k][box]] = n + k
    return ids, (int(r0), int(r1), int(c0), int(c1))


def _blob_boxes(mask: np.ndarray, merge: int) -> tuple[tuple[int, int, int, int], ...]:
    """(r0, r1, c0, c1), end exclusive, around each group of ``mask``'s cells, cells closer than
    ``merge`` joining one group (a mapped bed is a scatter of fragments: one box, not twenty).
    Searched in the mask's bounding box only (a target is a few hundred cells of a 960 x 960 map)."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return ()
    cols = np.flatnonzero(mask[rows[0] : rows[-1] + 1].any(axis=0))
    r0, c0 = int(rows[0]), int(cols[0])
    window = mask[r0 : rows[-1] + 1, c0 : cols[-1] + 1]
    grown = ndi.binary_dilation(window, iterations=merge) if merge > 0 else window
    labels, _ = ndi.label(grown, structure=np.ones((3, 3), bool))
    labels[~window] = 0  # each box spans the group's own cells, not the dilation
    return tuple(
        (r0 + s[0].start, r0 + s[0].stop, c0 + s[1].start, c0 + s[1].stop)
        for s in ndi.find_objects(labels)
        if s is not None
    )


def _scores(frontiers: list, field: str) -> np.ndarray:
    return np.array(
        [math.nan if getattr(f, field) is None else float(getattr(f, field)) for f in frontiers], np.float32
    )


def _scored(f) -> tuple[str, float]:
    """The score a frontier is drawn by and its name: fused, else the prior (LLM or pot), else CU (0 when
    none is finite)."""
    for kind, value in (("fused", f.fused), (prior_score_name(f.fusion), f.s_llm), ("CU", f.s_cu)):
        if value is not None and math.isfinite(value):
            return kind, float(value)
    return "CU", 0.0


def _score(f) -> float:
    return _scored(f)[1]


def _frontier_label(f, chosen: bool) -> str:
    """``F<id> <score>``, the dashboard's name, ★ when chosen; the score named is the one the colour
    shows (fused, else LLM, else CU); every score is on the point's hover (its ``score_*`` values)."""
    kind, value = _scored(f)
    return f"{'★' if chosen else ''}F{f.id} {kind} {value:.2f}"


def _fmt(v) -> str:
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def _no_rule(kind) -> str:
    """The fusion line of a step whose goal is not a frontier: no rule is in force."""
    return f"no frontier choice in force: the goal is {getattr(kind, 'value', kind)!r}, not a frontier"
