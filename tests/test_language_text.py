"""Tokenizer and vocabulary: the writing styles of the corpus and the <unk> rule."""

from nl2policy.language.text import MIN_FREQ, UNK, WordVocab, split_sentences, tokenize


def words(sentences):
    return [[t.text for t in s] for s in sentences]


def test_texting_shorthand_is_expanded():
    assert tokenize("ok so if ur carrying someone b/c theres ppl") == [
        "okay", "so", "if", "your", "carrying", "someone", "because", "there", "is", "people"]


def test_numbered_steps_and_bullets_are_sentences_without_their_markers():
    text = "Here's the plan:\n1. In the village\n   a) passenger aboard: airport\n- car close → slow down"
    assert words(split_sentences(text)) == [
        ["here", "is", "the", "plan"], ["in", "the", "village"], ["passenger", "aboard", "airport"],
        ["car", "close", "->", "slow", "down"]]


def test_pseudo_code_names_are_split_and_lines_are_sentences():
    text = "if isCarryingSomeone:\n    drive to airport\nelse:\n    wait_for_rider"
    assert words(split_sentences(text)) == [["if", "is", "carrying", "someone"], ["drive", "to", "airport"], ["else"], ["wait", "for", "rider"]]


def test_arrows_do_not_split_a_rule_and_spans_point_into_the_raw_text():
    text = "rightFree? -> change lanes. nope -> slow down"
    sentences = split_sentences(text)
    assert words(sentences) == [["right", "free", "->", "change", "lanes"], ["no", "->", "slow", "down"]]
    for s in sentences:
        for tok in s:
            raw = text[tok.start:tok.end].lower()
            assert tok.text in raw or tok.text in ("no", "->")


def test_rare_words_map_to_unk():
    texts = ["the taxi waits"] * MIN_FREQ + ["the taxi drives"] * (MIN_FREQ - 1)
    vocab = WordVocab.build(texts)
    assert vocab.encode(["taxi", "waits", "drives", "never"]) == [vocab.id("taxi"), vocab.id("waits"), 1, 1]
    assert vocab.itos[1] == UNK and "drives" not in vocab.stoi and "waits" in vocab.stoi
