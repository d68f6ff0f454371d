"""The tokenizer: comments, whitespace and case as LinuxCNC reads them; bad text refused."""

from __future__ import annotations

import pytest

from app.programs.errors import ProgramError
from app.programs.tokens import tokenize, tokenize_line


def texts(line):
    return [w.text for w in line.words]


def test_comments_whitespace_and_case_are_removed():
    line = tokenize_line("n10 g1 x 1 0.5 (move right) ; the (rest", 1)
    assert texts(line) == ["N10", "G1", "X10.5"]
    assert [w.value for w in line.words] == [10.0, 1.0, 10.5]


def test_numbers_in_every_form():
    line = tokenize_line("X-.5Y+2.Z3", 1)
    assert [w.value for w in line.words] == [-0.5, 2.0, 3.0]


def test_empty_and_comment_lines_keep_the_line_numbers():
    lines = tokenize("(title)\n\n%\nG1 X1")
    assert [line.number for line in lines] == [1, 2, 3, 4]
    assert [len(line.words) for line in lines] == [0, 0, 0, 2]


@pytest.mark.parametrize(
    ("text", "word"),
    [("G1 X", "X"), ("#1=2", "#1=2"), ("G1 (open", "("), ("G1 )", ")"), ("/G1", "/G1")],
)
def test_text_that_is_not_words_is_refused_with_its_line(text, word):
    with pytest.raises(ProgramError) as caught:
        tokenize("G21\n" + text)
    assert caught.value.line == 2
    assert caught.value.word == word
    assert str(caught.value).startswith("line 2: ")


def test_nested_comments_are_refused_as_linuxcnc_does():
    with pytest.raises(ProgramError, match="nest"):
        tokenize("G1 (a (b) c)")
