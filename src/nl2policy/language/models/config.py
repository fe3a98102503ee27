"""Named model configurations: which encoder, decoder, inputs and training data."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace


@dataclass(frozen=True)
class ModelConfig:
    encoder: str  # "flat" (BiGRU over all words) or "han" (words per sentence, then sentences)
    decoder: str  # "seq" (state follows the previous token) or "tree" (state from the parent node)
    minilm: bool  # fuse frozen MiniLM layers into the word inputs
    synthetic: int  # synthetic random-tree pairs added to training (0 = none)
    word_rnn: bool = True  # BiGRU over words; off for MiniLM inputs, which are already contextual
    aug_copies: int = 1  # augmented copies of each training description
    aug_swap: bool = False  # augmented copies also permute the actions they name (language/counterfactual.py)
    epochs: int = 30  # with the cosine schedule in train.fit; 10 left the decoder undertrained
    hidden: int = 64
    embed: int = 48
    lr: float = 3e-3
    batch: int = 32
    dropout: float = 0.3
    synth_per_tree: int = 1  # with synthetic data: fresh descriptions of each training tree
    ensemble: int = 1  # networks trained with consecutive seeds; decoding averages them
    member_draws: bool = False  # each ensemble member trains on its own augmented and synthetic draw
    beam: int = 1  # decoding: hypotheses kept by the beam search (1 = greedy)
    minilm_layers: int = 3  # MiniLM transformer layers run (of 6): accuracy against latency
    leaf_cost: float = 0.0  # decoding: nats a hypothesis pays for an action placed where a question could still go
    mention_cost: float = 0.0  # decoding: nats the final choice pays per action the text names that the tree never takes
    mutants: int = 0  # synthetic pairs whose tree is a one-edit mutant of a training tree (synthetic.mutate)
    coverage: bool = False  # attention that tracks what each word has received (network.Translator.attend; flat encoder)
    seed_offset: int = 0  # added to every member's seed and draw: another training run of the same recipe
    minilm_tune: int = 0  # MiniLM's top layers trained with the translator (0: all frozen)
    minilm_lr: float = 1e-4  # their peak learning rate (the pretrained weights move far less than the rest)
    question_cost: float = 0.0  # decoding: nats the final choice pays per question the text asks that the tree never does
    question_forms: str = "conditions"  # which patterns find those questions (mentions.QUESTION_FORMS)
    rule_cost: float = 0.0  # decoding: nats the final choice pays per rule the text states that the tree breaks (stated_rules.py)
    rule_forms: str = "plain"  # which statements those rules are read from (stated_rules.RULE_FORMS)
    root_cost: float = 0.0  # decoding: nats a tree pays for a root other than the question the text says to ask first
    findings_cost: float = 0.0  # decoding: weight of the learned findings' log-agreement (language/findings.py)
    other_domains: bool = False  # also train on the other domains' real descriptions (dataset.borrowed_pairs; tree decoder)

    def to_dict(self) -> dict:
        return asdict(self)


DECODING_FIELDS = ("ensemble", "beam", "leaf_cost", "mention_cost", "question_cost", "question_forms", "rule_cost",
                   "rule_forms", "root_cost", "findings_cost")
"""The settings that change only how trained networks are decoded (`ensemble`: how many of them)."""


def networks_config(cfg: ModelConfig) -> ModelConfig:
    """`cfg` without its decoding choices: two models train the same networks (on the same fold and
    kind of CPU) exactly when these are equal."""
    return replace(cfg, **{f: getattr(ModelConfig, f) for f in DECODING_FIELDS})


X4_MENTIONS = ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=4, member_draws=True, beam=4, mention_cost=1.0)
"""The config of the default's networks (seq2tree-minilm-synth-x4-mentions, below: DEFAULT_NETWORKS),
named so that the probes of one change to it are written as that change."""

MODELS: dict[str, ModelConfig] = {
    "seq2seq": ModelConfig("flat", "seq", False, 0),
    "seq2tree": ModelConfig("flat", "tree", False, 0),
    "seq2tree-minilm": ModelConfig("flat", "tree", True, 0, minilm_layers=6),
    "han2tree": ModelConfig("han", "tree", False, 0),
    "seq2tree-minilm-synth": ModelConfig("flat", "tree", True, 200, minilm_layers=6),  # + synthetic pairs
    # three of the above (seeds s, s+1, s+2), their step probabilities
    # averaged, each trained on its own draw of augmented and synthetic pairs (the real
    # descriptions are shared), decoded with a beam of 4. One network's accuracy moves by several
    # points with the synthetic draw alone; separate draws make the members differ where a single
    # draw is noise. The table (results/translation/translation.md) sets it beside one network,
    # and its beam beside greedy decoding of the same networks. It costs 3x the training time and
    # more translation time (StackedEncoder and StackedDecoder run the three as one batch;
    # benchmarks/translator_speed.py times it)
    "seq2tree-minilm-synth-x3": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=3, member_draws=True, beam=4),
    # the default until 2026-12-01: the networks of seq2tree-minilm-synth-x3 (same training), whose
    # final choice among the beam's hypotheses pays 1 nat for each action the text names that the
    # tree never takes (language/mentions.py). Written for the errors where a leaf follows the
    # corpus's habit instead of the text ("not in the village: drive to the city" decoded as
    # go_village); the patterns find an action missing from the writer's own tree in 1 of 200 taxi
    # and 3 of 200 highway descriptions, so the check rarely overrules a right tree. translation.md
    # sets each of its folds beside the same networks decoded without the check
    "seq2tree-minilm-synth-x3-mentions": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=3,
                                                     member_draws=True, beam=4, mention_cost=1.0),
    # the default until the eighth session of 2026-12-01, and the default's networks since (the
    # default decodes them with the question check as well; "the default" in the comments below,
    # down to the question checks, means this model): four members with the mention check, the first four of
    # seq2tree-minilm-synth-x6-mentions (members train independently, member m with seed s + m on
    # its own draw), so that model's folds recorded this one's accuracy as well ("its first 4
    # members" in translation.md): on taxi's 15 CV folds 81.50 against three members' 79.83, and
    # leave-writers-out 79.00 against 74.00. Two worker processes train four members in two
    # rounds, as they do three (whose third member trains alone): benchmarks/translator_speed.py
    # on one machine, results/translation/translator_speed.txt (four) against
    # translator_speed-x3-same-machine.txt (three): about 10% more training time, the same latency
    "seq2tree-minilm-synth-x4-mentions": X4_MENTIONS,
    # experimental: the default with twice the synthetic random-tree pairs (400 per member draw).
    # Most of the default's remaining taxi errors are compositional (a subtree the text describes
    # collapsed into one action, a condition nested under the wrong question), the kind of error
    # the synthetic pairs first fixed (seq2tree-minilm against seq2tree-minilm-synth); this asks
    # whether more of them keep helping. Training pairs 880 against 680: about 1.3x the time.
    # They do not: on taxi's CV repeat 0 it scored 80.00 against the default's 83.00 on the same
    # folds (better on 2, worse on 3; "Variants" in results/translation/translation.md), so it
    # stopped there
    "seq2tree-minilm-synth400-x4-mentions": replace(X4_MENTIONS, synthetic=400),
    # experimental: the default with two augmented copies of each training description instead
    # of one (real-writer wording is then 480 of 840 pairs instead of 320 of 680), the other
    # direction from synth400. On taxi's CV repeat 0: 82.00 against the default's 83.00 on the
    # same folds (better on 2, worse on 2), so it stopped there
    "seq2tree-minilm-synth-aug2-x4-mentions": replace(X4_MENTIONS, aug_copies=2),
    # experimental: the default with twice the hidden width (128): is the decoder short of capacity?
    # No: on taxi's CV repeat 0, 75.00 against the default's 83.00 on the same folds (worse on 4
    # of 5), and 1.6x the training time
    "seq2tree-minilm-synth-h128-x4-mentions": replace(X4_MENTIONS, hidden=128),
    # experimental: the other direction, a narrower network (hidden 48). Also below the default on
    # taxi's CV repeat 0: 79.50 against 83.00 on the same folds (better on 1, worse on 4)
    "seq2tree-minilm-synth-h48-x4-mentions": replace(X4_MENTIONS, hidden=48),
    # experimental: the default with more dropout (0.45 against 0.3): the wider network's drop
    # suggests overfitting, so does a more regularised one of the default's width do better? No:
    # on taxi's CV repeat 0, 74.50 against 83.00 on the same folds (worse on all 5)
    "seq2tree-minilm-synth-drop45-x4-mentions": replace(X4_MENTIONS, dropout=0.45),
    # experimental: the default with coverage attention (Translator.attend): its taxi errors are
    # mostly subtrees the text describes but the tree leaves out, under-translation in machine
    # translation's terms, for which coverage was made there. It does not help here: on taxi's CV
    # repeat 0, 80.00 against the default's 83.00 on the same folds (better on 1, worse on 3), and
    # about 1.25x the training time
    "seq2tree-minilm-synth-cov-x4-mentions": replace(X4_MENTIONS, coverage=True),
    # experimental: the default with half its random synthetic trees (100 of 200) replaced by
    # one-edit mutants of the training fold's trees (synthetic.mutate): the unseen trees the
    # default misses are mostly near misses of corpus trees, and random trees are far from them.
    # Same number of training pairs, so the same training time. It does not help: on taxi's CV
    # repeat 0, 78.50 against the default's 83.00 on the same folds (worse on all 5)
    "seq2tree-minilm-synth-mut-x4-mentions": replace(X4_MENTIONS, synthetic=100, mutants=100),
    # not a change: the default's recipe trained again with other seeds (every member's initial
    # weights and draw of augmented and synthetic pairs shifted by 100), to measure how far a
    # second training run alone moves the accuracy on the same folds, which is the yardstick for
    # the probes above. On taxi's 15 CV folds it scored 79.83 against the default's 81.50 (better
    # on 2, worse on 10), and on repeat 0, where the probes ran, 81.00 against 83.00: the default's
    # own recorded run is a favourable draw, and a probe within 2 points of it on repeat 0 is
    # within what retraining alone moves
    "seq2tree-minilm-synth-x4-mentions-rerun": replace(X4_MENTIONS, seed_offset=100),
    # experimental: the default with MiniLM's last layer trained along with the translator (a
    # float32 copy of layer 6 reading the cached, frozen layer 5; its own peak learning rate
    # 1e-4 against the rest's 3e-3). Every knob of the translator on top of frozen features has
    # come out within retraining noise, and what is left are compositional errors on trees no
    # training description had: the one part never adapted to this task is the text encoder.
    # It does not help either: on taxi's CV repeat 0, 82.00 against the default's 83.00 on the
    # same folds (better on 2, worse on 3; the default's recipe retrained with other seeds scored
    # 81.00 there), for about 4x the training time (750 s a fold against 180 s)
    "seq2tree-minilm-synth-tune1-x4-mentions": replace(X4_MENTIONS, minilm_tune=1),
    # not a change: a third training run of the default's recipe (seed_offset 200), whose folds
    # also record accuracy on the test descriptions whose tree no training description has
    # (evaluate.unseen_trees), which older folds do not. On taxi's 15 CV folds 81.67 (the
    # default's recorded run 81.50, the first rerun 79.83); 57.0% right on the 172 test
    # descriptions with an unseen tree, 91.6% on the rest
    "seq2tree-minilm-synth-x4-mentions-rerun2": replace(X4_MENTIONS, seed_offset=200),
    # experimental: the default, also trained on the other domain's real descriptions by the
    # training fold's writers (and their augmented copies; dataset.borrowed_pairs). The eight
    # writers wrote in both domains in one voice each, so the other domain doubles the real text
    # that shows how each of them composes a tree; the labels stay apart (the decoder scores both
    # domains' labels, the grammar allows only the text's domain). It does not help: on taxi's CV
    # repeat 0, 81.00 against the default's 83.00 on the same folds (better on 1, worse on 3),
    # at 1.8x the training time (324 s a fold against 180 s)
    "seq2tree-minilm-synth-cross-x4-mentions": replace(X4_MENTIONS, other_domains=True),
    # the default's networks (the same training: its folds retrain them bit for bit on one kind of
    # CPU), whose final choice among the beam's trees also pays 1 nat for each question the text
    # asks that the tree never does (mentions.named_questions; measured on taxi). Written for the errors
    # where the beam held the writer's tree but preferred a smaller or habitual one: "wait if you're
    # already in the city" decoded without at_city. On taxi's 15 CV folds 83.00 against the
    # default's 81.50 on the same networks (better on 6 folds, worse on none); leave-writers-out
    # 79.00, the same on every fold. The patterns were written reading the whole corpus (as the
    # action patterns were), so CV does not measure them on unread text (mentions.py)
    "seq2tree-minilm-synth-x4-mentions-questions": replace(X4_MENTIONS, question_cost=1.0),
    # the same networks again, the question check now finding questions by the extended forms too
    # (list headers, "Passenger on board?", "city road heavy -> village", `if rider:`; mentions.py):
    # on the corpus they find 96% of the questions the writers' trees ask, against 78% by the
    # conditions alone, and a question missing from the writer's tree in the same 4 of 200
    # descriptions. The cost, 2 nats, is the middle of the plateau (1.5 to 3 nats: 86.0 against
    # 85.5 at 1 nat) on the saved networks of CV repeat 0, in offline analyses of the seventh and
    # eighth sessions of 2026-12-01; repeats 1 and 2 never informed it. Each fold also records the check at 1 nat. On taxi's 15 CV
    # folds 84.17 against 81.50 for the same networks without a question check (better on 10 folds,
    # worse on none; repeats 1 and 2 alone: 83.25 against 80.75) and 83.00 for the conditions-only
    # check at 1 nat; leave-writers-out 81.00 against 79.00 (better on 3 of 4 folds, worse on none).
    # The default of the eighth session of 2026-12-01, until the rule check below
    "seq2tree-minilm-synth-x4-mentions-questions-ext": replace(X4_MENTIONS, question_cost=2.0, question_forms="extended"),
    # the default of the sessions of 2026-12-02 until the stated-first-question check below: the model
    # above, whose final choice also pays for each rule the text states that the
    # tree breaks (stated_rules.py: "no passenger and not in the village: go to the city", and no
    # branch that can do it). 100 nats: in effect a filter, a tree that breaks a stated rule is kept
    # only where every one of the beam's trees breaks one; no writer's own tree breaks a rule its
    # description states (0 of 200), so it is not weighed against the networks' scores. Written for
    # the leaves that follow the corpus's habit instead of the text, read off the errors of CV repeat 0
    # (on its saved networks, 88.0 against 86.0: a scratch analysis). Leave-writers-out 81.50 against
    # the default's 81.00 on the same networks (better on 1 fold, worse on none); CV repeat 0, the
    # folds the rules were written from, 88.00 against 86.00; repeats 1 and 2, held out from writing
    # them, 84.25 against 83.25 (better on 3 folds, worse on none); all 15 folds 85.50 against 84.17.
    # In highway (no rule patterns) only its question check reads anything
    "seq2tree-minilm-synth-x4-mentions-questions-ext-rules": replace(X4_MENTIONS, question_cost=2.0,
                                                                     question_forms="extended", rule_cost=100.0),
    # the model above with the rules read by the extended forms too (stated_rules.py): a quantified rule
    # ("When it's clear, I drive to the city, no matter what") is broken by any state under its
    # condition that gets another action, and an answered question ("Sitting at the airport? Drive to
    # the city") is a rule. No writer's own tree breaks one (0 of 200). Declared in the session of
    # 2026-12-02 before any of its folds ran; on the saved networks of CV repeat 0 (a scratch analysis)
    # 89.0 against the model above's 88.0. Same networks as the model above (its no-rule-check folds
    # reproduce seq2tree-minilm-synth-x4-mentions-questions-ext's, 19 of 19). On taxi's 15 CV folds
    # 87.00 against the model above's 85.50 (better on 6 folds, worse on none), leave-writers-out
    # 83.50 against 81.50 (better on 2 of 4, worse on none). The new forms were written reading the
    # corpus and the model above's errors on all 15 folds, so no fold measures them on unread text
    "seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext": replace(X4_MENTIONS, question_cost=2.0, question_forms="extended",
                                                                         rule_cost=100.0, rule_forms="extended"),
    # the model above, whose beam also pays 5 nats at the root for any question but the one the text
    # says to ask first ("First check whether the village has a long wait", "Everything starts with
    # the traffic", "the passenger comes first": stated_rules.first_question). 61 of the 200 taxi
    # descriptions say which, and every writer's tree asks it first. Paid inside the search, so the
    # beam explores trees under that root; 5 nats (the stated root at under e^-5 of another's
    # probability, where the networks are that sure, still loses) rather than a filter, as a cue
    # misread on a new writer's text should not force the root. Declared in the session of
    # 2026-12-02 before any of its folds ran; on the saved networks of CV repeat 0 (a scratch
    # analysis) 90.0 against the model above's 89.0, the same at 2 and at 100 nats. The default since:
    # on taxi's 15 CV folds 87.83 against the model above's 87.00 (better on 4, worse on none), and
    # 84.50 against 83.50 leave-writers-out (better on 2 of 4, worse on none), decoding the model
    # above's saved fold networks (translation-experiment --networks-from). Written, like the rules,
    # reading the corpus and the errors of all 15 folds. Highway has had question patterns and a stated
    # first question since the third session of 2026-12-02 (mentions.py, stated_rules.first_question;
    # no stated rules there), written reading the highway corpus but no model's highway errors: on
    # highway's 15 CV folds 83.33 against 79.83 for the same networks without them
    # (seq2tree-minilm-synth-x4-mentions; better on 10 folds, worse on none; the paper 80.38), and
    # 81.50 against 78.50 leave-writers-out (better on 3 of 4, worse on none)
    "seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext-root": replace(
        X4_MENTIONS, question_cost=2.0, question_forms="extended", rule_cost=100.0, rule_forms="extended", root_cost=5.0),
    # measured, not a default (six members train over the 5-minute budget): the default's decoding
    # checks on seq2tree-minilm-synth-x6-mentions's networks, the most accurate we train. Declared
    # in the session of 2026-12-02 before any of its folds ran; its first four members decoded
    # with the checks are the default, so its folds also reproduce the default's
    "seq2tree-minilm-synth-x6-mentions-questions-ext-rules": replace(X4_MENTIONS, ensemble=6, question_cost=2.0,
                                                                     question_forms="extended", rule_cost=100.0),
    # experimental: seq2tree-minilm-synth-x3's networks, decoded with a cost of 0.5 nats on each branch that
    # ends early (and no mention check). Most of the ensemble's errors are trees smaller than the
    # writer's (a subtree the text describes, collapsed into one action), and a beam that sums
    # log-probabilities favours fewer nodes. On the repeat-0 CV folds of an exploratory training
    # run (same config; the word GRU computed unpacked, which changes only floating-point rounding)
    # the cost helped, +2.5 (taxi) and +3.5 (highway) points; on seq2tree-minilm-synth-x3's own
    # networks for the same folds it did not (-1.5 / +0.5, results/translation/translation.md,
    # "Decoding choices"): a decoding tweak chosen on one training run did not carry over
    "seq2tree-minilm-synth-x3-leafcost": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=3,
                                                     member_draws=True, beam=4, leaf_cost=0.5),
    # measured, not a default: twice the members (no mention check). Members are trained
    # independently (member m: seed s + m, its own draw s + m), so its first three are
    # seq2tree-minilm-synth-x3's. On 5-fold CV x 3 it beat seq2tree-minilm-synth-x3 on the same
    # folds by about 2 points in both domains (results/translation/translation.md), but it trains
    # 6 members against 3: with two worker processes, three rounds against two, and two rounds
    # already take most of the 5-minute budget
    "seq2tree-minilm-synth-x6": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=6, member_draws=True, beam=4),
    # measured, not a default: the six members with the default's mention check. Its first three
    # and first four members decoded with the check are seq2tree-minilm-synth-x3-mentions and the
    # default, so its folds also score those on the same networks ("Decoding choices" in
    # results/translation/translation.md)
    "seq2tree-minilm-synth-x6-mentions": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=6,
                                                     member_draws=True, beam=4, mention_cost=1.0),
    # experimental: seq2tree-minilm-synth-x3 with counterfactual augmented copies (actions permuted
    # in text and tree, language/counterfactual.py), against the corpus's habit of one action per
    # branch. On CV repeat 0 it was below seq2tree-minilm-synth-x3 (taxi -1.5, highway -3 points)
    "seq2tree-minilm-synth-x3-swap": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=3,
                                                 member_draws=True, beam=4, aug_swap=True),
    # path-conditioned node classifier over frozen MiniLM states (models/pathnet.py); experimental:
    # in a one-fold exploratory check it was well below the default, so it is not the default
    "pathnet-minilm": ModelConfig("flat", "path", True, 0, epochs=30, hidden=96, lr=2e-3, batch=16),
    # tiny and quick, for smoke tests of the plumbing (CLI, saving, loading); not a translator to use
    "smoke": ModelConfig("flat", "tree", False, 0, aug_copies=0, epochs=1, hidden=16, embed=16, batch=64),
}
DEFAULT_MODEL = "seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext-root"
DEFAULT_NETWORKS = "seq2tree-minilm-synth-x4-mentions"
"""The model whose networks the default decodes: the same training, decoded with the action check
only (the default's question and rule checks change nothing but the final choice among the beam's trees).
Changes to the training are measured against it, since they decode as it does."""
