"""Step end -> status text, and step end -> map repaint, in the browser: latency of the live dashboard.

The controller stamps each snapshot with the wall time its StepEvent arrived (``stepped_at``). Two
moments are stamped in the page:

- status: a MutationObserver sees the panel's text say "Step N";
- map repaint: the page's WebGL uploads the step's map change, in the frame that first draws it:
  the cells changed since the last picture as vertex buffers (``bufferData`` / ``bufferSubData`` of
  more than ``MAP_BYTES``), or a decoded picture as a texture (``texImage2D`` / ``texSubImage2D``;
  the only way the map was drawn before the patches).

Both clocks are this machine's, so the differences are the latencies: drawing the map, encoding it,
the websocket hop, the page decoding the picture and rendering the frame. (viser's websocket lives
in a web worker, out of reach of page scripts and of playwright's websocket events, hence these
proxies.) A step whose map did not change uploads nothing and counts for status only. "A picture handed to the
page's image loader" stamps the camera pictures (and, drawn as before, the map's) as the page starts
decoding them.

    .venv/bin/python bench/bench_dashboard_latency.py [--steps 40] [--policy frontier] [--compare]
        [--dataset DIR --split train --scene NAME --episode N] [--profile OUT.txt]

``--compare`` first opens the Compare folder in the page and runs a comparison there (the dashboard's
policy vs cost-utility on the selected episode, episodes capped at ``--compare-max-steps``), so the
comparison's picture lies over the main view while the live steps are measured. ``--profile`` writes
cProfile's cumulative listing of the dashboard's draw thread (the view's ``_draw``) to a file.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import pstats
import socket
import statistics
import time

from playwright.sync_api import sync_playwright

from l3mvn.core.config import Config
from l3mvn_studio.server import start_dashboard

CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


STAMPS = """
const MAP_BYTES = 1000;  // the map's changed cells; a label rebuild in the same batch lands in the same frame
window.__stepSeen = {};
window.__mapUploads = [];
window.__frames = [];
window.__pictures = [];
const createObjectURL = URL.createObjectURL;
URL.createObjectURL = function (blob) {
  if (blob && String(blob.type).startsWith("image") && blob.size > 2000) {
    window.__pictures.push(performance.timeOrigin + performance.now());
  }
  return createObjectURL.call(URL, blob);
};
const frame = (t) => { if (window.__frames.length < 20000) window.__frames.push(t); requestAnimationFrame(frame); };
requestAnimationFrame(frame);
new MutationObserver(() => {
  const m = /Step (\\d+), action/.exec(document.body ? document.body.textContent : "");
  if (m && !(m[1] in window.__stepSeen)) window.__stepSeen[m[1]] = performance.timeOrigin + performance.now();
}).observe(document, {subtree: true, childList: true, characterData: true});
for (const gl of [window.WebGLRenderingContext, window.WebGL2RenderingContext]) {
  if (!gl) continue;
  for (const name of ["texImage2D", "texSubImage2D"]) {
    const original = gl.prototype[name];
    gl.prototype[name] = function (...args) {
      const source = args[args.length - 1];
      if (source instanceof HTMLImageElement || (window.ImageBitmap && source instanceof ImageBitmap)) {
        window.__mapUploads.push(performance.timeOrigin + performance.now());
      }
      return original.apply(this, args);
    };
  }
  for (const name of ["bufferData", "bufferSubData"]) {
    const original = gl.prototype[name];
    gl.prototype[name] = function (...args) {
      const data = name === "bufferData" ? args[1] : args[2];
      if (data && data.byteLength > MAP_BYTES) window.__mapUploads.push(performance.timeOrigin + performance.now());
      return original.apply(this, args);
    };
  }
}
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run_comparison(page) -> None:
    """Open the Compare folder, press Run both and wait for its picture over the main view."""
    t0 = time.perf_counter()
    page.get_by_text("Compare", exact=True).first.click()
    page.get_by_role("button", name="Run both").click()
    page.get_by_text("decisions ").first.wait_for(timeout=900_000)
    page.locator(".l3mvn-main-view img").first.wait_for(timeout=60_000)
    print(f"comparison shown after {time.perf_counter() - t0:.1f} s")


def _percentiles(name: str, values: list[float]) -> str:
    if not values:
        return f"{name}: none matched"
    values = sorted(values)
    p90 = values[int(0.9 * (len(values) - 1))]
    return f"{name}: n={len(values)} p50 {statistics.median(values):.1f} ms, p90 {p90:.1f} ms, max {values[-1]:.1f} ms"


