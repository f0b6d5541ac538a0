"""Masked-LM and causal-LM scorers on tiny models built in-process (no download)."""

import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import pytest  # noqa: E402
import torch  # noqa: E402
from tokenizers import Tokenizer, models, pre_tokenizers, processors, trainers  # noqa: E402
from transformers import (  # noqa: E402
    GPT2Config,
    GPT2LMHeadModel,
    PreTrainedTokenizerFast,
    RobertaConfig,
    RobertaForMaskedLM,
)

from l3mvn.agent.language import GOALS, make_scorer  # noqa: E402
from l3mvn.agent.language.queries import zero_shot_query  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402

CORPUS = [zero_shot_query(objs, g) for objs in [(), ("sink",), ("bed", "desk"), ("oven", "toilet")] for g in GOALS]
CORPUS += [s.replace("A frontier area", "A room") for s in CORPUS]
SETS = [{"sink", "bathtub"}, {"bed"}, {"oven", "refrigerator", "dining table"}]


def _tokenizer(specials):
    tok = Tokenizer(models.WordLevel(unk_token="<unk>"))
    tok.pre_tokenizer = pre_tokenizers.Whitespace()
    tok.train_from_iterator(CORPUS, trainers.WordLevelTrainer(special_tokens=specials))
    return tok


@pytest.fixture(scope="module")
def tiny_mlm():
    tok = _tokenizer(["<s>", "<pad>", "</s>", "<unk>", "<mask>"])
    tok.post_processor = processors.TemplateProcessing(single="<s> $A </s>", special_tokens=[("<s>", 0), ("</s>", 2)])
    fast = PreTrainedTokenizerFast(
        tokenizer_object=tok,
        bos_token="<s>",
        eos_token="</s>",
        pad_token="<pad>",
        unk_token="<unk>",
        mask_token="<mask>",
    )
    torch.manual_seed(0)
    config = RobertaConfig(
        vocab_size=fast.vocab_size,
        hidden_size=16,
        num_hidden_layers=1,
        num_attention_heads=2,
        intermediate_size=32,
        max_position_embeddings=40,
        pad_token_id=1,
    )
    return fast, RobertaForMaskedLM(config).eval()


@pytest.fixture(scope="module")
def tiny_gpt2():
    fast = PreTrainedTokenizerFast(
        tokenizer_object=_tokenizer(["<|endoftext|>", "<unk>"]), eos_token="<|endoftext|>", unk_token="<unk>"
    )
    torch.manual_seed(0)
    config = GPT2Config(vocab_size=fast.vocab_size, n_embd=16, n_layer=1, n_head=2, n_positions=40)
    return fast, GPT2LMHeadModel(config).eval()


def _check_distributions(out):
    for dist in out:
        assert tuple(dist) == GOALS
        assert all(p >= 0 for p in dist.values()) and sum(dist.values()) == pytest.approx(1.0)


def test_mlm_output_is_a_distribution(tiny_mlm):
    _check_distributions(make_scorer("mlm", tokenizer_and_model=tiny_mlm).score(SETS))


def test_causal_output_is_a_distribution(tiny_gpt2):
    _check_distributions(make_scorer("causal", tokenizer_and_model=tiny_gpt2).score(SETS))


@pytest.mark.parametrize("name, fixture", [("mlm", "tiny_mlm"), ("causal", "tiny_gpt2")])
def test_batched_scoring_equals_one_by_one(name, fixture, request):
    lm = request.getfixturevalue(fixture)
    together = make_scorer(name, tokenizer_and_model=lm, batch_size=7).score(SETS)
    for objects, expected in zip(SETS, together):
        alone = make_scorer(name, tokenizer_and_model=lm).score([objects])[0]
        assert alone == pytest.approx(expected, abs=1e-5)


@torch.inference_mode()
def test_pseudo_log_likelihood_equals_the_masking_loop(tiny_mlm):
    tok, model = tiny_mlm
    sentence = "A frontier area containing sink, toilet."
    ids = tok(sentence)["input_ids"]
    expected = 0.0
    for i in range(1, len(ids) - 1):
        masked = torch.tensor([ids])
        masked[0, i] = tok.mask_token_id
        expected += float(torch.log_softmax(model(input_ids=masked).logits[0, i], -1)[ids[i]])
    scorer = make_scorer("mlm", tokenizer_and_model=tiny_mlm, batch_size=3)
    assert scorer.pseudo_log_likelihood([sentence, "A room containing bed."])[0] == pytest.approx(expected, abs=1e-4)


@torch.inference_mode()
def test_causal_score_is_the_negated_lm_loss(tiny_gpt2):
    tok, model = tiny_gpt2
    sentence = "A room containing sink, toilet."
    ids = torch.tensor([tok(sentence)["input_ids"]])
    loss = float(model(input_ids=ids, labels=ids).loss)
    scorer = make_scorer("causal", tokenizer_and_model=tiny_gpt2)
    assert scorer.mean_log_likelihood([sentence, "A room containing bed."])[0] == pytest.approx(-loss, abs=1e-5)


def test_the_cache_hits_on_a_repeated_set(tiny_mlm):
    scorer = make_scorer("mlm", tokenizer_and_model=tiny_mlm)
    scorer.score([{"bed", "desk"}, {"desk", "bed"}])
    assert (scorer.cache_info().misses, scorer.cache_info().hits) == (6, 6)


@pytest.mark.parametrize(
    "name, model", [("mlm", "roberta-large"), ("mlm", "/nonexistent/roberta"), ("causal", "gpt2-large")]
)
def test_a_missing_model_raises_a_clear_error(name, model):
    with pytest.raises(L3MVNError, match=f"cannot load .*{model}.*huggingface-cli download"):
        make_scorer(name, model=model)
