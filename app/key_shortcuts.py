"""Keyboard shortcuts: a script each tab runs that turns keys into clicks on the page's own buttons.

A key clicks a button by its label, so a shortcut goes through the same checks as a click, does
nothing while its button is hidden or disabled, and is ignored only while the user types: in a text
or number field, a text area, editable text, or a dropdown whose list is open (its search box). The
focus a click leaves on a checkbox, a button, a closed dropdown or the map keeps the keys working.
The labels here are the ones the view gives its buttons.
"""

from __future__ import annotations

SHORTCUTS_MD = "Keys: `Space` run / pause, `N` step, `R` reset, `F` fit map (not while typing in a field)"
DRIVE_MD = (
    "Keys: `W` / `Up` forward, `A` / `Left` and `D` / `Right` turn, `Q` look up, `E` look down, "
    "`X` stop (ends the episode; it is scored like any policy's)"
)
# Pressed keys click the page's own buttons, so a shortcut goes through the same checks as a click.
SHORTCUTS_JS = """
if (!window.__l3mvnShortcuts) {
  window.__l3mvnShortcuts = true;
  const keys = {" ": ["Pause", "Run"], "n": ["Step"], "r": ["Reset"], "f": ["Fit map in view"]};
  // Drive keys (policy teleop) count only while the Drive buttons are shown; otherwise they stay
  // viser's camera keys.
  const drive = {"w": "Forward", "arrowup": "Forward", "a": "Turn left", "arrowleft": "Turn left",
                 "d": "Turn right", "arrowright": "Turn right", "q": "Look up", "e": "Look down", "x": "Stop"};
  const shown = (name) => Array.from(document.querySelectorAll("button"))
    .some((b) => b.textContent.trim() === name && b.offsetParent !== null);
  // Inputs that take no typed text: a key there is the page's, not the field's.
  const untyped = ["checkbox", "radio", "button", "submit", "reset", "range", "color", "file", "image", "hidden"];
  const typing = (t) => {
    if (!(t instanceof HTMLElement)) return false;
    if (t.isContentEditable || t.tagName === "TEXTAREA") return true;
    if (t.tagName !== "INPUT" || t.readOnly || untyped.includes(t.type)) return false;
    // A dropdown's input is a search box only while its list is open.
    return t.getAttribute("role") !== "combobox" || t.getAttribute("aria-expanded") === "true";
  };
  const ours = (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey || typing(e.target)) return null;
    const key = e.key.toLowerCase();
    if (drive[key] && shown("Forward")) return [drive[key]];
    return keys[key] || null;
  };
  // A focused button would take Space as a click of its own too: the key is ours alone.
  document.addEventListener("keyup", (e) => { if (ours(e)) { e.preventDefault(); e.stopPropagation(); } }, true);
  document.addEventListener("keydown", (e) => {
    const names = ours(e);
    if (!names) return;
    e.preventDefault();
    e.stopPropagation();
    if (e.repeat) return;
    const buttons = Array.from(document.querySelectorAll("button"));
    for (const name of names) {
      const b = buttons.find((x) => x.textContent.trim() === name && !x.disabled && x.offsetParent !== null);
      if (b) { b.click(); return; }
    }
  }, true);
}
"""
