"""The text path's inference forms (issue 20): MiniLM's forward written out equals
``transformers``' ``BertModel``, the referent stage's inference form equals its module form, and
the prompt cache still serves repeated prompts."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from model.config import ReferentConfig
from model.nets.numerals import NUMERIC_FEATURES
from model.nets.text import (
    MiniLMTextEncoder,
    load_minilm,
    load_minilm_forward,
    tokenize,
    validate_prompt,
)
from model.referent.candidates import LIDAR_EVIDENCE, RADAR_EVIDENCE
from model.referent.stage import CandidateBatch, ReferentStage, geometry_width

PROMPTS = (
    "the car ahead",
    "two cyclists on the right side, moving away from us at about twenty km/h",
    "a pedestrian",
)


def test_minilm_forward_equals_bert_model_single_and_padded():
    bert, forward = load_minilm(), load_minilm_forward()
    ids = [tokenize(p, 30)[0] for p in PROMPTS]
    length = max(map(len, ids))
    batch = torch.zeros(len(ids), length, dtype=torch.long)
    valid = torch.zeros(len(ids), length, dtype=torch.bool)
    for b, seq in enumerate(ids):
        batch[b, : len(seq)] = torch.tensor(seq)
        valid[b, : len(seq)] = True
    with torch.inference_mode():
        want = bert(input_ids=batch, attention_mask=valid.long()).last_hidden_state
        got = forward(batch, valid)
        for b, seq in enumerate(ids):
            one = forward(torch.tensor([seq]))[0]
            alone = bert(input_ids=torch.tensor([seq])).last_hidden_state[0]
            torch.testing.assert_close(one, alone, rtol=0, atol=1e-5)
            torch.testing.assert_close(got[b, : len(seq)], want[b, : len(seq)], rtol=0, atol=1e-5)


def test_prompt_cache_serves_a_repeated_prompt():
    encoder = MiniLMTextEncoder(max_tokens=30, cache_size=4)
    first = encoder([PROMPTS[1]])
    # the same prompt as the model passes it on once checked where it enters (validate_prompt)
    again = encoder([validate_prompt(f"  {PROMPTS[1]} ")])
    assert (encoder.cache_misses, encoder.cache_hits) == (1, 1)
    assert torch.equal(first.tokens, again.tokens) and torch.equal(first.numbers, again.numbers)
    both = encoder([PROMPTS[0], PROMPTS[1]])
    assert both.tokens.shape[0] == 2 and encoder.cache_hits == 2
    n = len(tokenize(PROMPTS[1], 30)[0])
    assert torch.equal(both.tokens[1, :n], first.tokens[0])
    assert not both.padding_mask[1, :n].any()


@pytest.mark.parametrize("padded", [False, True])
def test_referent_inference_form_equals_the_module_form(padded):
    torch.manual_seed(0)
    cfg = ReferentConfig()
    stage = ReferentStage(cfg, 384, 48, 40, 44).eval()
    n, k, t = 3, 9, 7
    padding = torch.zeros(n, k, dtype=torch.bool)
    text_padding = torch.zeros(n, t, dtype=torch.bool)
    if padded:
        padding[0, 5:] = True
        padding[2, 1:] = True
        text_padding[1, 4:] = True
    cands = CandidateBatch(
        torch.randn(n, k, geometry_width(cfg)),
        torch.randn(n, k, 48),
        torch.randn(n, k, 40 + LIDAR_EVIDENCE),
        torch.randn(n, k, 44 + RADAR_EVIDENCE),
        padding,
    )
    tokens = torch.randn(n, t, 384) * (~text_padding)[..., None]
    numbers = torch.rand(n, t, NUMERIC_FEATURES)
    with torch.enable_grad():  # the module form (the training path)
        want = stage(cands, tokens, numbers, text_padding).detach()
    with torch.no_grad():
        got = stage(cands, tokens, numbers, text_padding)
    real = ~padding
    np.testing.assert_allclose(got[real].numpy(), want[real].numpy(), rtol=0, atol=1e-5)
    assert torch.equal(got[padding], want[padding])
