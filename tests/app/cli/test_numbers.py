"""Issue 32 item 7: one reading of a typed number on the whole command line, the page's:
a decimal comma is a decimal point everywhere, and junk is refused naming the option."""

from __future__ import annotations

import argparse

import pytest

from app.cli import build_parser, main
from app.cli.numbers import number, parse_number


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("12.5", 12.5),
        ("12,5", 12.5),
        ("-0,5", -0.5),
        (",5", 0.5),
        ("+3", 3.0),
        ("-240", -240.0),
        ("\u22122,5", -2.5),  # a Unicode minus, as the page takes it
        (" 7 ", 7.0),
        ("2e-3", 0.002),
        ("2,5e-3", 0.0025),
        ("10.", 10.0),
    ],
)
def test_a_number_is_read_with_a_decimal_point_or_comma(text, value):
    assert parse_number(text) == value


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("1,234.5", "'1,234.5' is not one number"),  # a thousands separator: never 1.2345
        ("12,5,0", "'12,5,0' is not one number"),  # never 12.5 and 0, nor 1250
        ("1.2.3", "'1.2.3' is not one number"),
        ("", "empty"),
        ("abc", "'abc' is not a number (e.g. 12.5 or 12,5)"),
        ("inf", "'inf' is not a number"),
        ("nan", "'nan' is not a number"),
        ("1_000", "'1_000' is not a number"),
        ("12,5mm", "'12,5mm' is not a number"),
        ("1e999", "too large"),
    ],
)
def test_anything_else_is_refused_with_the_reason(text, words):
    with pytest.raises(ValueError, match=None) as refused:
        parse_number(text)
    assert words in str(refused.value)


def _refusal(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exited:
        build_parser().parse_args(argv)
    assert exited.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["run", "sinusoid", "--amplitude", "20", "x", "30"], "argument --amplitude: 'x'"),
        (["run", "sinusoid", "--phase", "0", "ninety", "0"], "argument --phase: 'ninety'"),
        (["run", "sinusoid", "--duration", "1,234.5"], "argument --duration: '1,234.5' is not"),
        (["gcode", "check", "f.ngc", "--work-offset", "0", "0", "a"], "argument --work-offset:"),
        (["gcode", "check", "f.ngc", "--start", "0", "0", "1,2,3"], "argument --start:"),
        (["calibrate", "--probe", "--plate-z", "deep"], "argument --plate-z: 'deep'"),
        (["home", "--config", "c.toml", "--angles-deg", "0", "0", "o"], "argument --angles-deg:"),
        (["tune", "--bandwidth", "20Hz"], "argument --bandwidth: '20Hz' is not a number"),
        (["design", "size", "--tilt", "lots"], "argument --tilt: 'lots'"),
    ],
)
def test_junk_is_refused_naming_the_option(argv, words, capsys):
    assert words in _refusal(argv, capsys)


@pytest.mark.parametrize(
    ("argv", "name", "value"),
    [
        (
            ["gcode", "check", "f.ngc", "--work-offset", "0", "12,5", "-2,5"],
            "work_offset",
            [0, 12.5, -2.5],
        ),
        (["gcode", "check", "f.ngc", "--start", "0", "0", "-240,5"], "start", [0, 0, -240.5]),
        (["gcode", "run", "f.ngc", "--work-offset", "-0,5", "0", "0"], "work_offset", [-0.5, 0, 0]),
        (["calibrate", "--probe", "--plate-z", "-262,5"], "plate_z", -262.5),
        (
            ["home", "--config", "c.toml", "--angles-deg", "-10,5", "0", "0"],
            "angles_deg",
            [-10.5, 0, 0],
        ),
        (["tune", "--bandwidth", "12,5", "--overshoot", "2,5"], "bandwidth", 12.5),
        (["design", "dynamics", "--point", "0", "0", "-0,25"], "point", [0, 0, -0.25]),
        (["design", "size", "--speed", "0,75"], "speed", 0.75),
        (["run", "sinusoid", "--duration", "2,5"], "duration", 2.5),
    ],
)
def test_every_command_reads_a_decimal_comma_also_in_a_negative_number(argv, name, value):
    assert getattr(build_parser().parse_args(argv), name) == value


def _parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_no_option_a_user_types_reads_numbers_with_plain_float():
    """Everywhere means every command: a float option would refuse 12,5 where the others
    take it. Only hidden options (help suppressed: set by deltadash itself) may."""
    plain = [
        (" ".join(path), action.option_strings)
        for path, parser in _parsers(build_parser())
        for action in parser._actions
        if action.type is float and action.help is not argparse.SUPPRESS
    ]
    assert plain == []
    typed = {
        " ".join(path)
        for path, parser in _parsers(build_parser())
        for action in parser._actions
        if action.type is number
    }
    assert {"run sinusoid", "gcode check", "gcode run", "calibrate", "home", "tune"} <= typed


def test_main_exits_2_on_junk_and_says_which_option(capsys):
    with pytest.raises(SystemExit) as exited:
        main(["run", "sinusoid", "--offset", "0", "0", "-240mm"])
    assert exited.value.code == 2
    assert "argument --offset: '-240mm' is not a number" in capsys.readouterr().err
