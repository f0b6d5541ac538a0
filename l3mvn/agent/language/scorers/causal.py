"""Zero-shot scoring with a causal LM by mean token log-likelihood (the official code: GPT-2-large
and "A room containing o1, ..., t.").

Score = mean over tokens 2..n of log p(w_i | w_<i) (what ``model(ids, labels=ids).loss`` negates),
batched with right padding; ``softmax(score / temperature)`` over the goals, temperature 1 as in the
code. ``template="paper"`` uses the paper's "A frontier area containing ..." instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import torch

from l3mvn.agent.language.models import load_causal_lm
from l3mvn.agent.language.queries import object_list, zero_shot_query
from l3mvn.agent.language.scorers.base import ObjectKey, Scorer, register
from l3mvn.agent.language.vocabulary import check_goal
from l3mvn.core.errors import L3MVNError

if TYPE_CHECKING:
    from transformers import PreTrainedModel, PreTrainedTokenizerBase

TEMPLATES = ("code", "paper")


@register("causal")
class CausalLMScorer(Scorer):
    temperature = 1.0

    def __init__(
        self,
        model: str = "gpt2-large",
        template: str = "code",
        batch_size: int = 32,
        tokenizer_and_model: tuple[PreTrainedTokenizerBase, PreTrainedModel] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(**kw)
        if template not in TEMPLATES:
            raise L3MVNError(f"unknown causal template {template!r}; valid: {', '.join(TEMPLATES)}")
        if batch_size < 1:
            raise L3MVNError(f"batch_size must be >= 1, got {batch_size}")
        self.model_name, self.template, self.batch_size = model, template, batch_size
        self.tokenizer, self.model = tokenizer_and_model or load_causal_lm(model)

    def sentence(self, objects: ObjectKey, goal: str) -> str:
        if self.template == "paper":
            return zero_shot_query(objects, goal)
        return f"A room containing {object_list([*objects, check_goal(goal)])}."

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        return self.mean_log_likelihood([self.sentence(objs, goal) for objs, goal in pairs])

    @torch.inference_mode()
    def mean_log_likelihood(self, sentences: list[str]) -> list[float]:
        ids = [self.tokenizer(s)["input_ids"] for s in sentences]
        if any(len(seq) < 2 for seq in ids):
            raise L3MVNError("a causal-LM query needs at least two tokens")
        pad = self.tokenizer.pad_token_id if self.tokenizer.pad_token_id is not None else ids[0][0]
        out: list[float] = []
        for start in range(0, len(ids), self.batch_size):
            chunk = ids[start : start + self.batch_size]
            width = max(map(len, chunk))
            batch = torch.full((len(chunk), width), pad, dtype=torch.long)
            attention = torch.zeros((len(chunk), width), dtype=torch.long)
            for row, seq in enumerate(chunk):
                batch[row, : len(seq)] = torch.tensor(seq)
                attention[row, : len(seq)] = 1
            logp = torch.log_softmax(self.model(input_ids=batch, attention_mask=attention).logits.float(), -1)
            token_logp = logp[:, :-1].gather(-1, batch[:, 1:, None])[..., 0]
            mask = attention[:, 1:].float()
            out += ((token_logp * mask).sum(1) / mask.sum(1)).tolist()
        return out
