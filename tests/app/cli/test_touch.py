"""``deltadash touch --url``: on a server (the in-process app on the twin with a plate 260 mm
under the base, its loop on simulated time, reached through the CLI's own HTTP helper): the
options in mm, mm/s and N are sent in SI (hand-converted), the touch is followed to its end,
and the outcome, the contact point [mm] and the forces printed are the server's; refusals
(torque off, a bad value, an SI value typed as mm) exit 2 and start nothing."""

from __future__ import annotations

import argparse
import io
import json
import re
import urllib.error
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.cli import run as cli_run
from app.cli import touch as cli_touch
from tests.support.app_client import make_client
from tests.support.sim_time import elapse
from tests.support.wait import ok_json, wait_for

URL = "http://127.0.0.1"
PLATE_Z_M = -0.26
SURFACE_Z_MM = -259.0  # the plate's face plus the tip's 1 mm radius (hardware/sim/surfaces.py)


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    hardware = {"sim": {"plates": [{"point_m": [0.0, 0.0, PLATE_Z_M]}]}}
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim", hardware=hardware) as c:
        yield c


@pytest.fixture
def served(app, monkeypatch) -> list[tuple[str, str, dict | None]]:
    """The CLI's HTTP calls go to the in-process app, with the same HTTPErrors; its waits
    between looks run the robot's simulated time. Returns the requests made."""
    made: list[tuple[str, str, dict | None]] = []

    def http(url, method="GET", body=None, headers=None):
        made.append((method, url.removeprefix(URL), body))
        response = app.request(method, url, json=body, headers=headers or {})
        if response.status_code >= 400:
            raise urllib.error.HTTPError(
                url, response.status_code, response.reason_phrase, {}, io.BytesIO(response.content)
            )
        return response.json()

    monkeypatch.setattr(cli_run, "_http", http)
    monkeypatch.setattr(cli_touch, "_wait", elapse)
    return made


def _torque(app: TestClient, on: bool) -> None:
    lease = ok_json(app.post("/api/lease", json={"client": "test", "take_over": True}))
    headers = {"x-lease": lease["lease_id"]}
    ok_json(app.post("/api/torque", json={"enabled": on}, headers=headers))
    if on:
        ok_json(app.post("/api/move", json={"position_m": [0, 0, -0.24]}, headers=headers))
        wait_for(lambda: _at_rest(app), "the tip at rest at (0, 0, -240) mm")
    app.delete("/api/lease", headers=headers)


def _at_rest(app: TestClient) -> bool:
    """The move done (mode idle) and the tip at (0, 0, -240) mm: a touch started while the
    arm still settles can read its motion as a contact force."""
    status = ok_json(app.get("/api/status"))
    return status["mode"] == "idle" and abs(status["ee"]["position_m"][2] + 0.24) < 1e-3


def _posted(made: list, path: str) -> list[dict | None]:
    return [body for method, p, body in made if method == "POST" and p == path]


def test_a_touch_prints_where_the_plate_is(app, served, capsys) -> None:
    _torque(app, True)
    argv = ["touch", "--url", URL, "--take-over", "--direction", "0,0,-1", "--force", "2"]
    code = main([*argv, "--speed", "10", "--travel", "50", "--retract", "2"])
    out, err = capsys.readouterr()
    assert code == 0, err + out
    # hand-converted: 10 mm/s = 0.01 m/s, 50 mm = 0.05 m, 2 mm = 0.002 m
    assert _posted(served, "/api/contact/touch") == [
        {
            "direction": [0.0, 0.0, -1.0],
            "force_n": 2.0,
            "speed_m_s": pytest.approx(0.01, abs=1e-15),
            "max_travel_m": pytest.approx(0.05, abs=1e-15),
            "retract_m": pytest.approx(0.002, abs=1e-15),
        }
    ]
    touch = ok_json(app.get("/api/contact"))["touch"]
    assert touch["outcome"] == "contact"
    lines = dict(line.split(": ", 1) for line in out.strip().splitlines())
    assert lines["touch"] == "contact"
    point = [float(v) for v in re.findall(r"-?\d+\.\d+", lines["contact point"])]
    assert lines["contact point"].endswith(" mm")
    assert point == pytest.approx([1e3 * c for c in touch["contact_point_m"]], abs=6e-4)
    assert point[2] == pytest.approx(SURFACE_Z_MM, abs=0.3)  # the twin's own plate
    force = [
        float(v)
        for v in re.findall(r"-?\d+\.\d+", lines["force at the stop (before any retract)"])[:3]
    ]
    assert force == pytest.approx(touch["force_n"], abs=0.006)
    peak = float(lines["peak force along the direction"].split()[0])
    assert peak == pytest.approx(touch["peak_force_n"], abs=0.006) and 2.0 <= peak < 15.0
    assert "(set 2 N)" in lines["peak force along the direction"]
    # followed to its end: the retract done, the arm no longer touching
    status = ok_json(app.get("/api/status"))
    assert status["mode"] != "touch" and not status["faults"]
    assert app.get("/api/lease").json()["held"] is False  # control given back


