"""A researcher's own policies and scorers, found in the packages they installed (Python entry points).

A package registers under a group in its own ``pyproject.toml``, as pytest and rerun plugins do::

    [project.entry-points."l3mvn.policies"]
    my-policy = "my_package.policy:SPEC"

Each entry point is loaded once per process and checked with ``accept``. One that cannot be loaded or
is not what the group expects is left out with a one-line warning naming it, so a broken plugin never
takes the built-in ones down; asking for it by name says why it is missing.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from l3mvn.core.errors import first_line

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Found:
    """What a group's entry points gave: the accepted objects by name, and why the others were left out."""

    objects: dict[str, Any] = field(default_factory=dict)
    problems: dict[str, str] = field(default_factory=dict)


def discover(group: str, accept: Callable[[str, Any], str | None], taken: frozenset[str] = frozenset()) -> Found:
    """The objects of the entry points in ``group``. ``accept(name, obj)`` returns why ``obj`` is not
    what the group expects (None: it is); a name in ``taken`` (a built-in's) is refused."""
    found = Found()
    for point in sorted(entry_points(group=group), key=lambda p: p.name):
        where = f"{point.value} ({point.dist.name if point.dist else 'unknown package'})"
        if point.name in taken or point.name in found.objects:
            problem: str | None = f"the name {point.name!r} is taken by a built-in or another plugin"
        else:
            try:
                obj = point.load()
            except Exception as exc:  # any import error of someone else's package: report, skip
                problem = f"cannot be loaded: {type(exc).__name__}: {first_line(exc)}"
            else:
                problem = accept(point.name, obj)
                if problem is None:
                    found.objects[point.name] = obj
                    continue
        found.problems[point.name] = f"{group} plugin {point.name!r} from {where} {problem}"
        log.warning("%s: left out", found.problems[point.name])
    return found
