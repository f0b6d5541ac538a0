"""Result files: one JSON line per finished episode, appended, read back for ``--resume``.

The ``--out`` file is held by one run at a time (``ResultWriter``):

* **Lock.** An exclusive ``flock`` on the file itself for the whole run, so two evals never interleave
  or duplicate rows in one file; a second run is refused before it writes a byte. The kernel drops
  the lock when the holder exits, however it exits (crash, ``kill -9``), so a lock is never stale.
* **Torn tail.** A line is appended with ``write`` calls of the whole encoded line; if one fails
  part-way (disk full) the file is cut back to where the line began, so this program never leaves a
  partial line. A file can still end without a newline (a killed editor, a machine that crashed
  before its disk caught up, a full disk under an older version). Before the first append that tail is dealt with, so
  the next row is never glued to it: a last line that is a whole JSON object only lacks its newline,
  which is added; anything else is a torn row: it is copied to ``<file>.torn-<time>`` beside the
  file, then cut off, so the file stays valid JSON lines, no byte is lost, and the torn row's
  episode is run again by ``--resume``.
* **Validation.** A row is used (skipped by ``--resume``, counted in the summary) only when it holds
  every field the summary reads, with the right type (``ROW_SCHEMA``); any other line of this run's
  policy and config is reported and its episode runs again, never a crash.

This module owns the format: every reader (``--resume``, the dashboard's Results panel, ``export
--results``) reads lines through ``read_result_lines`` and judges rows with ``row_problem``, and the
one writer encodes them with ``encode_row``. Reading streams one line at a time and never trusts the
file: only regular files are opened (a FIFO would block the reader forever), a line longer than
``MAX_LINE_BYTES`` is skipped without being held in memory, and a line that is not UTF-8, not JSON,
nested deeper than ``MAX_DEPTH`` or holding NaN or an infinite number is a problem of its line, never
an exception.
"""

from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import stat
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, BinaryIO

from l3mvn.core.config import SUCCESS_RULES
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.json_values import json_safe
from l3mvn.run.eval.job import is_error_row
from l3mvn.world.task.scoring import FAILURE_CAUSES

_CHUNK = 1 << 16
MAX_LINE_BYTES = 1 << 22  # a row with its config, timings and a traceback is a few KB; beyond this it is no row
MAX_DEPTH = 32  # a row nests its config sections and timings a few levels deep


# --- the row schema ----------------------------------------------------------------------------


def _text(v: Any) -> bool:
    return isinstance(v, str) and v != ""


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


# Every field that --resume, the summary, the dashboard and export read, with the check it must pass
# and what that check expects (for the report). The first three say whose row it is, then the
# metrics, then which episode it was.
ROW_SCHEMA: tuple[tuple[str, Callable[[Any], bool], str], ...] = (
    ("key", _text, "a scene/floor/episode key"),
    ("policy", _text, "a policy name"),
    ("config_hash", _text, "a config hash"),
    ("rule", lambda v: v in SUCCESS_RULES, f"one of {', '.join(SUCCESS_RULES)}"),
    ("goal", _text, "a goal category"),
    ("success", lambda v: _number(v) and v in (0, 1), "0 or 1"),
    ("spl", lambda v: v is None or (_number(v) and 0 <= v <= 1), "a number in [0, 1] or null"),
    ("dtg", lambda v: v is None or (_number(v) and v >= 0), "a number >= 0 or null"),
    ("failure", lambda v: v in FAILURE_CAUSES, "a failure cause (success, false_stop, ...)"),
    ("steps", _count, "a whole number >= 0"),
    ("scene", _text, "a scene name"),
    ("episode_id", _count, "a whole number >= 0"),
)


def row_problem(row: Any, rule: str | None = None) -> str | None:
    """Why ``row`` cannot be counted (its first missing or mistyped field), or None when it can.
    ``rule`` is the run's success rule: a row scored under another one cannot join its summary."""
    if not isinstance(row, dict):
        return f"not a JSON object but {_shown(row)}"
    for name, ok, expected in ROW_SCHEMA:
        if name not in row:
            return f"no {name!r}"
        if not ok(row[name]):
            return f"{name!r} is {_shown(row[name])}, not {expected}"
    if (row["success"] == 1) != (row["failure"] == "success"):
        return f"'success' is {_shown(row['success'])} but 'failure' is {_shown(row['failure'])}"
    if rule is not None and row["rule"] != rule:
        return f"'rule' is {_shown(row['rule'])}, but this config's rule is {rule!r}"
    return None


