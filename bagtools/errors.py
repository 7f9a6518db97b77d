"""Domain errors shared by the whole library.

Every error a user can cause (bad path, bad bag, missing topic or frame, bad
argument) is a :class:`BagtoolsError`. The CLI turns it into one line,
``bagtools: <file>: <problem>``, and exit status 2. Anything else is a bug.
"""

from __future__ import annotations

from pathlib import Path


class BagtoolsError(Exception):
    """A problem with the user's input, reported as one line.

    Args:
        problem: what is wrong, as a short sentence fragment.
        path: the file or directory it concerns, if any.
    """

    def __init__(self, problem: str, path: str | Path | None = None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.path = None if path is None else str(path)

    def __str__(self) -> str:
        return f"{self.path}: {self.problem}" if self.path else self.problem


class BagError(BagtoolsError):
    """The bag cannot be opened or read (missing, not a bag, corrupt)."""


class TopicError(BagtoolsError):
    """A requested topic is not in the bag, or has an unexpected type."""


class OutputExistsError(BagtoolsError):
    """An output would overwrite an existing file and ``--force`` was not given."""
