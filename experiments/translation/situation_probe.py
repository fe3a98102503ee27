"""Probe (issue 26): a learned reader of situations that reranks the beam.

Most of v2's remaining leave-trees-out errors in taxi have the right questions, actions and
root but a leaf under the wrong branch, or a question's branches swapped: what the findings
(per label) cannot see. Here each leaf is a situation, its path's (question, answer) pairs
and its action; one attention query per leaf reads the text (frozen MiniLM + BiGRU, as the
findings), and a tree's score is the mean of its leaves' scores. Trained contrastively: the
gold tree against perturbations of it of exactly those kinds (branches swapped, an action
moved to another leaf, a leaf's action changed, a question changed), softmax over the set.
Decoding: the beam's finished hypotheses, each scored by the beam plus `weight` times the
reader's log-softmax over them.

    .venv/bin/python -m experiments.translation.situation_probe --nets NETS --out results/translation/situations
"""

from __future__ import annotations

import argparse
import json
import math
import random
import time
from pathlib import Path

import torch
from torch import nn

from experiments.translation.evaluate import PROTOCOL_ROUNDS
from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.dataset import member_pairs
from nl2policy.language.decoding import beam_search
from nl2policy.language.findings import LAYERS, FindingsModel, _batch
from nl2policy.language.models.config import MODELS
from nl2policy.language.models.pretrained import DIM, MiniLMCache
from nl2policy.language.translator import TrainedTranslator, collate
from nl2policy.trees import Leaf, Node, Tree, TreeError
from nl2policy.trees.parse import validate

WEIGHTS = (0.0, 0.5, 1.0, 2.0, 4.0)


def leaves(tree: Tree, path: tuple = ()) -> list[tuple[tuple, str]]:
    if isinstance(tree, Leaf):
        return [(path, tree.action)]
    return leaves(tree.yes, path + ((tree.question, True),)) + leaves(tree.no, path + ((tree.question, False),))


def perturbations(tree: Tree, vocab, rng: random.Random, n: int) -> list[Tree]:
    """Up to `n` distinct valid trees near `tree` (the kinds in the module doc)."""
    nodes = []

    def walk(t: Tree, path: tuple) -> None:
        nodes.append(path)
        if isinstance(t, Node):
            walk(t.yes, path + (True,))
            walk(t.no, path + (False,))

    walk(tree, ())

    def get(t: Tree, path: tuple) -> Tree:
        for a in path:
            t = t.yes if a else t.no
        return t

    def put(t: Tree, path: tuple, new: Tree) -> Tree:
        if not path:
            return new
        return Node(t.question, put(t.yes, path[1:], new), t.no) if path[0] else Node(t.question, t.yes, put(t.no, path[1:], new))

    inner = [p for p in nodes if isinstance(get(tree, p), Node)]
    outer = [p for p in nodes if isinstance(get(tree, p), Leaf)]
    out, seen = [], {json.dumps(str(tree))}
    for _ in range(20 * n):
        if len(out) >= n:
            break
        kind = rng.randrange(4)
        if kind == 0 and inner:  # a question's branches swapped
            p = rng.choice(inner)
            t = get(tree, p)
            cand = put(tree, p, Node(t.question, t.no, t.yes))
        elif kind == 1 and len(outer) > 1:  # two leaves' actions exchanged
            p, q = rng.sample(outer, 2)
            a, b = get(tree, p), get(tree, q)
            cand = put(put(tree, p, b), q, a)
        elif kind == 2 and outer:  # a leaf's action changed
            p = rng.choice(outer)
            cand = put(tree, p, Leaf(rng.choice([a for a in vocab.action_ids if a != get(tree, p).action])))
        elif kind == 3 and inner:  # a question changed
            p = rng.choice(inner)
            t = get(tree, p)
            cand = put(tree, p, Node(rng.choice([q for q in vocab.question_ids if q != t.question]), t.yes, t.no))
        else:
            continue
        key = json.dumps(str(cand))
        if key in seen:
            continue
        seen.add(key)
        try:
            out.append(validate(cand, vocab))
        except TreeError:
            continue
    return out