def _repaints(stamps: dict[int, float], uploads: list[float]) -> dict[int, float]:
    """Each step's first picture upload after its stamp and before the next step's stamp."""
    out: dict[int, float] = {}
    steps = sorted(stamps)
    for n, nxt in zip(steps, steps[1:] + [None]):
        t0, t1 = stamps[n], (stamps[nxt] if nxt is not None else float("inf"))
        first = next((u for u in sorted(uploads) if t0 <= u < t1), None)
        if first is not None:
            out[n] = first
    return out


def _profile_draws(dash) -> cProfile.Profile:
    """Wrap the view's draw (it runs on the draw loop's own thread) in one profiler."""
    profile = cProfile.Profile()
    view = dash.view
    draw = view._draw

    def profiled(snap, full):
        profile.enable()
        try:
            draw(snap, full)
        finally:
            profile.disable()

    view._draws._draw = profiled
    return profile


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--policy", default="frontier")
    ap.add_argument("--gap", type=float, default=0.4, help="seconds between steps")
    ap.add_argument("--viewport", default="1600x1000", help="browser viewport WxH")
    ap.add_argument("--dataset", default=None, help="an episode dataset (default: procedural houses)")
    ap.add_argument("--split", default="val")
    ap.add_argument("--scene", default=None, help="scene to run (default: the first)")
    ap.add_argument("--episode", type=int, default=None, help="episode id (default: the scene's first)")
    ap.add_argument("--profile", default=None, help="write the draw thread's cProfile listing to this file")
    ap.add_argument("--compare", action="store_true", help="run a comparison in the page's Compare view first")
    ap.add_argument(
        "--compare-max-steps",
        type=int,
        default=120,
        help="with --compare: sim.max_steps of the dashboard (caps the two compared episodes)",
    )
    args = ap.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))

    cfg = Config()
    if args.compare:
        cfg = cfg.replace(sim=dataclasses.replace(cfg.sim, max_steps=args.compare_max_steps))
    dash = start_dashboard(
        port=_free_port(),
        dataset=args.dataset,
        split=args.split,
        houses=1 if args.dataset is None else 100,
        episodes_per_house=1 if args.dataset is None else 100,
        policy=args.policy,
        cfg=cfg,
    )
    ctl = dash.controller
    profile = _profile_draws(dash) if args.profile else None
    stamps: dict[int, float] = {}
    ctl.on_snapshot(lambda s: s.event is not None and stamps.setdefault(s.event.step, s.stepped_at))
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.add_init_script(STAMPS)
            page.goto(dash.url)
            page.wait_for_selector("canvas", timeout=20_000)
            while not dash.server.get_clients():
                time.sleep(0.05)
            if args.compare:
                _run_comparison(page)
            scene = args.scene or ctl.scene_keys[0]
            episode = args.episode if args.episode is not None else ctl.episodes_of(scene)[0].episode_id
            ctl.reset(scene, episode)
            ctl.wait_idle()
            time.sleep(1.0)
            for _ in range(args.steps):
                ctl.step()
                ctl.wait_idle()
                time.sleep(args.gap)
            time.sleep(0.5)
            seen = {int(k): v / 1000.0 for k, v in page.evaluate("window.__stepSeen").items()}
            uploads = [v / 1000.0 for v in page.evaluate("window.__mapUploads")]
            frames = page.evaluate("window.__frames")
            pictures = [v / 1000.0 for v in page.evaluate("window.__pictures")]
            browser.close()
    finally:
        dash.stop()
    stepped = {n: t for n, t in stamps.items() if n > 0}
    status = {n: (seen[n] - t) * 1000.0 for n, t in stepped.items() if n in seen}
    repaint = {n: (u - stepped[n]) * 1000.0 for n, u in _repaints(stepped, uploads).items()}
    if not status:
        raise SystemExit("no step reached the browser")
    behind = [repaint[n] - status[n] for n in repaint if n in status]
    received = {n: (u - stepped[n]) * 1000.0 for n, u in _repaints(stepped, pictures).items()}
    where = f"{args.dataset or 'procedural'} {scene} #{episode}"
    print(f"policy {args.policy} on {where}{', compare view open' if args.compare else ''}, {len(stepped)} steps")
    print(_percentiles("step -> status", list(status.values())))
    print(_percentiles("step -> map repaint", list(repaint.values())))
    print(_percentiles("map repaint - status (same step)", behind))
    print(_percentiles("step -> a picture handed to the page's image loader", list(received.values())))
    gaps = [b - a for a, b in zip(frames, frames[1:])]
    print(_percentiles("page frame interval", gaps))
    if profile is not None:
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats("cumulative").print_stats(40)
        with open(args.profile, "w") as f:
            f.write(out.getvalue())
        print(f"draw profile written to {args.profile}")


if __name__ == "__main__":
    main()
