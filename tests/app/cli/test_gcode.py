"""``deltadash gcode check``: offline, exit 0 only when the program passes, text or JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


@pytest.mark.parametrize("name", ["circle.ngc", "helix.ngc"])
def test_the_passing_examples_pass(capsys, name):
    assert main(["gcode", "check", str(EXAMPLES / name)]) == 0
    out = capsys.readouterr().out
    assert "PASSES" in out and "line " not in out


def test_pick_and_place_passes_with_its_work_offset_in_mm(capsys):
    path = str(EXAMPLES / "pick_and_place.ngc")
    assert main(["gcode", "check", path, "--work-offset", "0", "0", "-280", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["work_offset_m"] == pytest.approx([0.0, 0.0, -0.28])
    assert report["path_m"][-1] == pytest.approx([0.0, 0.0, -0.24])  # X0 Y0 Z40 over the table
    # without the offset its z = 5..40 mm is above the base: refused
    assert main(["gcode", "check", path]) == 1


def test_the_failing_example_fails_at_its_lines_as_documented(capsys):
    assert main(["gcode", "check", str(EXAMPLES / "fails.ngc"), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is False
    assert {v["line"] for v in report["violations"]} == {5, 6}
    assert {"ceiling", "workspace"} <= {v["kind"] for v in report["violations"]}
    assert main(["gcode", "check", str(EXAMPLES / "fails.ngc")]) == 1
    text = capsys.readouterr().out
    assert "FAILS" in text and "-60.000) mm" in text
    # folded as the page folds: in the report's order, a first cause (folded_under null)
    # as 'line N: ...', each other indented under the first cause of its own line
    rows = text.splitlines()[4:]
    for k, (row, v) in enumerate(zip(rows, report["violations"], strict=True)):
        if v["folded_under"] is None:
            assert row.startswith(f"  line {v['line']}: {v['kind']} at "), row
        else:
            assert row.startswith(f"      |_ {v['kind']} at "), row
            assert v["folded_under"] < k
            under = report["violations"][v["folded_under"]]
            assert under["folded_under"] is None and under["line"] == v["line"]
    assert "FAILS: 12 violations on 2 line(s): 2 first cause(s), 10 folded under them" in text
    documented = (EXAMPLES.parent / "docs" / "gcode.md").read_text()
    for line in text.splitlines()[3:]:  # the per-line violations, as docs/gcode.md shows
        assert line.strip() in documented, line


def test_a_program_that_cannot_be_read_exits_2_naming_line_and_word(tmp_path, capsys):
    program = tmp_path / "bad.ngc"
    program.write_text("G21\nG1 F100 X1\nG1 A30\n")
    assert main(["gcode", "check", str(program)]) == 2
    err = capsys.readouterr().err
    assert "line 3: A30:" in err and "wrist axis is not configured" in err


def test_a_missing_file_exits_2(tmp_path, capsys):
    assert main(["gcode", "check", str(tmp_path / "none.ngc")]) == 2
    assert "none.ngc" in capsys.readouterr().err


def test_the_start_is_in_mm(tmp_path, capsys):
    program = tmp_path / "still.ngc"
    program.write_text("(nothing)\n")
    assert main(["gcode", "check", str(program), "--start", "10", "0", "-250", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["start_m"] == pytest.approx([0.01, 0.0, -0.25])


def test_a_file_that_is_not_utf8_exits_2_naming_the_file_and_line(tmp_path, capsys):
    program = tmp_path / "latin1.ngc"
    program.write_bytes("G21\n(Stra\u00dfe)\nG0 X0\n".encode("latin-1"))
    assert main(["gcode", "check", str(program)]) == 2
    err = capsys.readouterr().err
    assert f"{program}: line 2: byte 0xdf is not UTF-8 text" in err
    assert "Traceback" not in err


def test_the_start_says_its_unit_in_the_help_and_in_its_errors(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["gcode", "check", "--help"])
    assert "millimetres" in capsys.readouterr().out
    program = tmp_path / "still.ngc"
    program.write_text("(nothing)\n")
    # metres where mm are meant: refused, saying the unit and what it would be in mm
    assert main(["gcode", "check", str(program), "--start", "0", "0", "-0.24"]) == 2
    err = capsys.readouterr().err
    assert "--start is in millimetres" in err and "give --start 0 0 -240" in err
    with pytest.raises(SystemExit) as refused:  # read by argparse, as every CLI number
        main(["gcode", "check", str(program), "--start", "0", "0", "nan"])
    assert refused.value.code == 2
    assert "argument --start: 'nan' is not a number" in capsys.readouterr().err


@pytest.mark.slow  # a deltadash process
def test_a_reader_that_leaves_ends_the_check_quietly():
    """`deltadash gcode check FILE | head`: no BrokenPipeError traceback, exit 141."""
    import os
    import subprocess
    import sys

    root = EXAMPLES.parent
    env = {**os.environ, "PYTHONPATH": str(root)}
    command = [sys.executable, "-m", "app.cli", "gcode", "check", "--json"]
    with subprocess.Popen(
        [*command, str(EXAMPLES / "fails.ngc")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=root,
        env=env,
    ) as child:
        child.stdout.close()  # the reader leaves before the report is written
        err = child.stderr.read().decode()
        code = child.wait(timeout=300)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert code == 141, err
