"""The recording format: every entity path the recorder writes, and the component columns read back.

Entity tree (all on the ``step`` sequence timeline)::

    camera                                             annotation context: the camera's class names, colours
    camera/rgb  camera/depth  camera/semantic          what the agent saw
    camera/rgb/target  camera/semantic/target          boxes around the target's pixels
    map                                                annotation context: the map's classes
    map/semantic  map/frontiers  map/frontier_cells    the agent's map (map-based policies only),
    map/trajectory  map/agent  map/goal  map/target    in map-cell pixels (x = col, y = row); frontiers
    map/short_term_goal  map/collision_marks           carry F<id> labels (best three and the chosen)
                                                       and every score (score_llm/cu/fused) on hover
    world/agent  world/agent/body  world/trajectory    the same in metres, in 3D
    world/goal
    metrics/ground_truth  metrics/timings_ms           one named line per value (SeriesLines)
    metrics/frontiers  metrics/frontier_scores         the count; each frontier's score, a line per F<id>
    metrics/chosen_frontier                            the chosen frontier's prior (LLM, or PONI's pot), CU, fused
    metrics/language/chosen[_metres]                   language policies: the chosen frontier's p(goal)
    metrics/language/by_goal/<goal>                    (and metres) per goal; every frontier's p(goal)
    log/decisions  log/episode                         text logs: each decision; the start, target changes, result
    log/language                                       a language policy's prompts and their scores
    log/fusion                                         the fusion rule in force (written when it changes)
    episode                                            a markdown card: which episode, its result

The recorder logs these paths as written here; rerun's reader names each with a leading slash
(``reader_path``). The reader decodes only the columns named below.
"""

from __future__ import annotations

CAMERA = "camera"
CAMERA_RGB = "camera/rgb"
CAMERA_DEPTH = "camera/depth"
CAMERA_SEMANTIC = "camera/semantic"
CAMERA_RGB_TARGET = "camera/rgb/target"
CAMERA_SEMANTIC_TARGET = "camera/semantic/target"

MAP = "map"
MAP_SEMANTIC = "map/semantic"
MAP_FRONTIERS = "map/frontiers"
MAP_FRONTIER_CELLS = "map/frontier_cells"
MAP_TRAJECTORY = "map/trajectory"
MAP_AGENT = "map/agent"
MAP_GOAL = "map/goal"
MAP_TARGET = "map/target"
MAP_SHORT_TERM_GOAL = "map/short_term_goal"
MAP_COLLISION_MARKS = "map/collision_marks"

WORLD = "world"
WORLD_AGENT = "world/agent"
WORLD_AGENT_BODY = "world/agent/body"
WORLD_TRAJECTORY = "world/trajectory"
WORLD_GOAL = "world/goal"

METRICS_GROUND_TRUTH = "metrics/ground_truth"
METRICS_TIMINGS_MS = "metrics/timings_ms"
METRICS_FRONTIERS = "metrics/frontiers"
METRICS_FRONTIER_SCORES = "metrics/frontier_scores"
METRICS_CHOSEN_FRONTIER = "metrics/chosen_frontier"
METRICS_LANGUAGE = "metrics/language"  # everything below it comes from a language policy only
LANGUAGE_CHOSEN = f"{METRICS_LANGUAGE}/chosen"  # the chosen frontier's p(goal), a line per goal
LANGUAGE_CHOSEN_METRES = f"{LANGUAGE_CHOSEN}_metres"  # a distance head's metres to each goal from it
LANGUAGE_BY_GOAL = f"{METRICS_LANGUAGE}/by_goal"  # /<goal>: p(goal) of every frontier, a line per F<id>

LOG = "log"
LOG_DECISIONS = "log/decisions"
LOG_LANGUAGE = "log/language"
LOG_FUSION = "log/fusion"
LOG_EPISODE = "log/episode"

EPISODE = "episode"

PROPERTIES = "__properties"  # rerun's own entity for the recording's properties: not part of the tree

# The component columns the reader decodes, as rerun's reader names them (archetype:component).
IMAGE_BUFFER, IMAGE_FORMAT = "Image:buffer", "Image:format"
SEGMENTATION_BUFFER, SEGMENTATION_FORMAT = "SegmentationImage:buffer", "SegmentationImage:format"
BOXES_CENTERS, BOXES_HALF_SIZES = "Boxes2D:centers", "Boxes2D:half_sizes"
POINTS_POSITIONS, POINTS_COLORS = "Points2D:positions", "Points2D:colors"
POINTS_LABELS, POINTS_RADII = "Points2D:labels", "Points2D:radii"
ARROWS_VECTORS = "Arrows2D:vectors"
STRIPS = "LineStrips2D:strips"
ANNOTATION_CONTEXT = "AnnotationContext:context"
TEXT_LOG = "TextLog:text"
TEXT_DOCUMENT = "TextDocument:text"
CLEAR = "Clear:is_recursive"  # present on a row that clears the entity


def language_by_goal(goal: str) -> str:
    """The entity of every frontier's p(``goal``): the goal's name with spaces as underscores."""
    return f"{LANGUAGE_BY_GOAL}/{goal.replace(' ', '_')}"


def reader_path(entity: str) -> str:
    """``entity`` as rerun's reader names it (``chunk.entity_path``): with a leading slash."""
    return f"/{entity}"
