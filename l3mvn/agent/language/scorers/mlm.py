"""Zero-shot scoring with a masked LM by pseudo-log-likelihood (the paper; default RoBERTa-large).

PLL(W) = sum_i log p(w_i | W with w_i masked) over W's non-special tokens. All masked variants of
all queries go through the model together in batches of ``batch_size`` sequences, so a call costs
ceil(sum of query lengths / batch_size) forwards. Normalisation: ``softmax(PLL / temperature)``
over the goals with temperature 1, i.e. p(t) proportional to the pseudo-likelihood of the sentence
naming t (multi-token goal names such as "potted plant" pay for their extra token, as in the paper).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import torch

from l3mvn.agent.language.models import load_masked_lm
from l3mvn.agent.language.queries import zero_shot_query
from l3mvn.agent.language.scorers.base import ObjectKey, Scorer, register
from l3mvn.core.errors import L3MVNError

if TYPE_CHECKING:
    from transformers import PreTrainedModel, PreTrainedTokenizerBase


@register("mlm")
class MaskedLMScorer(Scorer):
    temperature = 1.0

    def __init__(
        self,
        model: str = "roberta-large",
        batch_size: int = 64,
        tokenizer_and_model: tuple[PreTrainedTokenizerBase, PreTrainedModel] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(**kw)
        if batch_size < 1:
            raise L3MVNError(f"batch_size must be >= 1, got {batch_size}")
        self.model_name, self.batch_size = model, batch_size
        self.tokenizer, self.model = tokenizer_and_model or load_masked_lm(model)
        if self.tokenizer.mask_token_id is None:
            raise L3MVNError(f"model {model!r} has no mask token: not a masked LM")

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        return self.pseudo_log_likelihood([zero_shot_query(objs, goal) for objs, goal in pairs])

    @torch.inference_mode()
    def pseudo_log_likelihood(self, sentences: list[str]) -> list[float]:
        tok = self.tokenizer
        ids = [tok(s)["input_ids"] for s in sentences]
        special = set(tok.all_special_ids)
        variants = [(k, i) for k, seq in enumerate(ids) for i, t in enumerate(seq) if t not in special]
        totals = [0.0] * len(sentences)
        for start in range(0, len(variants), self.batch_size):
            chunk = variants[start : start + self.batch_size]
            width = max(len(ids[k]) for k, _ in chunk)
            batch = torch.full((len(chunk), width), tok.pad_token_id, dtype=torch.long)
            attention = torch.zeros((len(chunk), width), dtype=torch.long)
            for row, (k, i) in enumerate(chunk):
                batch[row, : len(ids[k])] = torch.tensor(ids[k])
                attention[row, : len(ids[k])] = 1
                batch[row, i] = tok.mask_token_id
            logp = torch.log_softmax(self.model(input_ids=batch, attention_mask=attention).logits.float(), -1)
            for row, (k, i) in enumerate(chunk):
                totals[k] += float(logp[row, i, ids[k][i]])
        return totals
