"""An attacker's pass over the API routes of issue 32 (program control and library, the
simulated drone and the hold on the pose input, run types and their checks, a run's series,
the wrist servo, the tuning list): every motion or state-changing route needs the token and
the lease, and refuses without them with nothing moved and nothing changed; a bad body is a
4xx naming the field, never a 500; an odd id reads nothing; every read needs the token where
other machines reach the server; the simulated drone cannot stand in for a live pose input
and stops with the lease that started it. In-process apps, the loop on simulated time."""

from __future__ import annotations

import time

import pytest

from app.programs.library import ProgramLibrary
from app.world.drone_feed import DroneFeed
from app.world.drone_sim import DroneSimParams
from tests.support.app_client import make_client, torque_on, unmoved
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TOKEN = "an-attackers-guess-is-not-this"
PROGRAM = "G21 G91 F360\nG1 X5\nG1 X-5\nM2"

# every route of issue 32 that moves the robot or changes what it, a run or the pose input
# does, with a body it would otherwise take
COMMANDS = [
    ("POST", "/api/programs/pause", None),
    ("POST", "/api/programs/resume", None),
    ("POST", "/api/programs/step", None),
    ("PUT", "/api/programs/feed", {"override": 0.5}),
    ("PUT", "/api/programs/optional-stop", {"on": True}),
    ("POST", "/api/programs/run", {"gcode": PROGRAM, "start_line": 2, "feed_override": 0.5}),
    ("POST", "/api/mav/simulated", {"running": True}),
    ("POST", "/api/tests/hold", {"source": "external", "position_m": [0, 0, 1.2]}),
    ("POST", "/api/servos/4/gains", {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}),
    ("POST", "/api/servos/4/step", {"step_rad": 0.1}),
    ("POST", "/api/servos/1/step", {"step_rad": 0.1}),
]

# the reads of issue 32
READS = [
    "/api/tests",
    "/api/programs/defaults",
    "/api/programs/library",
    "/api/programs/library/0123456789abcdef",
    "/api/runs/20260101-000000-sinusoid/series",
    "/api/tuning",
    "/api/mav/pose",
    "/api/status",
]


def _send(client, method: str, path: str, body, headers=None):
    return client.request(method, path, json=body, headers=headers or {})


def _state(client) -> dict:
    """What must not change when a command is refused: the loop's state, the runs, the
    simulated drone and the program library."""
    status = ok_json(client.get("/api/status"))
    return {
        "status": {
            "torque": status["torque"],
            "mode": status["mode"],
            "goal_m": status["goal"]["position_m"],
            "commanded_m": status["ee"]["commanded_m"],
        },
        "runs": len(ok_json(client.get("/api/runs"))),
        "drone": ok_json(client.get("/api/mav/pose"))["simulated"]["running"],
        "library": len(ok_json(client.get("/api/programs/library"))["programs"]),
    }


def _same(before: dict, after: dict) -> bool:
    """Nothing moved (torque off: no goal nor command, [null]*3, on both) nor changed."""
    old, new = before["status"], after["status"]
    moved = old != new and not unmoved(old, new)
    return not moved and all(before[k] == after[k] for k in ("runs", "drone", "library"))


# ---------------------------------------------------------------- beyond loopback, a token


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, server={"host": "0.0.0.0", "token": TOKEN}) as client:
        yield client


@pytest.mark.parametrize("path", READS)
def test_every_read_needs_the_token_beyond_loopback(guarded, path):
    refused = guarded.get(path)
    assert refused.status_code == 401, (path, refused.status_code, refused.text)
    assert "token" in refused.json()["detail"]
    wrong = guarded.get(path, headers={"Authorization": "Bearer " + TOKEN[:-1]})
    assert wrong.status_code == 401, path
    allowed = guarded.get(path, headers={"Authorization": f"Bearer {TOKEN}"})
    assert allowed.status_code != 401, (path, allowed.text)


@pytest.mark.parametrize(("method", "path", "body"), COMMANDS)
def test_every_command_needs_the_token_then_the_lease(guarded, method, path, body):
    auth = {"Authorization": f"Bearer {TOKEN}"}
    lease = take_lease(guarded, "holder", token=TOKEN, sticky=False)
    before = _state_with(guarded, auth)
    no_token = _send(guarded, method, path, body, {"X-Lease": lease["X-Lease"]})
    assert no_token.status_code == 401, (path, no_token.text)
    no_lease = _send(guarded, method, path, body, auth)
    assert no_lease.status_code == 409 and "lease" in no_lease.text, (path, no_lease.text)
    assert _same(before, _state_with(guarded, auth)), path


