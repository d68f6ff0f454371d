"""The deltadash command line's kinematics demo."""

import json

from app.cli import main


def test_ik_json_round_trips_through_fk(capsys):
    assert main(["ik", "0", "0", "-0.24", "--json"]) == 0
    ik = json.loads(capsys.readouterr().out)
    assert ik["ok"] is True
    assert main(["fk", *map(str, ik["joints_rad"]), "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    assert max(abs(a - b) for a, b in zip(fk["point_m"], [0, 0, -0.24], strict=True)) < 1e-12


def test_unreachable_point_names_the_nearest_reachable_one(capsys):
    assert main(["ik", "0.4", "0", "-0.2"]) == 1
    out = capsys.readouterr().out
    assert "unreachable" in out and "nearest reachable" in out


def test_fk_in_degrees(capsys):
    assert main(["fk", "30", "30", "30", "--deg"]) == 0
    assert "platform" in capsys.readouterr().out
