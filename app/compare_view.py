"""The Compare folder: two policies on the episode selected in the Episode folder, side by side.

"Run both" runs A then B on a thread of its own (the live session keeps its worker; the controls here
are held and say what runs meanwhile), then one picture shows A and B at the same step under one
slider, with "Jump to first difference". The picture is drawn over the main view (the map is what is
compared, and the side panel is too narrow for two maps); "Show in main view" puts it back in the
panel and the live map in front. The Results panel opens the same view for an episode of two result
files (``open_rows``).
"""

from __future__ import annotations

import base64
import contextlib
import itertools
import logging
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import viser

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.world.episode import Episode
from l3mvn_studio.compare import (
    Comparison,
    Contender,
    EpisodeSource,
    comparable_policies,
    compare_recordings,
    excluded_policies,
    run_comparison,
    side_folder,
)
from l3mvn_studio.map_image import png_bytes
from l3mvn_studio.page_layout import MAP_AREA_VARS
from l3mvn_studio.page_text import html, md
from l3mvn_studio.results import EpisodeRow, recording_of, rerun

log = logging.getLogger(__name__)

DEFAULT_B = "cost-utility"
FALLBACK_A = "frontier"  # A when the dashboard's policy cannot be compared
NO_PICTURE = ""  # until a comparison exists
_ORDER = itertools.count(1)  # overlays opened later lie on top of earlier ones


def main_view_html(
    rgb: np.ndarray, title: str, *, main_view: bool, note: str = 'untick "Show in main view" for the live map'
) -> str:
    """``rgb`` as a PNG in the page (lossless: the page receives exactly these pixels): over the main
    view (the map's canvas, scaled to fill it, under a title bar), or in the panel at its width."""
    src = "data:image/png;base64," + base64.b64encode(png_bytes(rgb)).decode("ascii")
    img = f"<img class='l3mvn-picture' alt='{html(title)}' src='{src}' style='max-width:100%;max-height:100%;"
    if not main_view:
        return f"<div>{img}display:block'></div>"
    head = (
        f"<div style='color:#eee;font:600 14px sans-serif;padding:6px 10px'>{html(title)} "
        f"<span style='font-weight:400;color:#aaa'>({html(note)})</span></div>"
    )
    return (
        f"<div class='l3mvn-main-view' style='position:fixed;{MAP_AREA_VARS};"
        f"z-index:{10 + next(_ORDER)};background:#181818;display:flex;"
        f"flex-direction:column'>{head}<div style='flex:1;min-height:0;display:flex;align-items:center;"
        f"justify-content:center;padding:4px'>{img}width:100%;height:100%;object-fit:contain'></div></div>"
    )