class SituationReader(nn.Module):
    def __init__(self, n_questions: int, n_actions: int, hidden: int = 128) -> None:
        super().__init__()
        self.mix = nn.Parameter(torch.zeros(LAYERS + 1))
        self.norm = nn.LayerNorm(DIM)
        self.rnn = nn.GRU(DIM, hidden // 2, batch_first=True, bidirectional=True)
        self.drop = nn.Dropout(0.3)
        self.cond = nn.Embedding(2 * n_questions, hidden)
        self.act = nn.Embedding(n_actions, hidden)
        self.query = nn.Sequential(nn.Linear(hidden, hidden), nn.Tanh(), nn.Linear(hidden, hidden))
        self.score = nn.Bilinear(hidden, hidden, 1)

    def text(self, states: torch.Tensor) -> torch.Tensor:
        x = torch.einsum("l,blnd->bnd", torch.softmax(self.mix, 0), states)
        return self.drop(self.rnn(self.drop(self.norm(x)))[0])

    def tree_scores(self, memory: torch.Tensor, mask: torch.Tensor, trees: list[list[tuple[list[int], int]]]) -> torch.Tensor:
        """memory (N, h) of one text; trees: each a list of leaves (condition ids, action id)."""
        out = []
        for leaves_ in trees:
            q = torch.stack([self.cond(torch.tensor(c)).sum(0) if c else torch.zeros(self.act.embedding_dim) for c, _ in leaves_])
            q = self.query(q + self.act(torch.tensor([a for _, a in leaves_])))
            att = torch.softmax((memory @ q.T).T.masked_fill(~mask[None], -1e9), -1)
            ctx = att @ memory
            out.append(self.score(ctx, q).mean())
        return torch.stack(out)


def encode_tree(tree: Tree, qi: dict, ai: dict) -> list[tuple[list[int], int]]:
    return [([2 * qi[q] + (0 if a else 1) for q, a in path], ai[action]) for path, action in leaves(tree)]


def train_reader(domain: str, pairs, cache: MiniLMCache, seed: int = 0, epochs: int = 8, negatives: int = 8) -> SituationReader:
    vocab = get_domain(domain).vocab
    qi = {q: i for i, q in enumerate(vocab.question_ids)}
    ai = {a: i for i, a in enumerate(vocab.action_ids)}
    torch.manual_seed(seed)
    rng = random.Random(seed)
    net = SituationReader(len(qi), len(ai))
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    order = list(range(len(pairs)))
    for _ in range(epochs):
        rng.shuffle(order)
        net.train()
        for i in range(0, len(order), 16):
            idx = order[i:i + 16]
            states, mask = _batch([pairs[j][0] for j in idx], cache)
            memory = net.text(states)
            loss = torch.zeros(())
            for b, j in enumerate(idx):
                gold = pairs[j][1]
                cands = [gold] + perturbations(gold, vocab, rng, negatives)
                scores = net.tree_scores(memory[b], mask[b], [encode_tree(t, qi, ai) for t in cands])
                loss = loss - torch.log_softmax(scores, 0)[0]
            opt.zero_grad()
            (loss / len(idx)).backward()
            opt.step()
    return net.eval()


def probe_fold(path: Path, cache: MiniLMCache) -> dict:
    saved = torch.load(path, weights_only=False)
    domain, name = saved["domain"], saved["name"]
    key = path.stem[len(f"{domain}-{name}-"):]
    specs = load_corpus(domain, rounds=PROTOCOL_ROUNDS[key.split("-")[0]])
    cfg = MODELS[name]
    model = TrainedTranslator.from_states(domain, name, cfg, saved["words"], saved["nets"][:cfg.ensemble], cache)
    model.findings = FindingsModel.from_state(saved["findings"], cache)
    pairs = member_pairs(domain, specs, saved["train"], cfg)
    pairs = pairs(0) if callable(pairs) else pairs
    start = time.time()
    reader = train_reader(domain, pairs, cache)
    seconds = time.time() - start
    vocab = get_domain(domain).vocab
    qi = {q: i for i, q in enumerate(vocab.question_ids)}
    ai = {a: i for i, a in enumerate(vocab.action_ids)}
    texts = [specs[i].description for i in saved["test"]]
    golds = [specs[i].tree for i in saved["test"]]
    out = {"domain": domain, "fold": key, "n": len(texts), "reader_seconds": round(seconds, 1)}
    with torch.inference_mode():
        hyps = []
        for i in range(0, len(texts), 32):
            chunk = texts[i:i + 32]
            hyps += beam_search(model, collate([model.encode(t) for t in chunk]), chunk, every=True)
        states, mask = _batch(texts, cache)
        right = {w: 0 for w in WEIGHTS}
        in_beam = 0
        for b, (hs, gold) in enumerate(zip(hyps, golds)):
            memory = reader.text(states[b:b + 1])[0]
            r = torch.log_softmax(reader.tree_scores(memory, mask[b], [encode_tree(t, qi, ai) for t, _, _ in hs]), 0)
            in_beam += any(t == gold for t, _, _ in hs)
            for w in WEIGHTS:
                best = max(range(len(hs)), key=lambda k: hs[k][2] + w * float(r[k]))
                right[w] += hs[best][0] == gold
    out["gold_in_beam"] = in_beam / len(texts)
    out.update({f"weight_{w}": right[w] / len(texts) for w in WEIGHTS})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nets", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--beam", type=int, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)
    runs = args.out / "runs.jsonl"
    done = {json.loads(l)["fold"] + json.loads(l)["domain"] for l in runs.read_text().splitlines()} if runs.is_file() else set()
    caches: dict[str, MiniLMCache] = {}
    for path in sorted(args.nets.glob("*.pt")):
        domain = path.stem.split("-")[0]
        if any(path.stem.endswith(d[:-len(domain)]) and d.endswith(domain) for d in done):
            continue
        result = probe_fold(path, caches.setdefault(domain, MiniLMCache()))
        print(json.dumps(result), flush=True)
        with runs.open("a") as fh:
            fh.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
