"""The dashboard's Head dropdown (issue 15 leftover): it sets ``policy.head`` of the config the worker
builds sessions from, takes effect on the next Reset, and is ignored (with a notice that says so) by
policies that do not score with the feed-forward scorer. The bag heads need no sentence encoder, so
these tests build real feed-forward scorers offline."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import serve_dashboard

from l3mvn.core.config import Config, PolicyConfig, SimConfig, config_hash
from l3mvn.core.config.policy import POLICY_HEADS
from l3mvn.core.errors import L3MVNError
from l3mvn.run.registry import scorer_of, with_scorer
from l3mvn.world.datasets import load_episode_set
from l3mvn_studio.session_worker import DEFAULT_HEAD_CHOICE, DashboardController

SMALL = Config(sim=SimConfig().with_frame(60, 80))
BAG = SMALL.replace(policy=PolicyConfig(head="frontiers-bag"))


def _controller(cfg: Config, policy: str) -> DashboardController:
    c = DashboardController(load_episode_set(None, "val", houses=1, episodes_per_house=1, cfg=cfg), cfg, policy=policy)
    c.notices = []
    c.on_notice(c.notices.append)
    return c


@pytest.fixture
def ctl():
    c = _controller(BAG, "l3mvn-ff")
    yield c
    c.close()


def _reset(c: DashboardController):
    scene = c.scene_keys[0]
    c.reset(scene, c.episodes_of(scene)[0].episode_id)
    assert c.wait_idle(60.0)
    assert c.snapshot.error is None, c.snapshot.error
    return c.session


def _hash(cfg: Config, policy: str) -> str:
    """The hash `l3mvn eval` writes for ``policy`` under ``cfg`` (its scorer in force written in)."""
    return config_hash(with_scorer(policy, cfg), policy, 0)


def _with_head(head: str | None) -> Config:
    return SMALL.replace(policy=dataclasses.replace(SMALL.policy, head=head))


def test_the_head_starts_on_the_config_and_a_pick_is_what_the_next_reset_scores_with(ctl):
    assert ctl.head == "frontiers-bag" and ctl.head_names() == (DEFAULT_HEAD_CHOICE,) + POLICY_HEADS
    first = _reset(ctl)
    assert first.policy.global_policy.scorer.kind == "frontiers-bag"
    assert first.config_hash == _hash(_with_head("frontiers-bag"), "l3mvn-ff")

    ctl.set_head("rooms-bag")
    assert ctl.cfg.policy.head == "rooms-bag" and ctl.head == "rooms-bag"
    assert ctl.notices[-1].text == "head 'rooms-bag' takes effect on the next Reset"
    assert ctl.session.policy.global_policy.scorer.kind == "frontiers-bag"  # the running episode keeps its own

    second = _reset(ctl)
    assert second.policy.global_policy.scorer.kind == "rooms-bag"
    assert second.config_hash == _hash(_with_head("rooms-bag"), "l3mvn-ff") != first.config_hash


def test_an_unknown_head_is_refused_with_the_valid_ones_and_changes_nothing(ctl):
    with pytest.raises(
        L3MVNError,
        match=r"^unknown head 'bogus'; valid heads: default \(rooms\), frontiers, rooms, "
        r"frontiers-bag, rooms-bag, map$",
    ):
        ctl.set_head("bogus")
    assert ctl.head == "frontiers-bag" and not ctl.notices


def test_the_head_survives_a_policy_change_and_policies_that_ignore_it_say_so_and_still_run(ctl):
    ctl.set_head("rooms-bag")
    ctl.set_policy("l3mvn-zs")
    ctl.set_head("rooms-bag")  # picked again under a policy that does not read it
    zero_shot = scorer_of("l3mvn-zs", ctl.cfg.policy)  # the LLM where one is installed, else room types
    assert f"ignored by policy 'l3mvn-zs', which scores with {zero_shot!r}" in ctl.notices[-1].text
    assert "only feed-forward scoring uses a head (policies l3mvn-ff, near+llm" in ctl.notices[-1].text
    zs = _reset(ctl)  # a head handed to another scorer would be refused: it is left out instead
    assert zs.policy.global_policy.scorer_name == zero_shot and zs.policy.global_policy.head is None
    assert zs.config_hash == _hash(_with_head(None), "l3mvn-zs")

    ctl.set_policy("oracle")
    ctl.set_head("rooms-bag")
    assert "ignored by policy 'oracle', which uses no language scorer" in ctl.notices[-1].text
    _reset(ctl)

    ctl.set_policy("l3mvn-ff")
    assert ctl.head == "rooms-bag"
    assert _reset(ctl).policy.global_policy.scorer.kind == "rooms-bag"

    ctl.set_head(DEFAULT_HEAD_CHOICE)
    assert ctl.cfg.policy.head is None and ctl.head == DEFAULT_HEAD_CHOICE


@pytest.fixture
def dash():
    yield from serve_dashboard(episodes_per_house=1, cfg=BAG, policy="l3mvn-ff")


def test_the_dropdown_starts_on_the_configs_head_and_is_held_with_the_other_controls(dash):
    head = dash.view.head
    assert head.value == "frontiers-bag" and tuple(head.options) == (DEFAULT_HEAD_CHOICE,) + POLICY_HEADS
    assert head in dash.view._held
    assert "feed-forward scoring only (l3mvn-ff, near+llm or Scorer feedforward)" in head.hint


def test_without_an_llm_the_zero_shot_policy_says_what_it_scores_with_instead(monkeypatch):
    from l3mvn.agent.language import llm

    monkeypatch.setattr(llm, "llm_problem", lambda model: f"LLM {model!r} is not installed")
    c = _controller(SMALL, "l3mvn-zs")
    try:
        session = _reset(c)
        assert session.policy.global_policy.scorer_name == "roomtype"
        assert any("scores with 'roomtype' instead of an LLM" in n.text and n.level == "warning" for n in c.notices)
    finally:
        c.close()


def test_a_head_file_the_server_starts_with_is_one_of_the_head_choices(tmp_path):
    import torch

    from l3mvn.agent.language import GOALS
    from l3mvn.agent.language.head import GoalHead, save_head

    path = tmp_path / "mine.pt"
    torch.manual_seed(0)
    meta = {"kind": "frontiers", "object_filter": "all", "encoder": "minilm", "goals": list(GOALS)}
    save_head(GoalHead(384, len(GOALS)).eval(), meta, path)
    c = _controller(_with_head(str(path)), "l3mvn-ff")
    try:
        assert c.head == str(path) and c.head_names() == (DEFAULT_HEAD_CHOICE,) + POLICY_HEADS + (str(path),)
        assert _reset(c).policy.global_policy.scorer.meta["kind"] == "frontiers"
        c.set_head("rooms")
        c.set_head(str(path))  # the file can be chosen again after another head
        assert c.cfg.policy.head == str(path)
    finally:
        c.close()
