"""An attacker's, a careless operator's and a maintainer's pass over the contact routes of
issue 33 (GET /api/contact, POST /api/contact/touch and /press, POST /api/stop, PUT
/api/servos/current) and the [contact] and plate config: every command needs the token and
the lease; a bad body is a 4xx naming the field, never a 500; a refused request moves
nothing (the commanded point before and after) and a refused goal never reaches the
servos; a touch or press is refused while e-stopped, faulted, torque off or while a
procedure owns the robot. In-process apps on the twin with a plate under the tool, the
loop on simulated time."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.config import ConfigError, load_settings
from app.control import commands
from app.control.contact import ContactMonitor
from app.control.controller import Controller
from app.control.state import ContactReading
from app.control.touch import unit_direction
from tests.support.app_client import make_client, torque_on
from tests.support.fake_bus import HOME_RAD, FakeBus
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TOKEN = "an-attackers-guess-is-not-this"
PLATE_Z_M = -0.26
HARDWARE = {"sim": {"plates": [{"point_m": [0.0, 0.0, PLATE_Z_M]}]}}
ABOVE_M = [0.0, 0.0, -0.24]  # 20 mm above the plate's face
SERVO_CURRENT = {"operating_mode": "position", "goal_current_a": [3.2, 3.2, 3.2]}

# every route of issue 33 that moves the robot or changes how it moves, with a body it
# would otherwise take
COMMANDS = [
    ("POST", "/api/contact/touch", {"direction": [0, 0, -1]}),
    ("POST", "/api/contact/press", {"direction": [0, 0, -1], "force_n": 2.0}),
    ("POST", "/api/stop", None),
    ("PUT", "/api/servos/current", SERVO_CURRENT),
]


def _send(client, method: str, path: str, body, headers=None):
    return client.request(method, path, json=body, headers=headers or {})


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _state(client) -> dict:
    """What a refused request must not change: torque, mode, the goal, the commanded point
    (the servos' last goal), the servo mode and the last touch."""
    status = _status(client)
    return {
        "torque": status["torque"],
        "mode": status["mode"],
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "servo_mode": status["servo_mode"],
        "goal_current_a": status["goal_current_a"],
        "touch": (ok_json(client.get("/api/contact"))["touch"] or {}).get("source_id"),
    }


def _same(before: dict, after: dict) -> bool:
    def close(a, b) -> bool:  # null (unknown: no goal with torque off) only equals null
        if a is None or b is None:
            return a is b
        a, b = np.array(a, float), np.array(b, float)
        return np.allclose(a, b, rtol=0, atol=1e-9, equal_nan=True)

    keys = ("torque", "mode", "servo_mode", "touch")
    return all(before[k] == after[k] for k in keys) and all(
        close(before[k], after[k]) for k in ("goal_m", "commanded_m", "goal_current_a")
    )


# ---------------------------------------------------------------- beyond loopback, a token


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, server={"host": "0.0.0.0", "token": TOKEN}) as client:
        yield client


def test_the_contact_read_needs_the_token_beyond_loopback(guarded):
    assert guarded.get("/api/contact").status_code == 401
    wrong = {"Authorization": "Bearer " + TOKEN[:-1]}
    assert guarded.get("/api/contact", headers=wrong).status_code == 401
    right = {"Authorization": f"Bearer {TOKEN}"}
    assert guarded.get("/api/contact", headers=right).status_code == 200


@pytest.mark.parametrize(("method", "path", "body"), COMMANDS)
def test_every_contact_command_needs_the_token_then_the_lease(guarded, method, path, body):
    auth = {"Authorization": f"Bearer {TOKEN}"}
    lease = take_lease(guarded, "holder", token=TOKEN, sticky=False)
    no_token = _send(guarded, method, path, body, {"X-Lease": lease["X-Lease"]})
    assert no_token.status_code == 401, (path, no_token.text)
    no_lease = _send(guarded, method, path, body, auth)
    assert no_lease.status_code == 409 and "lease" in no_lease.text, (path, no_lease.text)
    # a bad body without the token is refused for the token, never read
    junk = _send(guarded, method, path, {"direction": "rm -rf /"}, {})
    assert junk.status_code == 401, (path, junk.text)


