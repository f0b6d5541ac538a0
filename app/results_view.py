"""The Results panel: browse the eval result files of ``serve --results DIR``.

Pick a file (only files in that folder are offered), filter and sort its episodes, read summaries per
category and failure cause, open an episode's recording and scrub its steps, open it in rerun's web
viewer, or, without one, re-run it here with the config stored in its line (recorded, so it then
opens like any other). An episode loads into the live session at any step, run with its line's
config and policy: from there the policy continues (Step, Run) or teleop takes over. Other files can
be compared with the one shown: their config differences first, then each file's SR, SPL and DTG and
the paired differences against the shown file, then the episodes one solved and another did not; any
episode two files hold opens side by side (the Compare folder's view).
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import viser

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.paired import LEVEL
from l3mvn_studio.compare import EpisodeSource
from l3mvn_studio.compare_view import ComparePanel, main_view_html
from l3mvn_studio.map_image import png_rgb
from l3mvn_studio.page_text import code, html, md
from l3mvn_studio.recordings_view import RecordingsPanel
from l3mvn_studio.results import (
    ALL,
    SORT_KEYS,
    EpisodeRow,
    ResultFile,
    episode_start,
    filter_choices,
    list_result_files,
    load_result_file,
    recording_frames,
    recording_of,
    rerun,
    select,
    summaries,
)
from l3mvn_studio.results_comparison import FilesComparison, compare_files
from l3mvn_studio.session_worker import DashboardController

log = logging.getLogger(__name__)

NONE = "(none)"
TABLE_ROWS = 40  # rows the table shows; the episode dropdown holds them all
RERUN_NOTE = (
    "Re-run runs the episode again with the config stored in its line, this dashboard's "
    "episode set and seed, and records it: the same seed gives the same result (checked, "
    "and said, after each re-run)."
)


@dataclass(frozen=True)
class ResultsSource:
    """Where the panel reads from, where re-runs write, and the episode set a re-run uses (the serve flags)."""

    results_dir: Path
    recordings_dir: Path  # the eval's own recordings: read, never written
    rerun_dir: Path  # where Re-run live records (each re-run a file of its own)
    dataset: str | None
    split: str
    houses: int
    episodes_per_house: int
    seed: int
    scenes: str | None = None  # scan root of a habitat ObjectNav dataset (serve --scenes)

    @property
    def episodes(self) -> EpisodeSource:
        """The episode set a re-run or a load builds its episode from."""
        return EpisodeSource(self.dataset, self.split, self.houses, self.episodes_per_house, self.seed, self.scenes)


class ResultsPanel:
    """Builds the Results folder in the GUI and answers its controls (one state shared by every tab)."""

    def __init__(
        self,
        gui: viser.GuiApi,
        source: ResultsSource,
        *,
        on: Callable,
        tell: Callable,
        compare: ComparePanel | None = None,
        session: DashboardController | None = None,
        viewer: RecordingsPanel | None = None,
    ) -> None:
        """``session`` is the live session rows load into; ``viewer`` serves rows' recordings in rerun."""
        self.source, self._tell, self._compare_panel = source, tell, compare
        self._session, self._viewer = session, viewer
        self._file: ResultFile | None = None
        self._other: ResultFile | None = None
        self._compared: list[str] = []  # the files compared with the one shown, in the order picked
        if viewer is not None:
            viewer.add_folder("eval recordings", source.recordings_dir)
            viewer.add_folder("re-runs", source.rerun_dir)
        self._shown: list[EpisodeRow] = []
        self._frames: list[bytes] = []  # PNG per step
        self._decisions: list[str] = []
        self._lock = threading.Lock()
        with gui.add_folder("Results", expand_by_default=True):
            gui.add_markdown(
                f"Eval result files in {code(source.results_dir)}; recordings from "
                f"{code(source.recordings_dir)}; re-runs recorded in {code(source.rerun_dir)}."
            )
            self.file = gui.add_dropdown("Result file", self._file_names())
            self.refresh = gui.add_button("Refresh files")
            self.notes = gui.add_markdown("")
            self.filter = gui.add_dropdown("Filter", (ALL,))
            self.sort = gui.add_dropdown("Sort by", SORT_KEYS)
            self.descending = gui.add_checkbox("Descending", False)
            self.table = gui.add_html("")
            self.summary = gui.add_html("")
            self.episode = gui.add_dropdown("Episode", (NONE,))
            self.actions = gui.add_button_group("Episode actions", ("Open", "Open in rerun", "Re-run live"))
            self.rerun_link = gui.add_markdown("")
            self.step = gui.add_slider("Step", min=0, max=1, step=1, initial_value=0, disabled=True)
            self.load_step = gui.add_number(
                "Load at step", 0, min=0, step=1, hint="the step the episode loads at (follows the Step slider)"
            )
            self.live = gui.add_button_group(
                "Live session", ("Load into session", "Take over by hand"), disabled=session is None
            )
            self.loaded = gui.add_markdown("")
            self.picture = gui.add_image(np.zeros((8, 8, 3), np.uint8), label="Recorded step")
            self.main_view = gui.add_checkbox(
                "Recorded step in main view",
                True,
                hint="draw the recorded step over the live map, large; untick for the map",
            )
            self.large = gui.add_html("")
            self.decision = gui.add_markdown("")
            gui.add_markdown(RERUN_NOTE)
            self.compare = gui.add_dropdown(
                "Compare with", (NONE,) + self._file_names(), hint="each file picked joins the comparison"
            )
            self.clear_comparison = gui.add_button("Clear comparison")
            self.comparison = gui.add_html("")
            self.side_by_side = gui.add_button(
                "Compare side by side",
                disabled=compare is None,
                hint="the selected episode in both files, step by step (Compare tab)",
            )
        self._wire(on)
        if self.file.value != NONE:
            try:
                self._load(self.file.value)
            except L3MVNError:  # the first file is not a result file: its note says so, pick another
                pass

    @property
    def inputs(self) -> tuple:
        return (
            self.file,
            self.refresh,
            self.filter,
            self.sort,
            self.descending,
            self.episode,
            self.actions,
            self.step,
            self.load_step,
            self.live,
            self.main_view,
            self.compare,
            self.clear_comparison,
            self.side_by_side,
        )

    # --- controls ----------------------------------------------------------------------------
    def _wire(self, on: Callable) -> None:
        @on(self.file)
        def _(event) -> None:
            self._load(self.file.value)

        @on(self.refresh)
        def _(event) -> None:
            names = self._file_names()
            self.file.options = names
            self.compare.options = (NONE,) + names
            self._tell(
                event.client_id, f"{len([n for n in names if n != NONE])} result files in {self.source.results_dir}"
            )

        for handle in (self.filter, self.sort, self.descending):
            on(handle)(lambda event: self._show_table())

        @on(self.actions)
        def _(event) -> None:
            row = self._selected()
            if self.actions.value == "Open":
                self._open(row, event.client_id)
            elif self.actions.value == "Open in rerun":
                self.open_in_rerun(row, event.client_id)
            else:
                self._rerun(row, event.client_id)

        @on(self.step)
        def _(event) -> None:
            self._show_step(int(self.step.value))
            self.load_step.value = int(self.step.value)

        @on(self.live)
        def _(event) -> None:
            if self.live.value == "Load into session":
                self.load_into_session(self._selected(), int(self.load_step.value), event.client_id)
            else:
                self._live_session().take_over(client_id=event.client_id)

        @on(self.compare)
        def _(event) -> None:
            if self.compare.value != NONE and self.compare.value not in self._compared:
                self._compared.append(self.compare.value)
            self._compare()

        @on(self.clear_comparison)
        def _(event) -> None:
            self._compared.clear()
            self.compare.value = NONE
            self._compare()

        @on(self.main_view)
        def _(event) -> None:
            self._show_step(int(self.step.value))

        @on(self.side_by_side)
        def _(event) -> None:
            row = self._selected()
            if self._other is None or self._compare_panel is None:
                raise L3MVNError("pick a second file in Compare with first: the episode opens with each file's line")
            other = next((r for r in self._other.rows if r.raw["key"] == row.raw["key"]), None)
            if other is None:
                raise L3MVNError(
                    f"episode {row.raw['key']} is not in {self._other.path.name}; pick one both files hold"
                )
            self._compare_panel.open_rows(row, other, self.source.recordings_dir, event.client_id)

    def _file_names(self) -> tuple[str, ...]:
        names = tuple(p.name for p in list_result_files(self.source.results_dir))
        return names or (NONE,)

    def _load(self, name: str) -> None:
        """Show the file ``name``; a file that is not a result file leaves the last one shown and says why."""
        if name == NONE:
            raise L3MVNError(
                f"no result file in {self.source.results_dir}: run `l3mvn eval --out "
                f"{self.source.results_dir}/NAME.jsonl` first"
            )
        try:
            loaded = load_result_file(self.source.results_dir / name)
        except L3MVNError as exc:
            self.notes.content = f"**{md(name)}**: {md(exc)}"
            raise
        self._file = loaded
        left = f"; {len(loaded.problems)} lines left out: " + "; ".join(loaded.problems[:3]) if loaded.problems else ""
        self.notes.content = f"**{md(name)}**: {md(f'{len(loaded.rows)} episodes{left}')}"
        self.filter.options = filter_choices(loaded.rows)
        self.filter.value = ALL
        self._show_table()
        self._compare()

    def _show_table(self) -> None:
        if self._file is None:
            return
        self._shown = select(self._file.rows, self.filter.value, self.sort.value, self.descending.value)
        self.table.content = _table_html(self._shown)
        self.summary.content = _summary_html(self._shown)
        self.episode.options = tuple(r.label for r in self._shown) or (NONE,)

    def _selected(self) -> EpisodeRow:
        row = next((r for r in self._shown if r.label == self.episode.value), None)
        if row is None:
            raise L3MVNError("pick an episode first (the filter may have none)")
        return row

    def _open(self, row: EpisodeRow, client_id: int | None, path: Path | None = None) -> None:
        """Show ``path``, else the eval's recording of ``row``, else its newest re-run."""
        s = self.source
        path = path or recording_of(s.recordings_dir, row) or recording_of(s.rerun_dir, row)
        if path is None:
            self._clear_steps(
                f"no recording of {row.scene} episode {row.episode_id} ({row.policy}) in "
                f"{s.recordings_dir} or {s.rerun_dir}: press Re-run live to run and record it"
            )
            raise L3MVNError(f"no recording of this episode in {s.recordings_dir} or {s.rerun_dir}; press Re-run live")
        pictures, decisions = recording_frames(path)
        if not pictures:
            raise L3MVNError(f"{path.name} holds no steps")
        with self._lock:
            self._frames, self._decisions = pictures, decisions
        self.step.max = max(1, len(pictures) - 1)  # a slider needs two ends; _show_step clamps
        self.step.value = 0
        self.step.disabled = False
        self._show_step(0)
        self._tell(client_id, f"opened {path.name}: {len(pictures)} steps")

    def _recording(self, row: EpisodeRow) -> Path | None:
        """The eval's recording of ``row``, else its newest re-run."""
        s = self.source
        return recording_of(s.recordings_dir, row) or recording_of(s.rerun_dir, row)

    def open_in_rerun(self, row: EpisodeRow, client_id: int | None) -> str:
        """Serve ``row``'s recording in rerun's web viewer (the Recordings folder's viewer) and link it here."""
        if self._viewer is None:
            raise L3MVNError("this dashboard has no rerun viewer to open recordings in")
        path = self._recording(row)
        if path is None:
            raise L3MVNError(
                f"no recording of {row.raw.get('key')} ({row.policy}) in {self.source.recordings_dir} or "
                f"{self.source.rerun_dir}: press Re-run live to run and record it"
            )
        return self._viewer.open_path(path, client_id, also=self.rerun_link).url

    def load_into_session(self, row: EpisodeRow, step: int, client_id: int | None) -> None:
        """Load ``row``'s episode into the live session at ``step``, run with the line's stored config and
        policy; the replay is checked against the row's recording when there is one."""
        session = self._live_session()
        if not 0 <= step <= row.steps:
            raise L3MVNError(f"step {step} is outside this episode: it has steps 0 to {row.steps}")
        start = episode_start(row.raw, self.source.episodes, recording=self._recording(row))
        session.load(start, step, client_id=client_id)
        self.large.content = ""  # the live session is what to look at now; scrubbing shows the recording again
        self.loaded.content = md(
            f"loading {row.raw.get('key')} ({row.policy}) at step {step} into the live session: then Step or "
            "Run lets the policy go on, Take over by hand (or Policy teleop) drives it"
        )

    def _live_session(self) -> DashboardController:
        if self._session is None:
            raise L3MVNError("this Results panel has no live session to load episodes into")
        return self._session

    def _rerun(self, row: EpisodeRow, client_id: int | None) -> None:
        s = self.source
        self._tell(client_id, f"re-running {row.raw.get('key')} ({row.policy}); this takes a few seconds")
        done = rerun(row.raw, s.episodes, record_dir=s.rerun_dir)
        self.decision.content = md(done.summary)
        self._tell(client_id, done.summary, "info" if done.reproduced else "warning")
        self._open(row, client_id, done.recording)
        self.decision.content = md(done.summary)

    def _show_step(self, k: int) -> None:
        with self._lock:
            if not self._frames:
                return
            k = min(max(k, 0), len(self._frames) - 1)
            png, line = self._frames[k], self._decisions[k]
        picture = png_rgb(png)
        self.picture.image = picture
        self.decision.content = md(line)
        self.large.content = (
            main_view_html(picture, f"Recorded step: {line}", main_view=True) if self.main_view.value else ""
        )

    def _clear_steps(self, note: str) -> None:
        with self._lock:
            self._frames, self._decisions = [], []
        self.step.disabled = True
        self.picture.image = np.zeros((8, 8, 3), np.uint8)
        self.large.content = ""
        self.decision.content = md(note)

    def _compare(self) -> None:
        """Compare the file shown with every file picked in Compare with (none: clear the comparison)."""
        names = [n for n in self._compared if self._file is None or n != self._file.path.name]
        if not names or self._file is None:
            self.comparison.content = ""
            self._other = None
            return
        try:
            others = [load_result_file(self.source.results_dir / n) for n in names]
            self._other = others[-1]
            self.comparison.content = comparison_html(compare_files([self._file, *others]))
        except L3MVNError as exc:
            self.comparison.content = f"<i>{html(exc)}</i>"
            raise


