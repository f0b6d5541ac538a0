"""Notices in the browser tabs: a message for one tab or all of them, and a spinner while the worker is busy.

A notice about a tab's own request goes to that tab only; one with no tab goes to every tab. Passing
notices close by themselves; outcomes and failures stay until dismissed, so a user who looked away
for a minute still sees them.
"""

from __future__ import annotations

import viser

from l3mvn_studio.state import Notice

NOTICE_SECONDS = 8.0  # how long a passing notice stays; outcomes and failures stay until dismissed
_LEVEL_COLORS = {"info": "blue", "warning": "yellow", "error": "red"}
_LEVEL_TITLES = {"info": "L3MVN", "warning": "Request refused", "error": "Error"}


class TabNotices:
    """Shows notices in the tabs of one viser server."""

    def __init__(self, server: viser.ViserServer) -> None:
        self._server = server
        self._busy_notes: dict[int, viser.NotificationHandle] = {}

    def tell(self, client_id: int | None, text: str, level: str = "info") -> None:
        self.show(Notice(text, level, client_id))

    def show(self, notice: Notice) -> None:
        clients = self._server.get_clients()
        targets = (
            [clients[notice.client_id]]
            if notice.client_id in clients
            else ([] if notice.client_id is not None else list(clients.values()))
        )
        title = notice.title or _LEVEL_TITLES[notice.level]
        keep = notice.sticky or notice.level == "error"
        for client in targets:
            client.add_notification(
                title,
                notice.text,
                auto_close_seconds=None if keep else NOTICE_SECONDS,
                color=_LEVEL_COLORS[notice.level],
            )

    def show_busy(self, text: str) -> None:
        """A spinner notice in every tab while the worker holds the controls; gone when ``text`` is empty.

        Called from one thread only (the draw loop's): the spinners it keeps are its own."""
        clients = self._server.get_clients()
        for client_id, note in list(self._busy_notes.items()):
            if not text or client_id not in clients:
                if client_id in clients:
                    note.remove()
                del self._busy_notes[client_id]
        if not text:
            return
        for client_id, client in clients.items():
            note = self._busy_notes.get(client_id)
            if note is None:
                self._busy_notes[client_id] = client.add_notification(
                    "Working", text, loading=True, with_close_button=False, auto_close_seconds=None
                )
            elif note.body != text:
                note.body = text
