"""Nested prose: each question of a tree told with one of English's conditional constructions,
chosen afresh at every depth, so a reader learns what "unless", "only if", "except when", a
no-branch told first or a default stated up front do to a tree wherever they occur.

A branch is either an action (a clause: "the taxi should wait") or a subtree (sentences of its
own). Constructions that put a branch inside a clause take actions only; the others take both.
Questions whose branches repeat an action also come as one rule with "and" / "or"
("if A or B, wait; otherwise ..."), the way people compress them.
"""

from __future__ import annotations

from typing import Callable, Optional

from nl2policy.language.synthetic.words import Words, english
from nl2policy.trees import Leaf, Node, Tree

Told = tuple[Optional[str], str]
"""A branch in words: (its action id if it is an action, else None; its text)."""


def tell(tree: Tree, w: Words, depth: int = 0) -> Told:
    if isinstance(tree, Leaf):
        return tree.action, w.act_said(tree.action, correct=w.correct)
    merged = _merged(tree, w, depth) if w.chance(0.35) else None
    if merged is not None:
        return None, merged
    y, n = tell(tree.yes, w, depth + 1), tell(tree.no, w, depth + 1)
    fits = [c for c, needs in CONSTRUCTIONS if needs(y[0] is not None, n[0] is not None)]
    return None, w.pick(fits)(w, tree.question, y, n, depth)


def sentence(text: str) -> str:
    """Capitalized, ending in a stop."""
    text = text.strip()
    if not text:
        return text
    text = text[:1].upper() + text[1:]
    return text if text[-1] in ".!?:" else text + "."


def _if(w: Words) -> str:
    return w.en("if_formal") if w.formal and w.chance(0.6) else w.en("if")


def _else(w: Words, q: str, after_subtree: bool) -> str:
    """Words that open the no-branch after the yes-branch was told: after a subtree, mostly a
    pointer back to the question (a bare "otherwise" would be read as the inner question's)."""
    if after_subtree and w.chance(0.7):
        return w.en("back").format(neg=w.neg(q)) + ","
    if w.chance(0.3):
        return f"{_if(w)} {w.neg(q)},"
    return w.en("else") + ","


def _branch(told: Told, w: Words) -> str:
    """A branch after a condition: an action clause as it is, a subtree introduced."""
    action, text = told
    if action is not None:
        return text
    return w.pick(["", "then ", f"{w.en('in_that_case')}: ", ""]) + text[:1].lower() + text[1:]