def _state_with(client, headers) -> dict:
    saved = dict(client.headers)
    client.headers.update(headers)
    try:
        return _state(client)
    finally:
        client.headers.clear()
        client.headers.update(saved)


# ---------------------------------------------------------------- on loopback: the lease


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    # the pose's age is the station's clock while the loop runs on simulated time: a wide
    # margin before a pose is stale or lost
    world = {"stale_after_s": 1.0, "lost_after_s": 5.0}
    with make_client(tmp_path_factory.mktemp("runs"), world=world) as client:
        yield client
        client.post("/api/mav/simulated", json={"running": False}, headers=take_lease(client))


@pytest.fixture
def held(app):
    """``app`` with its control lease held by this test's client (headers returned, not
    sticky: each test says what it sends), the drone stopped, no run going."""
    lease = take_lease(app, "tests", sticky=False)
    app.post("/api/mav/simulated", json={"running": False}, headers=lease)
    app.post("/api/reset", headers=lease)
    yield lease
    lease = take_lease(app, "tests", sticky=False)
    app.post("/api/mav/simulated", json={"running": False}, headers=lease)
    for run in ok_json(app.get("/api/runs")):
        if run["state"] == "running":
            app.post(f"/api/runs/{run['run_id']}/abort", headers=lease)


@pytest.mark.parametrize(("method", "path", "body"), COMMANDS)
def test_another_clients_lease_or_none_moves_and_changes_nothing(app, held, method, path, body):
    ok_json(app.post("/api/torque", json={"enabled": True}, headers=held))
    before = _state(app)
    take_lease(app, "someone else", sticky=False)  # the lease we held is now stale
    for headers in ({}, held, {"X-Lease": "x" * 10_000}):
        answer = _send(app, method, path, body, headers)
        assert answer.status_code == 409, (path, headers.keys(), answer.text)
        assert "lease" in answer.json()["detail"]
    assert _same(before, _state(app)), path


# ---------------------------------------------------------------- bad bodies: 4xx, named


BAD_BODIES = [
    # (method, path, body as JSON text or bytes, content type, the field named)
    ("PUT", "/api/programs/feed", '{"override": 1.01}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": 100}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": "0.5"}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": NaN}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": Infinity}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": 1e400}', None, "override"),
    ("PUT", "/api/programs/feed", '{"override": 0.5, "boost": 2}', None, "boost"),
    ("PUT", "/api/programs/feed", '{"override": 0.5}', "text/plain", "body"),
    ("PUT", "/api/programs/feed", b'{"override": "\xff\xfe"}', None, "body"),
    ("PUT", "/api/programs/feed", "[0.5]", None, "body"),
    ("PUT", "/api/programs/optional-stop", '{"on": 1}', None, "on"),
    ("PUT", "/api/programs/optional-stop", '{"on": "true"}', None, "on"),
    (
        "POST",
        "/api/programs/run",
        '{"gcode": "G1 X1", "feed_override": 1.5}',
        None,
        "feed_override",
    ),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "feed_override": 0}', None, "feed_override"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "start_line": 0}', None, "start_line"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "start_line": -3}', None, "start_line"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "start_line": "2"}', None, "start_line"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "start_line": 2.5}', None, "start_line"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "start_line": true}', None, "start_line"),
    (
        "POST",
        "/api/programs/run",
        '{"gcode": "G1 X1", "optional_stop": "on"}',
        None,
        "optional_stop",
    ),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "name": "' + "n" * 5000 + '"}', None, "name"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "name": "../../etc/passwd"}', None, "name"),
    ("POST", "/api/programs/run", '{"gcode": 5}', None, "gcode"),
    ("POST", "/api/programs/run", '{"gcode": "G1 X1", "speed": 9}', None, "speed"),
    ("POST", "/api/mav/simulated", '{"running": "yes"}', None, "running"),
    ("POST", "/api/mav/simulated", '{"running": true, "rate_hz": 1e9}', None, "rate_hz"),
    ("POST", "/api/mav/simulated", '{"running": true, "seed": 1e30}', None, "seed"),
    ("POST", "/api/mav/simulated", '{"running": true, "seed": -1}', None, "seed"),
    ("POST", "/api/mav/simulated", '{"running": true, "latency_s": NaN}', None, "latency_s"),
    ("POST", "/api/tests/hold", '{"source": "external", "position_m": [0, 0]}', None, "position_m"),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "external", "position_m": [0, 0, NaN]}',
        None,
        "position_m",
    ),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "external", "position_m": [1e308, 0, 1]}',
        None,
        "position_m",
    ),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "simulated", "position_m": [1e308, 0, 1]}',
        None,
        "position_m",
    ),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "simulated", "position_m": [0, 0, 1e300]}',
        None,
        "position_m",
    ),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "external", "heading_rad": Infinity}',
        None,
        "heading_rad",
    ),
    (
        "POST",
        "/api/tests/hold",
        '{"source": "simulated", "heading_rad": 1e300}',
        None,
        "heading_rad",
    ),
    (
        "POST",
        "/api/hold",
        '{"source": "simulated", "frame": "world", "position_m": [1e308, 0, 1]}',
        None,
        "position_m",
    ),
    ("POST", "/api/tests/hold", '{"source": "mocap"}', None, "source"),
    ("POST", "/api/tests/hold", '{"duration_s": 1e9}', None, "duration_s"),
    ("POST", "/api/servos/4/step", '{"step_rad": NaN}', None, "step_rad"),
    ("POST", "/api/servos/4/step", '{"step_rad": 100}', None, "step_rad"),
    ("POST", "/api/servos/4/step", '{"step_rad": 0.1, "duration_s": 1e9}', None, "duration_s"),
    ("POST", "/api/servos/4/gains", '{"p": 1e9, "i": 0, "d": 0, "ff1": 0, "ff2": 0}', None, "p"),
    ("POST", "/api/servos/4/gains", '{"p": -1, "i": 0, "d": 0, "ff1": 0, "ff2": 0}', None, "p"),
    ("POST", "/api/servos/4/gains", '{"p": 8.5, "i": 0, "d": 0, "ff1": 0, "ff2": 0}', None, "p"),
    ("POST", "/api/tests/sinusoid/check", '{"amplitude_m": NaN}', None, "amplitude_m"),
    ("POST", "/api/tests/sinusoid/check", '{"frequency_hz": 1e400}', None, "frequency_hz"),
    ("POST", "/api/tests/sinusoid/check", '{"surprise": 1}', None, "surprise"),
]


