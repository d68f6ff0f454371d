"""G-code text to words: comments ``( )`` and ``;`` removed, whitespace ignored (as
LinuxCNC ignores it), every word a letter and a number.

No package from the index fits (none is installed; the ones published are unmaintained or
for 3D printers' dialects), and the grammar of our subset is one regular expression.
What the tokenizer cannot read is refused with its line and the text; what it reads but
the modal machine does not support is refused there (app/programs/modal.py).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass

from app.programs.errors import ProgramError

# ASCII digits only: \d would read Arabic-Indic or other Unicode digits as numbers
_WORD = re.compile(r"([A-Z])([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))(E[+-]?[0-9]+)?")
_NEWLINE = re.compile(r"\r\n|\n|\r")  # what an editor counts as a line break; not \f, U+2028
MAX_MAGNITUDE = 1e6  # no coordinate, feed or dwell of the subset is larger
UNBOUNDED = frozenset("IJKR")  # arc centres and radii: finite, any size (CAM posts nearly
# straight arcs with I = 2,426,220 mm); the modal machine bounds the radius in metres


@dataclass(frozen=True)
class Word:
    """One word: ``letter`` (upper case), its ``value`` and the ``text`` as written
    (``"G1"``, ``"X-10.5"``), for messages."""

    letter: str
    value: float
    text: str


@dataclass(frozen=True)
class Line:
    """The words of one program line; ``number``: its line in the file (1-based);
    ``percent``: a line that is only ``%`` (RS274/NGC's program delimiter; no words)."""

    number: int
    words: tuple[Word, ...]
    percent: bool = False


def _strip_comments(text: str, number: int) -> str:
    out: list[str] = []
    depth_open = False
    for char in text:
        if depth_open:
            if char == "(":
                raise ProgramError(number, "(", "comments cannot nest")
            depth_open = char != ")"
        elif char == "(":
            depth_open = True
        elif char == ";":
            break
        elif char == ")":
            raise ProgramError(number, ")", "closing a comment that was not opened")
        else:
            out.append(char)
    if depth_open:
        raise ProgramError(number, "(", "comment not closed on its line")
    return "".join(out)


def tokenize_line(text: str, number: int) -> Line:
    """One line of text -> its words.

    Raises:
        ProgramError: an unclosed or nested comment, or text that is not a letter and a
            number (``#1``, ``/``, ``X``, ``G1.2.3``), naming the text at fault.
    """
    code = "".join(_strip_comments(text, number).split()).upper()
    if code == "%":  # program delimiter, as LinuxCNC allows (the modal machine reads it)
        return Line(number, (), percent=True)
    words: list[Word] = []
    at = 0
    while at < len(code):
        match = _WORD.match(code, at)
        if match is None:
            rest = code[at : at + 12]
            raise ProgramError(
                number, rest, "not a word (a letter and a number, e.g. G1 or X-10.5)"
            )
        if match[3]:  # X1E308: not two words X1 and E308 (E is no word of the subset)
            raise ProgramError(
                number,
                match[0][:24],
                "exponent notation is not G-code: write the number in full (e.g. X0.001)",
            )
        value = float(match[2])
        if match[1] in UNBOUNDED:
            if not math.isfinite(value):  # 400 digits are inf
                raise ProgramError(number, match[0][:24], "out of range (too many digits)")
        elif not abs(value) <= MAX_MAGNITUDE:  # 400 digits are inf, 160 overflow later
            raise ProgramError(
                number, match[0][:24], f"out of range (at most {MAX_MAGNITUDE:,.0f} in size)"
            )
        words.append(Word(match[1], value, match[0]))
        at = match.end()
    return Line(number, tuple(words))


def program_lines(program: str) -> list[str]:
    """A program's lines as an editor numbers them: split at CR LF, LF or CR only (a form
    feed or U+2028 inside a line is not a line break here), a leading byte-order mark
    (Windows editors write one) dropped."""
    return _NEWLINE.split(program.removeprefix("\ufeff"))


def iter_lines(program: str) -> Iterator[Line]:
    """A program's text -> its lines of words, one at a time, empty lines included
    (numbers stay right). Lazy: a line is read only when asked for, so the modal machine
    meets the faults of a file in their order (a line it refuses before an unreadable
    later one) and never reads what follows a closing ``%``.

    Raises (when the line is reached):
        ProgramError: as ``tokenize_line``.
    """
    for i, text in enumerate(program_lines(program), start=1):
        yield tokenize_line(text, i)


def tokenize(program: str) -> list[Line]:
    """A program's text -> all its lines of words at once (``iter_lines`` as a list).

    Raises:
        ProgramError: the first line that cannot be read (see ``tokenize_line``).
    """
    return list(iter_lines(program))
