"""The Language folder in a real browser: an l3mvn-zs episode on a procedural house shows per-goal
bars and the fusion rule line with the numbers of the snapshot; a policy without language says so;
PONI shows its potentials the same way, and l3mvn-ff with the map head says what the words add.

Skips like tests/test_dashboard_browser.py when playwright or a chromium is missing. Set
L3MVN_SCREENSHOTS=DIR to keep the screenshot (docs/screenshots/dashboard_language_panel.png).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import serve_dashboard
from test_dashboard_browser import (  # noqa: E402  (after the skip: it needs playwright too)
    CHROMIUM,
    CHROMIUM_ARGS,
    VIEWPORT,
    _open_tab,
    _panel_text,
    _step_shown,
    _wait,
)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.core.config import Config  # noqa: E402
from l3mvn_studio.language_panel import BAR_PX, SHOWN_FRONTIERS  # noqa: E402
from l3mvn_studio.page_text import html  # noqa: E402

MAX_CLICKS = 40  # the look-around takes 12 steps; episode 0 of house 0 (toilet) chooses at step 13


def _step_to_first_choice(page, ctl, first: str):
    """Reset, then Step until the agent has chosen a frontier; that snapshot's map view."""
    page.get_by_role("button", name="Reset").click()
    _wait(lambda: _step_shown(page) == 0, timeout=60, what=first)
    for _ in range(MAX_CLICKS):
        view = ctl.snapshot.map
        if view is not None and view.fusion is not None:
            return view
        n = _step_shown(page)
        page.get_by_role("button", name="Step").click()
        _wait(lambda n=n: (_step_shown(page) or 0) > n, timeout=30, what="the next step")
    view = ctl.snapshot.map
    assert view is not None and view.fusion is not None, "the agent never chose a frontier"
    return view


@contextlib.contextmanager
def _language_page(url: str) -> Iterator:
    """A chromium page on the dashboard at ``url``, its canvas drawn, with the long timeout a first
    language-model load needs; the browser closes on leaving."""
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            page.set_default_timeout(60_000)
            page.goto(url)
            page.wait_for_selector("canvas", timeout=20_000)
            _open_tab(page, "Language")
            yield page
        finally:
            browser.close()


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, policy="l3mvn-zs", cfg=Config().with_frame(240, 320))


def test_the_language_folder_shows_bars_and_the_fusion_rule_of_the_choice(dash, tmp_path):
    shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
    ctl = dash.controller
    with _language_page(dash.url) as page:
        _wait(
            lambda: "scores frontiers with a prior" in _panel_text(page),
            timeout=20,
            what="the Language folder's note before the first choice",
        )

        view = _step_to_first_choice(page, ctl, "step 0 (the language model loads once)")
        line = view.fusion.describe()
        assert line.startswith("bound B = [0.15, 0.30]; max S_LLM")
        _wait(lambda: line in _panel_text(page), what="the fusion rule line with the snapshot's numbers")

        panel = page.get_by_text("Fusion rule").first
        panel.scroll_into_view_if_needed()
        text = _panel_text(page)
        chosen = next(f for f in view.frontiers if f.chosen)
        assert f"★ F{chosen.id} (chosen)" in text and f"{view.target} (target)" in text
        query = chosen.queries.get(view.target)
        assert query is None or query in text
        # The target's bar ringed on every shown card; the chosen card first, its bar as long as its p.
        bars = page.locator(f'span[data-goal="{view.target}"]')
        assert bars.count() == min(len(view.frontiers), SHOWN_FRONTIERS)
        assert "solid" in bars.first.evaluate("e => getComputedStyle(e).outlineStyle")
        width = bars.first.evaluate("e => e.getBoundingClientRect().width")
        assert width == pytest.approx(BAR_PX * chosen.llm_scores[view.target], abs=1.0)
        assert page.locator("span[data-goal]").count() == 6 * bars.count()  # every goal on every card
        page.wait_for_timeout(500)
        page.screenshot(path=str(shots / "dashboard_language_panel.png"))

        ctl.set_policy("cost-utility")
        page.get_by_role("button", name="Reset").click()
        _wait(
            lambda: "cost-utility uses no prior" in _panel_text(page),
            timeout=30,
            what="the note of a policy without language",
        )


