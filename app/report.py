"""``l3mvn report RESULTS... --out report.html``: one shareable HTML page over eval result files.

The page holds the summary per run and goal category with bootstrap intervals, the settings that
differ between files (first, before any number), the paired differences against the first file, the
failure causes, SR and SPL against episode length, and the outcome-sorted episode videos. It is one
file that opens from a disk with no server and no network (``report_page``), and it is written whole
or not at all: a bad input or a full disk is one line of error and leaves no partial page.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path

from l3mvn.core.errors import L3MVNError
from l3mvn.core.writing import write_file
from l3mvn_studio.report_data import read_report_data
from l3mvn_studio.report_page import render_page
from l3mvn_studio.report_videos import MAX_VIDEOS, choose_videos


@dataclass(frozen=True)
class WrittenReport:
    path: Path
    runs: int
    videos: int
    size: int  # bytes of the page


def write_report(
    results: list[str | Path],
    out: str | Path,
    *,
    videos: str | Path | None = None,
    max_videos: int = MAX_VIDEOS,
    title: str | None = None,
) -> WrittenReport:
    """Read ``results`` (the first is the reference), choose the videos and write the page to ``out``."""
    target = Path(out)
    for given in results:
        if _same_file(Path(given), target):
            raise L3MVNError(f"--out {target} is one of the result files; choose another --out such as report.html")
    data = read_report_data(list(results))
    chosen = choose_videos(data.runs, videos, max_videos)
    shown = title or "L3MVN evaluation: " + ", ".join(dict.fromkeys(run.policy for run in data.runs))
    page = render_page(data, chosen, shown)
    write_file(target, page, "report")
    return WrittenReport(target, len(data.runs), len(chosen.embedded), len(page.encode("utf-8")))


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected 0 or more, got {value}")
    return value


def add_report_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "results",
        nargs="+",
        metavar="RESULTS",
        help="eval result files (.jsonl, from `l3mvn eval --out`); the first is the reference of the "
        "paired differences",
    )
    parser.add_argument("--out", default="report.html", help="the HTML page to write (default report.html)")
    parser.add_argument(
        "--videos",
        default=None,
        metavar="DIR",
        help="the folder `l3mvn eval --video DIR` or `l3mvn export --results ... --out DIR` wrote: each "
        "episode's video is embedded, failures first",
    )
    parser.add_argument(
        "--max-videos",
        type=_count,
        default=MAX_VIDEOS,
        metavar="N",
        help=f"embed at most N videos (default {MAX_VIDEOS}); each one adds its size to the page",
    )
    parser.add_argument("--title", default=None, help="the page's title (default: the runs it shows)")


def run_report(args: argparse.Namespace) -> int:
    written = write_report(args.results, args.out, videos=args.videos, max_videos=args.max_videos, title=args.title)
    print(
        f"wrote {written.path}: {written.runs} run{'s' if written.runs != 1 else ''}, "
        f"{written.videos} video{'s' if written.videos != 1 else ''}, {written.size / (1 << 20):.1f} MiB"
    )
    return 0
