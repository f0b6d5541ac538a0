"""What a browser tab may send: every value is checked against the control it is for.

viser coerces what a tab sends to the control's type (``float("nan")``, ``bool("no")``) and checks
nothing else, and any page can send any frame; so each update must be one the control itself could
have produced. Each check returns None, or one line naming the problem and the valid choices, which
the tab that sent it is shown. ``UpdateGate`` applies the checks to every GUI update before viser
does, so a refused one changes nothing.
"""

from __future__ import annotations

import logging
import math
import reprlib
from collections.abc import Callable, Iterable, Sequence
from numbers import Real
from typing import Any

import viser

from l3mvn_studio.viser_hooks import handle_uuid, show_value_to

log = logging.getLogger(__name__)

CLICKABLE = (viser.GuiButtonHandle, viser.GuiButtonGroupHandle)  # on_click, not on_update; no value to show
_INPUTS = (viser.GuiInputHandle, *CLICKABLE)  # every control a tab can send values to
_SHOWN_CHOICES = 12  # valid choices listed in a notice
_bounded = reprlib.Repr()
_bounded.maxstring = _bounded.maxother = 60
_bounded.maxlist = _bounded.maxtuple = _bounded.maxdict = 4


def shown(value: Any) -> str:
    """``repr(value)`` cut short: a value from a client may be megabytes, and messages are one line."""
    return _bounded.repr(value)


def update_refusal(handle: Any, updates: dict[str, Any]) -> str | None:
    """Why a tab's update of ``handle`` is refused, or None when the control could have sent it."""
    label = handle.label
    if not isinstance(updates, dict) or set(updates) != {"value"}:
        return f"{label}: a page may only change a control's value, not {shown(updates)}"
    value = updates["value"]
    if handle.disabled:
        return f"{label} is disabled right now"
    if isinstance(handle, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)):
        return (
            None
            if isinstance(value, str) and value in handle.options
            else (f"{label}: {shown(value)} is not one of the choices; valid: {_choices(handle.options)}")
        )
    if isinstance(handle, viser.GuiSliderHandle):
        return (
            None
            if _finite(value) and handle.min <= value <= handle.max
            else (f"{label}: {shown(value)} is not a number from {handle.min:g} to {handle.max:g}")
        )
    if isinstance(handle, viser.GuiCheckboxHandle):
        return None if isinstance(value, bool) else f"{label}: {shown(value)} is not true or false"
    if isinstance(handle, viser.GuiButtonHandle):
        return None if value is True else f"{label}: a button click carries true, not {shown(value)}"
    return f"{label}: this page does not take input from a {type(handle).__name__}"


def ray_refusal(origin: Any, direction: Any) -> str | None:
    """Why a map click's ray is refused: its origin and direction must be three finite numbers each."""
    for name, vector in (("origin", origin), ("direction", direction)):
        if not (isinstance(vector, Sequence) and len(vector) == 3 and all(_finite(v) for v in vector)):
            return f"map click ignored: its ray {name} {shown(vector)} is not three finite numbers"
    return None


class UpdateGate:
    """Whether viser may apply a tab's GUI update (``viser_hooks.check_gui_updates``); runs on viser's
    event loop, before any state changes.

    A refused update changes nothing anywhere: the tab that sent it is told why and shown the value
    the server holds again; other tabs see nothing. A check that fails refuses too.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        handles: Iterable[Any],
        *,
        busy: Callable[[], str],
        tell: Callable[[int, str, str], None],
    ) -> None:
        """``handles``: the page's controls (anything else in it is skipped); ``busy``: what holds the
        page's controls now, if anything; ``tell(client_id, text, level)``: a notice to one tab."""
        self._server, self._busy, self._tell = server, busy, tell
        self._inputs = {handle_uuid(h): h for h in handles if isinstance(h, _INPUTS)}

    def __call__(self, client_id: int, uuid: str, updates: dict) -> bool:
        handle = self._inputs.get(uuid)
        try:
            problem = "that control is not on this page" if handle is None else update_refusal(handle, updates)
            if problem is None:
                return True
            busy = self._busy()
            if handle is not None and handle.disabled and busy:
                problem = f"{handle.label} is held while the dashboard is busy ({busy})"
            log.info("dashboard: refused an update from client %s: %s", client_id, problem)
            self._tell(client_id, problem, "warning")
            client = self._server.get_clients().get(client_id)
            if client is not None and handle is not None and not isinstance(handle, CLICKABLE):
                show_value_to(client, handle)
        except Exception:
            log.exception("dashboard: checking an update from client %s failed; refused it", client_id)
        return False


def _finite(value: Any) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def _choices(options: Sequence[str]) -> str:
    shown = ", ".join(options[:_SHOWN_CHOICES])
    return shown if len(options) <= _SHOWN_CHOICES else f"{shown}, ... ({len(options)} in all)"
