"""The side panel's text, checked without a server: the functions take records and return markup."""

from __future__ import annotations

import numpy as np

from l3mvn.run.viz import category_color
from l3mvn_studio.page_markdown import legend_html, no_map_markdown


def test_before_any_reset_a_map_policy_is_not_said_to_keep_no_map():
    assert "keeps no map" not in no_map_markdown("frontier", started=False)
    assert "frontiers appear after Reset" in no_map_markdown("l3mvn-zs", started=False)
    assert "keeps no map" in no_map_markdown("random-walk", started=False)


def test_the_agents_collision_marks_show_on_its_map_in_their_own_legend_colour():
    """Marks laid on floor the map shows free can close the way to a seen goal, and then the page must
    show them: they are painted over free floor, in a colour no category has."""
    from l3mvn.agent.decision import Decision
    from l3mvn.agent.mapping import SemanticMap
    from l3mvn.core.types import Action
    from l3mvn.run.viz import COLLISION_RGB
    from l3mvn.world.scenes.categories import SCAN_CATEGORIES
    from l3mvn.world.scenes.procedural import PROCEDURAL_CATEGORIES
    from l3mvn_studio.map_image import FREE, agent_map_view

    n = 80
    explored = np.zeros((n, n), bool)
    explored[20:60, 20:60] = True
    sem_map = SemanticMap(
        obstacle=np.zeros((n, n), bool),
        explored=explored,
        visited=np.zeros((n, n), bool),
        categories=np.zeros((1, n, n), bool),
        category_names=("toilet",),
        looked=explored,
        resolution_m=0.05,
        start_xy=(0.0, 0.0),
        agent_cell=(40, 40),
        agent_heading=0.0,
        local_cells=n,
        footprint_radius_cells=3,
    )
    marks = np.array([[40, 43], [41, 43], [39, 43]], np.int32)
    view = agent_map_view(Decision(action=Action.MOVE_FORWARD, map=sem_map, collision_marks=marks))
    r0, c0 = view.origin

    def pixel(r: int, c: int) -> tuple:
        return tuple(view.image[(r - r0) * view.scale, (c - c0) * view.scale])

    assert all(pixel(r, c) == COLLISION_RGB for r, c in marks) and pixel(40, 50) == FREE
    assert "collision marks" in legend_html(view.legend)
    colours = np.array([category_color(name) for name in PROCEDURAL_CATEGORIES + SCAN_CATEGORIES], float)
    assert np.linalg.norm(colours - np.array(COLLISION_RGB, float), axis=1).min() > 40


def test_guessed_obstacles_show_apart_from_seen_ones_in_their_own_legend_colour():
    """An obstacle guessed from depth too near to read may close a doorway the agent then avoids: the
    map must show which obstacles are guesses."""
    from l3mvn.agent.decision import Decision
    from l3mvn.agent.mapping import SemanticMap
    from l3mvn.core.types import Action
    from l3mvn.world.scenes.categories import SCAN_CATEGORIES
    from l3mvn.world.scenes.procedural import PROCEDURAL_CATEGORIES
    from l3mvn_studio.map_image import GUESSED, OBSTACLE, agent_map_view

    n = 80
    explored = np.zeros((n, n), bool)
    explored[20:60, 20:60] = True
    obstacle, inferred = np.zeros((n, n), bool), np.zeros((n, n), bool)
    obstacle[30, 30:50] = True
    inferred[50, 30:50] = obstacle[50, 30:50] = True
    sem_map = SemanticMap(
        obstacle=obstacle,
        explored=explored,
        visited=np.zeros((n, n), bool),
        categories=np.zeros((1, n, n), bool),
        category_names=("toilet",),
        looked=explored,
        resolution_m=0.05,
        start_xy=(0.0, 0.0),
        agent_cell=(40, 40),
        agent_heading=0.0,
        local_cells=n,
        footprint_radius_cells=3,
        inferred=inferred,
    )
    view = agent_map_view(Decision(action=Action.MOVE_FORWARD, map=sem_map))
    r0, c0 = view.origin

    def pixel(r: int, c: int) -> tuple:
        return tuple(view.image[(r - r0) * view.scale, (c - c0) * view.scale])

    assert pixel(30, 40) == OBSTACLE and pixel(50, 40) == GUESSED
    assert "guessed" in legend_html(view.legend)
    colours = np.array([category_color(name) for name in PROCEDURAL_CATEGORIES + SCAN_CATEGORIES], float)
    assert np.linalg.norm(colours - np.array(GUESSED, float), axis=1).min() > 40
    assert sem_map.copy().inferred[50, 40] and sem_map.copy().inferred is not inferred
