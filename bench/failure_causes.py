"""Charge every failed episode to the world or the agent (issue 12's failure analysis).

    l3mvn scenes audit --dataset DIR --split train --json --out AUDIT_DIR
    python bench/failure_causes.py AUDIT_DIR/audit.json RESULTS.jsonl [RESULTS.jsonl ...]

Prints one column per results file: SR, then the number of failures in each class of
``l3mvn.world.task.failures.CLASSES`` (world: lost floor / object unreachable / hidden; agent: never
looked / glimpsed, not confirmed / confirmed, not reached / stuck / false stop / in region, no stop).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from l3mvn.core.errors import L3MVNError  # noqa: E402
from l3mvn.run.eval.results import episode_lines  # noqa: E402
from l3mvn.world.task.failures import CLASSES, failure_table  # noqa: E402


def usable_rows(path: Path) -> tuple[list[dict], int]:
    """The finished-episode rows of a result file, and how many lines were not (torn, error, invalid)."""
    read = episode_lines(path)
    return [row for _, row in read.rows], len(read.problems)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("audit", help="audit.json written by `l3mvn scenes audit --out DIR`")
    ap.add_argument("results", nargs="+", help="result lines of `l3mvn eval --out`")
    args = ap.parse_args()
    report = json.loads(Path(args.audit).read_text())
    if not isinstance(report, dict) or not report.get("episodes"):
        raise SystemExit(
            f"error: {args.audit} holds no audited episodes: run `l3mvn scenes audit --out DIR` "
            "on a dataset split with episode files"
        )
    audits = {e["key"]: e for e in report["episodes"]}
    columns = []
    for path in args.results:
        rows, unusable = usable_rows(Path(path))
        if unusable:
            print(f"{path}: skipped {unusable} line(s) that are not finished-episode rows", file=sys.stderr)
        try:
            table = failure_table(rows, audits)
        except L3MVNError as exc:
            raise SystemExit(f"error: {path}: {exc}") from None
        sr = sum(r["success"] for r in rows) / max(len(rows), 1)
        columns.append((Path(path).stem, len(rows), sr, table))
    width = max(len(c) for c in CLASSES) + 2
    print("".ljust(width) + "".join(name[:18].rjust(20) for name, *_ in columns))
    print("episodes".ljust(width) + "".join(f"{n:>20d}" for _, n, _, _ in columns))
    print("SR".ljust(width) + "".join(f"{sr:>20.3f}" for _, _, sr, _ in columns))
    for cls in CLASSES:
        print(cls.ljust(width) + "".join(f"{t.get(cls, 0):>20d}" for *_, t in columns))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
