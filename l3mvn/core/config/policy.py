"""Settings that change what a named policy does (``--scorer``, ``--selection``, ``--seg-noise``, ``--llm``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError

# Language policies: the paper's bound rule, the thresholds of the authors' code, or (with a head that
# predicts distances) the frontier with the least cost-utility metres (C - U / lambda) + expected metres
# on to the goal (see l3mvn.agent.policies.language_policy).
SELECTIONS = ("paper", "official_code", "expected")
# Feed-forward heads: trained on frontiers of house maps, or on room object lists (the paper's recipe).
# The default stays the room head: the frontier head's mean regret per choice is lower on houses held
# out from its training, but whole episodes go no better with it (SR and SPL no higher; numbers:
# docs/benchmarks.md, l3mvn/data/language/MODEL_CARD.md).
# "-bag": the same head, data and recipe on a multi-hot bag of objects, without the language model
# (the ablation that says what MiniLM adds; l3mvn/data/language/MODEL_CARD.md).
HEAD_KINDS = ("frontiers", "rooms", "frontiers-bag", "rooms-bag")
# Beside those object-list heads, the map head: PONI's metres on from the partial map, corrected by the
# words of each frontier's window (a language + map prior, l3mvn.agent.potentials.language_map; the
# policy then chooses by PONI's least total).
MAP_HEAD = "map"
POLICY_HEADS = (*HEAD_KINDS, MAP_HEAD)
DEFAULT_HEAD = "rooms"
HEAD_FILE_SUFFIX = ".pt"
HEAD_SCORER = "feedforward"  # the one language scorer that reads a head
# The generative LM behind the ``llm`` scorer (l3mvn.agent.language.llm): a named model or a .gguf
# path, and the prompt it reads (l3mvn.agent.language.scorers.llm).
LLM_SCORER = "llm"
LLM_PROMPTS = ("paper", "contrastive")


@dataclass(frozen=True)
class PolicyConfig:
    scorer: str | None = None  # language policies: a scorer instead of the policy's default
    selection: str = "paper"
    # The paper's bound B: language alone decides above bound_high, exploration alone below
    # bound_low, and in between the two are fused (see l3mvn.agent.policies.language_policy).
    bound_low: float = 0.15
    bound_high: float = 0.30
    seg_noise: float = 0.0  # map-based policies: perception errors (see l3mvn.agent.perception)
    head: str | None = None  # feed-forward scorer: a head (POLICY_HEADS) instead of DEFAULT_HEAD, or a head file (.pt)
    # ... and the sentence embedder whose head it reads (Emb(W)): minilm, or an LLM (a named one or a
    # .gguf file) embedding the sentence itself; None: minilm, or the embedder a head file names.
    embedder: str | None = None
    llm: str = "smollm2-135m"  # the llm scorer's model: a named model or a .gguf file
    llm_prompt: str = "contrastive"  # ... and its prompt (LLM_PROMPTS; the one that ranked best offline)

    def __post_init__(self) -> None:
        if self.selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {self.selection!r}; valid: {', '.join(SELECTIONS)}")
        if self.head is not None and self.head not in POLICY_HEADS and not self.head.endswith(HEAD_FILE_SUFFIX):
            raise L3MVNError(
                f"unknown feed-forward head {self.head!r}; valid: {', '.join(POLICY_HEADS)} or a head file "
                f"(*{HEAD_FILE_SUFFIX}, from `l3mvn train-head` or `l3mvn poni train-language`)"
            )
        if self.embedder is not None and not self.embedder.strip():
            raise L3MVNError("policy.embedder must name a sentence embedder (minilm, smollm2-135m, ...) or be unset")
        if not 0.0 <= self.bound_low < self.bound_high <= 1.0:
            raise L3MVNError(
                f"the bound must satisfy 0 <= bound_low < bound_high <= 1, got {self.bound_low}, {self.bound_high}"
            )
        if self.llm_prompt not in LLM_PROMPTS:
            raise L3MVNError(f"unknown LLM prompt {self.llm_prompt!r}; valid: {', '.join(LLM_PROMPTS)}")
        if not self.llm.strip():
            raise L3MVNError("policy.llm must name an LLM (smollm2-135m, gemma3-270m) or a .gguf file")
        if not (math.isfinite(self.seg_noise) and 0.0 <= self.seg_noise <= 1.0):
            raise L3MVNError(f"seg_noise must lie in [0, 1], got {self.seg_noise}")