@pytest.mark.parametrize(("method", "path", "text", "kind", "field"), BAD_BODIES)
def test_a_bad_body_is_a_4xx_naming_the_field_and_nothing_changes(
    app, held, method, path, text, kind, field
):
    if path == "/api/tests/hold":  # a fresh pose: refused for the body, not the input
        _real_pose(app, time.monotonic())
    before = _state(app)
    headers = {**held, "Content-Type": kind or "application/json"}
    data = text if isinstance(text, bytes) else text.encode()
    answer = app.request(method, path, content=data, headers=headers)
    assert 400 <= answer.status_code < 500, (path, text[:80], answer.status_code, answer.text)
    assert field in answer.text, (path, text[:80], answer.text)
    assert _same(before, _state(app)), (path, text[:80])


def test_a_huge_program_is_refused_before_it_is_read(app, held):
    before = _state(app)
    gcode = "G1 X0\n" * 3_000_000  # 18 MB, over the request limit
    answer = app.post("/api/programs/run", json={"gcode": gcode}, headers=held)
    assert answer.status_code == 413, answer.text[:200]
    assert _same(before, _state(app))


# ---------------------------------------------------------------- odd ids read nothing


@pytest.mark.parametrize(
    "path",
    [
        "/api/programs/library/..%2F..%2F..%2Fetc%2Fpasswd",
        "/api/programs/library/%2e%2e",
        "/api/programs/library/0123456789ABCDEF",
        "/api/programs/library/0123456789abcdef0",
        "/api/programs/library/0123456789abcde%00",
        "/api/programs/library/" + "a" * 5000,
        "/api/programs/library/0123456789abcdef.json",
    ],
)
def test_an_odd_library_id_reads_nothing(app, path):
    answer = app.get(path)
    assert answer.status_code in (404, 422), (path[:80], answer.status_code, answer.text[:200])
    assert "gcode" not in answer.json(), path[:80]


@pytest.mark.parametrize(
    "path",
    [
        "/api/runs/..%2F..%2Fetc/series",
        "/api/runs/%2e%2e/series",
        "/api/runs/" + "r" * 5000 + "/series",
        "/api/runs/x/series?max_points=0",
        "/api/runs/x/series?max_points=9",
        "/api/runs/x/series?max_points=100000000000000000000000",
        "/api/runs/x/series?max_points=NaN",
        "/api/runs/x/series?max_points=1e3",
    ],
)
def test_an_odd_run_id_or_size_of_a_series_is_refused(app, path):
    answer = app.get(path)
    assert answer.status_code in (404, 422), (path[:80], answer.status_code, answer.text[:200])


