"""The Recordings folder: the newest recordings, and "Open in rerun" for any of them.

"Open in rerun" starts rerun's web viewer on the recording (a child of the server, on free ports of
the dashboard's own interface) and links it in the page, so replaying needs no terminal. One viewer
runs at a time: opening another recording stops the previous viewer, and closing the dashboard stops
the last one.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

import viser

from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording import list_recordings
from l3mvn.run.recording.replay import WebViewer, start_web_viewer
from l3mvn_studio.page_text import code

log = logging.getLogger(__name__)

NONE = "(no recording yet)"
LISTED = 8  # recordings the list names; the dropdown offers every one


class RecordingsPanel:
    """Builds the Recordings folder and answers its controls (one viewer shared by every tab)."""

    def __init__(
        self, gui: viser.GuiApi, record_dir: Callable[[], str | Path], host: str, *, on: Callable, tell: Callable
    ) -> None:
        """``record_dir`` gives the folder the dashboard records into now (it may change)."""
        self._record_dir, self.host, self._tell = record_dir, host, tell
        self._viewer: WebViewer | None = None
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

    def _wire(self, on: Callable) -> None:
        @on(self.buttons)
        def _(event) -> None:
            if self.buttons.value == "Refresh list":
                self.refresh()
            else:
                self.open(self.pick.value, event.client_id)

    def refresh(self) -> None:
        """List the folder again (newest first) and offer its recordings; the pick stays if it still exists."""
        found = list_recordings(self.record_dir)
        names = tuple(info.path.name for info in found) or (NONE,)
        keep = self.pick.value if self.pick.value in names else names[0]
        self.pick.options = names
        self.pick.value = keep
        self.pick.disabled = not found
        if not found:
            self.listing.content = (
                f"_no recordings in {code(f'{self.record_dir}/')} yet: tick Record (.rrd), then Reset_"
            )
            return
        lines = [f"{len(found)} in {code(f'{self.record_dir}/')}, newest first:", ""]
        lines += [f"- {code(info.path.name)} ({info.size_bytes / 1e6:.1f} MB)" for info in found[:LISTED]]
        self.listing.content = "\n".join(lines)

    def open(self, name: str, client_id: int | None = None) -> WebViewer:
        """Serve recording ``name`` (a file of the folder, nothing else) in rerun's web viewer."""
        offered = {info.path.name: info.path for info in list_recordings(self.record_dir)}
        if name not in offered:
            raise L3MVNError(
                f"no recording {name!r} in {self.record_dir}; valid: "
                f"{', '.join(offered) or 'none yet (tick Record, then Reset)'}"
            )
        with self._lock:
            if self._viewer is not None:
                self._viewer.stop()
            self._viewer = viewer = start_web_viewer(offered[name], self.host)
        self.link.content = (
            f"**[Open {code(name)} in rerun]({viewer.url})** (rerun's web viewer, a new tab; "
            "opening another recording stops this one)"
        )
        self._tell(client_id, f"rerun serves {name}: follow the link in the Recordings folder")
        log.info("rerun web viewer for %s at %s", name, viewer.url)
        return viewer

    def close(self) -> None:
        with self._lock:
            if self._viewer is not None:
                self._viewer.stop()
                self._viewer = None
