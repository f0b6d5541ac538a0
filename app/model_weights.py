"""Which language scorers can load here, decided from the disk alone (never the network).

A scorer whose weights are missing would make ``transformers`` try the model hub; offline that is a
minute of silent retries with the agent frozen. The dashboard asks this module first, shows those
scorers as unavailable with the reason, and refuses them at once.
"""

from __future__ import annotations

import inspect
from pathlib import Path

from l3mvn.agent.language import scorer_names
from l3mvn.agent.language.llm import llm_problem
from l3mvn.agent.language.models import resolve
from l3mvn.agent.language.scorers import Scorer
from l3mvn.core.config.policy import LLM_SCORER
from l3mvn.core.errors import L3MVNError


def scorer_problems() -> dict[str, str]:
    """{scorer name: why it cannot load here} for every registered scorer whose weights are not on disk."""
    names = set(scorer_names())
    problems: dict[str, str] = {}
    for cls in _subclasses(Scorer):
        name = getattr(cls, "name", "")
        model = _default_model(cls)
        if name in names and model is not None:
            problem = llm_problem(model) if name == LLM_SCORER else model_problem(model)
            if problem is not None:
                problems[name] = problem
    return dict(sorted(problems.items()))


def model_problem(model: str) -> str | None:
    """None when ``model`` (a local directory or a hub id) has its files on this disk, else why not."""
    try:
        source = resolve(model)
    except L3MVNError as exc:
        return str(exc)
    if Path(source).is_dir():
        return None if (Path(source) / "config.json").exists() else f"{source} has no config.json"
    from huggingface_hub import try_to_load_from_cache

    if isinstance(try_to_load_from_cache(source, "config.json"), str):
        return None
    return f"{model} is not on disk (huggingface-cli download {model})"


def _subclasses(cls: type) -> list[type]:
    found = []
    for sub in cls.__subclasses__():
        found += [sub, *_subclasses(sub)]
    return found


def _default_model(cls: type) -> str | None:
    """The ``model`` a scorer loads when built by name (its own or an ancestor's default), if any."""
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        param = inspect.signature(init).parameters.get("model") if init is not None else None
        if param is not None and isinstance(param.default, str):
            return param.default
    return None