class ComparePanel:
    """Builds the Compare folder and answers its controls (one state shared by every tab)."""

    def __init__(
        self,
        gui: viser.GuiApi,
        source: EpisodeSource,
        *,
        config: Config,
        record_dir: str | Path,
        current_policy: str,
        selected_episode: Callable[[], Episode],
        on: Callable,
        tell: Callable,
        overlay: viser.GuiFolderHandle | None = None,
    ) -> None:
        self.source, self.config, self.record_dir = source, config, Path(record_dir)
        self._selected_episode, self._tell = selected_episode, tell
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self.comparison: Comparison | None = None
        choices = comparable_policies()
        first = current_policy if current_policy in choices else FALLBACK_A
        excluded = "; ".join(f"`{p}` ({why})" for p, why in excluded_policies().items())
        with gui.add_folder("Compare"):  # in a tab of its own: open, or the tab looks empty
            gui.add_markdown(
                "Two policies on the episode selected in **Episode**, step by step, "
                f"run as `l3mvn eval` runs them (same seed). Not offered: {excluded}."
            )
            self.policy_a = gui.add_dropdown("Policy A", choices, initial_value=first)
            self.policy_b = gui.add_dropdown("Policy B", choices, initial_value=DEFAULT_B)
            self.run = gui.add_button("Run both")
            self.status = gui.add_markdown("")
            self.main_view = gui.add_checkbox(
                "Show in main view", True, hint="draw the comparison over the live map; untick for the map"
            )
            self.step = gui.add_slider("Compare step", min=0, max=1, step=1, initial_value=0, disabled=True)
            self.jump = gui.add_button("Jump to first difference", disabled=True)
            self.difference = gui.add_markdown("")
            self.lines = gui.add_markdown("")
        # Outside the folder (in ``overlay``, always shown, when given): a comparison opened from the
        # Results panel shows with the folder closed.
        with overlay if overlay is not None else contextlib.nullcontext():
            self.picture = gui.add_html(NO_PICTURE)
        self._held = (self.policy_a, self.policy_b, self.run, self.step, self.jump)
        self._followed = first  # the dashboard policy A last took
        self._wire(on)

    def follow_policy(self, name: str) -> None:
        """Policy A follows the dashboard's policy until the user picks another A here."""
        if self.policy_a.value == self._followed and name in self.policy_a.options and not self.busy:
            self.policy_a.value = self._followed = name

    @property
    def inputs(self) -> tuple:
        return (self.policy_a, self.policy_b, self.run, self.main_view, self.step, self.jump)

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # --- controls ----------------------------------------------------------------------------
    def _wire(self, on: Callable) -> None:
        @on(self.run)
        def _(event) -> None:
            episode = self._selected_episode()
            a = Contender(self.policy_a.value, self.config)
            b = Contender(self.policy_b.value, self.config)
            self._start(
                f"{episode.key}: A {a.policy} vs B {b.policy}",
                event.client_id,
                lambda progress: run_comparison(self.source, episode.key, a, b, self.record_dir, progress),
            )

        @on(self.step)
        def _(event) -> None:
            self.show(int(self.step.value))

        @on(self.jump)
        def _(event) -> None:
            c = self.comparison
            if c is None or c.first_difference is None:
                raise L3MVNError(
                    "no step to jump to: " + ("run a comparison first" if c is None else c.difference_line)
                )
            self.step.value = c.first_difference
            self.show(c.first_difference)

        @on(self.main_view)
        def _(event) -> None:
            self.show(int(self.step.value))

    def open_rows(self, a: EpisodeRow, b: EpisodeRow, recordings_dir: Path, client_id: int | None) -> None:
        """Compare the episode of two result lines: their recordings when both exist (and can be told
        apart: different policies), else each line re-run with its stored config and policy."""
        if a.raw.get("key") != b.raw.get("key"):
            raise L3MVNError(
                f"lines {a.index} and {b.index} are different episodes ({a.raw.get('key')} vs {b.raw.get('key')})"
            )
        key = str(a.raw["key"])
        self._start(
            f"{key}: A line {a.index} ({a.policy}) vs B line {b.index} ({b.policy})",
            client_id,
            lambda progress: self._compare_rows(a, b, recordings_dir, progress),
        )

    def _compare_rows(
        self, a: EpisodeRow, b: EpisodeRow, recordings_dir: Path, progress: Callable[[str], None]
    ) -> Comparison:
        stored = [recording_of(recordings_dir, r) for r in (a, b)]
        if a.policy != b.policy and all(stored):
            progress("reading both recordings")
            return compare_recordings(stored[0], stored[1], str(a.raw["key"]))
        paths = []
        for letter, row in (("A", a), ("B", b)):
            progress(f"re-running {letter} (line {row.index}, {row.policy}) with its stored config")
            folder = side_folder(self.record_dir, str(row.raw.get("config_hash", "stored")))
            done = rerun(row.raw, self.source, record_dir=folder)
            paths.append(done.recording)
            log.info("compare: %s", done.summary)
        progress("reading both recordings")
        return compare_recordings(paths[0], paths[1], str(a.raw["key"]))

    # --- the background run ------------------------------------------------------------------
    def _start(self, what: str, client_id: int | None, work: Callable[[Callable[[str], None]], Comparison]) -> None:
        with self._lock:
            if self.busy:
                raise L3MVNError(f"a comparison is running ({self.status.content.strip('*_ ')}): wait for it")
            self._thread = threading.Thread(
                target=self._run, args=(what, client_id, work), name="l3mvn-compare", daemon=True
            )
            self._hold(True, f"**Working**: {what}")
            self._thread.start()

    def _run(self, what: str, client_id: int | None, work: Callable) -> None:
        try:
            comparison = work(lambda text: setattr(self.status, "content", f"**Working**: {text}"))
        except L3MVNError as exc:
            self._done(None, f"_comparison failed: {exc}_")
            self._tell(client_id, f"compare: {exc}", "warning")
            return
        except Exception as exc:  # a bug: logged with its traceback, one line to the tab
            log.exception("compare: %s failed", what)
            self._done(None, f"_comparison failed: {type(exc).__name__}_")
            self._tell(client_id, f"compare failed: {type(exc).__name__}: {first_line(exc)}", "error")
            return
        self._done(
            comparison,
            f"{comparison.episode_key}, find **{comparison.goal}**: A {comparison.a.result}; B {comparison.b.result}",
        )
        self._tell(
            client_id,
            f"compared {comparison.episode_key}: {comparison.difference_line} (step through both in the Compare tab)",
        )

    def _done(self, comparison: Comparison | None, status: str) -> None:
        with self._lock:
            if comparison is not None:
                self.comparison = comparison
            self._hold(False, status)
            c = self.comparison
            if comparison is None:
                return
            self.step.max = max(1, c.steps - 1)  # a slider needs two ends; show() clamps
            self.step.value = 0
            self.jump.disabled = c.first_difference is None
            self.difference.content = f"**{md(c.difference_line)}**"
        self.show(0)

    def _hold(self, held: bool, status: str) -> None:
        for handle in self._held:
            handle.disabled = held
        if not held:
            self.step.disabled = self.comparison is None
            self.jump.disabled = self.comparison is None or self.comparison.first_difference is None
        self.status.content = md(status)

    # --- output ------------------------------------------------------------------------------
    def show(self, step: int) -> None:
        """A and B at ``step``, and each one's decision line under the picture."""
        c = self.comparison
        if c is None:
            self.picture.content = NO_PICTURE
            return
        step = min(max(step, 0), c.steps - 1)
        title = f"Compare {c.episode_key} (find {c.goal}), step {step}: A {c.a.label[3:]} | B {c.b.label[3:]}"
        self.picture.content = main_view_html(c.picture(step), title, main_view=self.main_view.value)
        self.lines.content = f"{md(c.a.decision_line(step))}\n\n{md(c.b.decision_line(step))}"
