"""``l3mvn export``: a video of a recorded episode, read back from its ``.rrd`` alone.

The MP4 (and, asked for, a GIF beside it) holds the title card and one frame per recorded step, as
``drawing.frames`` draws them from what ``recorded.read_episode`` reads.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.writing import replacing_path, write_file
from l3mvn.run.recording.drawing import FrameGeometry, VideoOptions, frames
from l3mvn.run.recording.recorded import RecordedEpisode, read_episode


@dataclass(frozen=True)
class VideoResult:
    """What ``export_video`` wrote: the MP4, the GIF beside it when asked for, and the frames' count and size."""

    path: Path
    gif: Path | None
    title_frames: int
    steps: int
    width: int
    height: int
    fps: float

    @property
    def frames(self) -> int:
        return self.title_frames + self.steps


def export_video(
    recording: str | Path, out: str | Path, options: VideoOptions = VideoOptions(), *, gif: bool = False
) -> VideoResult:
    """Write ``out`` (.mp4, OpenCV's mp4v) from ``recording``, and with ``gif`` a GIF beside it (same
    stem; one title frame held ``title_s``, for READMEs). Raises a one-line L3MVNError on bad input.

    The encoder reports no write errors, so the video is written beside ``out`` and read back: only a
    file holding every frame (a full disk leaves a few) is renamed to ``out``."""
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise L3MVNError(f"video {out} must end in .mp4 (add --gif for a GIF beside it)")
    ep = read_episode(recording)
    geo = FrameGeometry.of(ep, options)
    expected = options.title_frames + len(ep.steps)

    def whole(path: Path) -> None:
        capture = cv2.VideoCapture(str(path))
        found = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
        capture.release()
        if found != expected:
            raise L3MVNError(
                f"cannot write video {out}: {found} of its {expected} frames reached the disk (is it "
                "full?); nothing was written there"
            )

    with replacing_path(out, "video", check=whole) as partial:
        writer = cv2.VideoWriter(str(partial), cv2.VideoWriter.fourcc(*"mp4v"), options.fps, (geo.width, geo.height))
        if not writer.isOpened():
            raise L3MVNError(f"cannot write video {out}: OpenCV could not open it for writing")
        try:
            for frame in frames(ep, options):
                writer.write(np.ascontiguousarray(frame[..., ::-1]))
        finally:
            writer.release()
    gif_path = _write_gif(ep, options, out.with_suffix(".gif")) if gif else None
    return VideoResult(out, gif_path, options.title_frames, len(ep.steps), geo.width, geo.height, options.fps)


def _write_gif(ep: RecordedEpisode, options: VideoOptions, path: Path) -> Path:
    from PIL import Image

    images = (Image.fromarray(f) for f in frames(ep, options, title_frames=1))
    step_ms = round(1000 / options.fps)
    durations = [max(int(options.title_s * 1000), step_ms)] + [step_ms] * len(ep.steps)
    encoded = io.BytesIO()
    try:
        first = next(images)
        first.save(encoded, format="GIF", save_all=True, append_images=images, duration=durations, loop=0)
    except (OSError, ValueError) as exc:
        raise L3MVNError(f"cannot encode GIF {path}: {first_line(exc)}") from None
    return write_file(path, encoded.getvalue(), "GIF")
