"""Whole-tree styles: nested prose, one rule per leaf (plain, formal, numbered or lettered), a
default with its exceptions, an if / else-if chain, an outline, question-and-answer form, a
decision table, pseudo-code, terse arrows, a memo; then what writers wrap around a policy
(intros, asides, summaries, chatter) and how they type it (speech, texting, typos)."""

from __future__ import annotations

import random
from collections import Counter

from nl2policy.language.synthetic.prose import sentence, tell
from nl2policy.language.synthetic.words import Words, english
from nl2policy.trees import Leaf, Tree

Rule = tuple[list[tuple[str, bool]], str]
"""A leaf as a rule: the (question, answer) pairs on its path, and its action."""


def rules_of(tree: Tree, path: tuple = ()) -> list[Rule]:
    if isinstance(tree, Leaf):
        return [(list(path), tree.action)]
    return rules_of(tree.yes, path + ((tree.question, True),)) + rules_of(tree.no, path + ((tree.question, False),))


def _bullet(w: Words) -> str:
    return w.en("bullets")


def _mark(bullet: str, i: int) -> str:
    roman = ["i", "ii", "iii", "iv", "v", "vi", "vii", "viii"]
    return bullet.replace("{n}", str(i + 1)).replace("{l}", "abcdefgh"[i]).replace("{r}", roman[i])


def _conds(conds: list[tuple[str, bool]], w: Words) -> str:
    parts = [w.cond(q, yes) for q, yes in conds]
    if len(parts) > 2 and w.chance(0.5):
        return ", ".join(parts[:-1]) + w.pick([" and ", ", and "]) + parts[-1]
    joined = parts[0]
    for p in parts[1:]:
        joined += w.en("and") + p
    return joined


def nested(tree: Tree, w: Words) -> str:
    return tell(tree, w)[1]


def rules(tree: Tree, w: Words) -> str:
    """One rule per leaf, each with its whole path: "If A and not B, x." The last may be the
    catch-all ("In all other cases, x"), which is true of it given the others."""
    found = rules_of(tree)
    w.rng.shuffle(found) if w.chance(0.3) else None
    bullet = _bullet(w) if w.chance(0.7) else ""
    arrow = w.chance(0.3)
    lines = []
    for i, (conds, action) in enumerate(found):
        if i == len(found) - 1 and w.chance(0.35):
            body = f"{w.en('otherwise_rule')}{w.pick([': ', ', ', ' -> '])}{w.act_said(action)}"
        elif arrow:
            body = f"{_conds(conds, w)}{w.en('rule_arrows')}{w.act(action)}"
        else:
            head = w.en("if_formal") if w.formal else w.en("rule_heads")
            body = f"{head} {_conds(conds, w)}, {w.act_said(action)}"
        lines.append(_mark(bullet, i) + sentence(body))
    return ("\n" if bullet or w.chance(0.4) else " ").join(lines)


def default_exceptions(tree: Tree, w: Words) -> str:
    """The most common action as the default, every other leaf an exception with its path."""
    found = rules_of(tree)
    counts = Counter(a for _, a in found)
    top = max(counts.values())
    default = w.pick(sorted(a for a, c in counts.items() if c == top))
    head = sentence(w.pick([w.en("default").format(x=w.act_said(default)), w.en("always").format(a=w.act(default))]))
    exceptions = [(c, a) for c, a in found if a != default]
    bullet = _bullet(w) if w.chance(0.6) else ""
    lines = [_mark(bullet, i) + sentence(f"{w.pick(['if', 'when', 'where', 'but when'])} {_conds(c, w)}, {w.act_said(a)}")
             for i, (c, a) in enumerate(exceptions)]
    lead = sentence(w.en("exceptions")) if w.chance(0.5) else ""
    sep = "\n" if bullet else " "
    return sep.join(x for x in [head, lead] + lines if x)


