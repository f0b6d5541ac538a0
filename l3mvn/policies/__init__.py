"""Policies by name: each takes the environment it will act in and returns an object with
``reset(episode)`` and ``act(observation) -> Action | Decision``.

``oracle`` and ``random-walk`` act directly; every other name is the map-based agent with a different
global policy (only the choice of long-term goal differs between them). ``oracle-frontier`` is that
agent with a global policy that reads the ground truth: the ceiling for any frontier prior. The
paper's Table II ablations are names too: ``exp`` (= cost-utility), ``exp+llm`` (= l3mvn-ff) and
``near+llm``; ground truth vs noisy segmentation is ``--seg-noise``.
"""

from __future__ import annotations

from dataclasses import dataclass

from l3mvn.errors import L3MVNError
from l3mvn.policies.global_policies import GLOBAL_POLICIES
from l3mvn.policies.language_policy import SELECTIONS
from l3mvn.policies.oracle import FrontierOracle, OraclePolicy, RandomWalkPolicy
from l3mvn.sim.simulator import BuiltinSimulator

DIRECT_POLICIES = ("oracle", "random-walk")
# name -> (default scorer, exploration score, paradigm)
LANGUAGE_POLICIES = {
    "l3mvn-zs": ("roomtype", "cost-utility", "zero-shot"),
    "l3mvn-ff": ("feedforward", "cost-utility", "feedforward"),
    "near+llm": ("feedforward", "nearest", "feedforward"),
}
ALIASES = {"exp": "cost-utility", "exp+llm": "l3mvn-ff"}
POLICY_NAMES: tuple[str, ...] = (
    DIRECT_POLICIES + tuple(GLOBAL_POLICIES) + ("oracle-frontier",) + tuple(LANGUAGE_POLICIES) + tuple(ALIASES)
)


@dataclass(frozen=True)
class PolicyOptions:
    """Settings that change what a policy does (hashed into every result line)."""

    scorer: str | None = None  # language policies: override the default scorer
    selection: str = "paper"  # language policies: "paper" bound rule or "official_code" thresholds
    seg_noise: float = 0.0  # map-based policies: perception errors (see l3mvn.perception)

    def __post_init__(self) -> None:
        if self.selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {self.selection!r}; valid: {', '.join(SELECTIONS)}")
        if not 0.0 <= self.seg_noise <= 1.0:
            raise L3MVNError(f"--seg-noise must lie in [0, 1], got {self.seg_noise}")


def check_policy(name: str) -> str:
    if name not in POLICY_NAMES:
        raise L3MVNError(f"unknown policy {name!r}; valid policies: {', '.join(POLICY_NAMES)}")
    return name


def check_options(name: str, options: PolicyOptions) -> None:
    """Refuse settings the policy would ignore (they would still change the config hash)."""
    resolved = ALIASES.get(check_policy(name), name)
    language = tuple(LANGUAGE_POLICIES) + tuple(a for a, t in ALIASES.items() if t in LANGUAGE_POLICIES)
    if resolved not in LANGUAGE_POLICIES and (options.scorer is not None or options.selection != "paper"):
        raise L3MVNError(f"--scorer and --selection apply to language policies only ({', '.join(language)}), not {name!r}")
    if resolved in DIRECT_POLICIES and options.seg_noise:
        raise L3MVNError(f"--seg-noise applies to map-based policies; {name!r} does not read the semantic frames")


def make_policy(name: str, env: BuiltinSimulator, seed: int = 0, options: PolicyOptions | None = None,
                agent_cfg=None):
    """A fresh policy for ``env``. ``agent_cfg`` (an AgentConfig) applies to map-based policies."""
    from l3mvn.agent import AgentConfig, MapAgent
    from l3mvn.policies.language_policy import LanguageFrontierPolicy

    options = options or PolicyOptions()
    check_options(name, options)
    name = ALIASES.get(name, name)
    if name == "oracle":
        return OraclePolicy(env)
    if name == "random-walk":
        return RandomWalkPolicy(seed)
    if name in LANGUAGE_POLICIES:
        scorer, exploration, paradigm = LANGUAGE_POLICIES[name]
        global_policy = LanguageFrontierPolicy(name, options.scorer or scorer, exploration, options.selection, paradigm)
    elif name == "oracle-frontier":
        global_policy = FrontierOracle(env)
    else:
        global_policy = GLOBAL_POLICIES[name]()
    if options.seg_noise:
        import dataclasses

        agent_cfg = dataclasses.replace(agent_cfg or AgentConfig(), seg_noise=options.seg_noise)
    return MapAgent(global_policy, env.categories, env.cfg, agent_cfg, seed)
