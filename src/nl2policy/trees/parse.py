"""Reading and writing the corpus tree JSON, with validation that says where a tree is wrong.

Format: ``{"do": ACTION}`` or ``{"if": QUESTION, "yes": TREE, "no": TREE}``; a QUESTION is a
dictionary id or a learned threshold test on one of the domain's features (``raw:gap_ahead<0.2281``,
trees/raw.py). Rules checked here (the corpus README's): ids belong to the domain, at most 3 questions on a path, no
question repeated on a path, no question whose two branches are identical.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from nl2policy.trees.errors import TreeError
from nl2policy.trees.raw import RAW_PREFIX, parse_raw
from nl2policy.trees.tree import MAX_DEPTH, Leaf, Node, Tree, Vocabulary


def parse_tree(data: Any, vocab: Vocabulary) -> Tree:
    """Build a validated tree from a JSON string or an already-decoded object."""
    if isinstance(data, (str, bytes)):
        try:
            data = json.loads(data)
        except json.JSONDecodeError as exc:
            raise TreeError(f"malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from exc
        except UnicodeDecodeError as exc:
            raise TreeError("not UTF-8 text: a tree is JSON text") from exc
        except RecursionError as exc:  # json's decoder recurses once per nesting level
            raise TreeError(f"the JSON is nested too deeply (a tree has at most {MAX_DEPTH} questions on a path)") from exc
    tree = _build(data, vocab, "root", ())
    return tree


def _build(obj: Any, vocab: Vocabulary, where: str, path_questions: tuple[str, ...]) -> Tree:
    if not isinstance(obj, dict):
        raise TreeError(f"expected an object like {{\"do\": ...}} or {{\"if\": ...}}, got {type(obj).__name__}", where)
    keys = set(obj)
    if keys == {"do"}:
        action = obj["do"]
        if not isinstance(action, str):
            raise TreeError("'do' must name an action id (a string)", where)
        if action not in vocab.actions:
            raise TreeError(f"unknown action {action!r} for {vocab.domain}; known: {', '.join(vocab.actions)}", where)
        return Leaf(action)
    if keys == {"if", "yes", "no"}:
        question = obj["if"]
        if not isinstance(question, str):
            raise TreeError("'if' must name a question id (a string)", where)
        if not vocab.is_question(question):
            raise TreeError(unknown_question(question, vocab), where)
        if question.startswith(RAW_PREFIX):  # one id per test: "raw:speed>0.6" is "raw:speed>0.6000"
            question = parse_raw(question).id
        if question in path_questions:
            raise TreeError(f"question {question!r} is asked again on the same path", where)
        if len(path_questions) >= MAX_DEPTH:
            raise TreeError(f"more than {MAX_DEPTH} questions on a path (the grid has 4 levels)", where)
        inner = path_questions + (question,)
        yes = _build(obj["yes"], vocab, f"{where}.yes", inner)
        no = _build(obj["no"], vocab, f"{where}.no", inner)
        if yes == no:
            raise TreeError(f"question {question!r} has identical yes and no branches", where)
        return Node(question, yes, no)
    if "do" in keys and "if" in keys:
        raise TreeError("an object is either a leaf {\"do\": ...} or a question {\"if\": ..., \"yes\": ..., \"no\": ...}, not both", where)
    if "if" in keys:
        missing = sorted({"yes", "no"} - keys)
        extra = sorted(keys - {"if", "yes", "no"})
        detail = f"missing {missing}" if missing else f"unexpected keys {extra}"
        raise TreeError(f"question node {detail}", where)
    if "do" in keys:
        raise TreeError(f"leaf has unexpected keys {sorted(keys - {'do'})}", where)
    raise TreeError(f"expected key 'do' or 'if', got {sorted(keys) or 'an empty object'}", where)


def unknown_question(question: str, vocab: Vocabulary) -> str:
    """Why `question` is not one of `vocab`'s, and what would be."""
    if question.startswith(RAW_PREFIX) and vocab.features:
        hint = (f"a learned test reads raw:<feature>><value> or raw:<feature><<value>, with a feature of "
                f"{vocab.domain}: {', '.join(vocab.features)}")
    else:
        hint = f"known: {', '.join(vocab.questions)}"
    return f"unknown question {question!r} for {vocab.domain}; {hint}"


def validate(tree: Tree, vocab: Vocabulary) -> Tree:
    """Check a tree built in code (an edit, a decoder's output) by the same rules as JSON."""
    return parse_tree(tree_to_json(tree), vocab)


def tree_to_json(tree: Tree) -> dict:
    if isinstance(tree, Leaf):
        return {"do": tree.action}
    return {"if": tree.question, "yes": tree_to_json(tree.yes), "no": tree_to_json(tree.no)}


def load_tree_arg(arg: str, vocab: Vocabulary) -> Tree:
    """A CLI argument that is either inline JSON or a path to a JSON file."""
    text = arg.strip()
    if not text.startswith("{"):
        path = Path(arg)
        if not path.is_file():
            raise TreeError(f"not a JSON tree and no such file: {arg}", "argument")
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise TreeError(f"{arg} is not a UTF-8 text file; a tree file holds JSON text", "argument") from exc
        except OSError as exc:
            raise TreeError(f"cannot read {arg}: {exc.strerror or exc}", "argument") from exc
    return parse_tree(text, vocab)
