"""Recording files: their names (dataset, scene, episode, policy), the catalogue of a folder, and
reading one back (which steps it holds, whether it is readable at all, what survives a cut)."""

from __future__ import annotations

import os
import re
import secrets
import stat
import struct
import tempfile
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

from rerun.chunk import RrdReader

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.recording.entities import PROPERTIES, reader_path

APPLICATION_ID = "l3mvn"
DEFAULT_RECORD_DIR = "recordings"  # where recordings go when no folder is named (eval, serve)
TIMELINE = "step"
_NAME_PART = re.compile(r"[^A-Za-z0-9.-]+")
_RRD_MAGIC = b"RRF2"
_RRD_FILE_HEADER = 12
_RRD_MESSAGE = struct.Struct("<QQ")
_RRD_END = 0


def recording_path(
    recordings_dir: str | Path, dataset: str | Path, scene: str, episode_id: int, policy: str, tag: str | None = None
) -> Path:
    """``<dir>/<dataset>_<scene>_<episode>_<policy>[_<tag>].rrd``; a dataset path contributes its folder
    name, and anything but letters, digits, '.' and '-' becomes '-' so the name parses back
    unambiguously. ``tag`` tells apart several recordings of one episode (``unique_tag``)."""
    parts = [
        recording_name_part(Path(str(dataset)).name or str(dataset)),
        recording_name_part(scene),
        str(int(episode_id)),
        recording_name_part(policy),
    ]
    if tag is not None:
        parts.append(recording_name_part(tag))
    return Path(recordings_dir) / ("_".join(parts) + ".rrd")


def unique_tag(kind: str) -> str:
    """A name tag no other writer uses: ``<kind>-<UTC time>-<pid>-<random>`` (sorts by time)."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    return f"{kind}-{stamp}-{os.getpid()}-{secrets.token_hex(3)}"


@dataclass(frozen=True)
class RecordingInfo:
    """One ``.rrd`` on disk; the episode fields are None when the name does not follow the pattern."""

    path: Path
    dataset: str | None
    scene: str | None
    episode_id: int | None
    policy: str | None
    size_bytes: int
    mtime: float
    tag: str | None = None  # the name's fifth part: one of several recordings of the episode (a re-run)

    def to_dict(self) -> dict:
        return {
            "path": str(self.path),
            "name": self.path.name,
            "dataset": self.dataset,
            "scene": self.scene,
            "episode_id": self.episode_id,
            "policy": self.policy,
            "tag": self.tag,
            "size_bytes": self.size_bytes,
            "mtime": self.mtime,
        }


def parse_recording_name(path: str | Path) -> tuple[str, str, int, str, str | None] | None:
    """(dataset, scene, episode_id, policy, tag or None) from a name made by ``recording_path``, else None."""
    p = Path(path)
    parts = p.stem.split("_") if p.suffix == ".rrd" else []
    if len(parts) not in (4, 5) or not parts[2].isdigit() or not all(parts):
        return None
    return parts[0], parts[1], int(parts[2]), parts[3], (parts[4] if len(parts) == 5 else None)


def list_recordings(recordings_dir: str | Path) -> list[RecordingInfo]:
    """Every ``*.rrd`` directly in the folder, newest first (an absent folder has none)."""
    folder = Path(recordings_dir)
    if not folder.is_dir():
        return []
    out = []
    for path in folder.glob("*.rrd"):
        try:
            st = path.stat()
        except OSError:  # deleted while listing
            continue
        if not stat.S_ISREG(st.st_mode):  # a folder, FIFO or device named *.rrd is no recording
            continue
        parsed = parse_recording_name(path)
        dataset, scene, episode_id, policy, tag = parsed if parsed else (None, None, None, None, None)
        out.append(RecordingInfo(path, dataset, scene, episode_id, policy, st.st_size, st.st_mtime, tag))
    return sorted(out, key=lambda r: (-r.mtime, r.path.name))


def find_recording(recordings_dir: str | Path, scene: str, episode_id: int, policy: str) -> Path | None:
    """The newest recording of (scene, episode, policy) in the folder, whatever its dataset; None if none."""
    want = (recording_name_part(scene), int(episode_id), recording_name_part(policy))
    return next((r.path for r in list_recordings(recordings_dir) if (r.scene, r.episode_id, r.policy) == want), None)


def recording_name_part(text: str) -> str:
    """``text`` as a part of a file name: anything but letters, digits, '.' and '-' becomes '-'."""
    part = _NAME_PART.sub("-", str(text)).strip("-")
    if not part:
        raise L3MVNError(f"cannot name a recording after {text!r}: it needs a letter or digit")
    return part


@dataclass(frozen=True)
class RecordingSummary:
    """What a ``.rrd`` holds, read back with rerun's own reader."""

    path: Path
    application_id: str
    recording_id: str
    entity_paths: tuple[str, ...]
    steps: tuple[int, ...]  # distinct values on the ``step`` timeline, sorted
    lost_bytes: int = 0  # bytes after a mid-message cut, not read (see RecordingCut)


class RecordingCut(L3MVNError):
    """A recording cut off in the middle of a message (the writer crashed, was killed or ran out of disk).

    Its first ``intact_bytes`` are whole messages: rerun's viewer shows them, and
    ``read_recording(path, cut_ok=True)`` reads them. rerun's Python reader refuses the whole file,
    so without this a crash mid-write would cost the entire episode instead of its last step.
    """

    def __init__(self, path: Path, intact_bytes: int, total_bytes: int) -> None:
        self.path, self.intact_bytes, self.total_bytes = path, intact_bytes, total_bytes
        super().__init__(
            f"{path} ends inside a message (cut off mid-write, or still being written): its "
            f"last {self.lost_bytes} of {total_bytes} bytes are incomplete"
        )

    @property
    def lost_bytes(self) -> int:
        return self.total_bytes - self.intact_bytes


