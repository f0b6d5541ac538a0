"""The Recordings folder: the newest recordings of every folder the dashboard reads, and "Open in rerun".

It lists the live session's record folder and the folders the Results panel reads (the eval's own
recordings, the re-runs), each recording under its folder; a folder two roles share is listed once.
"Open in rerun" starts rerun's web viewer on the recording (a child of the server, on free ports of
the dashboard's own interface) and links it in the page, so replaying needs no terminal. One viewer
runs at a time: opening another recording stops the previous viewer, and closing the dashboard stops
the last one. The Results panel opens its rows' recordings through the same viewer (``open_path``).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import viser

from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording import list_recordings
from l3mvn.run.recording.replay import WebViewer, start_web_viewer
from l3mvn_studio.page_text import code, md

log = logging.getLogger(__name__)

NONE = "(no recording yet)"
LISTED = 8  # recordings the list names per folder; the dropdown offers every one
LIVE = "live session"


@dataclass(frozen=True)
class Offered:
    """One recording the dropdown offers: the folder's label and the file."""

    label: str
    path: Path

    @property
    def option(self) -> str:
        """The live session's recordings by name (as they always were), others after their folder's label."""
        return self.path.name if self.label.startswith(LIVE) else f"{self.label}: {self.path.name}"


class RecordingsPanel:
    """Builds the Recordings folder and answers its controls (one viewer shared by every tab)."""

    def __init__(
        self,
        gui: viser.GuiApi,
        record_dir: Callable[[], str | Path],
        host: str,
        *,
        on: Callable,
        tell: Callable,
    ) -> None:
        """``record_dir`` gives the folder the dashboard records into now (it may change)."""
        self._record_dir, self.host, self._tell = record_dir, host, tell
        self._folders: list[tuple[str, Path]] = []
        self._viewer: WebViewer | None = None
        self._links: list = []  # the markdown handles that link the running viewer
        self._lock = threading.Lock()
        with gui.add_folder("Recordings"):
            self.listing = gui.add_markdown("")
            self.pick = gui.add_dropdown("Recording", (NONE,), disabled=True)
            self.buttons = gui.add_button_group("Recording actions", ("Open in rerun", "Refresh list"))
            self.link = gui.add_markdown("")
        self.refresh()
        self._wire(on)

    @property
    def record_dir(self) -> Path:
        return Path(self._record_dir())

    @property
    def inputs(self) -> tuple:
        return (self.pick, self.buttons)

    def add_folder(self, label: str, folder: str | Path) -> None:
        """List ``folder`` too, under ``label`` (what it holds: the Results panel adds the folders it reads)."""
        self._folders.append((label, Path(folder)))
        self.refresh()

    def folders(self) -> list[tuple[str, Path]]:
        """(label, folder) of every folder listed, the live session's first; one folder two roles
        share is listed once, under both labels."""
        out: list[tuple[str, Path]] = []
        for label, folder in ((LIVE, self.record_dir), *self._folders):
            same = next((i for i, (_, seen) in enumerate(out) if _same_folder(seen, folder)), None)
            if same is None:
                out.append((label, folder))
            else:
                out[same] = (f"{out[same][0]} and {label}", out[same][1])
        return out

    def _wire(self, on: Callable) -> None:
        @on(self.buttons)
        def _(event) -> None:
            if self.buttons.value == "Refresh list":
                self.refresh()
            else:
                self.open(self.pick.value, event.client_id)

    def _offered(self) -> tuple[list[tuple[str, Path, list]], dict[str, Offered]]:
        listed, offered = [], {}
        for label, folder in self.folders():
            found = list_recordings(folder)
            listed.append((label, folder, found))
            for info in found:
                item = Offered(label, info.path)
                offered[item.option] = item
        return listed, offered

    def refresh(self) -> None:
        """List the folders again (newest first) and offer their recordings; the pick stays if it still exists."""
        listed, offered = self._offered()
        names = tuple(offered) or (NONE,)
        keep = self.pick.value if self.pick.value in names else names[0]
        self.pick.options = names
        self.pick.value = keep
        self.pick.disabled = not offered
        lines = []
        for label, folder, found in listed:
            if not found:
                hint = ": tick Record (.rrd), then Reset" if label.startswith(LIVE) else ""
                lines += [f"**{md(label)}** ({code(f'{folder}/')}): _no recordings yet{hint}_", ""]
                continue
            lines += [f"**{md(label)}** ({code(f'{folder}/')}): {len(found)}, newest first:", ""]
            lines += [f"- {code(info.path.name)} ({info.size_bytes / 1e6:.1f} MB)" for info in found[:LISTED]]
            lines.append("")
        self.listing.content = "\n".join(lines)

    def open(self, name: str, client_id: int | None = None) -> WebViewer:
        """Serve recording ``name`` (one the dropdown offers, nothing else) in rerun's web viewer."""
        _, offered = self._offered()
        if name not in offered:
            valid = ", ".join(offered) or "none yet (tick Record, then Reset)"
            raise L3MVNError(f"no recording {name!r} in {', '.join(str(f) for _, f in self.folders())}; valid: {valid}")
        return self.open_path(offered[name].path, client_id)

    def open_path(self, path: Path, client_id: int | None = None, also=None) -> WebViewer:
        """Serve ``path`` in rerun's web viewer (stopping the one before) and link it here, and in
        ``also`` (another panel's markdown) when given; the caller chose the file among those it offers.
        Every link to the viewer before goes first: it would lead to a stopped viewer."""
        with self._lock:
            for handle in self._links:
                handle.content = ""
            if self._viewer is not None:
                self._viewer.stop()
            self._viewer = viewer = start_web_viewer(path, self.host)
            self._links = [self.link] if also is None else [self.link, also]
        link = f"**[Open {code(path.name)} in rerun]({viewer.url})**"
        self.link.content = f"{link} (rerun's web viewer, a new tab; opening another recording stops this one)"
        if also is not None:
            also.content = f"{link} (a new tab)"
        self._tell(client_id, f"rerun serves {path.name}: follow the link in the Recordings tab")
        log.info("rerun web viewer for %s at %s", path, viewer.url)
        return viewer

    def close(self) -> None:
        with self._lock:
            if self._viewer is not None:
                self._viewer.stop()
                self._viewer = None


def _same_folder(a: Path, b: Path) -> bool:
    return a.resolve() == b.resolve()
