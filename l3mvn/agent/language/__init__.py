"""Language side of L3MVN: which goal a frontier's objects point to.

Vocabulary (``vocabulary``), room data (``rooms``), co-occurrence statistics and the informative list
(``cooccurrence``), query sentences (``queries``), scorers behind one interface (``scorers``:
``make_scorer("mlm" | "causal" | "embedding" | "roomtype" | "feedforward")``) and head training
(``train_head``: room lists; ``frontier_head``: frontiers of house maps, from ``frontier_file`` data).
"""

from l3mvn.agent.language.build_stats import build_stats_file
from l3mvn.agent.language.cooccurrence import CooccurrenceStats, build_stats, load_stats, stats_table
from l3mvn.agent.language.queries import feedforward_query, zero_shot_query
from l3mvn.agent.language.rooms import Room, load_rooms, rooms_in, split_of
from l3mvn.agent.language.scorers import CacheInfo, Scorer, make_scorer, scorer_names
from l3mvn.agent.language.train_head import train_any_head, train_head
from l3mvn.agent.language.vocabulary import GOALS, canonical, check_goal, query_phrase, to_coco, to_gibson

__all__ = [
    "GOALS",
    "canonical",
    "check_goal",
    "query_phrase",
    "to_coco",
    "to_gibson",
    "Room",
    "load_rooms",
    "rooms_in",
    "split_of",
    "CooccurrenceStats",
    "build_stats",
    "build_stats_file",
    "load_stats",
    "stats_table",
    "zero_shot_query",
    "feedforward_query",
    "Scorer",
    "CacheInfo",
    "make_scorer",
    "scorer_names",
    "train_head",
    "train_any_head",
]