@pytest.mark.parametrize("servo", ["0", "5", "-1", "99999999999999999999999", "4.0", "wrist"])
def test_an_odd_servo_id_is_refused(app, held, servo):
    before = _state(app)
    for method, tail, body in [
        ("GET", "gains", None),
        ("POST", "gains", {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}),
        ("POST", "step", {"step_rad": 0.1}),
    ]:
        answer = _send(app, method, f"/api/servos/{servo}/{tail}", body, held)
        assert answer.status_code in (404, 422), (servo, tail, answer.status_code, answer.text)
    assert _same(before, _state(app))


# ---------------------------------------------------------------- the simulated drone


def _pose(client) -> dict:
    return ok_json(client.get("/api/mav/pose"))


def _real_pose(client, t_s: float, z_m: float = 1.5) -> dict:
    """A motion-capture pose near where the simulated drone hovers (it would pass the
    tracker's jump check): the case where a simulated one could stand in for it."""
    body = {"t": t_s, "position": [0.0, 0.0, z_m], "quaternion": [1.0, 0.0, 0.0, 0.0]}
    return ok_json(client.post("/api/mav/pose", json=body))


def test_the_simulated_drone_is_refused_while_a_live_pose_input_streams(app, held):
    assert _real_pose(app, time.monotonic())["accepted"]
    assert _pose(app)["state"] == "ok" and _pose(app)["source"] == "http"
    answer = app.post("/api/mav/simulated", json={"running": True}, headers=held)
    assert answer.status_code == 409, answer.text
    assert "source" in answer.json()["detail"] or "pose" in answer.json()["detail"]
    assert _pose(app)["simulated"]["running"] is False
    assert _pose(app)["source"] == "http"


@pytest.mark.slow  # waits for the drone's feed and for the lease to lapse
@pytest.mark.parametrize("how", ["given back", "taken over"])
def test_the_simulated_drone_stops_with_the_lease_that_started_it(app, held, how):
    # no live input: wait until the last test's pose is lost before starting the drone
    wait_for(lambda: _pose(app)["state"] != "ok", "no live pose input")
    ok_json(app.post("/api/mav/simulated", json={"running": True, "rate_hz": 50}, headers=held))
    wait_for(lambda: _pose(app)["simulated"]["running"], "the drone flying")
    if how == "given back":
        assert app.request("DELETE", "/api/lease", headers=held).status_code == 200
    else:
        take_lease(app, "another station", sticky=False)
    wait_for(
        lambda: not _pose(app)["simulated"]["running"],
        f"the drone stopped once its lease was {how}",
        seen=lambda: _pose(app)["simulated"],
    )
    assert "lease" in (_pose(app)["simulated"]["last_error"] or "")


@pytest.mark.slow  # a hold run started and aborted
def test_the_simulated_drone_is_refused_while_a_hold_in_the_world_runs(app, held):
    torque_on_with(app, held)
    body = {"source": "simulated", "duration_s": 60.0}
    run_id = ok_json(app.post("/api/tests/hold", json=body, headers=held))["run_id"]
    wait_for(lambda: _state(app)["status"]["mode"] == "hold-world", "the hold running")
    answer = app.post("/api/mav/simulated", json={"running": True}, headers=held)
    assert answer.status_code == 409 and "hold" in answer.json()["detail"], answer.text
    assert _pose(app)["simulated"]["running"] is False
    ok_json(app.post(f"/api/runs/{run_id}/abort", headers=held))


def torque_on_with(client, headers) -> None:
    saved = dict(client.headers)
    client.headers.update(headers)
    try:
        torque_on(client)
    finally:
        client.headers.clear()
        client.headers.update(saved)


def test_a_hold_on_the_pose_input_with_a_live_pose_is_refused_without_the_lease(app, held):
    _real_pose(app, time.monotonic())
    before = _state(app)
    answer = app.post(
        "/api/tests/hold", json={"source": "external", "position_m": [0, 0, 1.2]}, headers={}
    )
    assert answer.status_code == 409 and "lease" in answer.text
    assert _same(before, _state(app))


# ---------------------------------------------------------------- program control


def test_resume_with_no_program_or_after_an_estop_moves_nothing(app, held):
    ok_json(app.post("/api/torque", json={"enabled": True}, headers=held))
    app.post("/api/estop")
    before = _state(app)
    for path in ("/api/programs/resume", "/api/programs/step", "/api/programs/pause"):
        answer = app.post(path, headers=held)
        assert answer.status_code == 409, (path, answer.text)
    app.post("/api/reset", headers=held)
    after = _state(app)
    answer = app.post("/api/programs/resume", headers=held)
    assert answer.status_code == 409, answer.text
    assert _same(after, _state(app))
    assert before["runs"] == after["runs"]