# ---------------------------------------------------------------- on loopback, the twin


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim", hardware=HARDWARE) as c:
        yield c


@pytest.fixture
def held(app):
    """``app`` with its lease held by this test (headers returned, not sticky), nothing
    e-stopped nor faulted, torque on and the tip resting 20 mm above the plate."""
    lease = take_lease(app, "tests", sticky=False)
    app.post("/api/reset", headers=lease)
    app.post("/api/stop", headers=lease)
    _with(app, lease, torque_on)
    _go(app, lease, ABOVE_M)
    yield lease
    lease = take_lease(app, "tests", sticky=False)
    app.post("/api/stop", headers=lease)
    app.post("/api/reset", headers=lease)


def _with(client, headers, action, *args):
    saved = dict(client.headers)
    client.headers.update(headers)
    try:
        return action(client, *args)
    finally:
        client.headers.clear()
        client.headers.update(saved)


def _go(client, lease, point) -> None:
    ok_json(client.post("/api/move", json={"position_m": list(point)}, headers=lease))
    wait_for(
        lambda: (
            (s := _status(client))["mode"] == "idle"
            and np.allclose(s["ee"]["commanded_m"], point, atol=1e-6)
            and np.allclose(s["ee"]["position_m"], point, atol=1e-3)
        ),
        f"the tip at {list(point)}",
        seen=lambda: _status(client)["ee"],
    )


@pytest.mark.parametrize(("method", "path", "body"), COMMANDS)
def test_another_clients_lease_or_none_moves_and_changes_nothing(app, held, method, path, body):
    before = _state(app)
    take_lease(app, "someone else", sticky=False)  # the lease we held is now stale
    for headers in ({}, held, {"X-Lease": "x" * 10_000}, {"X-Lease": "\u00e9"}):
        try:
            answer = _send(app, method, path, body, headers)
        except UnicodeEncodeError:  # httpx refuses a non-ASCII header: nothing was sent
            continue
        assert answer.status_code == 409, (path, headers.keys(), answer.text)
        assert "lease" in answer.json()["detail"]
    assert _same(before, _state(app)), path


# ---------------------------------------------------------------- bad bodies: 4xx, named

