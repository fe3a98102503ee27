"""MiniLM word features: aligned to our tokens, and read past the model's window."""

import numpy as np

from nl2policy.language.models.pretrained import DIM, MAX_PIECES, encode_tokens
from nl2policy.language.text import split_sentences


def _tokens(text):
    return [t for sentence in split_sentences(text) for t in sentence]


def test_every_word_of_a_text_longer_than_the_window_gets_features(one_torch_thread):
    text = " ".join(f"Then the taxi drives to the airport number {i}." for i in range(60))
    tokens = _tokens(text)
    assert len(tokens) > MAX_PIECES  # well past one window
    states = encode_tokens(text, tokens, layers=1)
    assert states.shape == (2, len(tokens), DIM)
    assert (np.abs(states[-1]).sum(-1) > 0).all()  # the end of the text is read, not cut off


def test_a_text_inside_one_window_gets_the_models_usual_states(one_torch_thread):
    """Reading in windows must not change a short text: its first word's features are the
    model's own output for that word piece, with the usual [CLS] ... [SEP] around the text."""
    import torch

    from nl2policy.language.models.pretrained import _load

    text = "Drive to the airport if you have a passenger, otherwise wait."
    tokens = _tokens(text)
    states = encode_tokens(text, tokens, layers=2)
    tokenizer, model = _load(2)
    with torch.inference_mode():
        usual = model(**tokenizer(text, return_tensors="pt"), output_hidden_states=True).hidden_states
    assert tokens[0].text.lower() == "drive" and tokenizer.tokenize(text)[0] == "drive"  # one piece, at index 1
    for layer in range(3):
        assert np.allclose(states[layer, 0], usual[layer][0, 1].numpy(), atol=2e-2)


def test_the_traced_forward_gives_the_eager_models_states_bit_for_bit(one_torch_thread):
    """Translation and training read MiniLM through a TorchScript trace (pretrained._forward);
    it must be the eager model's arithmetic exactly, at any length up to the window (the trace
    saw one length only)."""
    import torch

    from nl2policy.language.models.pretrained import _forward, _HiddenStates, _load

    traced, eager = _forward(2), _HiddenStates(_load(2)[1]).eval()
    assert isinstance(traced, torch.jit.ScriptModule)
    with torch.inference_mode():
        for n in (1, 2, 15, 16, 17, 90, MAX_PIECES):
            ids = torch.randint(1000, 20000, (1, n))
            assert torch.equal(traced(ids), eager(ids)), n


def test_a_forward_that_cannot_be_traced_falls_back_to_the_eager_model(monkeypatch):
    import torch

    from nl2policy.language.models import pretrained

    def refuse(*args, **kwargs):
        raise RuntimeError("no tracing here")

    monkeypatch.setattr(torch.jit, "trace", refuse)
    pretrained._forward.cache_clear()
    try:
        assert isinstance(pretrained._forward(2), pretrained._HiddenStates)
    finally:
        pretrained._forward.cache_clear()