def chain(tree: Tree, w: Words) -> str:
    """An if / else-if chain down the no-branches while the yes-branches are actions."""
    parts, node, first = [], tree, True
    while not isinstance(node, Leaf) and isinstance(node.yes, Leaf):
        head = w.en("if") if first else w.pick(["else if", "otherwise, if", "or else, if", "if not that, then if", "failing that, if"])
        parts.append(sentence(f"{head} {w.pos(node.question)}, {w.act_said(node.yes.action)}"))
        node, first = node.no, False
    rest = tell(node, w)[1]
    if first:
        return rest
    tail = w.en("else") + ", " + (rest if isinstance(node, Leaf) else rest[:1].lower() + rest[1:])
    return " ".join(parts + [sentence(tail)])


def outline(tree: Tree, w: Words) -> str:
    """A nested outline: each question, then its yes and no lines indented under it."""
    yes, no = w.pick(english()["yes_no"])
    ask = w.chance(0.5)

    def lines(node: Tree, depth: int) -> list[str]:
        pad = "  " * depth
        if isinstance(node, Leaf):
            return [f"{pad}{w.act(node.action)}"]
        head = w.question(node.question) if ask else w.pos(node.question).capitalize() + "?"
        out = [pad + head]
        for word, branch in ((yes, node.yes), (no, node.no)):
            if isinstance(branch, Leaf):
                out.append(f"{pad}  {word} -> {w.act(branch.action)}")
            else:
                out += [f"{pad}  {word}:"] + lines(branch, depth + 2)
        return out

    return "\n".join(lines(tree, 0))


def qa(tree: Tree, w: Words) -> str:
    """Question-and-answer form: the questions numbered in order, each answer an action or the
    number of the question asked next."""
    yes, no = w.pick(english()["yes_no"])
    lines: list[str] = []

    def walk(node: Tree) -> int:
        number = len(lines) + 1
        lines.append("")
        said = [w.act(b.action) if isinstance(b, Leaf) else f"{w.pick(['see', 'go to', 'ask'])} Q{walk(b)}"
                for b in (node.yes, node.no)]
        lines[number - 1] = f"Q{number}: {w.question(node.question)} {yes} -> {said[0]}; {no} -> {said[1]}"
        return number

    if isinstance(tree, Leaf):
        return sentence(w.act_said(tree.action))
    walk(tree)
    return "\n".join(lines)


def table(tree: Tree, w: Words) -> str:
    """A decision table: one column per question the tree asks, one row per leaf, '-' where
    the row does not depend on the question."""
    found = rules_of(tree)
    order = []
    for conds, _ in found:
        for q, _ in conds:
            if q not in order:
                order.append(q)
    yes, no = w.pick(english()["yes_no"])
    sep = w.pick([" | ", "\t", ", ", " / "])
    header = sep.join([w.short(q) for q in order] + [w.pick(["action", "do", "then", "what to do"])])
    rows = []
    for conds, action in found:
        given = dict(conds)
        rows.append(sep.join([yes if given.get(q) is True else no if given.get(q) is False else "-" for q in order] + [w.act(action)]))
    return "\n".join([header] + rows)


def code(tree: Tree, w: Words, indent: int = 0) -> str:
    """Pseudo-code: if/else blocks, `if not` with the branches swapped, elif chains, arrows."""
    pad = "    " * indent
    if isinstance(tree, Leaf):
        return f"{pad}{w.act(tree.action)}"
    r = w.rng.random()
    if r < 0.35:
        return f"{pad}if {w.code(tree.question)}:\n{code(tree.yes, w, indent + 1)}\n{pad}else:\n{code(tree.no, w, indent + 1)}"
    if r < 0.5:
        neg = w.pick(["not ", "!", "NOT "])
        return f"{pad}if {neg}{w.code(tree.question)}:\n{code(tree.no, w, indent + 1)}\n{pad}else:\n{code(tree.yes, w, indent + 1)}"
    if r < 0.75 and not isinstance(tree.no, Leaf) and isinstance(tree.yes, Leaf):
        lines, node, word = [], tree, "if"
        while not isinstance(node, Leaf) and isinstance(node.yes, Leaf):
            lines.append(f"{pad}{word} {w.code(node.question)} -> {w.act(node.yes.action)}")
            node, word = node.no, w.pick(["else if", "elif", "otherwise if"])
        rest = code(node, w, indent + 1)
        lines.append(f"{pad}else ->\n{rest}" if not isinstance(node, Leaf) else f"{pad}else -> {w.act(node.action)}")
        return "\n".join(lines)
    return f"{pad}{w.code(tree.question)}? ->\n{code(tree.yes, w, indent + 1)}\n{pad}{w.pick(['nope', 'no', 'else'])} ->\n{code(tree.no, w, indent + 1)}"


