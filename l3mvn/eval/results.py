"""Result files: one JSON line per finished episode, appended, read back for ``--resume``.

A line is written with a single ``write`` of the whole encoded line and flushed, so an interrupted
run never leaves a partial line (a torn last line from a crashed disk is skipped on ``--resume``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable

from l3mvn.errors import L3MVNError


class ResultWriter:
    """Appends result lines; each line is one write() of complete bytes, then flushed."""

    def __init__(self, path: str | Path | None) -> None:
        self.path = Path(path) if path else None
        self._fd: int | None = None
        if self.path:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)

    def write(self, row: dict) -> None:
        if self._fd is not None:
            os.write(self._fd, (json.dumps(row, sort_keys=True) + "\n").encode())

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def read_results(path: str | Path) -> list[dict]:
    """Complete result lines of a JSONL file; a torn or foreign line is skipped."""
    path = Path(path)
    if not path.exists():
        return []
    rows = []
    with path.open("r", encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if not line.endswith("\n"):
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(row, dict) and "key" in row and "policy" in row:
                rows.append(row)
    return rows


def done_keys(rows: Iterable[dict], policy: str, config_hash: str) -> set[str]:
    """Keys finished under this policy and config; error rows do not count (resume retries them)."""
    return {r["key"] for r in rows
            if r.get("policy") == policy and r.get("config_hash") == config_hash and "error" not in r}


def check_resumable(path: str | Path | None, resume: bool) -> None:
    if resume and not path:
        raise L3MVNError("--resume needs --out FILE (the results to resume from)")