def test_si_and_json(app, served, capsys) -> None:
    _torque(app, True)
    argv = ["touch", "--url", URL, "--take-over", "--direction=-z", "--si", "--json"]
    code = main([*argv, "--speed", "0,01", "--travel", "0.05", "--retract", "0.002"])
    out, err = capsys.readouterr()
    assert code == 0, err + out
    body = _posted(served, "/api/contact/touch")[-1]
    assert body == {
        "direction": [0.0, 0.0, -1.0],
        "speed_m_s": 0.01,
        "max_travel_m": 0.05,
        "retract_m": 0.002,
    }  # no force: the server's default
    printed = json.loads(out)
    assert printed == ok_json(app.get("/api/contact"))["touch"]
    assert printed["contact_point_m"][2] == pytest.approx(SURFACE_Z_MM / 1e3, abs=3e-4)


def test_nothing_under_it_is_no_contact_exit_1(app, served, capsys) -> None:
    _torque(app, True)
    code = main(["touch", "--url", URL, "--take-over", "--direction=+x", "--travel", "10"])
    out, _ = capsys.readouterr()
    assert code == 1
    assert "touch: no contact" in out and "contact point: (none) mm" in out
    assert "travel (furthest commanded): 10.000 mm" in out


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--force", "40"], "force_n"),
        (["--travel", "400"], "max_travel_m"),
    ],
)
def test_a_refused_touch_exits_2_and_names_the_field(app, served, capsys, args, words) -> None:
    _torque(app, True)
    before = ok_json(app.get("/api/contact"))["touch"]
    code = main(["touch", "--url", URL, "--take-over", *args])
    err = capsys.readouterr().err
    assert code == 2 and "error: 422" in err and words in err, err
    assert ok_json(app.get("/api/contact"))["touch"] == before
    assert app.get("/api/lease").json()["held"] is False


def test_si_typed_as_mm_and_torque_off_are_refused_before_a_touch(app, served, capsys) -> None:
    code = main(["touch", "--url", URL, "--take-over", "--travel", "0.05"])
    assert code == 2
    assert "--travel 0.05 mm looks like SI: give 50 mm, or add --si" in capsys.readouterr().err
    _torque(app, False)
    code = main(["touch", "--url", URL, "--take-over"])
    assert code == 2 and "torque is off" in capsys.readouterr().err
    assert not _posted(served, "/api/contact/touch")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("0,0,-1", (0.0, 0.0, -1.0)),
        ("-z", (0.0, 0.0, -1.0)),
        ("+x", (1.0, 0.0, 0.0)),
        ("y", (0.0, 1.0, 0.0)),
        ("0.5 0,5 -1", (0.5, 0.5, -1.0)),
        ("1;0;0", (1.0, 0.0, 0.0)),
    ],
)
def test_direction_reads_an_axis_or_three_numbers(text, expected) -> None:
    assert cli_touch.direction(text) == expected


@pytest.mark.parametrize(
    ("text", "words"),
    [("0,0", "three numbers"), ("0,0,0", "must not be zero"), ("a,b,c", "not a number")],
)
def test_a_bad_direction_is_refused_with_the_reason(text, words) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=words):
        cli_touch.direction(text)
