"""Policies by name: each is a ``PolicySpec`` that builds an object with ``reset(episode)`` and
``act(observation) -> Action | Decision``.

The built-in policies are registered here: ``oracle`` and ``random-walk`` (world-side baselines that
act directly), and the map-based agent with different global policies (only the choice of long-term
goal differs between them). ``oracle-frontier`` is that agent handed the world's ground-truth
distances: the ceiling for any frontier prior. The paper's Table II ablations are names too: ``exp``
(= cost-utility), ``exp+llm`` (= l3mvn-ff) and ``near+llm``. ``teleop`` is the map-based agent with a
person choosing each action (the dashboard's Drive keys); it refuses to act on its own.

A researcher's own policy registers from its own package under the entry-point group
``l3mvn.policies`` (see ``l3mvn.core.plugins``): the entry point names a ``PolicySpec``. It then runs in
``l3mvn eval --policy NAME`` and appears in the dashboard like a built-in one.

A spec sees only what its kind may: an agent gets the categories, the config tree and a seed; only a
spec marked ``ground_truth`` is handed the environment and the task.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

from l3mvn.agent.modular import MapAgent
from l3mvn.agent.modular.teleop import TeleopAgent
from l3mvn.agent.policies.global_policies import CostUtility, GlobalPolicy, NearestFrontier, RandomSample
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy, shared_scorer
from l3mvn.agent.policies.oracle_frontier import FrontierOracle
from l3mvn.core.config import Config, PolicyConfig, PotentialConfig
from l3mvn.core.config.policy import HEAD_SCORER, LLM_SCORER
from l3mvn.core.errors import L3MVNError
from l3mvn.core.plugins import discover
from l3mvn.run.session import Policy
from l3mvn.world.baselines import ObjectDistances, OraclePolicy, RandomWalkPolicy
from l3mvn.world.sim.base import Environment, MotionModel
from l3mvn.world.task import ObjectNavTask

PLUGIN_GROUP = "l3mvn.policies"
TELEOP = "teleop"  # the built-in policy a person drives from the dashboard


@dataclass(frozen=True)
class PolicyContext:
    """What a spec builds a policy from. ``env`` and ``task`` are set only for a ``ground_truth`` spec."""

    categories: tuple[str, ...]
    config: Config
    seed: int
    env: Environment | None = None
    task: ObjectNavTask | None = None


@dataclass(frozen=True)
class Language:
    """A language policy's defaults: the scorer it reads, the exploration score it fuses with, and
    the paradigm of the paper it follows (zero-shot or feed-forward); ``fallback``: the scorer it reads
    instead where its own cannot load (no LLM installed), said in a notice."""

    scorer: str
    exploration: str
    paradigm: str
    fallback: str | None = None


@dataclass(frozen=True)
class PolicySpec:
    """A policy by name. ``map_based``: it maps the semantic frames (``--seg-noise`` applies; the
    dashboard draws its map and frontiers); ``language``: it scores frontiers with a language scorer
    (``--scorer``, ``--selection`` and ``--head`` apply); ``driven``: a person chooses its actions, so it
    never runs by itself (no eval, no comparison); ``ground_truth``: it reads the world, so it is built
    with the environment and the task; ``same_as``: another name for that policy (the paper's);
    ``prior``: it scores frontiers with a learned prior that is no language model (``--set poni.*``
    applies; the Language folder shows its scores as it shows a language policy's); ``ready``: checks
    before the first episode that what it reads loads (a missing checkpoint is one error, not one per
    episode)."""

    name: str
    build: Callable[[PolicyContext], Policy]
    summary: str
    map_based: bool = True
    language: Language | None = None
    driven: bool = False
    ground_truth: bool = False
    same_as: str | None = None
    prior: bool = False
    ready: Callable[[Config], None] | None = None  # loads what the policy reads, or says in one line why not


def _map_agent(global_policy: Callable[[PolicyContext], GlobalPolicy]) -> Callable[[PolicyContext], Policy]:
    def build(ctx: PolicyContext) -> Policy:
        return MapAgent(global_policy(ctx), ctx.categories, ctx.config, ctx.seed)

    return build


def _language(name: str, language: Language) -> Callable[[PolicyContext], Policy]:
    def policy(ctx: PolicyContext) -> GlobalPolicy:
        p = ctx.config.policy
        if _reads_map_head(name, p):
            return _map_head_policy(name, language, ctx.config)
        return LanguageFrontierPolicy(
            name,
            scorer_of(name, p) or language.scorer,
            language.exploration,
            p.selection,
            language.paradigm,
            (p.bound_low, p.bound_high),
            p.head,
            ctx.config.frontiers.cu_lambda,
            (p.llm, p.llm_prompt),
            p.embedder,
        )

    return _map_agent(policy)


def _oracle(ctx: PolicyContext) -> Policy:
    if not isinstance(ctx.env, MotionModel):
        raise L3MVNError(
            f"policy 'oracle' plans on the environment's motion model, and a {type(ctx.env).__name__} "
            "has none (forward_result): run it on the built-in simulator or the habitat bridge"
        )
    assert ctx.task is not None
    return OraclePolicy(ctx.env, ctx.task)


def _oracle_frontier(ctx: PolicyContext) -> GlobalPolicy:
    assert ctx.task is not None
    return FrontierOracle(ObjectDistances(ctx.task))


@cache
def _potential_model(checkpoint: str | None, cfg: PotentialConfig):  # -> PotentialModel (torch loads on first use)
    from l3mvn.agent.potentials import PotentialModel

    return PotentialModel.load(checkpoint, cfg)


def _reads_map_head(name: str, options: PolicyConfig) -> bool:
    """Whether policy ``name`` scores with the feed-forward scorer and its head is a map head."""
    if scorer_of(name, options) != HEAD_SCORER or options.head is None:
        return False
    from l3mvn.agent.potentials.language_map import map_head_file

    return map_head_file(options.head) is not None


@cache
def _map_head(file: str, version: int, poni_checkpoint: str):  # -> LanguageMapHead (torch loads on first use)
    """The head at ``file`` as of ``version`` (its mtime: a retrained file is read anew)."""
    from l3mvn.agent.potentials.language_map import LanguageMapHead

    return LanguageMapHead.load(file, poni_checkpoint)


def _map_head_policy(name: str, language: Language, config: Config) -> GlobalPolicy:
    """PONI's policy with the map head's words: what the feed-forward policies become with ``--head map``."""
    from l3mvn.agent.potentials import PotentialPolicy
    from l3mvn.agent.potentials.language_map import map_head_file

    p = config.policy
    if language.exploration != "cost-utility":
        raise L3MVNError(
            f"the map head adds to PONI's totals, which carry cost-utility's bonuses: policy {name!r} fuses "
            f"with {language.exploration!r}; use it with l3mvn-ff"
        )
    if p.selection != PolicyConfig.selection or p.embedder is not None:
        raise L3MVNError(
            "the map head chooses by PONI's least total and reads the embedder it was trained with: "
            "--selection and --embedder apply to the object-list heads (frontiers, rooms and their bags)"
        )
    model = _potential_model(config.poni.checkpoint, config.poni)
    file = map_head_file(p.head)
    assert file is not None  # ``_reads_map_head`` said so
    version = file.stat().st_mtime_ns if file.is_file() else 0  # a missing file: the loader names it
    words = _map_head(str(file), version, model.source)
    return PotentialPolicy(model, config.poni, config.frontiers.cu_lambda, words, name)


def _head_ready(name: str) -> Callable[[Config], None]:
    """Where policy ``name`` scores with the feed-forward scorer, load its head and embedder once:
    an unknown head file or an embedder without a head is one line before any episode runs."""

    def ready(config: Config) -> None:
        p = config.policy
        if _reads_map_head(name, p):
            spec = policy_spec(name)
            assert spec.language is not None  # only language specs are made ready with this
            _map_head_policy(name, spec.language, config)
        elif scorer_of(name, p) == HEAD_SCORER:
            shared_scorer(HEAD_SCORER, p.head, embedder=p.embedder)

    return ready


def _poni_ready(config: Config) -> None:
    from l3mvn.agent.potentials import PotentialPolicy

    PotentialPolicy(_potential_model(config.poni.checkpoint, config.poni), config.poni, config.frontiers.cu_lambda)


def _poni(ctx: PolicyContext) -> GlobalPolicy:
    from l3mvn.agent.potentials import PotentialPolicy

    cfg = ctx.config.poni
    return PotentialPolicy(_potential_model(cfg.checkpoint, cfg), cfg, ctx.config.frontiers.cu_lambda)


def _teleop(ctx: PolicyContext) -> Policy:
    # Frontiers scored by cost-utility, so the page shows what the agent would do.
    return TeleopAgent(CostUtility(), ctx.categories, ctx.config, ctx.seed)


_ZERO_SHOT = Language(LLM_SCORER, "cost-utility", "zero-shot", fallback="roomtype")
_FEED_FORWARD = Language("feedforward", "cost-utility", "feedforward")
_NEAR_FEED_FORWARD = Language("feedforward", "nearest", "feedforward")

BUILT_IN: tuple[PolicySpec, ...] = (
    PolicySpec(
        "oracle",
        _oracle,
        "ground-truth shortest path: a check of the simulator and the metrics",
        map_based=False,
        ground_truth=True,
    ),
    PolicySpec(
        "random-walk",
        lambda ctx: RandomWalkPolicy(ctx.seed),
        "uniformly random actions (the paper's baseline)",
        map_based=False,
    ),
    PolicySpec("frontier", _map_agent(lambda ctx: NearestFrontier()), "the nearest frontier (Yamauchi)"),
    PolicySpec(
        "cost-utility",
        _map_agent(lambda ctx: CostUtility()),
        "the frontier with the best size for its distance (the paper's Exp)",
    ),
    PolicySpec(
        "random-sample",
        _map_agent(lambda ctx: RandomSample(ctx.config.planner.obstacle_dilation_cells)),
        "a random unexplored cell of the local map",
    ),
    PolicySpec(
        "oracle-frontier",
        _map_agent(_oracle_frontier),
        "the frontier nearest the goal by the ground truth: the ceiling for any frontier prior",
        ground_truth=True,
    ),
    PolicySpec(
        "poni",
        _map_agent(_poni),
        "the frontier nearest the goal by PONI's potentials, predicted from the partial map (Table I's PONI)",
        prior=True,
        ready=_poni_ready,
    ),
    PolicySpec(
        "l3mvn-zs",
        _language("l3mvn-zs", _ZERO_SHOT),
        "zero-shot language scores fused with cost-utility (the paper's L3MVN-ZS)",
        language=_ZERO_SHOT,
        ready=_head_ready("l3mvn-zs"),
    ),
    PolicySpec(
        "l3mvn-ff",
        _language("l3mvn-ff", _FEED_FORWARD),
        "the feed-forward head's scores fused with cost-utility (the paper's L3MVN-FF)",
        language=_FEED_FORWARD,
        ready=_head_ready("l3mvn-ff"),
    ),
    PolicySpec(
        "near+llm",
        _language("near+llm", _NEAR_FEED_FORWARD),
        "the feed-forward head's scores fused with the nearest frontier (the paper's Table II)",
        language=_NEAR_FEED_FORWARD,
        ready=_head_ready("near+llm"),
    ),
    PolicySpec(
        "exp",
        _map_agent(lambda ctx: CostUtility()),
        "= cost-utility (the paper's Table II name)",
        same_as="cost-utility",
    ),
    PolicySpec(
        "exp+llm",
        _language("l3mvn-ff", _FEED_FORWARD),
        "= l3mvn-ff (the paper's Table II name)",
        language=_FEED_FORWARD,
        same_as="l3mvn-ff",
        ready=_head_ready("l3mvn-ff"),
    ),
    PolicySpec(TELEOP, _teleop, "the map-based agent driven by hand in the dashboard", driven=True),
)


@cache
def _registry() -> tuple[dict[str, PolicySpec], dict[str, str]]:
    """Built-ins and plugins by name (loaded once per process), and why any plugin was left out."""
    specs = {spec.name: spec for spec in BUILT_IN}

    def accept(name: str, obj: object) -> str | None:
        if not isinstance(obj, PolicySpec):
            return f"is a {type(obj).__name__}, not an l3mvn.run.registry.PolicySpec"
        if obj.name != name:
            return f"names its spec {obj.name!r}: the entry point and the spec must have one name"
        return None

    found = discover(PLUGIN_GROUP, accept, frozenset(specs))
    return {**specs, **found.objects}, found.problems


def policies() -> dict[str, PolicySpec]:
    """Every policy by name: the built-in ones, then the installed plugins'."""
    return dict(_registry()[0])


def policy_names(*, driven: bool = True, same: bool = True) -> tuple[str, ...]:
    """Policy names; ``driven=False`` leaves out those a person drives, ``same=False`` the other names."""
    return tuple(
        name for name, spec in _registry()[0].items() if (driven or not spec.driven) and (same or spec.same_as is None)
    )


def policy_spec(name: str) -> PolicySpec:
    """The spec of ``name``; an unknown name is a one-line error naming the valid ones (and a plugin
    of that name that could not be loaded, with why)."""
    specs, problems = _registry()
    if name not in specs:
        why = f" ({problems[name]})" if name in problems else ""
        raise L3MVNError(f"unknown policy {name!r}{why}; valid policies: {', '.join(specs)}")
    return specs[name]


def names_where(test: Callable[[PolicySpec], bool]) -> tuple[str, ...]:
    """The names of the policies whose spec passes ``test`` (e.g. the language ones, for a message)."""
    return tuple(name for name, spec in _registry()[0].items() if test(spec))


def keeps_map(name: str) -> bool:
    """Whether the policy ``name`` maps what it sees (an unknown name: False)."""
    spec = _registry()[0].get(name)
    return spec is not None and spec.map_based


def reads_language(name: str) -> bool:
    """Whether the policy ``name`` scores frontiers with a language scorer (an unknown name: False)."""
    spec = _registry()[0].get(name)
    return spec is not None and spec.language is not None


def scores_frontiers(name: str) -> bool:
    """Whether the policy ``name`` scores frontiers with a prior, a language scorer or another learned
    one (an unknown name: False): what the dashboard's Language folder shows."""
    spec = _registry()[0].get(name)
    return spec is not None and (spec.language is not None or spec.prior)


def language_policies() -> tuple[str, ...]:
    """The language policies by their own names (the paper's other names left out), for messages."""
    return names_where(lambda spec: spec.language is not None and spec.same_as is None)


def scorer_choice(name: str, options: PolicyConfig) -> tuple[str | None, str | None]:
    """The language scorer a policy ``name`` built with ``options`` reads (``--scorer`` when given, else
    the policy's own, else its fallback where its own cannot load here), and why it is the fallback
    (None when it is not); (None, None) for a policy that reads no language model."""
    language = policy_spec(name).language
    if language is None:
        return None, None
    if options.scorer is not None:
        return options.scorer, None
    problem = None
    if language.scorer == LLM_SCORER:
        from l3mvn.agent.language.llm import llm_problem  # the language package loads torch: only here

        problem = llm_problem(options.llm)
    if problem is not None and options.llm != PolicyConfig.llm:  # a model asked for by name: no fallback
        raise L3MVNError(problem)
    if problem is None or language.fallback is None:
        return language.scorer, None
    return language.fallback, (f"policy {name!r} scores with {language.fallback!r} instead of an LLM: {problem}")


def scorer_of(name: str, options: PolicyConfig) -> str | None:
    """The language scorer a policy ``name`` built with ``options`` reads (``scorer_choice``)."""
    return scorer_choice(name, options)[0]


def with_scorer(name: str, config: Config) -> Config:
    """``config`` with the scorer a language policy will read written into its policy section, so the
    hash and every result line name it (what the policy falls back to depends on what is installed)."""
    scorer = scorer_of(name, config.policy)
    if scorer is None or config.policy.scorer == scorer:
        return config
    return dataclasses.replace(config, policy=dataclasses.replace(config.policy, scorer=scorer))


def check_policy(name: str) -> str:
    policy_spec(name)
    return name


def check_options(name: str, options: PolicyConfig) -> None:
    """Refuse settings the policy would ignore (they would still change the config hash)."""
    spec = policy_spec(name)
    if spec.language is None and (options.scorer is not None or options.selection != "paper"):
        language = ", ".join(n for n, s in _registry()[0].items() if s.language is not None)
        raise L3MVNError(f"--scorer and --selection apply to language policies only ({language}), not {name!r}")
    llm_settings = (options.llm, options.llm_prompt) != (PolicyConfig.llm, PolicyConfig.llm_prompt)
    if llm_settings and scorer_of(name, options) != LLM_SCORER:
        raise L3MVNError(
            f"--llm and --prompt apply to the {LLM_SCORER} scorer only; policy {name!r} scores with "
            f"{scorer_of(name, options) or 'no language model'} (add --scorer {LLM_SCORER})"
        )
    if options.embedder is not None and scorer_of(name, options) != HEAD_SCORER:
        raise L3MVNError(
            f"--embedder applies to the {HEAD_SCORER} scorer only; policy {name!r} scores with "
            f"{scorer_of(name, options) or 'no language model'}"
        )
    if not spec.map_based and options.seg_noise:
        raise L3MVNError(f"--seg-noise applies to map-based policies; {name!r} does not read the semantic frames")


def check_ready(name: str, config: Config) -> None:
    """Refuse, in one line, a policy whose model or checkpoint under ``config`` does not load."""
    ready = policy_spec(name).ready
    if ready is not None:
        ready(config)


def make_policy(name: str, env: Environment, task: ObjectNavTask, config: Config, seed: int = 0) -> Policy:
    """A fresh policy ``name`` for ``env`` under ``config`` (its ``policy`` section must suit the
    policy, see ``check_options``); only a ground-truth spec is handed ``env`` and ``task``."""
    check_options(name, config.policy)
    spec = policy_spec(name)
    world = spec.ground_truth
    return spec.build(
        PolicyContext(tuple(env.categories), config, seed, env=env if world else None, task=task if world else None)
    )
