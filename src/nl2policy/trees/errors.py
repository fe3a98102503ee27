"""The one error type for bad trees, carrying where in the tree the problem is."""

from __future__ import annotations


class TreeError(ValueError):
    """A tree that cannot be used, with the path to the offending part.

    `where` is a path such as ``root.yes.no`` (JSON input) or ``token 4`` / ``slot 6``, so a
    person editing a tree by hand can find the spot.
    """

    def __init__(self, message: str, where: str = "root") -> None:
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}")
