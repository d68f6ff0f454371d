"""The one error of a program that cannot be read or interpreted."""

from __future__ import annotations


class ProgramError(ValueError):
    """A program refused before planning: names its line (1-based, as an editor counts)
    and the word at fault (``"G92"``, ``"A10"``, ``""`` when no single word is).

    ``str(error)`` reads ``line 3: G92: not supported (...)``.
    """

    def __init__(self, line: int, word: str, reason: str) -> None:
        self.line, self.word, self.reason = line, word, reason
        where = f"line {line}: {word}: " if word else f"line {line}: "
        super().__init__(where + reason)

    def __reduce__(self) -> tuple[type[ProgramError], tuple[int, str, str]]:
        """Pickled as its three fields (a check in a worker process raises it there)."""
        return (type(self), (self.line, self.word, self.reason))
