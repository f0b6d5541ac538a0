"""Rerun recordings of episodes: a step-event subscriber that writes one ``.rrd`` per episode, plus
reading, listing, replaying and exporting them to video (``l3mvn export``).

Entity tree (all on the ``step`` sequence timeline)::

    camera/rgb  camera/depth  camera/semantic          what the agent saw
    camera/rgb/target  camera/semantic/target          boxes around the target's pixels
    map/semantic  map/frontiers  map/frontier_cells    the agent's map (map-based policies only),
    map/trajectory  map/agent  map/goal  map/target    in map-cell pixels (x = col, y = row); frontiers
    map/short_term_goal                                carry F<id> labels (best three and the chosen)
                                                       and every score (score_llm/cu/fused) on hover
    world/agent  world/trajectory  world/goal          the same in metres, in 3D
    metrics/ground_truth  metrics/timings_ms           one named line per value (SeriesLines)
    metrics/frontiers  metrics/frontier_scores         the count; each frontier's score, a line per F<id>
    metrics/chosen_frontier                            the chosen frontier's LLM, CU and fused scores
    log/decisions  log/language  log/episode           text logs
    episode                                            a markdown card: which episode, its result

Class names and colours come from annotation contexts (``camera`` and ``map``) built with
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
from l3mvn.run.recording.layout import MapBounds, default_blueprint, map_view_bounds
from l3mvn.run.recording.recorder import Recorder
from l3mvn.run.recording.video import VideoOptions, VideoResult, export_video, read_episode
from l3mvn.run.recording.replay import (
    DEFAULT_WEB_PORT,
    add_replay_arguments,
    run_replay,
    viewer_executable,
    web_viewer_url,
)

__all__ = [
    "APPLICATION_ID", "DEFAULT_WEB_PORT", "TIMELINE", "MapBounds", "Recorder", "RecordingInfo", "RecordingSummary",
    "VideoOptions", "VideoResult", "add_replay_arguments", "default_blueprint", "export_video", "find_recording", "list_recordings", "map_view_bounds", "open_recording",
    "parse_recording_name", "read_episode", "read_recording", "recording_path", "run_replay",
    "viewer_executable", "web_viewer_url",
]
