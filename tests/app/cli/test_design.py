"""``deltadash design`` through its own add_parser (app/cli/__init__.py wires it in)."""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

import pytest

from app.cli import design
from app.config import RobotSettings


def _run(argv: list[str], capsys) -> tuple[int, str]:
    parser = argparse.ArgumentParser(prog="deltadash")
    design.add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    code = args.handler(args)
    return code, capsys.readouterr().out


@pytest.mark.slow
def test_synth_json_answers_the_thesis_problem(capsys, tmp_path):
    code, out = _run(
        ["design", "synth", "--json", "--popsize", "10", "--maxiter", "40", "--out", str(tmp_path)],
        capsys,
    )
    payload = json.loads(out)
    for key in ("L", "l", "Rbar", "H", "objective", "contains"):
        assert key in payload
    assert payload["contains"] is True and code == 0
    assert payload["thesis"]["contains"] is False
    assert payload["thesis"]["vertex_distance_mm"] == pytest.approx(60.9, abs=0.5)
    assert payload["power_of_point"] <= payload["thesis"]["power_of_point"]
    config = tomllib.loads((tmp_path / "design.toml").read_text())
    assert set(config) == {"robot"}
    robot = config["robot"]
    assert robot["type"] == "rotary" and robot["r"] == 0.038
    assert robot["R"] == pytest.approx(payload["Rbar"] + 0.038, abs=1e-6)
    RobotSettings(**robot).build()  # the server's own loader accepts it
    assert (tmp_path / "synth_ours.png").read_bytes()[:4] == b"\x89PNG"
    assert "thesis 4.3" in (tmp_path / "report.md").read_text()


def test_size_json_puts_the_thesis_figures_beside_ours(capsys):
    code, out = _run(
        [
            "design",
            "size",
            "--json",
            "--grid",
            "4",
            "--region",
            "-0.05",
            "-0.05",
            "-0.28",
            "0.05",
            "0.05",
            "-0.2",
        ],
        capsys,
    )
    payload = json.loads(out)
    assert payload["thesis"] == {"static_nm": 0.656, "peak_nm": 0.905, "speed_rpm": 48.0}
    assert 0.2 < payload["static_nm"]["value"] < payload["peak_nm"]["value"]
    assert payload["passes"] is True and code == 0


@pytest.mark.slow  # renders figures
def test_workspace_writes_figures(capsys, tmp_path):
    code, out = _run(
        [
            "design",
            "workspace",
            "--json",
            "--cells",
            "30",
            "--sections",
            "-0.25",
            "--out",
            str(tmp_path),
        ],
        capsys,
    )
    payload = json.loads(out)
    assert code == 0 and 0.01 < payload["volume_m3"] < 0.2
    assert len(payload["figures"]) == 3
    for path in payload["figures"]:
        assert Path(path).read_bytes()[:4] == b"\x89PNG"


def test_dynamics_static_torques_are_equal_on_the_axis(capsys):
    code, out = _run(["design", "dynamics", "--json", "--point", "0", "0", "-0.25"], capsys)
    torques = json.loads(out)["torques_nm"]
    assert code == 0 and torques[0] == pytest.approx(torques[1]) == pytest.approx(torques[2])


@pytest.mark.parametrize("command", ["dynamics", "size", "workspace", "synth"])
def test_every_command_explains_itself(command, capsys):
    with pytest.raises(SystemExit) as exited:
        _run(["design", command, "--help"], capsys)
    assert exited.value.code == 0
    assert "--json" in capsys.readouterr().out


@pytest.mark.slow
def test_size_on_its_defaults_says_what_drives_the_peak_and_why_it_is_not_the_thesis(capsys):
    # issue 17: on its own defaults the command printed FAIL and 11.3 against 0.905 N m
    code, out = _run(["design", "size", "--grid", "5"], capsys)
    assert code == 1 and "FAIL" in out
    assert "not the thesis's 0.905 N m" in out
    assert "near the top of the region" in out and "reflected rotor inertia" in out
    assert "speed constraint" in out and "docs/design.md" in out
    code, out = _run(["design", "size", "--grid", "5", "--json"], capsys)
    payload = json.loads(out)
    cause = payload["peak_cause"]
    assert cause["point_mm"] == payload["peak_nm"]["point_mm"]
    assert cause["joint"] == payload["peak_nm"]["joint"]
    # laws: removing the speed or the top of the region cannot raise the peak
    assert cause["peak_nm_zero_speed"] <= payload["peak_nm"]["value"]
    assert cause["peak_nm_below"] <= payload["peak_nm"]["value"]
    assert cause["peak_nm_below"] < payload["peak_nm"]["value"] / 5  # the top drives it
    assert 0 <= cause["boundary_distance_mm"] < 10
