"""The one reading of a number the user types on the command line, shared by every command.

The page's rule (``parseDecimal`` in static/js/ui.js), so that what the page takes the command
line takes too: a decimal point or a decimal comma (``12.5``, ``12,5``, ``-0,5``, ``,5``),
a leading ``+``, ``-`` or Unicode minus. Refused, with the reason, never read another way:
more than one separator (``1,234.5``, ``12,5,0``: a thousands separator or three numbers
written as one), an empty word, ``inf`` / ``nan``, digit groups (``1_000``) and anything else.
Beyond the page, an exponent is read (``2e-3``, ``2,5e-3``), as SI values are often written.

``number`` is the argparse ``type=`` of every numeric option: argparse then names the option
in its error (``argument --amplitude: 'abc' is not a number (e.g. 12.5 or 12,5)``, exit 2).
``allow_negative_numbers`` (called once on the whole ``deltadash`` parser) lets a negative
decimal-comma number (``-0,5``) or one with an exponent (``-2e-3``) stand as a value, where
argparse alone reads it as an unknown option.

Only the standard library is imported: ``deltadash --help`` stays fast.
"""

from __future__ import annotations

import argparse
import math
import re

_NUMBER = re.compile(r"[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?")
# a word starting like a negative number: a value, not an option (no option starts with -<digit>)
_NEGATIVE = re.compile(r"^-[.,]?\d")


def parse_number(text: str) -> float:
    """The number ``text`` means (see the module's rule); a decimal comma is a decimal point.

    Raises:
        ValueError: ``text`` is not one number; the message quotes it and says why.
    """
    word = str(text).strip().replace("\u2212", "-")
    if not word:
        raise ValueError("an empty value is not a number")
    if _NUMBER.fullmatch(word):
        value = float(word.replace(",", "."))
        if math.isfinite(value):
            return value
        raise ValueError(f"{text!r} is too large a number")
    if len(re.findall(r"[.,]", word)) > 1 and re.fullmatch(r"[+-]?[\d.,]+", word):
        raise ValueError(
            f"{text!r} is not one number: write one decimal separator (12.5 or 12,5), no "
            "thousands separator, and separate numbers with spaces"
        )
    raise ValueError(f"{text!r} is not a number (e.g. 12.5 or 12,5)")


def number(text: str) -> float:
    """argparse ``type=``: :func:`parse_number`, its refusal as argparse's error (which names
    the option)."""
    try:
        return parse_number(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def allow_negative_numbers(parser: argparse.ArgumentParser) -> None:
    """Let ``parser`` and every sub-command parser under it take ``-0,5``, ``-2e-3`` and
    ``-240mm`` as values: argparse alone reads only ``-5`` and ``-0.5`` so, and anything else
    starting with ``-`` as an unknown option. No option of deltadash starts with -<digit>.
    tests/app/cli/test_numbers.py checks that argparse still honours it."""
    parser._negative_number_matcher = _NEGATIVE  # argparse's own hook, one per parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                allow_negative_numbers(sub)
