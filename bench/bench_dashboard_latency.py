"""Step end -> new map in the browser: median latency of the live dashboard.

The controller stamps each snapshot with the wall time its StepEvent arrived (``stepped_at``). The
view sends the map, the markers and the status text of a step in one atomic batch, so the page has
the new map when the status shows "Step N": a MutationObserver in the page stamps that moment. Both
clocks are this machine's, so the difference is the latency: drawing the map, encoding it, the
websocket hop and the page applying the update. (viser's websocket lives in a web worker, out of
reach of page scripts and of playwright's websocket events, hence this proxy.)

    .venv/bin/python bench/bench_dashboard_latency.py [--steps 40] [--policy frontier] [--compare]

``--compare`` first opens the Compare folder in the page and runs a comparison there (the dashboard's
policy vs cost-utility on the selected episode, episodes capped at ``--compare-max-steps``), so the
comparison's picture lies over the main view while the live steps are measured.
"""

from __future__ import annotations

import argparse
import dataclasses
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


SEEN_STEPS = """
window.__stepSeen = {};
new MutationObserver(() => {
  const m = /Step (\\d+), action/.exec(document.body ? document.body.textContent : "");
  if (m && !(m[1] in window.__stepSeen)) window.__stepSeen[m[1]] = performance.timeOrigin + performance.now();
}).observe(document, {subtree: true, childList: true, characterData: true});
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--policy", default="frontier")
    ap.add_argument("--gap", type=float, default=0.4, help="seconds between steps")
    ap.add_argument("--compare", action="store_true", help="run a comparison in the page's Compare view first")
    ap.add_argument(
        "--compare-max-steps",
        type=int,
        default=120,
        help="with --compare: sim.max_steps of the dashboard (caps the two compared episodes)",
    )
    args = ap.parse_args()

    cfg = Config()
    if args.compare:
        cfg = cfg.replace(sim=dataclasses.replace(cfg.sim, max_steps=args.compare_max_steps))
    dash = start_dashboard(port=_free_port(), houses=1, episodes_per_house=1, policy=args.policy, cfg=cfg)
    ctl = dash.controller
    stamps: dict[int, float] = {}
    ctl.on_snapshot(lambda s: s.event is not None and stamps.setdefault(s.event.step, s.stepped_at))
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 900, "height": 600})
            page.add_init_script(SEEN_STEPS)
            page.goto(dash.url)
            page.wait_for_selector("canvas", timeout=20_000)
            while not dash.server.get_clients():
                time.sleep(0.05)
            if args.compare:
                _run_comparison(page)
            scene = ctl.scene_keys[0]
            ctl.reset(scene, ctl.episodes_of(scene)[0].episode_id)
            ctl.wait_idle()
            time.sleep(1.0)
            for _ in range(args.steps):
                ctl.step()
                ctl.wait_idle()
                time.sleep(args.gap)
            time.sleep(0.5)
            seen = {int(k): v / 1000.0 for k, v in page.evaluate("window.__stepSeen").items()}
            browser.close()
    finally:
        dash.stop()
    latencies = [(seen[n] - t) * 1000.0 for n, t in stamps.items() if n in seen and n > 0]
    if not latencies:
        raise SystemExit("no map updates reached the browser")
    latencies.sort()
    print(
        f"policy {args.policy}{', compare view open' if args.compare else ''}, "
        f"{len(latencies)}/{len(stamps)} steps matched: step end -> map in browser "
        f"median {statistics.median(latencies):.1f} ms, p90 {latencies[int(0.9 * (len(latencies) - 1))]:.1f} ms, "
        f"max {latencies[-1]:.1f} ms"
    )


if __name__ == "__main__":
    main()
