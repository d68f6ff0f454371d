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
    [
        ("G1 X", "X"),
        ("#1=2", "#1=2"),
        ("G1 (open", "("),
        ("G1 )", ")"),
        ("/G1", "/G1"),
        ("G0 X\u0661\u0660\u0660", "X\u0661\u0660\u0660"),  # Arabic-Indic 100: ASCII digits only
    ],
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


@pytest.mark.parametrize(
    ("text", "word"),
    [
        ("G1 F" + "9" * 400, "F" + "9" * 23),  # inf as a float
        ("G2 X1 Y0 R" + "1" * 400, "R" + "1" * 23),  # inf as a float
        ("G1 X-2000000", "X-2000000"),
    ],
)
def test_numbers_beyond_any_coordinate_are_refused_naming_the_word(text, word):
    with pytest.raises(ProgramError) as info:
        tokenize(f"G21\n{text}")
    assert info.value.line == 2 and info.value.word == word
    assert "out of range" in str(info.value)
    assert tokenize("G1 X-1000000 F1000000")[0].words[1].value == -1e6  # the bound itself


def test_arc_centres_and_radii_of_any_finite_size_are_read():
    """FreeCAD posts I-2426220.106 (UGS#2517): I, J, K and R are not bounded here; the
    modal machine bounds the arc's radius in metres (tests/programs/test_field_reports.py)."""
    words = tokenize("G2 X-27.306 Y52.107 I-2426220.106 J-10.411 R" + "1" * 160)[0].words
    assert [w.value for w in words[3:5]] == [-2426220.106, -10.411]
    assert words[5].value == float("1" * 160)


def test_percent_lines_are_marked_for_the_modal_machine():
    lines = tokenize("%\n% (end)\nG0 X1")
    assert [line.percent for line in lines] == [True, True, False]


def test_lines_are_counted_as_an_editor_counts_them():
    # a form feed or U+2028 inside a line is not a line break; CR LF, LF and CR are
    lines = tokenize("G0 X0\x0cY0\r\nG1 X1 ; U+2028 \u2028 in a comment\rG92")
    assert [line.number for line in lines] == [1, 2, 3]
    assert [texts(line) for line in lines] == [["G0", "X0", "Y0"], ["G1", "X1"], ["G92"]]
    # a byte-order mark (Windows editors write one) is not part of the first word
    assert [w.text for w in tokenize("\ufeffG0 X1")[0].words] == ["G0", "X1"]


@pytest.mark.parametrize(
    ("text", "word"), [("G1 X1e308", "X1E308"), ("G1 F1200 Y-2.5E-3", "Y-2.5E-3")]
)
def test_exponent_notation_is_refused_naming_the_word_it_is_in(text, word):
    """X1e308 was read as X1 and E308 and refused naming E308; the word is X1E308."""
    with pytest.raises(ProgramError) as info:
        tokenize(f"G21\n{text}")
    assert info.value.line == 2 and info.value.word == word
    assert "exponent notation" in str(info.value)
