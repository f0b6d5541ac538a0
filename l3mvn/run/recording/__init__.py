"""Rerun recordings of episodes: a step-event subscriber that writes one ``.rrd`` per episode, plus
reading, listing, replaying and exporting them to video (``l3mvn export``).

``entities`` holds the entity tree and the columns read back: the one place that spells them. The
``recorder`` writes a recording, ``layout`` is its viewer layout and colours, ``catalogue`` names, lists
and checks the files, ``recorded`` reads an episode back, ``drawing`` draws its frames, ``video``
exports them, ``replay`` opens a recording in rerun's viewer.

Class names and colours come from annotation contexts (the camera's and the map's) built with
``l3mvn.run.viz.category_palette``, so "bed" has one colour in the camera image, the map and the dashboard.
The layout (``layout.default_blueprint``) puts the map first and is re-sent fitted to the mapped area.
Each recorder owns its own ``RecordingStream``, so several episodes can be recorded at once.
"""

from l3mvn.run.recording.catalogue import (
    APPLICATION_ID,
    TIMELINE,
    RecordingInfo,
    RecordingSummary,
    find_recording,
    list_recordings,
    open_recording,
    parse_recording_name,
    read_recording,
    recording_path,
)
from l3mvn.run.recording.drawing import VideoOptions
from l3mvn.run.recording.layout import MapBounds, default_blueprint, map_view_bounds
from l3mvn.run.recording.recorded import read_episode
from l3mvn.run.recording.recorder import Recorder
from l3mvn.run.recording.replay import (
    DEFAULT_WEB_PORT,
    add_replay_arguments,
    run_replay,
    viewer_executable,
    web_viewer_url,
)
from l3mvn.run.recording.video import VideoResult, export_video

__all__ = [
    "APPLICATION_ID",
    "DEFAULT_WEB_PORT",
    "TIMELINE",
    "MapBounds",
    "Recorder",
    "RecordingInfo",
    "RecordingSummary",
    "VideoOptions",
    "VideoResult",
    "add_replay_arguments",
    "default_blueprint",
    "export_video",
    "find_recording",
    "list_recordings",
    "map_view_bounds",
    "open_recording",
    "parse_recording_name",
    "read_episode",
    "read_recording",
    "recording_path",
    "run_replay",
    "viewer_executable",
    "web_viewer_url",
]