def _shown(value: Any) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


# --- lines -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ResultLine:
    """One non-blank line of a result file: its JSON value, or why it has none."""

    number: int  # 1-based
    row: Any  # the parsed value (None when ``problem`` is set)
    problem: str | None  # not a JSON value at all: too long, not UTF-8, not JSON, too deep, NaN


def encode_row(row: dict) -> bytes:
    """``row`` as one line of the file. NaN and infinities, which JSON has no words for, are written
    as null, so every reader can read every line this program writes."""
    try:
        text = json.dumps(row, sort_keys=True, allow_nan=False)
    except ValueError:
        text = json.dumps(json_safe(row), sort_keys=True, allow_nan=False)
    return (text + "\n").encode()


def parse_line(line: bytes) -> tuple[Any, str | None]:
    """The JSON value of one line, or (None, why it has none)."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError:
        return None, "not UTF-8 text"
    try:
        value = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except json.JSONDecodeError as exc:
        return None, f"not JSON ({exc.msg} at column {exc.colno})"
    except RecursionError:
        return None, f"nested deeper than {MAX_DEPTH} levels"
    except ValueError as exc:  # NaN, Infinity or a number too large for a float
        return None, str(exc)
    if _depth(value) > MAX_DEPTH:
        return None, f"nested deeper than {MAX_DEPTH} levels"
    return value, None


def _no_constant(name: str) -> None:
    raise ValueError(f"holds {name}, which is not a number JSON allows")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"holds {text[:20]}, a number too large for a float")
    return value


def _depth(value: Any) -> int:
    """How deep lists and objects nest in ``value`` (a scalar is 0), without recursion."""
    deepest, todo = 0, [(value, 1)]
    while todo:
        item, level = todo.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, level)
        if level <= MAX_DEPTH:
            todo.extend((child, level + 1) for child in children)
    return deepest


def read_lines(fh: IO[bytes]) -> Iterator[ResultLine]:
    """Every non-blank line of an open binary file, one at a time (see the module docstring)."""
    number = 0
    while True:
        line = fh.readline(MAX_LINE_BYTES + 1)
        if not line:
            return
        number += 1
        if len(line) > MAX_LINE_BYTES and not line.endswith(b"\n"):
            while (rest := fh.readline(_CHUNK)) and not rest.endswith(b"\n"):
                pass  # the rest of an overlong line is skipped, never held
            yield ResultLine(number, None, f"longer than {MAX_LINE_BYTES >> 20} MiB")
            continue
        if not line.strip():
            continue
        row, problem = parse_line(line)
        yield ResultLine(number, row, problem)


def read_result_lines(path: str | Path) -> Iterator[ResultLine]:
    """The lines of the result file ``path`` (a one-line L3MVNError when it cannot be opened or is
    not a regular file)."""
    with open_regular(Path(path), "results file") as fh:
        yield from read_lines(fh)


def open_regular(path: Path, what: str) -> BinaryIO:
    """``path`` opened for reading when it is a regular file. It is opened without blocking and
    checked before a byte is read: a FIFO or a device would otherwise hang or stream forever."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise L3MVNError(f"{what} {_name(path)} not found") from None
    except OSError as exc:
        raise L3MVNError(f"cannot read {what} {_name(path)}: {_reason(exc)}") from None
    kind = stat.S_IFMT(os.fstat(fd).st_mode)
    if kind != stat.S_IFREG:
        os.close(fd)
        shown = {
            stat.S_IFDIR: "a folder",
            stat.S_IFIFO: "a FIFO",
            stat.S_IFCHR: "a device",
            stat.S_IFBLK: "a device",
            stat.S_IFSOCK: "a socket",
        }.get(kind, "not a regular file")
        raise L3MVNError(f"{what} {_name(path)} is {shown}, not a regular file")
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


