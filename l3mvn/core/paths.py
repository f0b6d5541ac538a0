"""Paths that come from data files and flags, kept inside the folder they belong to.

A name read from a file or typed as a flag (a split, a scene key) becomes a folder or file name, and
a path read from a data file (a scan's ``scene_id``) is looked up under a root the user chose. Neither
may reach outside: a ``..``, an absolute path or a separator in a name would read or write anywhere.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path, PurePath

from l3mvn.core.errors import L3MVNError

# The data shipped inside the package (room contents, language statistics and heads).
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "data"
# Where a source checkout finds the project's shared research data: ``<repo>/../shared``.
SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
CACHE_ENV = "L3MVN_CACHE"  # overrides the cache folder (default ~/.cache/l3mvn)


def cache_root() -> Path:
    """The folder of what is derived once and kept (converted LLMs and their scores, decoded maps)."""
    return Path(os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "l3mvn")


def plain_name(value: object, what: str, example: str) -> str:
    """``value`` when it can be one file or folder name (printable, no '/' or '\\', not '.' or '..');
    else a one-line L3MVNError naming ``what`` and an ``example`` of a valid one."""
    if (
        not isinstance(value, str)
        or not value
        or not value.isprintable()
        or any(c in value for c in "/\\")
        or value in (".", "..")
    ):
        shown = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
        raise L3MVNError(
            f"{what} must be a plain name such as {example!r} (no '/' or '\\', not '.' or '..'), got {shown}"
        )
    return value


def relative_parts(path: str, what: str, root: object) -> tuple[str, ...]:
    """The parts of ``path`` (from a data file) that are looked up under ``root``: an absolute path
    loses its anchor (it is matched by its tail), and a ``..`` part, which could climb out of the
    root, is a one-line L3MVNError naming the root."""
    pure = PurePath(path)
    parts = pure.parts[1:] if pure.anchor else pure.parts
    if ".." in parts or not parts:
        raise L3MVNError(f"{what} {path!r} would leave {root}: it must name a file inside it (no '..' parts)")
    return parts


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, read in blocks: what names a model file or ties a file to another."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            digest.update(block)
    return digest.hexdigest()
