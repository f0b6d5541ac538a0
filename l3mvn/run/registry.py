"""Policies by name: each is built for the environment it will act in and is an object with
``reset(episode)`` and ``act(observation) -> Action | Decision``.

``oracle`` and ``random-walk`` act directly; every other name is the map-based agent with a different
global policy (only the choice of long-term goal differs between them). ``oracle-frontier`` is that
agent with a global policy that reads the ground truth: the ceiling for any frontier prior. The
paper's Table II ablations are names too: ``exp`` (= cost-utility), ``exp+llm`` (= l3mvn-ff) and
``near+llm``; ground truth vs noisy segmentation is ``--seg-noise``. ``teleop`` is the map-based agent
with a person choosing each action (the dashboard's Drive keys); it refuses to act on its own.
"""

from __future__ import annotations

from l3mvn.agent.modular import MapAgent
from l3mvn.agent.modular.teleop import TeleopAgent
from l3mvn.core.config import Config, PolicyConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.agent.policies.global_policies import GLOBAL_POLICIES, RandomSample
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy
from l3mvn.agent.policies.oracle_frontier import FrontierOracle
from l3mvn.world.baselines import ObjectDistances, OraclePolicy, RandomWalkPolicy
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import ObjectNavTask

DIRECT_POLICIES = ("oracle", "random-walk")
# name -> (default scorer, exploration score, paradigm)
LANGUAGE_POLICIES = {
    "l3mvn-zs": ("roomtype", "cost-utility", "zero-shot"),
    "l3mvn-ff": ("feedforward", "cost-utility", "feedforward"),
    "near+llm": ("feedforward", "nearest", "feedforward"),
}
ALIASES = {"exp": "cost-utility", "exp+llm": "l3mvn-ff"}
TELEOP = "teleop"  # the map-based agent driven by hand from the dashboard (l3mvn.agent.modular.teleop)
POLICY_NAMES: tuple[str, ...] = (
    DIRECT_POLICIES + tuple(GLOBAL_POLICIES) + ("oracle-frontier",) + tuple(LANGUAGE_POLICIES) + tuple(ALIASES)
    + (TELEOP,)
)


def check_policy(name: str) -> str:
    if name not in POLICY_NAMES:
        raise L3MVNError(f"unknown policy {name!r}; valid policies: {', '.join(POLICY_NAMES)}")
    return name


def check_options(name: str, options: PolicyConfig) -> None:
    """Refuse settings the policy would ignore (they would still change the config hash)."""
    resolved = ALIASES.get(check_policy(name), name)
    language = tuple(LANGUAGE_POLICIES) + tuple(a for a, t in ALIASES.items() if t in LANGUAGE_POLICIES)
    if resolved not in LANGUAGE_POLICIES and (options.scorer is not None or options.selection != "paper"):
        raise L3MVNError(f"--scorer and --selection apply to language policies only ({', '.join(language)}), not {name!r}")
    if resolved in DIRECT_POLICIES and options.seg_noise:
        raise L3MVNError(f"--seg-noise applies to map-based policies; {name!r} does not read the semantic frames")


def make_policy(name: str, env: BuiltinSimulator, task: ObjectNavTask, config: Config, seed: int = 0):
    """A fresh policy ``name`` for ``env`` under ``config`` (its ``policy`` section must suit the
    policy, see ``check_options``); only the ground-truth policies read ``task``."""
    check_options(name, config.policy)
    name = ALIASES.get(name, name)
    if name == "oracle":
        return OraclePolicy(env, task)
    if name == "random-walk":
        return RandomWalkPolicy(seed)
    if name == TELEOP:  # frontiers scored by cost-utility, so the page shows what the agent would do
        return TeleopAgent(GLOBAL_POLICIES["cost-utility"](), env.categories, config, seed)
    if name in LANGUAGE_POLICIES:
        scorer, exploration, paradigm = LANGUAGE_POLICIES[name]
        p = config.policy
        global_policy = LanguageFrontierPolicy(name, p.scorer or scorer, exploration, p.selection, paradigm,
                                               (p.bound_low, p.bound_high), p.head,
                                               config.frontiers.cu_lambda)
    elif name == "oracle-frontier":
        global_policy = FrontierOracle(ObjectDistances(task))
    elif name == RandomSample.name:
        global_policy = RandomSample(config.planner.obstacle_dilation_cells)
    else:
        global_policy = GLOBAL_POLICIES[name]()
    return MapAgent(global_policy, env.categories, config, seed)