def if_else(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "If A, y. Otherwise, x." """
    return f"{sentence(f'{_if(w)} {w.pos(q)}, {_branch(y, w)}')} {sentence(f'{_else(w, q, y[0] is None)} {_branch(n, w)}')}"


def no_first(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """The no-branch first: "If not A, x. Otherwise, y." """
    if n[0] is None and w.chance(0.7):
        other = w.en("back").format(neg=w.pos(q)) + ","
    else:
        other = w.pick([w.en("else") + ",", f"{_if(w)} {w.pos(q)},", w.pick(["if it is,", "if so,", "when it is,"])])
    return f"{sentence(f'{_if(w)} {w.neg(q)}, {_branch(n, w)}')} {sentence(f'{other} {_branch(y, w)}')}"


def both_told(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "If A, y. If not A, x." """
    first, second = (w.pos(q), y), (w.neg(q), n)
    if w.chance(0.3):
        first, second = second, first
    return " ".join(sentence(f"{_if(w)} {s}, {_branch(b, w)}") for s, b in (first, second))


def check_first(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "Check whether A. If so, y. If not, x." """
    ask = (w.en("then_check") if depth and w.chance(0.5) else w.en("check")).format(s=w.pos(q))
    return f"{sentence(ask)} {sentence(w.en('yes_reply') + ' ' + _branch(y, w))} " \
           f"{sentence(w.en('no_reply') + ' ' + _branch(n, w))}"


def asked(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """The dictionary's question asked outright, its answers after it."""
    yes, no = w.pick(english()["yes_no"])
    form = w.pick(["{Q} {yes}: {y}. {no}: {n}.", "{Q} If {yes}, {y}; if {no}, {n}.", "{Q}\n{yes} -> {y}\n{no} -> {n}\n"])
    return form.format(Q=w.question(q), yes=yes, no=no, y=_branch(y, w).rstrip("."), n=_branch(n, w).rstrip("."))


def unless_first(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "Unless A, x. If A, y." """
    again = w.pick([f"{_if(w)} {w.pos(q)},", "if it is,", f"{w.en('in_that_case')},", "if it does,"])
    return f"{sentence(w.en('unless') + ' ' + w.pos(q) + ', ' + _branch(n, w))} {sentence(again + ' ' + _branch(y, w))}"


def unless_after(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "x, unless A, in which case y" (x an action). """
    tail = w.pick([", in which case ", "; then ", " - in that case ", ". If it is, "])
    return sentence(f"{n[1]}, {w.en('unless')} {w.pos(q)}{tail}{_branch(y, w)}")


def unless_no(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "y, unless not-A: then x" (y an action). """
    tail = w.pick([": then ", ", in which case ", "; in that case "])
    return sentence(f"{y[1]}, {w.en('unless')} {w.neg(q)}{tail}{_branch(n, w)}")


def only_if(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """ "y only if A; otherwise x" (y an action). """
    return f"{sentence(y[1] + ' ' + w.en('only_if') + ' ' + w.pos(q))} {sentence(_else(w, q, False) + ' ' + _branch(n, w))}"


def by_default(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """A default first, the exception after: "By default x. But if A, y." (x an action)."""
    lead = w.en("default").format(x=n[1]) if w.chance(0.6) else w.en("always").format(a=w.act(n[0]))
    turn = w.pick(["but ", "however, ", "except ", "only ", ""])
    return f"{sentence(lead)} {sentence(f'{turn}{_if(w)} {w.pos(q)}, {_branch(y, w)}')}"


def except_when(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """The exception first: "Except when A, x. When A, y." """
    return f"{sentence(w.en('unless') + ' ' + w.pos(q) + ', ' + _branch(n, w))} " \
           f"{sentence(w.pick(['when', 'where', 'if']) + ' ' + w.pos(q) + ', ' + _branch(y, w))}"


def postfix(w: Words, q: str, y: Told, n: Told, depth: int) -> str:
    """Both actions with their conditions after them: "y if A, and x if not"."""
    form = w.pick(["{y} if {p}, and {n} if not", "{y} if {p}; {n} otherwise", "{y} when {p}, {n} when {np}",
                   "{y} if {p}, else {n}", "{y} as long as {p}; if not, {n}", "{y} when {p}, and {n} when not",
                   "{y} when {p}, and {n} when it is not"])
    return sentence(form.format(y=y[1], n=n[1], p=w.pos(q), np=w.neg(q)))


Construction = Callable[[Words, str, Told, Told, int], str]
ANY: Callable[[bool, bool], bool] = lambda y_action, n_action: True
CONSTRUCTIONS: list[tuple[Construction, Callable[[bool, bool], bool]]] = [
    (if_else, ANY), (if_else, ANY), (no_first, ANY), (both_told, ANY), (check_first, ANY), (asked, ANY),
    (unless_first, ANY), (except_when, ANY), (unless_after, lambda y, n: n), (unless_no, lambda y, n: y),
    (only_if, lambda y, n: y), (by_default, lambda y, n: n), (postfix, lambda y, n: y and n),
]
"""Each construction with which branches it can hold (True: an action clause there)."""


def _merged(tree: Node, w: Words, depth: int) -> Optional[str]:
    """One "and"/"or" rule for a question whose other branch is a question sharing an action:
    A ? x : (B ? x : z) -> "if A or B, x; otherwise z"; A ? (B ? y : x) : x -> "if A and B, y;
    otherwise x" (each also with B's answer no)."""
    q, yes, no = tree.question, tree.yes, tree.no
    if isinstance(yes, Leaf) and isinstance(no, Node):
        for inner, shared, rest in ((True, no.yes, no.no), (False, no.no, no.yes)):
            if shared == yes:
                cond = f"{w.pos(q)}{w.en('or')}{w.cond(no.question, inner)}"
                head = sentence(f"{_if(w)} {cond}, {w.act_said(yes.action)}")
                return f"{head} {sentence(w.en('else') + ', ' + _branch(tell(rest, w, depth + 2), w))}"
    if isinstance(no, Leaf) and isinstance(yes, Node):
        for inner, shared, rest in ((True, yes.no, yes.yes), (False, yes.yes, yes.no)):
            if shared == no:
                cond = f"{w.pos(q)}{w.en('and')}{w.cond(yes.question, inner)}"
                head = sentence(f"{_if(w)} {cond}, {_branch(tell(rest, w, depth + 2), w)}")
                return f"{head} {sentence(w.en('else') + ', ' + w.act_said(no.action))}"
    return None
