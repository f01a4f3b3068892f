"""The documented error types of the motion layer.

Every reader and binder raises one of these (all ``ValueError``s, so the CLI reports them cleanly); file
errors carry the file and 1-based line (and column when known) of the offending text.
"""

from __future__ import annotations


class LocatedError(ValueError):
    """An error in a named file at an optional line/column: ``str()`` is ``"file:line:col: message"``."""

    def __init__(
        self, message: str, file: str | None = None, line: int | None = None, column: int | None = None
    ):
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        super().__init__(self._format())

    def _format(self) -> str:
        where = [str(p) for p in (self.file, self.line, self.column) if p is not None]
        return f"{':'.join(where)}: {self.message}" if where else self.message


class ChannelsetError(LocatedError):
    """A malformed channelset (file or in-memory data)."""


class BindingError(ValueError):
    """A channelset or posture graph cannot be bound to the given figures."""


class PostureGraphError(LocatedError):
    """A malformed posture graph file, or a request it cannot satisfy (unknown posture, unreachable goal)."""
