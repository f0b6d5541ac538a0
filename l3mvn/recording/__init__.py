"""Rerun recordings of episodes: a step-event subscriber that writes one ``.rrd`` per episode, plus
reading, listing and replaying them.

Entity tree (all on the ``step`` sequence timeline)::

    camera/rgb  camera/depth  camera/semantic          what the agent saw
    map/semantic  map/frontiers  map/frontier_cells    the agent's map (map-based policies only),
    map/trajectory  map/agent  map/goal  map/short_term_goal   in map-cell pixels (x = col, y = row)
    world/agent  world/trajectory  world/goal          the same in metres, in 3D
    metrics/ground_truth  metrics/timings_ms           one named line per value (SeriesLines)
    metrics/frontiers
    log/decisions  log/language  log/episode           text logs
    episode                                            a markdown card: which episode, its result

Class names and colours come from annotation contexts (``camera`` and ``map``) built with
``l3mvn.viz.category_palette``, so "bed" has one colour in the camera image, the map and the dashboard.
Each recorder owns its own ``RecordingStream``, so several episodes can be recorded at once.
"""

from l3mvn.recording.catalogue import (
    APPLICATION_ID,
    TIMELINE,
    RecordingInfo,
    RecordingSummary,
    list_recordings,
    open_recording,
    parse_recording_name,
    read_recording,
    recording_path,
)
from l3mvn.recording.layout import default_blueprint
from l3mvn.recording.recorder import Recorder
from l3mvn.recording.replay import (
    DEFAULT_WEB_PORT,
    add_replay_arguments,
    run_replay,
    viewer_executable,
    web_viewer_url,
)

__all__ = [
    "APPLICATION_ID", "DEFAULT_WEB_PORT", "TIMELINE", "Recorder", "RecordingInfo", "RecordingSummary",
    "add_replay_arguments", "default_blueprint", "list_recordings", "open_recording", "parse_recording_name",
    "read_recording", "recording_path", "run_replay", "viewer_executable", "web_viewer_url",
]