def arrows(tree: Tree, w: Words) -> str:
    """Terse: "car close ahead? slow down. otherwise: ..." """
    if isinstance(tree, Leaf):
        return w.act(tree.action)
    if w.chance(0.3):
        return f"{w.short(tree.question)} ? ({arrows(tree.yes, w)}) : ({arrows(tree.no, w)})"
    return (f"{w.short(tree.question)}? {arrows(tree.yes, w)}. "
            f"{w.pick([w.short(tree.question, False), 'if not', 'otherwise', 'no', 'else'])}: {arrows(tree.no, w)}.")


def memo(tree: Tree, w: Words) -> str:
    """A memo in a formal register: a heading, the rules (or a default with exceptions), a
    sign-off."""
    w.formal = True
    body = w.pick([rules, rules, default_exceptions, nested])(tree, w)
    return "\n".join([w.en("memo_heads"), sentence(w.en("intros")), body, w.en("memo_ends")])


STYLES = {"nested": nested, "rules": rules, "default": default_exceptions, "chain": chain, "outline": outline,
          "qa": qa, "table": table, "code": code, "arrows": arrows, "memo": memo}
STYLE_WEIGHTS = {"nested": 6, "rules": 3, "default": 1.5, "chain": 1, "outline": 1, "qa": 0.7, "table": 0.5,
                 "code": 1, "arrows": 1, "memo": 1.5}
"""How often each style is drawn: prose most, since most people write prose."""
STRUCTURED = {"outline", "qa", "table", "code"}
"""Styles whose line layout carries the tree: no speech, no reflow."""


# ---- around the policy, and how it is typed ----------------------------------------------------
def asides(tree: Tree, w: Words) -> list[str]:
    """Sentences about questions or actions the tree leaves out."""
    used = set()
    for conds, action in rules_of(tree):
        used |= {q for q, _ in conds} | {action}
    free_q = [q for q in w.q if q not in used]
    free_a = [a for a in w.a if a not in used]
    out = []
    for _ in range(w.pick([1, 1, 2])):
        if free_q and (not free_a or w.chance(0.7)):
            q = w.short(w.pick(free_q))
            out.append(sentence(w.en("asides_question").format(q=q, Q=q[:1].upper() + q[1:])))
        elif free_a:
            out.append(sentence(w.en("asides_action").format(a=w.act(w.pick(free_a)))))
    return out


def speech(text: str, rng: random.Random) -> str:
    """A transcribed voice memo: lower case, few stops, fillers between words."""
    fillers = english()["fillers"]
    words = text.replace("\n", " ").replace(".", rng.choice([",", " and", "", "."])).lower().split()
    out = []
    for word in words:
        out.append(word)
        if rng.random() < 0.07:
            out.append(rng.choice(fillers))
    return " ".join(out)


def texting(text: str, rng: random.Random) -> str:
    text = text.lower().replace("'", "")
    for long, short in english()["texting"].items():
        if rng.random() < 0.5:
            text = text.replace(f" {long} ", f" {short} ")
    if rng.random() < 0.6:
        text += " " + rng.choice(english()["emoji"])
    return text


def typos(text: str, rng: random.Random, n: int = 2) -> str:
    """Swap two letters inside a few words."""
    words = text.split(" ")
    for _ in range(n):
        i = rng.randrange(len(words))
        word = words[i]
        if len(word) > 4 and word.isalpha():
            j = rng.randrange(1, len(word) - 2)
            words[i] = word[:j] + word[j + 1] + word[j] + word[j + 2:]
    return " ".join(words)
