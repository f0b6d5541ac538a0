"""Notices in the browser tabs: a message for one tab or all of them, and a spinner while the worker is busy.

A notice about a tab's own request goes to that tab only; one with no tab goes to every tab. Each tab
shows one notice card at a time, so notices never pile up over the map: a new notice takes the place
of the card on screen. Notices that come together (one click often causes two) share one card, each
text in full and in order, because a card replaced at once would never be seen. Passing notices close
by themselves; outcomes and failures stay until dismissed or replaced, so a user who looked away for a
minute still sees them. The busy spinner is apart: it stays while the worker is busy, whatever comes.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import viser

from l3mvn_studio.state import Notice

NOTICE_SECONDS = 8.0  # how long a passing notice stays; outcomes and failures stay until dismissed
TOGETHER_SECONDS = 1.0  # notices this soon after a card's first one join it instead of replacing it
CARD_TEXTS = 8  # texts one card holds at most (a flood of refusals): the newest, after a count of the rest
_LEVELS = ("info", "warning", "error")  # least to most severe: a card takes its most severe notice's colour
_LEVEL_COLORS = {"info": "blue", "warning": "yellow", "error": "red"}
_LEVEL_TITLES = {"info": "L3MVN", "warning": "Request refused", "error": "Error"}
SEPARATOR = " · "  # between the texts of one card


@dataclass
class _Card:
    """One tab's notice card: the notices it shows and when the first came."""

    started: float
    notices: list[Notice] = field(default_factory=list)
    handle: viser.NotificationHandle | None = None

    def show_in(self, client: viser.ClientHandle) -> None:
        worst = max(self.notices, key=lambda n: _LEVELS.index(n.level))
        title = next(n for n in reversed(self.notices) if n.level == worst.level).title
        texts = list(dict.fromkeys(n.text for n in self.notices))  # a repeated text once
        if len(texts) > CARD_TEXTS:
            texts = [f"({len(texts) - CARD_TEXTS + 1} earlier notices)", *texts[-CARD_TEXTS + 1 :]]
        keep = any(n.sticky or n.level == "error" for n in self.notices)
        if self.handle is not None:
            self.handle.remove()  # gone already when it closed by itself or was dismissed: then a no-op
        self.handle = client.add_notification(
            title or _LEVEL_TITLES[worst.level],
            SEPARATOR.join(texts),
            auto_close_seconds=None if keep else NOTICE_SECONDS,
            color=_LEVEL_COLORS[worst.level],
        )


class TabNotices:
    """Shows notices in the tabs of one viser server."""

    def __init__(self, server: viser.ViserServer) -> None:
        self._server = server
        self._busy_notes: dict[int, viser.NotificationHandle] = {}
        self._cards: dict[int, _Card] = {}  # each tab's card on screen (or closed by itself since)
        self._lock = threading.Lock()  # notices come from the worker's thread and the handlers'

    def tell(self, client_id: int | None, text: str, level: str = "info") -> None:
        self.show(Notice(text, level, client_id))

    def show(self, notice: Notice) -> None:
        clients = self._server.get_clients()
        targets = (
            [clients[notice.client_id]]
            if notice.client_id in clients
            else ([] if notice.client_id is not None else list(clients.values()))
        )
        now = time.monotonic()
        with self._lock:
            for client_id in set(self._cards) - set(clients):  # tabs closed since
                del self._cards[client_id]
            for client in targets:
                card = self._cards.setdefault(client.client_id, _Card(now))
                if now - card.started > TOGETHER_SECONDS:  # a new card takes the place of the last one's
                    card.started, card.notices = now, []
                card.notices.append(notice)
                card.show_in(client)

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
