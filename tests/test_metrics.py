import math

import numpy as np
import pytest

from l3mvn.core.config import Config, TaskConfig
from l3mvn.run.eval.metrics import format_summary, summarize
from l3mvn.world.task.regions import geodesic_field, goal_region
from l3mvn.world.task.scoring import EpisodeOutcome, score_episode


def _outcome(**kw):
    base = dict(
        stopped=True,
        in_success_region=True,
        steps=40,
        path_length_m=6.0,
        shortest_path_m=5.0,
        final_distance_m=0.0,
        saw_target=True,
        entered_region=True,
        recent_collision_rate=0.0,
        coverage=0.3,
    )
    base.update(kw)
    return EpisodeOutcome(**base)


def test_spl_is_shortest_over_walked_when_walked_longer():
    s, spl, dtg, cause = score_episode(_outcome(), TaskConfig())
    assert (s, cause, dtg) == (1.0, "success", 0.0) and math.isclose(spl, 5.0 / 6.0)


def test_spl_caps_at_one_when_walked_less_than_shortest():
    assert score_episode(_outcome(path_length_m=4.0), TaskConfig())[1] == 1.0


@pytest.mark.parametrize(
    "kw,cause",
    [
        (dict(in_success_region=False, final_distance_m=2.0), "false_stop"),
        (dict(stopped=False, in_success_region=False, saw_target=False, entered_region=False), "never_saw_target"),
        (
            dict(stopped=False, in_success_region=False, saw_target=False, entered_region=False, coverage=0.5),
            "never_saw_target",
        ),
        (
            dict(stopped=False, in_success_region=False, saw_target=False, entered_region=False, coverage=0.95),
            "unseen_in_explored",
        ),
        (dict(stopped=False, in_success_region=False, entered_region=False), "saw_target_not_reached"),
        (dict(stopped=False, in_success_region=True), "timeout"),
        (dict(stopped=False, in_success_region=False, recent_collision_rate=0.8), "stuck"),
    ],
)
def test_each_failure_cause_is_distinguished(kw, cause):
    s, spl, _, c = score_episode(_outcome(**kw), TaskConfig())
    assert (s, spl, c) == (0.0, 0.0, cause)


def test_summary_reports_per_category_and_names_the_rule():
    rows = [
        dict(key="a", goal="toilet", policy="p", success=1.0, spl=0.5, dtg=0.0, failure="success", rule="semexp"),
        dict(key="b", goal="toilet", policy="p", success=0.0, spl=0.0, dtg=3.0, failure="false_stop", rule="semexp"),
        dict(key="c", goal="bed", policy="p", success=1.0, spl=1.0, dtg=0.0, failure="success", rule="semexp"),
    ]
    s = summarize(rows)
    assert s["episodes"] == 3 and math.isclose(s["success"], 2 / 3, abs_tol=1e-4)
    assert s["per_category"]["toilet"]["success"] == 0.5 and s["rule"] == "semexp"
    assert s["failure_causes"] == {"success": 2, "false_stop": 1}
    assert "success rule: semexp" in format_summary(s)


def test_summary_refuses_to_mix_rules():
    rows = [
        dict(key="a", goal="bed", policy="p", success=1.0, spl=1.0, dtg=0.0, failure="success", rule=r)
        for r in ("semexp", "geodesic")
    ]
    with pytest.raises(ValueError, match="mix success rules"):
        summarize(rows)


def test_geodesic_field_goes_around_a_wall():
    passable = np.ones((21, 21), bool)
    passable[10, :18] = False  # wall with a gap at the east end
    src = np.zeros_like(passable)
    src[0, 0] = True
    d = geodesic_field(passable, src, 1.0)
    assert d[0, 0] == 0.0
    straight = 20.0
    assert d[20, 0] > straight + 20  # must detour through the gap near column 18-20
    assert np.isinf(geodesic_field(passable, np.zeros_like(src), 1.0)).all()


def test_semexp_region_is_a_one_metre_disk_around_the_goal_and_adds_one_metre(tiny_scene):
    g = goal_region(tiny_scene, "toilet", Config())
    toilet = tiny_scene.category_mask("toilet")
    rows, cols = np.nonzero(g.region)
    tr, tc = np.nonzero(toilet)
    d2 = ((rows[:, None] - tr[None]) ** 2 + (cols[:, None] - tc[None]) ** 2).min(1)
    assert d2.max() <= 20**2
    x, y = tiny_scene.cell_center(80, 30)
    assert math.isclose(g.shortest_path_length(x, y), g.distance_at(x, y) + 1.0)


def test_geodesic_rule_region_is_inside_the_semexp_region(tiny_scene):
    semexp = goal_region(tiny_scene, "toilet", Config())
    strict = goal_region(tiny_scene, "toilet", Config(task=TaskConfig(success_rule="geodesic")))
    assert strict.region.sum() > 0 and not (strict.region & ~semexp.region).any()
    assert strict.length_offset_m == 0.0