TOUCH, PRESS, CURRENT = "/api/contact/touch", "/api/contact/press", "/api/servos/current"
BAD_BODIES = [
    # (path, body as JSON text, content type, the field named)
    (TOUCH, '{"direction": [0, 0, NaN]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, Infinity]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, -1e400]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, -1, 0]}', None, "direction"),
    (TOUCH, '{"direction": "down"}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, "-1"]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, true]}', None, "direction"),
    (TOUCH, '{"direction": [[0], [0], [-1]]}', None, "direction"),
    (TOUCH, '{"direction": {"x": 0, "y": 0, "z": -1}}', None, "direction"),
    (TOUCH, '{"direction": null}', None, "direction"),
    (TOUCH, "{}", None, "direction"),
    (TOUCH, '{"direction": [1e-300, 0, 0]}', None, "direction"),
    (TOUCH, '{"direction": [1e-200, 1e-200, 0]}', None, "direction"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": 15.000001}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": 1e308}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": 0}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": 0.8}', None, "force_n"),  # = detect
    (TOUCH, '{"direction": [0, 0, -1], "force_n": NaN}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": "2"}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "force_n": true}', None, "force_n"),
    (TOUCH, '{"direction": [0, 0, -1], "speed_m_s": 0.1000001}', None, "speed_m_s"),
    (TOUCH, '{"direction": [0, 0, -1], "speed_m_s": -0.01}', None, "speed_m_s"),
    (TOUCH, '{"direction": [0, 0, -1], "speed_m_s": 1e-320}', None, "speed_m_s"),
    (TOUCH, '{"direction": [0, 0, -1], "speed_m_s": 9.9e-5}', None, "speed_m_s"),
    (TOUCH, '{"direction": [0, 0, -1], "max_travel_m": 0.3000001}', None, "max_travel_m"),
    (TOUCH, '{"direction": [0, 0, -1], "max_travel_m": Infinity}', None, "max_travel_m"),
    (TOUCH, '{"direction": [0, 0, 1], "max_travel_m": 0.2}', None, "max_travel_m"),
    (TOUCH, '{"direction": [1, 0, 0], "max_travel_m": 0.25}', None, "max_travel_m"),
    (TOUCH, '{"direction": [0, 0, -1], "retract_m": -0.001}', None, "retract_m"),
    (TOUCH, '{"direction": [0, 0, -1], "retract_m": 0.06}', None, "retract_m"),
    (TOUCH, '{"direction": [0, 0, -1], "retract_m": null}', None, "retract_m"),
    (TOUCH, '{"direction": [0, 0, -1], "retract_m": "0"}', None, "retract_m"),
    (TOUCH, '{"direction": [0, 0, -1], "force": 2}', None, "force"),
    (TOUCH, '{"direction": [0, 0, -1], "extra": {"a": [1, {"b": null}]}}', None, "extra"),
    (TOUCH, '{"direction": [0, 0, -1]}', "text/plain", "body"),
    (TOUCH, "[0, 0, -1]", None, "body"),
    (TOUCH, "null", None, "body"),
    (TOUCH, '{"direction": [0, 0, -1]', None, "body"),
    (PRESS, '{"direction": [0, 0, -1]}', None, "force_n"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 15.000001}', None, "force_n"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": -2}', None, "force_n"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 1e400}', None, "force_n"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": "2"}', None, "force_n"),
    (PRESS, '{"direction": [0, 0, 0], "force_n": 2}', None, "direction"),
    (PRESS, '{"direction": [NaN, 0, -1], "force_n": 2}', None, "direction"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "frame": "World"}', None, "frame"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "frame": "tool"}', None, "frame"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "duration_s": 0}', None, "duration_s"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "duration_s": 1e9}', None, "duration_s"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "duration_s": NaN}', None, "duration_s"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "duration_s": 3600.001}', None, "duration_s"),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "hold": {}}', None, "hold"),
    (
        PRESS,
        '{"direction": [0, 0, -1], "force_n": 2, "frame": "world", "hold": {"source": "mocap"}}',
        None,
        "source",
    ),
    (
        PRESS,
        '{"direction": [0, 0, -1], "force_n": 2, "frame": "world", "hold": {"x": 1}}',
        None,
        "x",
    ),
    (
        PRESS,
        '{"direction": [0, 0, -1], "force_n": 2, "frame": "world", '
        '"hold": {"position_m": [0, 0, NaN]}}',
        None,
        "position_m",
    ),
    (
        PRESS,
        '{"direction": [0, 0, -1], "force_n": 2, "frame": "world", '
        '"hold": {"latency_compensation": "yes"}}',
        None,
        "latency_compensation",
    ),
    (PRESS, '{"direction": [0, 0, -1], "force_n": 2, "speed": 1}', None, "speed"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [NaN, 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [1e400, 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [-1, 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [3.21, 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [1, 1, 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [[1], 1, 1]}', None, "goal"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": 1}', None, "goal"),
    (CURRENT, '{"operating_mode": 5, "goal_current_a": [1, 1, 1]}', None, "operating_mode"),
    (CURRENT, '{"operating_mode": "current", "goal_current_a": [1, 1, 1]}', None, "operating"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [1, 1, 1], "x": 0}', None, "x"),
    (CURRENT, '{"operating_mode": "position", "goal_current_a": [1, 1, 1]}', "text/xml", "body"),
]


@pytest.mark.parametrize(("path", "text", "kind", "field"), BAD_BODIES)
def test_a_bad_body_is_a_4xx_naming_the_field_and_nothing_moves(app, held, path, text, kind, field):
    before = _state(app)
    method = "PUT" if path == CURRENT else "POST"
    headers = {**held, "Content-Type": kind or "application/json"}
    answer = app.request(method, path, content=text.encode(), headers=headers)
    assert 400 <= answer.status_code < 500, (path, text[:80], answer.status_code, answer.text)
    assert field in answer.text, (path, text[:80], answer.text)
    assert _same(before, _state(app)), (path, text[:80])


@pytest.mark.parametrize(
    ("path", "text", "kind", "field"),
    [
        (CURRENT, '{"operating_mode": "position", "goal_current_a": ["1", 1, 1]}', None, "goal"),
        (CURRENT, '{"operating_mode": "position", "goal_current_a": [true, 1, 1]}', None, "goal"),
    ],
)
def test_servo_currents_as_strings_or_booleans_are_refused_with_torque_off(
    app, held, path, text, kind, field
):
    # torque off: the body is taken as it is (torque on answers 409 whatever the body)
    ok_json(app.post("/api/torque", json={"enabled": False}, headers=held))
    before = _state(app)
    answer = app.put(
        path, content=text.encode(), headers={**held, "Content-Type": "application/json"}
    )
    assert answer.status_code == 422, answer.text
    assert field in answer.text, answer.text
    assert _same(before, _state(app))


@pytest.mark.parametrize("direction", [[1e200, 1e200, -1e200], [0, 1e300, -1e300]])
def test_a_huge_direction_is_a_direction(direction):
    d = unit_direction(direction)
    assert np.linalg.norm(d) == pytest.approx(1.0, abs=1e-12)
    assert d == pytest.approx(
        np.asarray(direction, float) / abs(direction[-1]) / math.sqrt(np.count_nonzero(direction))
    )


def test_a_huge_direction_touches_as_its_unit_direction(app, held):
    body = {"direction": [0, 0, -1e300], "max_travel_m": 0.005}
    result = ok_json(app.post(TOUCH, json=body, headers=held))["result"]
    assert result["end_m"] == pytest.approx([0.0, 0.0, -0.245], abs=1e-9)
    app.post("/api/stop", headers=held)


# ---------------------------------------------------------------- limits exactly at the edge


def test_a_touch_and_a_press_exactly_at_the_force_limit_are_accepted(app, held):
    limits = ok_json(app.get("/api/contact"))["limits"]
    at = limits["force_limit_n"]
    body = {"direction": [0, 0, -1], "force_n": at, "max_travel_m": 0.005, "speed_m_s": 0.1}
    result = ok_json(app.post(TOUCH, json=body, headers=held))["result"]
    assert result["end_m"] == pytest.approx([0.0, 0.0, -0.245], abs=1e-9)
    assert _status(app)["mode"] == "touch"
    assert ok_json(app.post("/api/stop", headers=held))["result"] is True
    before = _state(app)
    over = {**body, "force_n": math.nextafter(at, math.inf)}
    answer = app.post(TOUCH, json=over, headers=held)
    assert answer.status_code == 422 and "force_n" in answer.text, answer.text
    press = {"direction": [0, 0, -1], "force_n": math.nextafter(at, math.inf)}
    answer = app.post(PRESS, json=press, headers=held)
    assert answer.status_code == 422 and "force_n" in answer.text, answer.text
    assert _same(before, _state(app))
    ok_json(app.post(PRESS, json={**press, "force_n": at}, headers=held))
    assert _status(app)["mode"] == "press"
    assert ok_json(app.post("/api/stop", headers=held))["result"] is True


# ---------------------------------------------------------------- refused while not allowed


def _refused_everywhere(app, lease, why: str) -> None:
    before = _state(app)
    simulated = {"frame": "world", "hold": {"source": "simulated"}}
    for path, body in [
        (TOUCH, {"direction": [0, 0, -1]}),
        (PRESS, {"direction": [0, 0, -1], "force_n": 2.0}),
        (PRESS, {"direction": [0, 0, -1], "force_n": 2.0, **simulated}),
    ]:
        answer = app.post(path, json=body, headers=lease)
        assert answer.status_code == 409, (path, body, answer.text)
        assert why in answer.json()["detail"], (path, body, answer.text)
    # on the pose input with no pose: refused for the pose (checked first), 409 or 422
    for hold in ({}, {"position_m": [0.0, 0.0, 1.0]}):
        body = {"direction": [0, 0, -1], "force_n": 2.0, "frame": "world", "hold": hold}
        answer = app.post(PRESS, json=body, headers=lease)
        assert answer.status_code in (409, 422), (hold, answer.text)
        assert "pose" in answer.json()["detail"], (hold, answer.text)
    assert _same(before, _state(app))


def test_touch_and_press_are_refused_while_estopped(app, held):
    ok_json(app.post("/api/estop"))
    _refused_everywhere(app, held, "e-stop")


def test_touch_and_press_are_refused_with_torque_off(app, held):
    ok_json(app.post("/api/torque", json={"enabled": False}, headers=held))
    _refused_everywhere(app, held, "torque")


def test_a_press_with_nothing_under_it_faults_and_then_nothing_is_accepted(app, held):
    _go(app, held, [0.0, 0.0, -0.20])  # 60 mm above the plate, beyond the press's 20 mm
    ok_json(app.post(PRESS, json={"direction": [0, 0, -1], "force_n": 2.0}, headers=held))
    wait_for(lambda: _status(app)["faults"], "the press's fault", seen=lambda: _status(app)["mode"])
    status = _status(app)
    assert "no contact" in status["faults"][0]["reason"], status["faults"]
    # the press moved at most its travel before it faulted
    assert status["ee"]["commanded_m"][2] >= -0.20 - 0.02 - 1e-6, status["ee"]
    _refused_everywhere(app, held, "fault")


def test_touch_and_press_are_refused_while_a_procedure_owns_the_robot(app, held):
    owner = app.app.state.controller.owner
    claim = owner.claim("calibration run cal-attack", "POST /api/calibration/cal-attack/abort")
    try:
        _refused_everywhere(app, held, "calibration run cal-attack")
        ok_json(app.post("/api/torque", json={"enabled": False}, headers=held))
        before = _state(app)
        answer = app.put(CURRENT, json=SERVO_CURRENT, headers=held)
        assert answer.status_code == 409 and "calibration" in answer.text, answer.text
        assert _same(before, _state(app))
    finally:
        owner.release(claim)


# ---------------------------------------------------------------- ordering


def test_stop_with_nothing_running_changes_nothing(app, held):
    before = _state(app)
    assert ok_json(app.post("/api/stop", headers=held))["result"] is False
    assert _same(before, _state(app)), (before, _state(app))
    ok_json(app.post("/api/torque", json={"enabled": False}, headers=held))
    before = _state(app)
    assert ok_json(app.post("/api/stop", headers=held))["result"] is False
    assert _same(before, _state(app)), (before, _state(app))


def test_a_touch_during_a_touch_starts_from_where_the_first_is_commanded(app, held):
    slow = {"direction": [0, 0, -1], "speed_m_s": 0.005, "max_travel_m": 0.015}
    first = ok_json(app.post(TOUCH, json=slow, headers=held))["result"]
    wait_for(lambda: _status(app)["ee"]["commanded_m"][2] < -0.241, "the first touch moving")
    second = ok_json(app.post(TOUCH, json={**slow, "direction": [1, 0, 0]}, headers=held))
    second = second["result"]
    assert second["start_m"][2] < first["start_m"][2]  # it starts where the first had got to
    assert second["end_m"] == pytest.approx(np.add(second["start_m"], [0.015, 0, 0]), abs=1e-9)
    touch = ok_json(app.get("/api/contact"))["touch"]
    assert touch["source_id"] == second["source_id"]
    assert ok_json(app.post("/api/stop", headers=held))["result"] is True


def test_servo_current_is_refused_with_torque_on_and_during_a_touch(app, held):
    before = _state(app)
    answer = app.put(CURRENT, json=SERVO_CURRENT, headers=held)
    assert answer.status_code == 409 and "torque" in answer.text, answer.text
    assert _same(before, _state(app))
    ok_json(app.post(TOUCH, json={"direction": [0, 0, -1], "speed_m_s": 0.005}, headers=held))
    answer = app.put(CURRENT, json=SERVO_CURRENT, headers=held)
    assert answer.status_code == 409, answer.text
    assert _status(app)["servo_mode"] == "position"


def test_the_servo_current_round_trips_with_torque_off_and_torque_comes_back(app, held):
    ok_json(app.post("/api/torque", json={"enabled": False}, headers=held))
    body = {"operating_mode": "current_based_position", "goal_current_a": [1.0, 2.0, 3.209]}
    assert ok_json(app.put(CURRENT, json=body, headers=held)) == {
        "operating_mode": "current_based_position",
        "goal_current_a": pytest.approx([1.0, 2.0, 3.209]),
    }
    status = _status(app)
    assert status["servo_mode"] == "current_based_position"
    assert status["goal_current_a"] == pytest.approx([1.0, 2.0, 3.209])
    back = {"operating_mode": "position", "goal_current_a": [3.209] * 3}
    ok_json(app.put(CURRENT, json=back, headers=held))
    assert _status(app)["servo_mode"] == "position"


# ---------------------------------------------------------------- the world frame


@pytest.mark.parametrize("position_m", [None, [0.0, 0.0, 1.0]])
def test_a_press_in_the_world_without_a_pose_is_refused_and_moves_nothing(app, held, position_m):
    # with a world goal it was accepted and then held with no attitude, pressing nothing
    before = _state(app)
    hold = {"source": "external", "position_m": position_m}
    body = {"direction": [0, 0, -1], "force_n": 2.0, "frame": "world", "hold": hold}
    answer = app.post(PRESS, json=body, headers=held)
    assert answer.status_code in (409, 422), answer.text
    assert "pose" in answer.json()["detail"], answer.text
    assert _same(before, _state(app))


def test_a_press_in_the_world_at_an_absurd_goal_is_refused(app, held):
    before = _state(app)
    hold = {"source": "simulated", "position_m": [1e308, 0, 1]}
    body = {"direction": [0, 0, -1], "force_n": 2.0, "frame": "world", "hold": hold}
    answer = app.post(PRESS, json=body, headers=held)
    assert 400 <= answer.status_code < 500, answer.text
    assert "position_m" in answer.text, answer.text
    assert _same(before, _state(app))


# ---------------------------------------------------------------- the estimate without a current


def test_the_estimate_without_a_current_is_invalid_with_its_reason(app, held):
    bus = app.app.state.node.controller.joint_bus
    real = bus.read_state

    def no_current():
        state = real()
        current = np.array(state.current_a, dtype=float)
        current[1] = np.nan
        object.__setattr__(state, "current_a", current)
        return state

    bus.read_state = no_current
    try:
        wait_for(lambda: not _status(app)["contact"]["valid"], "the estimate refused")
        contact = _status(app)["contact"]
        assert "current" in contact["reason"], contact
        assert ok_json(app.get("/api/contact"))["estimate"]["valid"] is False
        before = _state(app)
        answer = app.post(TOUCH, json={"direction": [0, 0, -1]}, headers=held)
        assert answer.status_code == 409 and "not valid" in answer.text, answer.text
        assert _same(before, _state(app))
    finally:
        bus.read_state = real
    wait_for(lambda: _status(app)["contact"]["valid"], "the estimate back")


# ---------------------------------------------------------------- config


def _refused(field: str, **sections) -> None:
    with pytest.raises(ConfigError) as err:
        load_settings(**sections)
    assert field in str(err.value), str(err.value)


@pytest.mark.parametrize(
    ("contact", "field"),
    [
        ({"detect_force_n": 15.0}, "detect_force_n"),
        ({"detect_force_n": 5.0, "force_limit_n": 4.0, "touch_force_n": 2.0}, "detect_force_n"),
        ({"touch_force_n": 16.0}, "touch_force_n"),
        ({"touch_force_n": 0.5}, "touch_force_n"),  # at or below detect: no touch could run
        ({"touch_force_n": 0.8}, "touch_force_n"),
        ({"force_limit_n": 0.0}, "force_limit_n"),
        ({"force_limit_n": math.nan}, "force_limit_n"),
        ({"force_limit_n": math.inf}, "force_limit_n"),
        ({"force_limit_n": 61.0}, "force_limit_n"),
        ({"collision_force_n": -1.0}, "collision_force_n"),
        ({"touch_speed_m_s": 0.0}, "touch_speed_m_s"),
        ({"touch_speed_m_s": 1e-320}, "touch_speed_m_s"),
        ({"touch_max_travel_m": 1.0}, "touch_max_travel_m"),
        ({"admittance_m_per_n_s": 0.0}, "admittance_m_per_n_s"),
        ({"press_travel_m": math.nan}, "press_travel_m"),
        ({"estimate": "maybe"}, "estimate"),
        ({"limit": 3.0}, "limit"),
    ],
)
def test_a_bad_contact_section_is_refused_naming_the_field(contact, field):
    _refused(field, contact=contact)


@pytest.mark.parametrize(
    ("plate", "field"),
    [
        ({"point_m": [0, 0, -0.26], "stiffness_n_m": 0.0}, "stiffness_n_m"),
        ({"point_m": [0, 0, -0.26], "stiffness_n_m": -1.0}, "stiffness_n_m"),
        ({"point_m": [0, 0, -0.26], "normal": [0, 0, 0]}, "normal"),
        ({"point_m": [0, 0, -0.26], "normal": [0, 0, 1e-12]}, "normal"),
        ({"point_m": [0, 0, -0.26], "normal": [0, 0, math.nan]}, "normal"),
        ({"point_m": [0, 0, math.inf]}, "point_m"),
        ({"point_m": [0, 0]}, "point_m"),
        ({"point_m": [0, 0, -0.26], "half_size_m": [0.1, 0.0]}, "half_size_m"),
        ({"point_m": [0, 0, -0.26], "half_size_m": [0.1, math.inf]}, "half_size_m"),
        ({"point_m": [0, 0, -0.26], "thickness_m": 0.0}, "thickness_m"),
        ({"point_m": [0, 0, -0.26], "damping_n_s_m": -1.0}, "damping_n_s_m"),
        ({"point_m": [0, 0, -0.26], "friction": -0.1}, "friction"),
        ({"point_m": [0, 0, -0.26], "fixed_in": "moon"}, "fixed_in"),
        ({"point_m": [0, 0, -0.26], "colour": "red"}, "colour"),
        ({"normal": [0, 0, 1]}, "point_m"),
    ],
)
def test_a_bad_plate_is_refused_naming_the_field(plate, field):
    _refused(field, hardware={"backend": "sim", "sim": {"plates": [plate]}})


@pytest.mark.parametrize(
    ("hardware", "field"),
    [
        ({"operating_mode": "current"}, "operating_mode"),
        ({"goal_current_a": 0.0}, "goal_current_a"),
        ({"goal_current_a": 3.3}, "goal_current_a"),
        ({"goal_current_a": math.nan}, "goal_current_a"),
        ({"goal_current_a": [1.0, 1.0]}, "goal_current_a"),
        ({"goal_current_a": [1.0, -1.0, 1.0]}, "goal_current_a"),
    ],
)
def test_a_bad_servo_current_in_the_config_is_refused_naming_the_field(hardware, field):
    _refused(field, hardware=hardware)


def test_a_huge_plate_normal_is_normalised():
    settings = load_settings(
        hardware={
            "backend": "sim",
            "sim": {"plates": [{"point_m": [0, 0, -0.26], "normal": [0, 0, 1e300]}]},
        }
    )
    plate = settings.hardware.sim.plates[0].build()
    assert np.asarray(plate.normal) == pytest.approx([0.0, 0.0, 1.0])


# ---------------------------------------------------------------- the fault's hold


class Colliding:
    """A force estimator that reads 7 N pushing down: past collision_force_n (6 N)."""

    def estimate(self, joints, **_):
        return ContactReading(np.array([0.0, 0.0, -7.0]), np.full(3, 0.1), True, None)


def test_a_collision_past_a_joint_limit_holds_within_the_limits():
    # the arm held 0.01 rad inside joint 1's lower limit, jogging, is pushed 0.03 rad past
    # it: the fault holds where measured, but never commands a joint outside its limits
    # (it wrote -0.6275 rad against a -0.6 rad limit)
    bus = FakeBus()
    bus.position = np.array([-0.59, HOME_RAD[1], HOME_RAD[2]])
    loop = Controller(load_settings(contact={"collision_stop": True}), bus, "fake")
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    loop.step()
    gate = loop.ctx.model.gate
    assert loop.state.commanded_rad[0] == pytest.approx(-0.59) and gate.joint_min_rad[0] == -0.6
    loop.state.contact_monitor = ContactMonitor(Colliding(), loop.settings.contact)
    commands.jog_by(loop.state, loop.ctx, np.array([0.0, 0.0, 0.001]), None)
    bus.position = np.array(loop.state.commanded_rad)
    bus.position[0] = -0.63
    bus.calls.clear()
    loop.step()
    assert loop.state.faults and loop.state.faults[0].kind == "collision"
    goals = [np.array(call[1]) for call in bus.calls if call[0] == "write_goal"]
    assert len(goals) == 1
    assert goals[0] == pytest.approx([-0.6, HOME_RAD[1], HOME_RAD[2]], abs=1e-12)
    assert (goals[0] >= np.array(gate.joint_min_rad)).all()