def open_recording(path: str | Path) -> RrdReader:
    """Rerun's reader for ``path``, or L3MVNError naming the file when it is missing or not a recording.

    A file that ends between two messages (still being written, or closed before its footer) is
    read by scanning it. A file that ends inside a message raises RecordingCut, which says where
    the whole messages end; ``read_recording(path, cut_ok=True)`` reads up to there.
    """
    p = Path(path)
    if not p.is_file():
        raise L3MVNError(f"recording {p} not found" + ("" if not p.exists() else " (not a file)"))
    try:
        return _reader(p)
    except L3MVNError:
        intact = _intact_length(p)
        if intact is None:
            raise
        raise RecordingCut(p, intact, p.stat().st_size) from None


def read_recording(path: str | Path, *, cut_ok: bool = False) -> RecordingSummary:
    """Entity paths and step numbers of the first recording in ``path`` (reads every chunk).

    A file cut off mid-message raises RecordingCut, unless ``cut_ok``: then the summary covers the
    whole messages before the cut and ``lost_bytes`` says how much followed it.
    """
    p = Path(path)
    try:
        return _summarise(open_recording(p), p)
    except RecordingCut as cut:
        if not cut_ok:
            raise
        with tempfile.TemporaryDirectory(prefix="l3mvn-cut-") as folder:
            prefix = _copy_prefix(p, cut.intact_bytes, Path(folder) / p.name)
            try:
                summary = _summarise(_reader(prefix), p)
            except L3MVNError:  # rerun's reason names the temporary copy: of no use to the reader
                raise L3MVNError(
                    f"{cut}, and the {cut.intact_bytes} bytes before it hold no readable recording"
                ) from None
        return replace(summary, lost_bytes=cut.lost_bytes)


def _reader(path: Path) -> RrdReader:
    """``RrdReader(path)`` holding at least one recording; its failures as one-line L3MVNErrors."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer": expected for a live or interrupted recording
            reader = RrdReader(path)
            recordings = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise L3MVNError(f"{path} is not a readable rerun recording: {first_line(exc)}") from None
    if not recordings:
        raise L3MVNError(f"{path} holds no rerun recording (only blueprints)")
    return reader


def _summarise(reader: RrdReader, path: Path) -> RecordingSummary:
    """The summary of ``reader``'s first recording, named ``path`` (which may differ from what it reads)."""
    entry = reader.recordings()[0]
    entities: set[str] = set()
    steps: set[int] = set()
    try:
        for chunk in reader.stream(store=entry):
            entities.add(chunk.entity_path)
            if TIMELINE in chunk.timeline_names:
                steps.update(chunk.to_record_batch().column(TIMELINE).to_pylist())
    except (RuntimeError, ValueError, OSError) as exc:
        raise L3MVNError(f"{path} is not a readable rerun recording: {first_line(exc)}") from None
    entities.discard(reader_path(PROPERTIES))
    return RecordingSummary(
        path,
        entry.application_id,
        entry.recording_id,
        tuple(sorted(entities)),
        tuple(sorted(s for s in steps if s is not None)),
    )


def _intact_length(path: Path) -> int | None:
    """Where the whole messages of a file cut mid-message end; None if it is not cut but broken otherwise."""
    ending, offset = _framing(path)
    return offset if ending == "cut" else None


def recording_gap(path: str | Path) -> str | None:
    """None when ``path`` is a finished recording (every message and rerun's end marker on disk);
    else what is missing, in words: a writer that ran out of disk leaves a cut or open file."""
    p = Path(path)
    try:
        ending, offset = _framing(p)
        size = p.stat().st_size
    except OSError as exc:
        return f"cannot be read back ({exc.strerror or exc})"
    if ending == "end":
        return None
    if ending == "cut":
        return f"ends inside a message: its last {size - offset} of {size} bytes are incomplete"
    if ending == "open":
        return f"ends after {size} bytes without rerun's end marker: the writer stopped before the end"
    return "is not a rerun recording"


def _framing(path: Path) -> tuple[str, int]:
    """How rerun's framing of ``path`` ends: ``("end", offset)`` at a whole end marker, ``("cut",
    offset)`` where a message runs past the end of the file, ``("open", size)`` when the file ends
    between messages without an end marker, ``("foreign", 0)`` when it is no rerun file at all.

    rerun's framing (``re_log_encoding``): a 12-byte file header starting ``RRF2``, then messages of
    a 16-byte header (kind, payload length: little-endian u64s) and the payload. Kind 0 ends the
    messages; the index and footer after it are not needed to read them.
    """
    size = path.stat().st_size
    with path.open("rb") as f:
        if f.read(len(_RRD_MAGIC)) != _RRD_MAGIC:
            return "foreign", 0
        offset = _RRD_FILE_HEADER
        while offset < size:
            f.seek(offset)
            header = f.read(_RRD_MESSAGE.size)
            if len(header) < _RRD_MESSAGE.size:
                return "cut", offset
            kind, length = _RRD_MESSAGE.unpack(header)
            if offset + _RRD_MESSAGE.size + length > size:
                return "cut", offset
            if kind == _RRD_END:
                return "end", offset
            offset += _RRD_MESSAGE.size + length
    return "open", size


def _copy_prefix(src: Path, length: int, dst: Path) -> Path:
    """The first ``length`` bytes of ``src`` in ``dst``, copied a block at a time (recordings can be large)."""
    with src.open("rb") as fin, dst.open("wb") as fout:
        left = length
        while left:
            block = fin.read(min(left, 1 << 20))
            if not block:
                break
            fout.write(block)
            left -= len(block)
    return dst