@pytest.fixture(scope="module")
def poni_dash():
    yield from serve_dashboard(episodes_per_house=2, policy="poni", cfg=Config().with_frame(240, 320))


def test_the_language_folder_shows_ponis_potentials_like_a_language_models_scores(poni_dash, tmp_path):
    shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
    ctl = poni_dash.controller
    with _language_page(poni_dash.url) as page:
        _wait(
            lambda: "poni scores frontiers with a prior" in _panel_text(page),
            timeout=20,
            what="the Language folder's note before the first choice",
        )
        view = _step_to_first_choice(page, ctl, "step 0")
        assert view.fusion.rule == "potentials" and view.fusion.scorer.startswith("poni (poni.pt)")
        line = view.fusion.describe()
        assert line.startswith("PONI: least metres to the frontier")
        _wait(lambda: line in _panel_text(page), what="PONI's rule line with the snapshot's numbers")
        text = _panel_text(page)
        chosen = next(f for f in view.frontiers if f.chosen)
        assert f"★ F{chosen.id} (chosen)" in text and "object potential PONI predicts" in text
        assert f"potential {chosen.s_llm:.2f}" in text
        assert "S_LLM" not in text  # nor the Frontiers table (Episode tab, below), whose column is "potential" too
        assert all(f.label.startswith(f"F{f.id}  pot ") for f in view.frontiers)  # and the map's labels
        metres = chosen.expected_m[view.target]
        assert f"{chosen.llm_scores[view.target]:.2f} {metres:.1f} m" in text  # the bar's value and its metres
        assert page.locator("span[data-goal]").count() % 6 == 0 and page.locator("span[data-goal]").count() >= 6
        page.wait_for_timeout(500)
        page.screenshot(path=str(shots / "dashboard_poni_panel.png"))
        _open_tab(page, "Episode")
        _wait(lambda: "potential" in _panel_text(page), what="the Frontiers table")
        assert "S_LLM" not in _panel_text(page)


@pytest.fixture(scope="module")
def map_head_dash():
    from l3mvn.agent.potentials.language_map import shipped_language_map

    if not shipped_language_map().is_file():
        pytest.skip("the shipped map head is not installed")
    cfg = Config().with_frame(240, 320)
    cfg = cfg.replace(policy=replace(cfg.policy, head="map"))
    yield from serve_dashboard(episodes_per_house=2, policy="l3mvn-ff", cfg=cfg)


def test_the_map_head_shows_ponis_potentials_and_names_the_words_and_each_frontiers_sentence(map_head_dash, tmp_path):
    shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
    ctl = map_head_dash.controller
    with _language_page(map_head_dash.url) as page:
        view = _step_to_first_choice(page, ctl, "step 0 (the sentence embedder loads once)")
        assert view.fusion.rule == "potentials" and " + minilm words (language_map.pt)" in view.fusion.scorer
        line = view.fusion.describe()
        assert "from the object potential and the minilm words of the frontier's window" in line
        _wait(lambda: line in _panel_text(page), what="the map head's rule line with the snapshot's numbers")
        text = _panel_text(page)
        assert "plus what the minilm words of the frontier's window add" in text
        chosen = next(f for f in view.frontiers if f.chosen)
        sentence = chosen.queries[view.target]  # the sentence the head read, shown as the frontier's query
        assert sentence.startswith("This frontier contains") and html(sentence) in page.content()
        assert f"potential {chosen.s_llm:.2f}" in text and "S_LLM" not in text
        page.wait_for_timeout(500)
        page.screenshot(path=str(shots / "dashboard_map_head_panel.png"))
