"""Zero-shot scoring with sentence embeddings: runs offline with the shipped MiniLM.

``embedding``: cosine between "A frontier area containing o1, ..., ok." and "A frontier area
containing a <goal>.", ``softmax(cos / 0.05)`` over goals (cosines between such sentences differ by
~0.1, so 0.05 turns a 0.1 gap into odds of e^2).

``roomtype``: a two-hop reading that asks the encoder only what it knows well, which room a set of
objects makes and which goal a room holds:
p(goal | objects) = sum_r p(r | objects) p(goal | r) over ``ROOM_TYPES``, with
p(r | objects) = softmax_r(cos("A room containing o1, ..., ok.", "A <r>.") / 0.05) and
p(goal | r) = softmax_goal((cos("A <r>.", "A room containing a <goal>.") - mean_r' cos(r', goal)) / 0.05).
Subtracting each goal's mean over the room types removes the encoder's bias for some goal words
(without it "couch" and "bed" fall to chance). No number here is fitted to room data: the templates,
room list and temperatures were chosen by hand and checked on the train/val buildings only.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from l3mvn.agent.language.models import MINILM, load_sentence_encoder
from l3mvn.agent.language.queries import object_list
from l3mvn.agent.language.scorers.base import ObjectKey, Scorer, register
from l3mvn.agent.language.vocabulary import query_phrase

ROOM_TYPES: tuple[str, ...] = (
    "bathroom",
    "bedroom",
    "living room",
    "kitchen",
    "dining room",
    "office",
    "hallway",
    "laundry room",
)


class _EmbeddingBase(Scorer):
    def __init__(self, model: str = MINILM, **kw: Any) -> None:
        super().__init__(**kw)
        self.model_name = model
        self.encoder = load_sentence_encoder(model)
        self._text_cache: dict[str, np.ndarray] = {}

    def clear_cache(self) -> None:
        super().clear_cache()
        self._text_cache.clear()

    def embed(self, texts: list[str]) -> np.ndarray:
        """Unit embeddings, each text encoded once per scorer (goal and room sentences recur)."""
        new = [t for t in dict.fromkeys(texts) if t not in self._text_cache]
        if new:
            self._text_cache.update(zip(new, self.encoder.encode(new)))
        return np.stack([self._text_cache[t] for t in texts])


@register("embedding")
class EmbeddingScorer(_EmbeddingBase):
    temperature = 0.05

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        ctx = self.embed([f"A frontier area containing {object_list(objs)}." for objs, _ in pairs])
        goal = self.embed([f"A frontier area containing a {query_phrase(g)}." for _, g in pairs])
        cosines: list[float] = (ctx * goal).sum(1).tolist()  # numpy types tolist() as Any
        return cosines


@register("roomtype")
class RoomTypeScorer(_EmbeddingBase):
    """Raw score = log p(goal | objects); temperature 1 so the softmax returns that distribution."""

    temperature = 1.0
    room_temperature = 0.05
    goal_temperature = 0.05

    def __init__(self, room_types: tuple[str, ...] = ROOM_TYPES, **kw: Any) -> None:
        super().__init__(**kw)
        self.room_types = tuple(room_types)
        rooms = self.embed([f"A {r}." for r in self.room_types])
        goals = self.embed([f"A room containing a {query_phrase(g)}." for g in self.goals])
        sim = rooms @ goals.T
        self.p_goal_given_room = _softmax((sim - sim.mean(0, keepdims=True)) / self.goal_temperature)
        self._rooms = rooms

    def room_distribution(self, objects: ObjectKey) -> dict[str, float]:
        """p(room type | objects): why a frontier scored as it did."""
        return dict(zip(self.room_types, map(float, self._p_room([objects])[0])))

    def _p_room(self, keys: list[ObjectKey]) -> np.ndarray:
        ctx = self.embed([f"A room containing {object_list(k)}." for k in keys])
        return _softmax(ctx @ self._rooms.T / self.room_temperature)

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        keys = list(dict.fromkeys(objs for objs, _ in pairs))
        p_goal = self._p_room(keys) @ self.p_goal_given_room
        row = {k: i for i, k in enumerate(keys)}
        return [float(np.log(max(p_goal[row[o], self.goals.index(g)], 1e-12))) for o, g in pairs]


def _softmax(z: np.ndarray) -> np.ndarray:
    e = np.exp(z - z.max(axis=-1, keepdims=True))
    p: np.ndarray = e / e.sum(axis=-1, keepdims=True)  # numpy types the division as Any
    return p
