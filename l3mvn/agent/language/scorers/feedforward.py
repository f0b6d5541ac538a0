"""Feed-forward scoring (the paper's second paradigm): "This frontier contains o1, ..., and ok." ->
sentence embedding -> trained head -> one number per goal.

Four heads share that architecture (``HEAD_KINDS``, chosen with ``head=``, a kind or a file):

- ``rooms``: trained on room object lists (the paper's recipe); its outputs are logits, softmax over
  goals (temperature 1) is p(goal), and only informative objects enter the sentence.
- ``frontiers``: trained on frontiers of house maps (``l3mvn.agent.language.frontier_head``); its outputs
  are the expected metres from the frontier to each goal (``expected_distance``), and every mapped
  category enters the sentence (the file's ``object_filter``: objects that say nothing about a room,
  such as a couch, a vase, a book or a clock, still say how far a goal lies beyond a frontier). p(goal) =
  softmax over goals of -metres / ``distance_temperature_m``: which goal lies nearest through it.
- ``rooms-bag``, ``frontiers-bag``: the same heads trained the same way on a multi-hot bag of the
  objects (``head.bag_features``) instead of the sentence embedding: the ablation without the
  language model. No sentence is written and the embedder is never imported or loaded; the query
  shown for a frontier is the bag itself ("bag of objects: ..."), the only thing the head reads.

The embedder (Emb(W)) is MiniLM, as in the paper's code, or the generative LLM itself
(``model="smollm2-135m"``: the mean of its last hidden states over the sentence); a head is trained
for one embedder and its file names it.

One forward per unique object set gives all six outputs; they fill six cache entries.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from l3mvn.agent.language.head import (
    BAG_FEATURES,
    SHIPPED_HEADS,
    bag_features,
    base_kind,
    is_bag,
    load_head,
)
from l3mvn.agent.language.models import MINILM, load_sentence_encoder, resolve
from l3mvn.agent.language.queries import feedforward_query
from l3mvn.agent.language.scorers.base import ObjectKey, Scorer, register
from l3mvn.core.config.policy import DEFAULT_HEAD, HEAD_KINDS
from l3mvn.core.errors import L3MVNError


@register("feedforward")
class FeedForwardScorer(Scorer):
    temperature = 1.0
    distance_temperature_m = 1.0

    @property
    def label(self) -> str:
        if self.model_name is None:
            return f"{self.name} ({self.kind} head)"
        return f"{self.name} ({self.kind} head on {self.model_name})"

    def __init__(self, model: str | None = None, head: str | Path | None = None, **kw: Any) -> None:
        """``model``: the sentence embedder (Emb(W)) whose head to read, minilm or an LLM; None reads
        minilm's shipped heads, or the embedder a head file was trained on."""
        super().__init__(**kw)
        head = DEFAULT_HEAD if head is None else head
        if isinstance(head, str) and head in HEAD_KINDS:
            if is_bag(head) and model is not None:
                raise L3MVNError(f"the {head} head reads a bag of objects, not sentence embeddings: drop {model!r}")
            embedder = (model or MINILM).lower()
            key = head if is_bag(head) else embedder if head == "rooms" else f"{embedder}-{head}"
            if key not in SHIPPED_HEADS:
                raise L3MVNError(
                    f"no shipped head of kind {head!r} for embedder {embedder!r} "
                    f"(shipped: {', '.join(SHIPPED_HEADS)}); train one with `l3mvn train-head --model ...` "
                    "and pass its file"
                )
            head = SHIPPED_HEADS[key]
        elif isinstance(head, str) and not Path(head).exists():
            raise L3MVNError(f"unknown feed-forward head {head!r}; valid: {', '.join(HEAD_KINDS)} or a head file")
        self.head, self.meta = load_head(head)
        if tuple(self.meta.get("goals", ())) != self.goals:
            raise L3MVNError(f"head {head} was trained for goals {self.meta.get('goals')}, not {self.goals}")
        self.kind = self.meta.get("kind", "rooms")
        if self.kind not in HEAD_KINDS:
            raise L3MVNError(f"head {head} is of kind {self.kind!r}; valid: {', '.join(HEAD_KINDS)}")
        if "object_filter" not in kw:
            self.object_filter = self.meta.get("object_filter", self.object_filter)
        # A bag head reads its vocabulary's multi-hot vector: no sentence encoder is loaded at all.
        self.vocabulary: tuple[str, ...] | None = None
        self.encoder = None
        self.model_name: str | None = None
        if self.meta.get("features") == BAG_FEATURES:
            if model is not None:
                raise L3MVNError(f"head {head} reads a bag of objects, not sentence embeddings: drop {model!r}")
            self.vocabulary = tuple(self.meta.get("vocabulary", ()))
            if len(self.vocabulary) != self.head.in_dim:
                raise L3MVNError(
                    f"head {head}: a vocabulary of {len(self.vocabulary)} objects for a {self.head.in_dim}-d input"
                )
        else:
            trained_on = str(self.meta.get("encoder", MINILM))
            if model is not None and resolve(model) != resolve(trained_on):
                raise L3MVNError(f"head {head} reads {trained_on!r} embeddings, not {model!r}: give {trained_on!r}")
            self.model_name = trained_on
            self.encoder = load_sentence_encoder(trained_on)
            if self.encoder.dim != self.head.in_dim:
                raise L3MVNError(
                    f"head {head} expects {self.head.in_dim}-d embeddings; {trained_on!r} gives {self.encoder.dim}"
                )
        self._metres: dict[ObjectKey, np.ndarray] = {}

    @property
    def predicts_distance(self) -> bool:
        return base_kind(self.kind) == "frontiers"

    def features(self, keys: list[ObjectKey]) -> np.ndarray:
        """The head's input rows: the bag of objects, or the embedding of the paper's sentence."""
        if self.vocabulary is not None:
            return bag_features(keys, self.vocabulary)
        assert self.encoder is not None  # a head without a vocabulary reads sentence embeddings
        return self.encoder.encode([feedforward_query(k) for k in keys])

    @torch.inference_mode()
    def logits(self, keys: list[ObjectKey]) -> torch.Tensor:
        out: torch.Tensor = self.head(torch.from_numpy(self.features(keys)))  # torch types a module call as Any
        return out

    def expected_distance(self, object_sets: Sequence[Iterable[str]]) -> np.ndarray:
        """(frontiers, goals) expected metres from each frontier to each goal (frontier head only);
        a frontier with no object gets the head's answer for "nothing", which the data taught too."""
        if not self.predicts_distance:
            raise L3MVNError(f"the {self.kind} head predicts p(goal), not distances; use a frontiers head")
        keys = [tuple(sorted(self.query_objects(s))) for s in object_sets]
        new = [k for k in dict.fromkeys(keys) if k not in self._metres]
        if new:
            self._metres.update(zip(new, self.logits(new).numpy().astype(np.float64)))
        return np.stack([self._metres[k] for k in keys]) if keys else np.zeros((0, len(self.goals)))

    def clear_cache(self) -> None:
        super().clear_cache()
        self._metres.clear()

    def queries(self, objects: Iterable[str]) -> dict[str, str]:
        """One input for all goals: the head reads the sentence's embedding (or the bag of objects,
        shown as such: no sentence exists for a bag head) and outputs every goal's number."""
        key = self.query_objects(objects)
        if not key:
            return {}
        if self.vocabulary is not None:
            return {"all goals": "bag of objects: " + ", ".join(o for o in key if o in self.vocabulary)}
        return {"all goals": feedforward_query(key)}

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        keys = list(dict.fromkeys(objs for objs, _ in pairs))
        if self.predicts_distance:
            metres = self.expected_distance(keys)
            row = {k: i for i, k in enumerate(keys)}
            return [-float(metres[row[o], self.goals.index(g)]) / self.distance_temperature_m for o, g in pairs]
        logits = self.logits(keys)
        row = {k: i for i, k in enumerate(keys)}
        return [float(logits[row[o], self.goals.index(g)]) for o, g in pairs]
