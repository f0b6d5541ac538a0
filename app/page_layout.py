"""Where the page's panels sit: the map fills what two docked panels leave free.

The camera panel docks left and the control panel right, each at a fixed width, so the map's canvas
is the rest of the window and nothing covers it. A picture drawn "over the main view" covers exactly
that canvas: each tab's script keeps the canvas's box in CSS variables (``MAP_AREA_VARS``) that such
pictures position themselves by, and follows the canvas when the window or a panel is resized.
"""

from __future__ import annotations

import viser

from l3mvn_studio.session_worker import FRAME_WIDTH

# CSS px. The camera panel shows RGB at its display width (FRAME_WIDTH) beside its scrollbar; with
# the control panel both leave a map wide enough to read on a 1280-px screen.
CAMERA_WIDTH = FRAME_WIDTH + 24
CONTROL_WIDTH = 420
# left, top, width, height of the map's canvas, with fallbacks for a tab whose script has not run yet.
MAP_AREA_VARS = (
    "left:var(--l3mvn-map-left,0px);top:var(--l3mvn-map-top,0px);"
    "width:var(--l3mvn-map-width,100vw);height:var(--l3mvn-map-height,100vh)"
)
MAP_AREA_JS = """
if (!window.__l3mvnMapArea) {
  window.__l3mvnMapArea = true;
  const root = document.documentElement.style;
  const follow = () => {
    const canvas = document.querySelector("canvas");
    if (!canvas) return;
    const box = canvas.getBoundingClientRect();
    for (const [name, px] of [["left", box.left], ["top", box.top], ["width", box.width], ["height", box.height]]) {
      const value = `${Math.round(px)}px`;
      if (root.getPropertyValue(`--l3mvn-map-${name}`) !== value) root.setProperty(`--l3mvn-map-${name}`, value);
    }
  };
  follow();
  window.addEventListener("resize", follow);
  setInterval(follow, 250);  // a dragged panel moves the canvas without resizing the window
}
"""


def dock_panels(gui: viser.GuiApi, camera: viser.PanelHandle) -> None:
    """The control panel on the right, ``camera`` on the left, both at their fixed widths."""
    gui.main_panel.dock_right()
    gui.main_panel.set_width(CONTROL_WIDTH)
    camera.dock_left()
    camera.set_width(CAMERA_WIDTH)