@pytest.mark.slow  # a program checked in a worker and run to its M0
def test_resume_after_an_estop_and_reset_of_a_paused_program_moves_nothing(app, held):
    torque_on_with(app, held)
    gcode = "G21 G91 F360\nG1 X5\nM0\nG1 X-5\nM2"
    answer = app.post("/api/programs/run", json={"gcode": gcode}, headers=held)
    run_id = ok_json(answer)["run_id"]

    def progress() -> dict:
        run = ok_json(app.get(f"/api/runs/{run_id}"))
        return run["progress"] or {"state": run["state"]}

    wait_for(
        lambda: progress().get("paused") is not None, "the program stopped at its M0", seen=progress
    )
    app.post("/api/estop")
    wait_for(
        lambda: ok_json(app.get(f"/api/runs/{run_id}"))["state"] != "running",
        "the run ended by the e-stop",
    )
    ok_json(app.post("/api/reset", headers=held))
    before = _state(app)
    for path in ("/api/programs/resume", "/api/programs/step"):
        answer = app.post(path, headers=held)
        assert answer.status_code == 409, (path, answer.text)
    answer = app.put("/api/programs/feed", json={"override": 1.0}, headers=held)
    assert answer.status_code == 409, answer.text
    assert _same(before, _state(app))
    assert ok_json(app.get(f"/api/runs/{run_id}"))["state"] != "running"


@pytest.mark.slow  # the e-stop's hold and a check's refusal
def test_a_program_run_with_the_robot_estopped_is_refused_and_nothing_is_checked(app, held):
    ok_json(app.post("/api/torque", json={"enabled": True}, headers=held))
    app.post("/api/estop")
    before = _state(app)
    answer = app.post("/api/programs/run", json={"gcode": PROGRAM, "start_line": 2}, headers=held)
    assert answer.status_code == 409, answer.text
    assert _same({**before, "library": _state(app)["library"]}, _state(app))
    app.post("/api/reset", headers=held)


@pytest.mark.slow  # the OpenAPI schema is built
def test_the_feed_override_is_never_above_100_percent_in_the_schema(app):
    schema = ok_json(app.get("/openapi.json"))["components"]["schemas"]
    assert schema["FeedOverrideRequest"]["properties"]["override"]["maximum"] == 1.0
    assert schema["RunProgramRequest"]["properties"]["feed_override"]["maximum"] == 1.0


def test_the_library_keeps_at_most_its_cap_and_no_entry_over_its_size(tmp_path):
    library = ProgramLibrary(tmp_path, max_bytes=100, max_entries=3)
    for n in range(10):
        library.add(f"G1 X{n}", f"p{n}", "check", now=float(n))
    assert [e.name for e in library.entries()] == ["p9", "p8", "p7"]
    assert len(list(tmp_path.iterdir())) == 6  # two files each, nothing left behind
    assert library.add("G1 X1\n" * 50, "big", "check") is None
    assert len(library.entries()) == 3


@pytest.mark.parametrize(
    "path", ["/api/programs/check", "/api/programs/dry-run", "/api/programs/run"]
)
def test_a_program_with_a_lone_surrogate_is_a_422_naming_gcode_and_is_not_kept(app, held, path):
    # JSON may escape a lone surrogate; no UTF-8 text holds one (it was a 500 in the library)
    before = _state(app)
    text = rb'{"gcode": "G21 G91 F360\nG1 X1 (\ud800)"}'
    headers = {**held, "Content-Type": "application/json"}
    answer = app.post(path, content=text, headers=headers)
    assert answer.status_code == 422, answer.text[:300]
    assert answer.json()["detail"].startswith("gcode:"), answer.text[:300]
    assert "surrogate" in answer.json()["detail"]
    assert _same(before, _state(app))


def test_a_drone_feed_stops_itself_once_it_is_no_longer_allowed():
    pushed: list[dict] = []
    allowed = {"now": True}
    feed = DroneFeed(pushed.append, DroneSimParams(rate_hz=200.0), allowed=lambda: allowed["now"])
    feed.start()
    try:
        wait_for(lambda: len(pushed) >= 3, "the feed pushing")
        allowed["now"] = False
        wait_for(lambda: not feed.running, "the feed stopped itself")
        sent = len(pushed)
        assert "lease" in (feed.last_error or "")
        assert feed.status()["running"] is False and feed.sent == sent
    finally:
        feed.stop()
    assert len(pushed) == sent  # nothing pushed after it stopped
