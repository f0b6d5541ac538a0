"""Feed-forward scoring (the paper's second paradigm): "This frontier contains o1, ..., and ok." ->
sentence embedding -> trained head -> softmax over goals (temperature 1) -> p(goal).

One forward per unique object set gives all six goals' logits; they fill six cache entries.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch

from l3mvn.errors import L3MVNError
from l3mvn.language.head import SHIPPED_HEADS, load_head
from l3mvn.language.models import MINILM, load_sentence_encoder
from l3mvn.language.queries import feedforward_query
from l3mvn.language.scorers.base import ObjectKey, Scorer, register


@register("feedforward")
class FeedForwardScorer(Scorer):
    temperature = 1.0

    def __init__(self, model: str = MINILM, head: str | Path | None = None, **kw):
        super().__init__(**kw)
        if head is None:
            if model.lower() not in SHIPPED_HEADS:
                raise L3MVNError(
                    f"no shipped head for embedder {model!r} (shipped: {', '.join(SHIPPED_HEADS)}); "
                    "train one with `l3mvn train-head --model ...` and pass head=<file>"
                )
            head = SHIPPED_HEADS[model.lower()]
        self.model_name = model
        self.head, self.meta = load_head(head)
        if tuple(self.meta.get("goals", ())) != self.goals:
            raise L3MVNError(f"head {head} was trained for goals {self.meta.get('goals')}, not {self.goals}")
        self.encoder = load_sentence_encoder(model)
        if self.encoder.dim != self.head.in_dim:
            raise L3MVNError(f"head {head} expects {self.head.in_dim}-d embeddings; {model!r} gives {self.encoder.dim}")

    @torch.inference_mode()
    def logits(self, keys: list[ObjectKey]) -> torch.Tensor:
        emb = self.encoder.encode([feedforward_query(k) for k in keys])
        return self.head(torch.from_numpy(emb))

    def queries(self, objects) -> dict[str, str]:
        """One sentence for all goals: the head reads its embedding and outputs p(goal)."""
        key = self.query_objects(objects)
        return {"all goals": feedforward_query(key)} if key else {}

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        keys = list(dict.fromkeys(objs for objs, _ in pairs))
        logits = self.logits(keys)
        row = {k: i for i, k in enumerate(keys)}
        return [float(logits[row[o], self.goals.index(g)]) for o, g in pairs]
