"""``l3mvn export``: a video of one recording, or of the episodes of a result file, named by outcome.

The video is H.264 in MP4 (VP9 in WebM where the installed PyAV lacks libx264: ``export_video``).

A result file's episodes are read through the result-line format's reader (``l3mvn.run.eval.results``):
a malformed line is named with its line number and skipped, the others are exported; each episode's
recording is found by (scene, episode, policy) in ``--recordings``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.results import episode_lines
from l3mvn.run.recording.catalogue import find_recording, recording_name_part
from l3mvn.run.recording.drawing import VideoOptions
from l3mvn.run.recording.video import VideoResult, export_video


def result_video_name(row: dict) -> str:
    """``<outcome>_<scene>_<episode>_<policy>.mp4``, outcome ``success`` or ``fail_<cause>``. The policy is
    always named: videos of several result files (one policy each) may share a folder."""
    outcome = "success" if row.get("success") == 1 else f"fail_{recording_name_part(str(row.get('failure')))}"
    parts = [outcome.replace("-", "_"), recording_name_part(str(row["scene"])), str(int(row["episode_id"]))]
    return "_".join(parts + [recording_name_part(str(row["policy"]))]) + ".mp4"


def export_result_video(
    row: dict,
    recordings_dir: str | Path,
    out_dir: str | Path,
    options: VideoOptions = VideoOptions(),
    *,
    gif: bool = False,
) -> VideoResult:
    """The video of one result row (``row_problem`` passed it), from its recording in
    ``recordings_dir`` (the newest, if several share the folder), named by outcome."""
    found = find_recording(recordings_dir, row["scene"], int(row["episode_id"]), row["policy"])
    if found is None:
        raise L3MVNError(
            f"no recording of {row['scene']} episode {row['episode_id']} ({row['policy']}) in "
            f"{recordings_dir}: run eval with --record"
        )
    return export_video(found, Path(out_dir) / result_video_name(row), options, gif=gif)


def add_export_arguments(parser: argparse.ArgumentParser) -> None:
    """``l3mvn export VIDEO.mp4 --recording FILE.rrd`` or ``--results FILE --recordings DIR --out DIR``."""
    parser.add_argument("video", nargs="?", help="the MP4 to write (one recording)")
    parser.add_argument("--recording", help="the .rrd to export (l3mvn eval --record writes them)")
    parser.add_argument("--results", help="batch: an eval result file (.jsonl); one video per episode line")
    parser.add_argument("--recordings", help="batch: the folder holding the recordings of --results")
    parser.add_argument("--out", help="batch: the folder to write <outcome>_<scene>_<episode>_<policy>.mp4 into")
    parser.add_argument("--failures", action="store_true", help="batch: only the episodes that failed")
    parser.add_argument("--gif", action="store_true", help="also write a GIF beside each MP4 (for READMEs)")
    defaults = VideoOptions()
    parser.add_argument("--fps", type=float, default=defaults.fps, help=f"steps per second (default {defaults.fps:g})")
    parser.add_argument(
        "--height",
        type=int,
        default=defaults.height,
        help=f"height of the camera and map panels in pixels (default {defaults.height})",
    )
    parser.add_argument(
        "--title-seconds",
        type=float,
        default=defaults.title_s,
        help=f"how long the title card with the outcome shows (default {defaults.title_s:g})",
    )


def run_export(args: argparse.Namespace) -> int:
    options = VideoOptions(fps=args.fps, height=args.height, title_s=args.title_seconds)
    if args.results is None:
        if args.video is None or args.recording is None:
            raise L3MVNError(
                "export needs VIDEO.mp4 --recording FILE.rrd, or --results FILE.jsonl --recordings DIR --out DIR"
            )
        if args.recordings or args.out or args.failures:
            raise L3MVNError("--recordings, --out and --failures go with --results (batch export), not --recording")
        _report(export_video(args.recording, args.video, options, gif=args.gif))
        return 0
    if args.video or args.recording:
        raise L3MVNError("--results exports a batch into --out: drop VIDEO.mp4 and --recording")
    if not args.recordings or not args.out:
        raise L3MVNError("--results needs --recordings DIR (the .rrd files) and --out DIR (where videos go)")
    if not Path(args.recordings).is_dir():
        raise L3MVNError(f"recordings folder {args.recordings} not found")
    read = episode_lines(args.results)
    for problem in read.problems:
        print(f"{args.results}: skipped {problem}", file=sys.stderr)
    rows = [row for _, row in read.rows]
    if not rows:
        raise L3MVNError(
            f"{args.results} holds no episode line to export"
            + (f" (first problem: {read.problems[0]})" if read.problems else "")
        )
    chosen = [r for r in rows if not args.failures or r["success"] != 1]
    if not chosen:
        print(f"{args.results}: no {'failed ' if args.failures else ''}episodes: nothing to export")
        return 0
    skipped = []
    for row in chosen:
        try:
            _report(export_result_video(row, args.recordings, args.out, options, gif=args.gif))
        except L3MVNError as exc:
            skipped.append(f"{row['key']}: {exc}")
    for line in skipped:
        print(f"skipped {line}", file=sys.stderr)
    if len(skipped) == len(chosen):
        raise L3MVNError(
            f"no video written: none of the {len(chosen)} episodes could be exported (first: {skipped[0]})"
        )
    print(f"wrote {len(chosen) - len(skipped)} videos to {args.out}" + (f", skipped {len(skipped)}" if skipped else ""))
    return 0


_CODEC_NAMES = {"h264": "H.264 MP4", "vp9": "VP9 WebM"}


def _report(v: VideoResult) -> None:
    gif = f" and {v.gif}" if v.gif else ""
    print(
        f"wrote {v.path}{gif}: {_CODEC_NAMES[v.codec]}, {v.frames} frames ({v.title_frames} title + {v.steps} steps), "
        f"{v.width}x{v.height} at {v.fps:g} fps"
    )
