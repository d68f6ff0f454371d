"""Contact through the API (issue 33), on the twin with a plate under the tool, the loop
on simulated time: GET /api/contact and the status's estimate; a touch that stops at its
set force with the contact point where MuJoCo's plate is; a press that holds its force;
refusals that name the field and move nothing."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

PLATE_Z_M = -0.26
TIP_RADIUS_M = 0.001  # hardware/sim/surfaces.py: the tip's sphere touches at its radius
SURFACE_Z_M = PLATE_Z_M + TIP_RADIUS_M  # where the tip's centre stands at first contact


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    hardware = {"sim": {"plates": [{"point_m": [0.0, 0.0, PLATE_Z_M]}]}}
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim", hardware=hardware) as c:
        take_lease(c)
        ok_json(c.post("/api/torque", json={"enabled": True}))
        yield c


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _go(client, point: list[float]) -> None:
    ok_json(client.post("/api/move", json={"position_m": point}))
    wait_for(
        lambda: (
            _status(client)["mode"] == "idle"
            and np.allclose(_status(client)["ee"]["position_m"], point, atol=1e-3)
        ),
        f"the tip at {point}",
    )


def test_the_estimate_is_in_the_status_and_near_zero_in_free_air(client) -> None:
    _go(client, [0.0, 0.0, -0.24])
    contact = _status(client)["contact"]
    assert contact["valid"] is True, contact
    # free, at rest: only friction and the model's errors, within 3 sigma of zero
    force, std = np.asarray(contact["force_n"]), np.asarray(contact["std_n"])
    assert (np.abs(force) <= 3 * std + 0.05).all(), contact
    answer = ok_json(client.get("/api/contact"))
    assert answer["limits"]["force_limit_n"] == 15.0
    assert answer["estimate"]["valid"] is True


def test_a_touch_stops_at_its_force_where_the_plate_is(client) -> None:
    _go(client, [0.0, 0.0, -0.24])
    started = ok_json(client.post("/api/contact/touch", json={"direction": [0, 0, -1]}))
    source_id = started["result"]["source_id"]
    wait_for(
        lambda: (
            (t := ok_json(client.get("/api/contact"))["touch"]) is not None
            and t["source_id"] == source_id
            and t["outcome"] != "touching"
        ),
        "the touch's end",
    )
    touch = ok_json(client.get("/api/contact"))["touch"]
    assert touch["outcome"] == "contact", touch
    # the contact point against the twin's own plate (its face plus the tip's radius)
    assert touch["contact_point_m"][2] == pytest.approx(SURFACE_Z_M, abs=3e-4), touch
    # stopped at the set force (2 N, the default), overshooting it by little
    assert 2.0 <= touch["peak_force_n"] <= 3.0, touch
    status = _status(client)
    assert status["mode"] == "idle" and not status["faults"]
    assert status["contact"]["force_n"][2] == pytest.approx(-2.0, abs=0.8)
    _go(client, [0.0, 0.0, -0.24])


def test_a_touch_with_nothing_under_it_ends_without_contact(client) -> None:
    _go(client, [0.05, 0.0, -0.20])
    ok_json(client.post("/api/contact/touch", json={"direction": [1, 0, 0], "max_travel_m": 0.01}))
    wait_for(
        lambda: (
            (t := ok_json(client.get("/api/contact"))["touch"]) is not None
            and t["outcome"] not in ("touching", "contact")
        ),
        "the touch's end",
    )
    touch = ok_json(client.get("/api/contact"))["touch"]
    assert touch["outcome"] == "no contact", touch
    assert touch["travel_m"] == pytest.approx(0.01, abs=1e-9)
    assert np.isnan(np.asarray(touch["contact_point_m"], dtype=float)).all()
    _go(client, [0.0, 0.0, -0.24])


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"direction": [0, 0, 0]}, "direction"),
        ({"direction": [0, 0, -1], "force_n": 40.0}, "force_n"),
        ({"direction": [0, 0, -1], "force_n": 0.5}, "force_n"),
        ({"direction": [0, 0, -1], "speed_m_s": 0.5}, "speed_m_s"),
        ({"direction": [0, 0, -1], "max_travel_m": 0.3}, "max_travel_m"),
        ({"direction": [0, 0, -1], "retract_m": 0.2}, "retract_m"),
        ({"direction": [0, 0, -1], "force_n": -1}, "force_n"),
        ({"direction": [0, 0, -1], "bogus": 1}, "bogus"),
    ],
)
def test_a_bad_touch_is_refused_naming_the_field_and_moves_nothing(client, body, field) -> None:
    before = _status(client)["ee"]["commanded_m"]
    answer = client.post("/api/contact/touch", json=body)
    assert answer.status_code == 422, answer.text
    assert field in answer.text
    assert _status(client)["ee"]["commanded_m"] == before
    assert _status(client)["mode"] == "idle"


def test_a_press_holds_its_force_on_the_plate(client) -> None:
    _go(client, [0.0, 0.0, -0.255])
    body = {"direction": [0, 0, -1], "force_n": 3.0, "duration_s": 3.0}
    ok_json(client.post("/api/contact/press", json=body))
    wait_for(lambda: _status(client)["mode"] == "press", "the press running")
    wait_for(lambda: _status(client)["mode"] != "press", "the press's end", timeout_s=60)
    status = _status(client)
    assert not status["faults"], status["faults"]
    # after 3 s the force along the press is its set force, within the estimate's error
    assert -status["contact"]["force_n"][2] == pytest.approx(3.0, abs=0.5), status["contact"]
    _go(client, [0.0, 0.0, -0.24])


def test_a_press_over_the_force_limit_is_refused(client) -> None:
    answer = client.post("/api/contact/press", json={"direction": [0, 0, -1], "force_n": 20.0})
    assert answer.status_code == 422 and "force_n" in answer.text, answer.text
    answer = client.post(
        "/api/contact/press", json={"direction": [0, 0, -1], "force_n": 2.0, "hold": {}}
    )
    assert answer.status_code == 422 and "hold" in answer.text, answer.text


def test_stop_ends_a_press_and_the_arm_holds_without_a_reset(client) -> None:
    _go(client, [0.0, 0.0, -0.255])
    ok_json(client.post("/api/contact/press", json={"direction": [0, 0, -1], "force_n": 2.0}))
    wait_for(lambda: _status(client)["mode"] == "press", "the press running")
    answer = ok_json(client.post("/api/stop"))
    assert answer["result"] is True
    status = _status(client)
    assert status["mode"] == "idle" and not status["estopped"] and status["torque"]
    assert ok_json(client.post("/api/stop"))["result"] is False  # nothing left to stop
    _go(client, [0.0, 0.0, -0.24])
