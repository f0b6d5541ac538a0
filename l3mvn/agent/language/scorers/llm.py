"""Zero-shot scoring with a generative LM that installs offline (``l3mvn.agent.language.llm``).

Two prompts (``LLM_PROMPTS``):

* ``paper``: the paper's query W = "A frontier area containing o1, ..., ok, t." scored by its
  log-likelihood log p(W) (every token, from the model's start of text). The objects' part is the same
  for every goal, so it runs once and each goal continues from its cached state.
* ``contrastive``: three worked examples in a fixed format, whose answers lie outside the goal set (so
  they show the format without favouring a goal), then "Near o1, ..., ok, there is a" and the goal;
  the score is log p(goal | objects) - log p(goal | no objects): the goal's own prior (a short, common
  word is likely anywhere) subtracted, so only what the objects say about it is left.

Scores are softmax(score / temperature) over the six goals (``Scorer``), and every raw score is also
kept on disk beside the converted model (``scores.jsonl``), by prompt, objects and goal, so a model
scores an object set once across episodes, runs and worker processes.
"""

from __future__ import annotations

import copy
import hashlib
import inspect
import json
import logging
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import torch

from l3mvn.agent.language.llm import LoadedLLM, load_llm
from l3mvn.agent.language.queries import object_list, zero_shot_query
from l3mvn.agent.language.scorers.base import ObjectKey, Scorer, register
from l3mvn.agent.language.vocabulary import query_phrase
from l3mvn.core.config.policy import LLM_PROMPTS, PolicyConfig
from l3mvn.core.errors import L3MVNError

log = logging.getLogger(__name__)

# Worked examples of the contrastive prompt: everyday rooms whose answer is no ObjectNav goal.
_EXAMPLES = (
    ("stove, oven, sink", "kettle"),
    ("desk, monitor, keyboard", "mouse"),
    ("towel, shampoo, bathtub", "bath mat"),
)
_NOTHING = "nothing in particular"


def contrastive_context(objects: Sequence[str]) -> str:
    """The contrastive prompt up to the goal: the examples, then the frontier's objects."""
    shots = "".join(f"Near {objs}, there is a {answer}.\n" for objs, answer in _EXAMPLES)
    return f"{shots}Near {object_list(objects) if objects else _NOTHING}, there is a"


