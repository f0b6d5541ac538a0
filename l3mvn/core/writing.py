"""Files written whole or not at all: a full disk, a quota or a bad path is an error, never a success.

Writers that produce a file in one go (a report, a map, an episode file, an image, a video) write it
through a temporary file beside the target, flush it to the disk (``fsync``: a full disk or a quota
often reports only then), and rename it over the target only when every byte is there. On any
failure the temporary file is removed, an existing target is left as it was, and the OSError becomes
a one-line L3MVNError naming what was being written and why. A target that exists and is not a
regular file (``/dev/full``, a FIFO) is written in place: replacing a device node would be worse.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import BinaryIO

from l3mvn.core.errors import L3MVNError


def make_folder(path: str | Path, what: str) -> Path:
    """``path`` as a folder that exists (created with its parents), or a one-line L3MVNError: a file
    in the way, no permission, a full disk."""
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise L3MVNError(f"{what} {folder} is a file, not a folder") from None
    except OSError as exc:
        raise _failed(what, folder, exc) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise L3MVNError(f"{what} {folder}: no permission to write there")
    return folder


def write_file(path: str | Path, data: bytes | str, what: str) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` whole or not at all; returns ``path``."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    with replacing(path, what) as fh:
        fh.write(payload)
    return Path(path)


@contextmanager
def replacing(path: str | Path, what: str) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through (see the module docstring)."""
    with replacing_path(path, what) as temporary:
        try:
            with open(temporary, "wb") as fh:
                yield fh
        except OSError as exc:
            raise _failed(what, Path(path), exc) from None


@contextmanager
def replacing_path(path: str | Path, what: str, *, check: Callable[[Path], None] | None = None) -> Iterator[Path]:
    """A temporary path for a writer that needs a file name (a video encoder): fill it, and on leaving
    it is checked (``check`` may raise an L3MVNError of its own), synced and renamed over ``path``."""
    target = Path(path)
    in_place = _special(target)
    temporary = (
        target if in_place else target.with_name(f".{target.name}.partial-{secrets.token_hex(4)}{target.suffix}")
    )
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _failed(what, target, exc) from None
    try:
        yield temporary
        if check is not None:
            check(temporary)
        if not in_place:  # a device reports its failures on write; a FIFO has nothing to sync
            _sync(temporary)
            os.replace(temporary, target)
            _sync_folder(target.parent)
    except OSError as exc:
        raise _failed(what, target, exc) from None
    finally:
        if not in_place:
            with suppress(OSError):
                temporary.unlink()


def _special(path: Path) -> bool:
    """An existing target that is not a regular file (a device, a FIFO): written in place."""
    try:
        return not stat.S_ISREG(path.stat().st_mode) and not path.is_dir()
    except OSError:
        return False


def _sync(path: Path) -> None:
    """Flush the regular file ``path``'s bytes to the disk."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_folder(folder: Path) -> None:
    """Make the rename itself durable (where the filesystem lets a folder be synced)."""
    with suppress(OSError):
        fd = os.open(folder, os.O_RDONLY | os.O_CLOEXEC)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _failed(what: str, path: Path, exc: OSError) -> L3MVNError:
    reason = exc.strerror or str(exc)
    if isinstance(exc, IsADirectoryError):
        reason = "it is a folder"
    elif isinstance(exc, NotADirectoryError):
        reason = "a part of the path is a file, not a folder"
    return L3MVNError(f"cannot write {what} {path}: {reason}; nothing was written there")
