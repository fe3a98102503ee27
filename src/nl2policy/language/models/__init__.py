"""The translators: one encoder-decoder family whose parts reproduce the paper's models.

Seq2Seq = flat BiGRU encoder + sequential decoder over the pre-order tree tokens;
Seq2Tree = same encoder + binary tree decoder (each node decoded from its parent's state);
Seq2Tree+MiniLM = Seq2Tree whose word inputs are fused with frozen MiniLM layers (ELMo-style;
all six layers for the MiniLM models: six read new writers better than three in our checks);
HAN2Tree = hierarchical (word, sentence) attention encoder + tree decoder;
seq2tree-minilm-synth = Seq2Tree+MiniLM trained with synthetic pairs as well;
seq2tree-minilm-synth-x3 = an ensemble of three of those (decoding averages their steps, beam of 4);
seq2tree-minilm-synth-x3-mentions = the same ensemble, whose final choice among the beam's trees
also pays 1 nat per action the text names that the tree never takes (language/mentions.py);
seq2tree-minilm-synth-x4-mentions (the default's networks) = the same with four members: a fourth member
gained taxi 1.7 points (CV) and 5 (leave-writers-out) for no more training time on two cores;
seq2tree-minilm-synth-x3-leafcost (experimental) = the x3 ensemble, whose beam also charges a
branch that ends early (an action where a question could still go) 0.5 nats;
seq2tree-minilm-synth-x3-swap (experimental) = x3 trained with counterfactual augmented
copies (the actions a description names permuted in text and tree, language/counterfactual.py);
seq2tree-minilm-synth-x6 and -x6-mentions (measured, not defaults) = six members: 1.5x the default's training time;
seq2tree-minilm-synth400-, -synth-aug2-, -synth-h128-, -synth-h48- and -synth-drop45-x4-mentions
(experimental) = the default with twice the synthetic pairs, two augmented copies per description,
a hidden width of 128 or 48, or dropout 0.45: each below the default on taxi's CV repeat 0;
so are -synth-cov-x4-mentions (coverage attention, `network.Translator.attend`),
-synth-mut-x4-mentions (half the random synthetic trees replaced by one-edit mutants of training
trees, `synthetic.mutate`) and -synth-tune1-x4-mentions (MiniLM's last layer trained along with the translator,
`ModelConfig.minilm_tune`, `network.Translator._minilm_states`) and -synth-cross-x4-mentions (also
trained on the other domain's descriptions by the same writers, `dataset.borrowed_pairs`);
seq2tree-minilm-synth-x4-mentions-questions = the default's networks, whose final choice among the
beam's trees also pays 1 nat per question the text asks that the tree never asks
(mentions.named_questions; taxi only until the highway patterns of the third session of 2026-12-02);
seq2tree-minilm-synth-x4-mentions-questions-ext = the same networks, the question check finding
questions by their extended forms too (list headers, code) and paying 2 nats for each;
seq2tree-minilm-synth-x4-mentions-questions-ext-rules = the model above, whose final
choice also keeps away from a tree that breaks a rule the text states (language/stated_rules.py);
seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext = the same, the rules also read by their
extended forms ("..., no matter what" holds in every state under it; "At the airport? Drive to the city");
seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext-root (the default) = the model above, whose beam also
pays 5 nats at the root for any question but the one the text says to ask first
(stated_rules.first_question);
seq2tree-minilm-synth-x6-mentions-questions-ext-rules (measured) = the default's checks on the six
members of seq2tree-minilm-synth-x6-mentions (over the training budget);
seq2tree-minilm-synth-x4-mentions-rerun and -rerun2 = not changes: the default's recipe with other
seeds (`ModelConfig.seed_offset`), to measure what retraining alone moves.
Configurations live in `config.py`; the network in `network.py`.
"""

from nl2policy.language.models.config import MODELS, ModelConfig

__all__ = ["MODELS", "ModelConfig"]