def _number(v: float | None, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


# Cells wrap (after '_', '/', '.' and '-' too: causes and file names are long single words) and the box
# scrolls: no column is ever cut.
_TABLE_STYLE = (
    "font-size:11px;border-collapse:collapse",
    "padding:1px 4px;text-align:left;vertical-align:top;overflow-wrap:break-word;border-bottom:1px solid #eee",
)
_BREAK_AFTER = re.compile(r"([_/]|[.-](?=[A-Za-z]))")  # never inside a number
_COLUMNS = ("#", "scene", "ep", "goal", "ok", "SPL", "DTG", "steps", "cause", "cov")


def _html_table(head: tuple[str, ...], rows: list[tuple], caption: str = "") -> str:
    table, cell = _TABLE_STYLE
    th = "".join(f"<th style='{cell}'>{html(h)}</th>" for h in head)
    body = "".join(
        "<tr>"
        + "".join(f"<td style='{cell}'>{v if isinstance(v, _Raw) else _breakable(v)}</td>" for v in row)
        + "</tr>"
        for row in rows
    )
    cap = f"<div style='font-size:12px;font-weight:600;margin-top:6px'>{html(caption)}</div>" if caption else ""
    return f"{cap}<div style='overflow:auto;max-height:420px'><table style='{table}'><tr>{th}</tr>{body}</table></div>"


def _breakable(value: object) -> str:
    """``value`` escaped, with a line-break opportunity after each '_' and '/', and each '.' and '-'
    followed by a letter."""
    return _BREAK_AFTER.sub(r"\1<wbr>", html(str(value)))


class _Raw(str):
    """Markup the table puts in a cell as is (a bar chart)."""


def _table_html(rows: list[EpisodeRow]) -> str:
    if not rows:
        return "<i>no episode matches the filter</i>"
    cells = [
        (
            r.index,
            r.scene.removeprefix("procedural-"),
            r.episode_id,
            r.goal,
            "yes" if r.success else "no",
            _number(r.spl),
            _number(r.dtg, 1),
            r.steps,
            r.failure,
            _number(r.coverage),
        )
        for r in rows[:TABLE_ROWS]
    ]
    more = (
        f"<div style='font-size:11px'>{len(rows) - TABLE_ROWS} more in the Episode list</div>"
        if len(rows) > TABLE_ROWS
        else ""
    )
    policies = ", ".join(sorted({r.policy for r in rows}))
    return _html_table(_COLUMNS, cells, f"{len(rows)} episodes ({policies})") + more


def _bar(fraction: float, colour: str = "#2860c8", width: int = 80) -> _Raw:
    w = round(max(0.0, min(1.0, fraction)) * width)
    return _Raw(
        f"<span style='display:inline-block;width:{width}px;height:8px;background:#ddd'>"
        f"<span style='display:block;width:{w}px;height:8px;background:{colour}'></span></span>"
    )


def _summary_html(rows: list[EpisodeRow]) -> str:
    if not rows:
        return ""
    out = []
    for by in ("goal", "scene"):
        groups, causes = summaries(rows, by)
        out.append(
            _html_table(
                (by, "eps", "SR", "", "SPL"),
                [(g, n, _bar(sr), f"{sr:.2f}", f"{spl:.2f}") for g, (n, sr, spl) in groups.items()],
                f"Per {'category' if by == 'goal' else by}",
            )
        )
    total = sum(causes.values())
    out.append(
        _html_table(
            ("outcome", "", "episodes"),
            [(c, _bar(n / total, "#28a046" if c == "success" else "#c83030"), n) for c, n in causes.items()],
            "Per outcome",
        )
    )
    return "".join(out)


_MEASURE_NAMES = {"success": "SR", "spl": "SPL"}


def _estimate(e) -> str:
    return "-" if e.mean != e.mean else f"{e.mean:.2f} [{e.low:.2f}, {e.high:.2f}]"


def comparison_html(c: FilesComparison) -> str:
    """The comparison of several files: config differences first and prominently, then each file on the
    shared episodes, the paired differences against the first, and the episodes one file solved alone."""
    if c.config_notes:
        items = "".join(f"<li>{html(n)}</li>" for n in c.config_notes)
        head = (
            "<div class='l3mvn-config-differs' style='border:2px solid #c86400;background:#fff1dc;"
            "padding:4px 6px;font-size:12px'><b>Configs differ</b> (beside the policy): the numbers below "
            f"compare more than the policies.<ul style='margin:2px 0 0 16px;padding:0'>{items}</ul></div>"
        )
    else:
        head = "<div style='font-size:12px;color:#286428'>Same config in every file (beside the policy).</div>"
    left = [f"{s.name}: {s.left_out}" for s in c.summaries if s.left_out]
    scope = f"Compared on the {c.shared} episodes every file holds" + (
        f"; left out (not in every file): {', '.join(left)}" if left else ""
    )
    level = f"{int(LEVEL * 100)}%"
    out = [head, f"<div style='font-size:11px;margin-top:4px'>{html(scope)}</div>"]
    out.append(
        _html_table(
            ("file", "policy", "SR", "SPL", "DTG (m)"),
            [(s.name, s.policies, *(_estimate(s.measures[m]) for m in ("SR", "SPL", "DTG"))) for s in c.summaries],
            f"Each file (mean [{level} interval])",
        )
    )
    for p in c.pairings:
        rows = [
            (
                group,
                d.n,
                _MEASURE_NAMES.get(d.measure, d.measure),
                f"{d.mean_a:.2f}",
                f"{d.mean_b:.2f}",
                f"{d.mean:+.2f}",
                f"[{d.low:+.2f}, {d.high:+.2f}]",
                f"{d.wins} / {d.losses}",
            )
            for group, diffs in p.rows.items()
            for d in diffs
        ]
        out.append(
            _html_table(
                ("category", "n", "", "A", "B", "B - A", f"{level} interval", "B better / worse"),
                rows,
                f"Paired differences: B = {p.b} against A = {c.names[0]}",
            )
        )
    for name, only_a, only_b in c.solved_by_one:
        out.append(
            f"<div style='font-size:11px;margin-top:4px'>Solved by <b>{html(c.names[0])}</b> only vs "
            f"{html(name)} ({len(only_a)}): {html(', '.join(only_a) or 'none')}<br>Solved by <b>{html(name)}</b> "
            f"only ({len(only_b)}): {html(', '.join(only_b) or 'none')}</div>"
        )
    return "".join(out)
