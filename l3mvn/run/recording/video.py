"""``l3mvn export``: a video of a recorded episode, read back from its ``.rrd`` alone.

The video (and, asked for, a GIF beside it) holds the title card and one frame per recorded step, as
``drawing.frames`` draws them from what ``recorded.read_episode`` reads. It is H.264 in an MP4, the
one pairing every browser, slide tool and chat app plays, encoded by the FFmpeg that PyAV's wheel
ships; a PyAV built without libx264 writes VP9 in WebM beside the asked-for name instead, and says so.
"""

from __future__ import annotations

import io
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.writing import replacing_path, write_file
from l3mvn.run.recording.drawing import FrameGeometry, VideoOptions, frames
from l3mvn.run.recording.recorded import RecordedEpisode, read_episode

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VideoResult:
    """What ``export_video`` wrote: the video (``path``, its ``codec`` ``"h264"`` in MP4 or ``"vp9"`` in
    WebM), the GIF beside it when asked for, and the frames' count and size."""

    path: Path
    codec: str
    gif: Path | None
    title_frames: int
    steps: int
    width: int
    height: int
    fps: float

    @property
    def frames(self) -> int:
        return self.title_frames + self.steps


@dataclass(frozen=True)
class _Format:
    codec: str  # the name a decoder reports
    encoder: str
    container: str
    suffix: str
    options: dict[str, str]  # the encoder's
    muxer_options: dict[str, str]


# Quality 20 keeps the small text of the band legible; the veryfast preset encodes in about half
# medium's time for a file a few percent larger (a batch export writes one video per episode);
# faststart puts the index first, so a browser starts playing before the whole file has arrived.
_H264 = _Format("h264", "libx264", "mp4", ".mp4", {"crf": "20", "preset": "veryfast"}, {"movflags": "+faststart"})
# Constant quality (bitrate 0); cpu-used 4 keeps VP9, far slower than x264, within a few times its time.
_VP9 = _Format("vp9", "libvpx-vp9", "webm", ".webm", {"crf": "32", "b": "0", "cpu-used": "4", "row-mt": "1"}, {})


def h264_available() -> bool:
    """Whether the installed PyAV carries the H.264 encoder (its wheels do; a build against a system
    FFmpeg may not)."""
    return "libx264" in av.codecs_available


def export_video(
    recording: str | Path, out: str | Path, options: VideoOptions = VideoOptions(), *, gif: bool = False
) -> VideoResult:
    """Write ``out`` (.mp4, H.264) from ``recording``, and with ``gif`` a GIF beside it (same stem; one
    title frame held ``title_s``, for READMEs). Without libx264 the video is VP9 in ``out`` with the
    suffix .webm, logged as a warning and named in the result. Raises a one-line L3MVNError on bad input.

    The video is written beside its name and read back: only a file holding every frame (a full disk
    may leave a few) is renamed into place; an encoder or container error leaves nothing there."""
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise L3MVNError(f"video {out} must end in .mp4 (add --gif for a GIF beside it)")
    ep = read_episode(recording)
    geo = FrameGeometry.of(ep, options)
    fmt = _H264 if h264_available() else _VP9
    path = out.with_suffix(fmt.suffix)
    if fmt is _VP9:
        log.warning("this PyAV has no H.264 encoder (libx264): %s is VP9 in WebM, not MP4", path)
    expected = options.title_frames + len(ep.steps)

    def whole(written: Path) -> None:
        found = _count_frames(written)
        if found != expected:
            raise L3MVNError(
                f"cannot write video {path}: {found} of its {expected} frames reached the disk (is it "
                "full?); nothing was written there"
            )

    with replacing_path(path, "video", check=whole) as partial:
        _encode(partial, fmt, frames(ep, options), geo, options.fps, path)
    gif_path = _write_gif(ep, options, out.with_suffix(".gif")) if gif else None
    return VideoResult(
        path, fmt.codec, gif_path, options.title_frames, len(ep.steps), geo.width, geo.height, options.fps
    )


def _encode(
    partial: Path, fmt: _Format, images: Iterable[np.ndarray], geo: FrameGeometry, fps: float, path: Path
) -> None:
    """Encode ``images`` (RGB) into ``partial``; an FFmpeg error (a full disk among them) becomes a
    one-line L3MVNError naming ``path``, where the video goes."""
    try:
        with av.open(str(partial), "w", format=fmt.container, options=fmt.muxer_options) as container:
            stream = container.add_stream(fmt.encoder, rate=Fraction(fps).limit_denominator(1001), options=fmt.options)
            # FrameGeometry.of makes width and height even, which yuv420p (chroma at half size) needs:
            # no pad or crop here.
            stream.width, stream.height, stream.pix_fmt = geo.width, geo.height, "yuv420p"
            for image in images:
                container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
            container.mux(stream.encode())
    except av.error.FFmpegError as exc:
        raise L3MVNError(
            f"cannot write video {path}: {fmt.encoder} in {fmt.container}: {exc.strerror or first_line(exc)}; "
            "nothing was written there"
        ) from None


def _count_frames(path: Path) -> int:
    """The frames a decoder finds in ``path`` (0 when it cannot read it at all)."""
    try:
        with av.open(str(path)) as container:
            return sum(1 for _ in container.decode(video=0))
    except av.error.FFmpegError:
        return 0


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