@dataclass
class EpisodeLines:
    """The episode rows of a result file, each with its line number, and one problem per line left out."""

    rows: list[tuple[int, dict]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def episode_lines(path: str | Path, *, limit: int | None = None) -> EpisodeLines:
    """Every countable episode row of ``path`` (``row_problem`` is None), at most ``limit`` of them;
    every other line becomes ``"line N: why"`` (an error row says which episode failed and why)."""
    found = EpisodeLines()
    for line in read_result_lines(path):
        problem = line.problem
        if problem is None and isinstance(line.row, dict) and is_error_row(line.row):
            key = line.row.get("key") if _text(line.row.get("key")) else "?"
            reason = _shorter(first_line(str(line.row["error"])))
            problem = f"episode {key} failed to run: {reason}"
        elif problem is None:
            problem = row_problem(line.row)
        if problem is not None:
            found.problems.append(f"line {line.number}: {problem}")
        elif limit is not None and len(found.rows) >= limit:
            found.problems.append(f"line {line.number}: past the first {limit} episodes, not read")
            break
        else:
            found.rows.append((line.number, line.row))
    return found


def _shorter(text: str) -> str:
    return text if len(text) <= 200 else text[:197] + "..."


# --- reading back for --resume -----------------------------------------------------------------


@dataclass
class Previous:
    """What ``--resume`` found in the file for one policy and config: the rows it may keep, and the
    lines it cannot use (``"line N: why"``), whose episodes run again."""

    rows: dict[str, dict] = field(default_factory=dict)
    unusable: list[str] = field(default_factory=list)

    def report(self, path: str | Path) -> str | None:
        """One line for stderr naming how many lines were set aside and the first of them."""
        if not self.unusable:
            return None
        n = len(self.unusable)
        lines = "line cannot" if n == 1 else "lines cannot"
        return f"{_name(Path(path))}: {n} {lines} be used, their episodes run again (first: {self.unusable[0]})"


def previous_rows(lines: Iterable[ResultLine], policy: str, config_hash: str, rule: str) -> Previous:
    """Sort a result file's lines for a resumed run. Rows of another policy or config are left
    alone; error rows are retried silently (that is their purpose); every other line that fails
    ``row_problem`` is listed as unusable. A key finished more than once keeps its last row."""
    found = Previous()
    for line in lines:
        number, row, problem = line.number, line.row, line.problem
        if problem is None:
            if _foreign(row, policy, config_hash) or _retried(row):
                continue
            problem = row_problem(row, rule)
        if problem:
            key = row.get("key") if isinstance(row, dict) and _text(row.get("key")) else None
            found.unusable.append(f"line {number}{f' ({key})' if key else ''}: {problem}")
        else:
            found.rows[row["key"]] = row
    return found


def _retried(row: Any) -> bool:
    """An error row of a known episode: it carries no metrics on purpose and its episode runs again."""
    return isinstance(row, dict) and is_error_row(row) and _text(row.get("key"))


def _foreign(row: Any, policy: str, config_hash: str) -> bool:
    """A row that says it belongs to another policy or config: not this run's business."""
    return (
        isinstance(row, dict)
        and _text(row.get("policy"))
        and _text(row.get("config_hash"))
        and (row["policy"], row["config_hash"]) != (policy, config_hash)
    )


def check_resumable(path: str | Path | None, resume: bool) -> None:
    if resume and not path:
        raise L3MVNError("--resume needs --out FILE (the results to resume from)")


# --- the --out file ----------------------------------------------------------------------------


class ResultWriter:
    """The ``--out`` file of one run, from open to close (see the module docstring): locked, its
    torn tail set aside, read back for ``--resume`` through the same descriptor, appended to one
    whole line at a time. Without a path every method is a no-op, so the caller needs no branch.

    Every failure is an ``L3MVNError`` of one line. A device or pipe (``/dev/null``) is written to
    but never locked, repaired or resumed from: it has no lines to keep.
    """

    def __init__(self, path: str | Path | None) -> None:
        self.path = Path(path) if path else None
        self.repair: str | None = None  # one line for stderr when the tail had to be dealt with
        self._fd: int | None = None
        self._regular = False
        if self.path is not None:
            self._fd = _open(self.path)
            try:
                self._prepare()
            except BaseException:
                self._close_quietly()
                raise

    def _prepare(self) -> None:
        """Lock, check and repair a regular file before anything is read or appended."""
        assert self._fd is not None and self.path is not None  # __init__ opened the file
        try:
            self._regular = stat.S_ISREG(os.fstat(self._fd).st_mode)
            if self._regular:
                _lock(self._fd, self.path)
                _check_looks_like_results(self._fd, self.path)
                self.repair = _repair_tail(self._fd, self.path)
        except OSError as exc:
            raise L3MVNError(f"cannot use --out {_name(self.path)}: {_reason(exc)}") from None

    def __enter__(self) -> ResultWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self._close_quietly()  # the error already on its way says more than a failed close

    def previous(self, policy: str, config_hash: str, rule: str) -> Previous:
        """The rows already in the file for this policy and config (see ``previous_rows``)."""
        if self._fd is None:
            return Previous()
        if not self._regular:
            raise L3MVNError(f"--resume reads its rows back from --out, and {self.path} is not a regular file")
        return previous_rows(self._lines(), policy, config_hash, rule)

    def write(self, row: dict) -> None:
        """Append ``row`` as one line. A write that fails part-way is cut back off the file, so the
        file holds whole lines only and every row written before stays."""
        if self._fd is None:
            return
        data = encode_row(row)
        start, done = None, 0
        try:
            start = os.fstat(self._fd).st_size if self._regular else None
            while done < len(data):
                done += os.write(self._fd, data[done:])
        except BaseException as exc:
            if start is not None:
                self._truncate(start)  # whatever part of this line reached the file, and only that
            if isinstance(exc, OSError):
                raise L3MVNError(
                    f"cannot write to {_name(self.path)}: {_reason(exc)}; the rows written before "
                    "are kept (--resume runs the rest)"
                ) from None
            raise

    def close(self) -> None:
        """Flush the rows to disk and let go of the file (and its lock). A disk that fails only now
        (NFS, a quota) is reported rather than ignored."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        failed = None
        try:
            if self._regular:
                os.fsync(fd)
        except OSError as exc:
            failed = exc
        try:
            os.close(fd)  # closed even when it reports an error: never retried
        except OSError as exc:
            failed = failed or exc
        if failed:
            raise L3MVNError(f"cannot save {_name(self.path)}: {_reason(failed)}")

    def _close_quietly(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            with suppress(OSError):
                os.close(fd)

    def _truncate(self, size: int) -> None:
        assert self._fd is not None  # write cuts back only a file it holds
        try:
            os.ftruncate(self._fd, size)
        except OSError as exc:
            raise L3MVNError(
                f"cannot write to {_name(self.path)} and cannot cut back the partial line it "
                f"left ({_reason(exc)}); the next run sets it aside"
            ) from None

    def _lines(self) -> Iterator[ResultLine]:
        assert self._fd is not None  # previous reads back only a file it holds
        try:
            with os.fdopen(os.dup(self._fd), "rb") as fh:  # the dup shares the lock; closing it keeps it
                fh.seek(0)
                yield from read_lines(fh)
        except OSError as exc:
            raise L3MVNError(f"cannot read {_name(self.path)}: {_reason(exc)}") from None


def _open(path: Path) -> int:
    """Open (creating it and its folder) for reading and appending; every refusal in one line."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise L3MVNError(
            f"cannot create the folder of --out {_name(path)}: {_name(_file_in(path))} is a file, not a folder"
        ) from None
    except OSError as exc:
        raise L3MVNError(f"cannot create the folder of --out {_name(path)}: {_reason(exc)}") from None
    try:
        return os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except IsADirectoryError:
        raise L3MVNError(
            f"--out {_name(path)} is a directory; give a file such as {_name(path / 'results.jsonl')}"
        ) from None
    except OSError as exc:
        raise L3MVNError(f"cannot open --out {_name(path)}: {_reason(exc)}") from None