@register("llm")
class LLMScorer(Scorer):
    """A named GGUF model (``smollm2-135m``, ``gemma3-270m``) or a .gguf path; ``loaded`` takes a model
    built elsewhere (tests build a tiny one)."""

    temperature = 1.0

    def __init__(
        self,
        model: str = PolicyConfig.llm,
        prompt: str = PolicyConfig.llm_prompt,
        loaded: LoadedLLM | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(**kw)
        if prompt not in LLM_PROMPTS:
            raise L3MVNError(f"unknown LLM prompt {prompt!r}; valid: {', '.join(LLM_PROMPTS)}")
        self.prompt = prompt
        self.llm = loaded or load_llm(model)
        self.model_name = self.llm.model_id
        self._disk = _DiskCache(self.llm.folder / "scores.jsonl", _prompt_key(prompt))
        self._priors: dict[str, float] = {}
        # transformers 5 names the key-value cache ``cache``; earlier releases ``past_key_values``.
        self._kv_arg = "cache" if "cache" in inspect.signature(self.llm.model.forward).parameters else "past_key_values"

    @property
    def label(self) -> str:
        return f"{self.name} {self.model_name} ({self.prompt} prompt)"

    def clear_cache(self) -> None:
        """Forget every score, the ones read from disk too (the file stays): the next call runs the model."""
        super().clear_cache()
        self._disk.forget()

    def queries(self, objects: Iterable[str]) -> dict[str, str]:
        """The texts scored for a frontier, by goal (what the dashboard shows)."""
        key = self.query_objects(objects)
        return {g: self.sentence(key, g) for g in self.goals} if key else {}

    def sentence(self, objects: ObjectKey, goal: str) -> str:
        """The sentence scored for one goal: the paper's query, or the contrastive prompt's last line
        (its worked examples, the same for every frontier, come before it)."""
        if self.prompt == "paper":
            return zero_shot_query(objects, goal)
        return f"{contrastive_context(objects).splitlines()[-1]} {query_phrase(goal)}."

    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        out: dict[tuple[ObjectKey, str], float] = {}
        by_objects: dict[ObjectKey, list[str]] = {}
        for objects, goal in pairs:
            hit = self._disk.get(objects, goal)
            if hit is None:
                by_objects.setdefault(objects, []).append(goal)
            else:
                out[(objects, goal)] = hit
        for objects, goals in by_objects.items():
            for goal, score in zip(goals, self._score_set(objects, goals)):
                out[(objects, goal)] = score
                self._disk.put(objects, goal, score)
        return [out[p] for p in pairs]

    def _score_set(self, objects: ObjectKey, goals: list[str]) -> list[float]:
        if self.prompt == "paper":
            return self._continuations("", [zero_shot_query(objects, g) for g in goals], whole=True)
        scores = self._continuations(contrastive_context(objects), [f" {query_phrase(g)}." for g in goals])
        return [s - self._prior(g) for s, g in zip(scores, goals)]

    def _prior(self, goal: str) -> float:
        """log p(goal | the prompt with no objects): how likely the model finds the goal anywhere."""
        if goal not in self._priors:
            self._priors[goal] = self._continuations(contrastive_context(()), [f" {query_phrase(goal)}."])[0]
        return self._priors[goal]

    @torch.inference_mode()
    def _continuations(self, context: str, texts: list[str], whole: bool = False) -> list[float]:
        """log p(text | context) for each text (``whole``: the texts are whole sentences and their
        shared beginning is scored too). The shared tokens run once; each text continues from them."""
        tok, model = self.llm.tokenizer, self.llm.model
        start = [tok.bos_token_id] if tok.bos_token_id is not None else []
        seqs = [start + tok(context + t, add_special_tokens=False)["input_ids"] for t in texts]
        shared = _common_prefix(seqs)
        if not whole:  # the context's own tokens are not scored, even where they merge with the text's
            shared = min(shared, len(start + tok(context, add_special_tokens=False)["input_ids"]))
        if shared < 1:
            raise L3MVNError("an LLM query needs a start-of-text token or a context to score from")
        head = torch.tensor([seqs[0][:shared]])
        run = model(input_ids=head, use_cache=True)
        state = _kv_state(run)
        logp_head = torch.log_softmax(run.logits[0].float(), -1)
        head_score = float(logp_head[:-1].gather(-1, head[0, 1:, None]).sum()) if whole else 0.0
        out = []
        for seq in seqs:
            rest = torch.tensor([seq[shared:]])
            score = head_score + float(logp_head[-1, seq[shared]]) if rest.shape[1] else head_score
            if rest.shape[1] > 1:
                tail = model(input_ids=rest[:, :-1], use_cache=True, **{self._kv_arg: copy.deepcopy(state)})
                logp = torch.log_softmax(tail.logits[0].float(), -1)
                score += float(logp.gather(-1, rest[0, 1:, None]).sum())
            out.append(score)
        return out


def _prompt_key(prompt: str) -> str:
    """The prompt's name and a digest of its wording: scores kept for another wording never count."""
    wording = zero_shot_query(("sink",), "bed") if prompt == "paper" else contrastive_context(("sink",))
    return f"{prompt}-{hashlib.sha1(wording.encode()).hexdigest()[:8]}"


def _kv_state(output: Any) -> Any:
    """The key-value cache a forward pass returned (``cache`` in transformers 5, ``past_key_values`` before)."""
    return output.cache if getattr(output, "cache", None) is not None else output.past_key_values


def _common_prefix(seqs: list[list[int]]) -> int:
    n = min(map(len, seqs))
    for i in range(n):
        if any(s[i] != seqs[0][i] for s in seqs):
            return i
    return n


class _DiskCache:
    """The raw scores a model gave under one prompt, kept in a JSON-lines file shared by processes:
    read once, appended to line by line (each line one ``write``, so appends from several workers do
    not interleave). A line that does not parse is skipped."""

    def __init__(self, path: Path, prompt: str) -> None:
        self.path, self.prompt = path, prompt
        self._warned = False
        self._scores: dict[tuple[ObjectKey, str], float] = {}
        skipped = 0
        if path.is_file():
            for line in path.read_text(errors="replace").splitlines():
                try:
                    rec = json.loads(line)
                    if rec["prompt"] == prompt:
                        self._scores[(tuple(sorted(rec["objects"])), rec["goal"])] = float(rec["score"])
                except (ValueError, KeyError, TypeError):
                    skipped += 1
        if skipped:  # a line cut by a crash or a full disk: those scores are computed again
            log.warning("%s: %d unreadable lines skipped; their scores are computed again", path, skipped)

    def forget(self) -> None:
        self._scores.clear()

    def get(self, objects: ObjectKey, goal: str) -> float | None:
        return self._scores.get((tuple(sorted(objects)), goal))

    def put(self, objects: ObjectKey, goal: str, score: float) -> None:
        self._scores[(tuple(sorted(objects)), goal)] = score
        line = json.dumps({"prompt": self.prompt, "objects": sorted(objects), "goal": goal, "score": score})
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                os.write(fd, (line + "\n").encode())
            finally:
                os.close(fd)
        except OSError as exc:  # the score stands; only the next run pays for it again
            if not self._warned:
                log.warning(
                    "cannot keep LLM scores in %s (%s): they are recomputed next time", self.path, exc.strerror or exc
                )
                self._warned = True
