"""The top-level help (plain text, every command the README names) and the start-up law:
building the parser, --help, ik and fk import none of the heavy libraries."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[3]
HEAVY = ("fastapi", "uvicorn", "mujoco", "matplotlib", "scipy", "viser", "starlette")


def _readme_commands() -> list[list[str]]:
    """Each ``deltadash CMD [SUB]`` the README names, as [cmd, *subs]; "a|b" alternatives
    are split (``deltadash ik|fk``, ``deltadash design synth|size|workspace|dynamics``)."""
    text = (ROOT / "README.md").read_text()
    found = []
    for commands, subs in re.findall(r"deltadash ([a-z][a-z|]*)(?: ([a-z][a-z|]*))?", text):
        found += [[c, *(subs.split("|") if subs else [])] for c in commands.split("|")]
    return found


def test_the_readme_names_commands():
    names = {c[0] for c in _readme_commands()}
    assert {"serve", "run", "runs", "design", "emulate", "ik", "fk"} <= names  # not vacuous
    assert ["design", "synth", "size", "workspace", "dynamics"] in _readme_commands()


def test_top_level_help_lists_every_command_the_readme_names(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    listed = set(re.findall(r"^    ([a-z]+)\s", text, flags=re.M))
    for command, *subs in _readme_commands():
        assert command in listed, f"README names `deltadash {command}`, --help does not"
        for sub in subs:
            with pytest.raises(SystemExit):
                main([command, "--help"])
            assert re.search(rf"^    {sub}\s", capsys.readouterr().out, flags=re.M), sub


def test_top_level_help_is_plain_text():
    text = build_parser().format_help()
    assert "``" not in text and "{" not in text  # no reST markup, no {a,b,c} choice lists
    assert "COMMAND --help" in text


def _loaded_after(code: str) -> dict[str, bool]:
    program = (
        "import json, sys\n"
        f"{code}\n"
        f"print(json.dumps({{m: m in sys.modules for m in {HEAVY!r} + ('pydantic',)}}))"
    )
    done = subprocess.run(
        [sys.executable, "-c", program],
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT), "PATH": ""},
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.slow
def test_building_the_parser_imports_no_heavy_library():
    loaded = _loaded_after("from app.cli import build_parser; build_parser().format_help()")
    assert not any(loaded.values()), loaded


@pytest.mark.slow
@pytest.mark.parametrize("argv", [["ik", "0", "0", "-240"], ["fk", "30", "30", "30"]])
def test_ik_and_fk_import_no_heavy_library(argv):
    loaded = _loaded_after(f"from app.cli import main; assert main({argv!r}) == 0")
    assert not any(loaded.values()), loaded  # pydantic too: no config file, no environment