def _file_in(path: Path) -> Path:
    """The first ancestor of ``path`` that exists as something other than a folder."""
    return next((p for p in path.parents if p.exists() and not p.is_dir()), path.parent)


def _lock(fd: int, path: Path) -> None:
    """Hold the file exclusively until it is closed; refuse at once if another run holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _lock_holder(fd)
        who = f"pid {holder}" if holder else "its lock is held"
        raise L3MVNError(
            f"{_name(path)} is being written by another l3mvn eval ({who}); wait for it to "
            "finish or choose another --out"
        ) from None
    except OSError as exc:
        if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
            raise L3MVNError(f"cannot lock {_name(path)}: {_reason(exc)}") from None
        raise L3MVNError(
            f"{_name(path)} is on a filesystem without file locks; choose an --out on a local disk"
        ) from None


def _lock_holder(fd: int) -> int | None:
    """The pid holding a ``flock`` on ``fd``'s file, read from /proc/locks (Linux); None elsewhere,
    or when the holder is in another pid namespace."""
    st = os.fstat(fd)
    ident = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        table = Path("/proc/locks").read_text()
    except OSError:
        return None
    for line in table.splitlines():
        # "1: FLOCK  ADVISORY  WRITE 29420 fe:00:2146581 0 EOF"; a waiter's line has "->" after "1:"
        fields = line.split()
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[5] == ident and fields[4].isdigit():
            return int(fields[4]) or None
    return None


def _check_looks_like_results(fd: int, path: Path) -> None:
    """Refuse to append to (let alone repair) a file that is not JSON lines: a mistyped --out."""
    if os.fstat(fd).st_size and os.pread(fd, 1, 0) != b"{":
        raise L3MVNError(
            f"--out {_name(path)} is not an l3mvn results file (it does not start with a JSON "
            "row); choose another --out"
        )


def _repair_tail(fd: int, path: Path) -> str | None:
    """Make the file end in a newline before anything is appended (see the module docstring);
    returns one line saying what was done, or None when the file was whole."""
    size = os.fstat(fd).st_size
    if size == 0 or os.pread(fd, 1, size - 1) == b"\n":
        return None
    start = _last_line_start(fd, size)
    tail = os.pread(fd, size - start, start)
    row, problem = parse_line(tail)
    if problem is None and isinstance(row, dict):
        os.write(fd, b"\n")
        return f"{_name(path)}: its last line had no newline (the row is whole); added one"
    kept = _set_aside(path, tail)
    os.ftruncate(fd, start)
    os.fsync(fd)
    return (
        f"{_name(path)} ended in a torn line ({len(tail)} bytes, an interrupted write): moved it to "
        f"{_name(kept)}; --resume runs its episode again"
    )


def _last_line_start(fd: int, size: int) -> int:
    """Offset just past the file's last newline (0 when it has none), reading backwards."""
    end = size
    while end > 0:
        begin = max(0, end - _CHUNK)
        newline = os.pread(fd, end - begin, begin).rfind(b"\n")
        if newline >= 0:
            return begin + newline + 1
        end = begin
    return 0


def _set_aside(path: Path, tail: bytes) -> Path:
    """Copy a torn tail to a new file beside ``path`` (never overwriting one) and sync it, so it is
    on disk before it is cut from the results."""
    stamp = time.strftime("%Y%m%dT%H%M%S")
    for n in range(1, 1000):
        kept = path.with_name(f"{path.name}.torn-{stamp}" + (f"-{n}" if n > 1 else ""))
        try:
            with kept.open("xb") as fh:
                fh.write(tail)
                fh.flush()
                os.fsync(fh.fileno())
            return kept
        except FileExistsError:
            continue
        except OSError as exc:
            raise L3MVNError(
                f"{_name(path)} ends in a torn line and it cannot be set aside in {_name(kept)} "
                f"({_reason(exc)}); delete its last line by hand"
            ) from None
    raise L3MVNError(f"{_name(path)} ends in a torn line and {_name(path)}.torn-{stamp}* are all taken")


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def _name(path: Path | None) -> str:
    """The path as the user gave it, shortened in the middle when it is absurdly long (a name the
    filesystem refused for its length must not fill the terminal)."""
    text = str(path)
    return text if len(text) <= 120 else f"{text[:60]}...{text[-40:]}"
