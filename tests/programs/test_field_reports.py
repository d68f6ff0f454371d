"""Field reports on G-code (issue 28 section 3): percent lines, tiny CAM arcs, huge-radius
arcs and the order faults are reported in."""

from __future__ import annotations

import numpy as np
import pytest

from app.config import load_settings
from app.programs.check import check_program
from app.programs.errors import ProgramError
from app.programs.modal import interpret
from app.programs.tokens import iter_lines

START = (0.0, 0.0, -0.24)
ZERO = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def settings():
    return load_settings()


def run(text, start=START, offset=ZERO):
    return interpret(iter_lines(text), start, offset)


# --- 1. percent lines (RS274/NGC) ---------------------------------------------------------


def test_nothing_after_the_closing_percent_line_is_run_or_read():
    """RS274/NGC: the useful contents of a % ... % file stop at the second % line."""
    text = "%\nG0 X0 Y0 Z-240\nG1 X10 F600\n%\nG0 X30 Y0 Z-100"
    program = run(text)
    assert [s.kind for s in program.segments] == ["linear"]  # no rapid to z = -100 mm
    np.testing.assert_allclose(program.segments[-1].end_m, (0.01, 0.0, -0.24), atol=1e-15)
    assert program.lines == 4  # the program ends at its closing % line
    # what follows the closing % is not even read: not G-code there is no fault
    assert run("(title)\n%\nG1 X1 F10\n%\nthis is a note, #1 = 2 (\n").lines == 4


def test_a_file_opened_by_percent_and_never_closed_is_refused_at_its_end():
    text = "\n%\nG1 X1 F10\nG1 X2\n"  # lines 1-5 (the last one empty)
    with pytest.raises(ProgramError) as caught:
        run(text)
    assert caught.value.line == 5 and caught.value.word == ""
    assert "line 2" in caught.value.reason and "%" in caught.value.reason
    # ended by M2 (the reading stops there, as LinuxCNC's does): no closing % needed
    assert [s.kind for s in run("%\nG1 X1 F10\nM2\nG1 X2").segments] == ["linear"]
    # a % line in a file that does not open with one is only a delimiter, as before
    assert len(run("G1 X1 F10\n%\nG1 X2").segments) == 2


def test_the_check_refuses_an_unclosed_percent_file_naming_the_line(settings):
    with pytest.raises(ProgramError, match=r"^line 3: .*line 1"):
        check_program("%\nG1 F600 X1 Y0 Z-240\nG1 X2", settings)


# --- the first fault of a file first -------------------------------------------------------


def test_the_first_fault_by_line_is_reported_before_a_later_unreadable_line(settings):
    """A semantic fault on line 2 (G92), unreadable text on line 5 (#1): line 2."""
    text = "G21\nG92 X0\nG1 F600 X1 Y0 Z-240\nG1 X2\n#1 = 2\n"
    with pytest.raises(ProgramError) as caught:
        check_program(text, settings)
    assert (caught.value.line, caught.value.word) == (2, "G92")
    # without the early fault the late one is found
    with pytest.raises(ProgramError) as caught:
        check_program(text.replace("G92 X0", ""), settings)
    assert caught.value.line == 5
