"""Showing a tree to a person: indented text for terminals, DOT for Graphviz users, and a
self-contained SVG for the web app (drawn here, so no Graphviz binary is needed).
"""

from __future__ import annotations

from html import escape
from typing import Mapping, Optional

from nl2policy.trees.grid import to_grid
from nl2policy.trees.tree import GRID_SLOTS, Leaf, Node, Tree, Vocabulary


def _label(item: str, vocab: Optional[Vocabulary]) -> str:
    if vocab is None:
        return item
    return vocab.wording(item)


def to_text(tree: Tree, vocab: Optional[Vocabulary] = None) -> str:
    """Indented text with box-drawing branches; wording from `vocab` when given, else ids."""
    lines: list[str] = []

    def walk(node: Tree, prefix: str, head: str) -> None:
        if isinstance(node, Leaf):
            lines.append(f"{head}-> {_label(node.action, vocab)}")
            return
        lines.append(f"{head}{_label(node.question, vocab)}")
        for i, (answer, child) in enumerate((("yes", node.yes), ("no", node.no))):
            last = i == 1
            branch = "└─ " if last else "├─ "
            walk(child, prefix + ("   " if last else "│  "), f"{prefix}{branch}{answer}: ")

    walk(tree, "", "")
    return "\n".join(lines)


def to_dot(tree: Tree, vocab: Optional[Vocabulary] = None) -> str:
    out = ["digraph policy {", "  node [fontname=Helvetica];"]
    counter = 0

    def walk(node: Tree) -> str:
        nonlocal counter
        name = f"n{counter}"
        counter += 1
        label = _label(node.action if isinstance(node, Leaf) else node.question, vocab).replace('"', '\\"')
        shape = "box, style=rounded" if isinstance(node, Leaf) else "ellipse"
        out.append(f'  {name} [label="{label}", shape={shape}];')
        if isinstance(node, Node):
            out.append(f'  {name} -> {walk(node.yes)} [label="yes"];')
            out.append(f'  {name} -> {walk(node.no)} [label="no"];')
        return name

    walk(tree)
    out.append("}")
    return "\n".join(out)


def to_svg(
    tree: Tree,
    vocab: Optional[Vocabulary] = None,
    highlight: Optional[Mapping[int, str]] = None,
    width: int = 960,
    notes: Optional[Mapping[int, str]] = None,
) -> str:
    """A grid-laid-out SVG: each slot of the 15-slot grid has a fixed place.

    `highlight` maps grid slot -> CSS colour, used by the app to mark changed or
    low-confidence nodes; `notes` maps slot -> a short line shown under the label (a
    confidence, say). Each node carries ``data-slot`` so pages can attach handlers.
    """
    grid = to_grid(tree)
    highlight = dict(highlight or {})
    levels = 4
    row_h, box_h = 110, 54
    height = levels * row_h
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="{width}" height="{height}" '
        'font-family="Helvetica, Arial, sans-serif" font-size="12">'
    ]

    def centre(slot: int) -> tuple[float, float]:
        level = (slot + 1).bit_length() - 1
        index = slot - (2 ** level - 1)
        span = width / 2 ** level
        return span * (index + 0.5), row_h * level + row_h / 2

    for slot in range(GRID_SLOTS):
        if grid[slot] is None or slot * 2 + 1 >= GRID_SLOTS or grid[2 * slot + 1] is None:
            continue
        x, y = centre(slot)
        for child, answer in ((2 * slot + 1, "yes"), (2 * slot + 2, "no")):
            cx, cy = centre(child)
            parts.append(f'<line x1="{x:.1f}" y1="{y + box_h / 2:.1f}" x2="{cx:.1f}" y2="{cy - box_h / 2:.1f}" stroke="#777"/>')
            parts.append(
                f'<text x="{(x + cx) / 2:.1f}" y="{(y + cy) / 2:.1f}" text-anchor="middle" fill="#555">{answer}</text>'
            )
    for slot, item in enumerate(grid):
        if item is None:
            continue
        x, y = centre(slot)
        level = (slot + 1).bit_length() - 1
        box_w = min(width / 2 ** level - 8, 220)
        is_leaf = vocab.actions.__contains__(item) if vocab else _is_leaf_slot(grid, slot)
        fill = highlight.get(slot, "#e8f5e9" if is_leaf else "#e3f2fd")
        rx = 14 if is_leaf else 4
        parts.append(
            f'<g class="{"leaf" if is_leaf else "question"}" data-slot="{slot}" data-id="{escape(item)}">'
            f'<rect x="{x - box_w / 2:.1f}" y="{y - box_h / 2:.1f}" width="{box_w:.1f}" height="{box_h}" rx="{rx}" '
            f'fill="{fill}" stroke="#456"/>'
        )
        note = (notes or {}).get(slot)
        lines = _wrap(_label(item, vocab), max(8, int(box_w / 6.5)))[: 2 if note else 3]
        for i, line in enumerate(lines):
            parts.append(f'<text x="{x:.1f}" y="{y - 10 + i * 14:.1f}" text-anchor="middle">{escape(line)}</text>')
        if note:
            parts.append(f'<text class="note" x="{x:.1f}" y="{y + 22:.1f}" text-anchor="middle" font-size="10" '
                         f'fill="#333">{escape(note)}</text>')
        parts.append("</g>")
    parts.append("</svg>")
    return "".join(parts)


def _is_leaf_slot(grid: list, slot: int) -> bool:
    child = 2 * slot + 1
    return child >= GRID_SLOTS or grid[child] is None


def _wrap(text: str, width: int) -> list[str]:
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    if line:
        lines.append(line)
    return lines
