"""A cold ``nl2policy translate`` loads only what it needs (issue 29): MiniLM's tokenizer straight
from tokenizer.json and its int8 forward from a saved TorchScript file, never transformers. Both
must be exactly what the translator was trained on."""

import json
import subprocess
import sys

import pytest

from nl2policy.language.corpus import load_corpus

ODD = ["", "   ", "Über-fast café → airport!!", "x" * 3000, "If I have a passenger... go; else: wait?", "日本語のテキスト", "a\tb\nc"]


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_fast_tokenizer_gives_transformers_pieces_and_offsets(domain):
    from nl2policy.language.models.pretrained import _load, fast_tokenizer

    slow, fast = _load(2)[0], fast_tokenizer()
    assert (fast.token_to_id("[CLS]"), fast.token_to_id("[SEP]")) == (slow.cls_token_id, slow.sep_token_id)
    for text in [s.description for s in load_corpus(domain)] + ODD:
        usual = slow(text, add_special_tokens=False, return_offsets_mapping=True)
        enc = fast.encode(text, add_special_tokens=False)
        assert enc.ids == usual["input_ids"], text[:60]
        assert [tuple(o) for o in enc.offsets] == [tuple(o) for o in usual["offset_mapping"]], text[:60]


def test_saved_forward_is_the_traced_forward_bit_for_bit(one_torch_thread):
    import torch

    from nl2policy.language.models import pretrained

    pretrained.saved_forward.cache_clear()
    built = pretrained.saved_forward(2)  # builds and saves (or loads what an earlier test saved)
    assert pretrained.saved_forward_path(2).is_file()
    pretrained.saved_forward.cache_clear()
    loaded = pretrained.saved_forward(2)
    traced = pretrained._forward(2)
    with torch.inference_mode():
        for n in (1, 16, 90, pretrained.MAX_PIECES):
            ids = torch.randint(1000, 20000, (1, n))
            assert torch.equal(loaded(ids), traced(ids)) and torch.equal(built(ids), traced(ids)), n


def test_a_damaged_saved_forward_is_rebuilt(one_torch_thread, tmp_path, monkeypatch):
    from nl2policy.language.models import pretrained

    pretrained.saved_forward(2)
    # damage a copy in a data folder of this test's own: the user's is shared with every other
    # test process (pytest-xdist), whose translations would load the damaged file meanwhile
    shared = pretrained.saved_forward_path(2)
    monkeypatch.setenv("NL2POLICY_HOME", str(tmp_path))
    path = pretrained.saved_forward_path(2)
    assert path != shared
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"not a torchscript file")
    pretrained.saved_forward.cache_clear()
    try:
        pretrained.saved_forward(2)
    finally:
        pretrained.saved_forward.cache_clear()  # later tests load the user's file again
    import torch

    torch.jit.load(str(path))  # rewritten whole


COLD = """
import json, sys
from nl2policy.cli import app
try:
    app(["translate", "--domain", "taxi", "--json", sys.argv[1]])
except SystemExit as exc:
    assert not exc.code, exc.code
training = sorted(m for m in sys.modules if m.startswith(TRAINING))
print(json.dumps({"transformers": "transformers" in sys.modules, "training": training}))
"""
TRAINING = ("nl2policy.language.train", "nl2policy.language.members", "nl2policy.language.dataset",
            "nl2policy.language.augment", "nl2policy.language.synthetic", "nl2policy.language.shipping")
"""The training stack: a translation loads a model and never needs any of it."""
COLD = f"TRAINING = {TRAINING!r}\n" + COLD


def test_cold_translate_imports_neither_transformers_nor_training():
    from nl2policy.language.translate import translate

    text = "If I have a passenger I drive to the airport, otherwise I go to the city."
    subprocess.run([sys.executable, "-c", COLD, text], capture_output=True, text=True, timeout=300, check=True)  # builds the cache
    proc = subprocess.run([sys.executable, "-c", COLD, text], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.strip().splitlines()
    assert json.loads(lines[-1]) == {"transformers": False, "training": []}
    assert json.loads(lines[-2]) == translate("taxi", text).to_json()  # the same translation as in-process


def test_importing_translate_loads_no_training_module():
    code = ("import sys, nl2policy.language.translate, nl2policy.cli\n"
            f"print(sorted(m for m in sys.modules if m.startswith({TRAINING!r})))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[]"


def test_the_executable_ends_fast_with_all_its_output_written():
    """`nl2policy translate` skips the interpreter's teardown (os._exit): whatever it printed
    to a pipe must be there, warnings on stderr included."""
    from nl2policy.language.translate import translate

    text = "If I have a passenger go to the airport"
    expected = translate("taxi", text)
    assert expected.warnings  # the check below needs some
    proc = subprocess.run([sys.executable, "-m", "nl2policy.cli", "translate", "--domain", "taxi", "--json", text],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout) == expected.to_json()
    proc = subprocess.run([sys.executable, "-m", "nl2policy.cli", "translate", "--domain", "taxi", text],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stdout.rstrip().endswith(f"confidence: {expected.confidence:.2f}")
    assert proc.stderr.count("warning:") == len(expected.warnings) and "Quantizer" not in proc.stderr
