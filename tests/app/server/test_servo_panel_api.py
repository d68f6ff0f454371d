"""The servo panel's API (issue 21): one servo's gains read from its own registers and
written to them (the emulated bus: real packets, the emulator's control tables read back),
bad values refused naming the field with nothing written, refusals while the arm moves or
something else holds it, the revert and the config file; and a step of one joint, on the
emulated bus and on the twin, whose record rises towards its goal."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from hardware.dynamixel.control_table import Reg
from tests.support.app_client import make_client, settle_at, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}
TUNED = {"p": 1010, "i": 37, "d": 120, "ff1": 4, "ff2": 9}
REGISTERS = {
    "p": Reg.POSITION_P_GAIN,
    "i": Reg.POSITION_I_GAIN,
    "d": Reg.POSITION_D_GAIN,
    "ff1": Reg.FEEDFORWARD_1ST_GAIN,
    "ff2": Reg.FEEDFORWARD_2ND_GAIN,
}
HOME = (0.0, 0.0, -0.24)  # joints 30.085 deg each
HIGH_3 = 0.55  # joint 3's upper limit here [rad] (31.5 deg): a step up 3 deg passes it
JOINTS = [{"servo_id": 1}, {"servo_id": 2}, {"servo_id": 3, "max_angle_rad": HIGH_3}]
# a starved simulator (the twin, or the one the emulated servos move) may stall or lag for
# a while on a loaded machine: these tests look at the panel, not at the loop's faults
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
# a held jog's heartbeat may come late too: the jog below must still be going when the
# requests after its start arrive (CI once saw it stopped at the 0.15 s default)
SLOW_DEADMAN = {"hold_timeout_s": 2.0}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    folder = tmp_path_factory.mktemp("panel")
    with make_client(folder, hardware={"joints": JOINTS}, safety=PATIENT, jog=SLOW_DEADMAN) as c:
        take_lease(c)
        yield c


@pytest.fixture
def resting(client):
    """The shared client holding the arm at the home point, the factory gains on every
    servo (nothing left to revert), no run going."""
    client.post("/api/reset")
    take_lease(client)
    settle_at(client, HOME)
    at_rest(client)
    while client.app.state.tuning.revertable:
        ok_json(client.post("/api/tuning/revert"))
    return client


def at_rest(client) -> None:
    """Wait until the goal's jog stands at its goal (settle_at waits for the commanded point
    within 0.1 mm of it: the jog's last ticks may still be to come)."""

    def status() -> dict:
        return ok_json(client.get("/api/status"))

    def standing() -> bool:
        now = status()
        gap = np.subtract(now["goal"]["position_m"], now["ee"]["commanded_m"])
        return bool(np.abs(gap).max() < 1e-9)

    wait_for(standing, "the jog to stand at its goal", seen=lambda: status()["ee"])


def registers(client, servo_id: int) -> dict[str, int]:
    table = client.app.state.backend.emulator.servo(servo_id).table
    return {name: table.get(reg) for name, reg in REGISTERS.items()}


def all_registers(client) -> dict[int, dict[str, int]]:
    return {sid: registers(client, sid) for sid in client.app.state.controller.servo_ids}


@pytest.mark.slow
def test_a_read_is_of_the_servos_own_registers(resting):
    body = ok_json(resting.get("/api/servos/2/gains"))
    assert body["servo_id"] == 2 and body["joint"] == 2
    assert body["servo"] == body["in_use"] == FACTORY
    assert body["limits"] == {k: {"min": 0, "max": 16383} for k in REGISTERS}
    assert body["step_rad"]["max"] == pytest.approx(math.radians(5.0))
    assert body["revertable"] is False
    # something else (another tool on the bus) writes the servo: the read shows it, the
    # loop's own record of what it set does not change
    table = resting.app.state.backend.emulator.servo(2).table
    table.set(Reg.POSITION_P_GAIN, 777)
    try:
        body = ok_json(resting.get("/api/servos/2/gains"))
        assert body["servo"]["p"] == 777 and body["in_use"]["p"] == 800
    finally:
        table.set(Reg.POSITION_P_GAIN, 800)


@pytest.mark.slow
def test_a_write_reaches_the_servos_registers_and_the_revert_restores_them(resting):
    written = ok_json(resting.post("/api/servos/2/gains", json=TUNED))
    assert written["servo"] == TUNED  # read back from the servo after the write
    assert written["gains"] == {"1": FACTORY, "2": TUNED, "3": FACTORY}
    assert written["config_written"] is None  # this server runs from no file
    assert all_registers(resting) == {1: FACTORY, 2: TUNED, 3: FACTORY}
    assert ok_json(resting.get("/api/status"))["gains"]["2"] == TUNED
    read = ok_json(resting.get("/api/servos/2/gains"))
    assert read["servo"] == read["in_use"] == TUNED and read["revertable"] is True
    # two writes, two reverts, in order
    ok_json(resting.post("/api/servos/1/gains", json={**FACTORY, "p": 900}))
    assert registers(resting, 1)["p"] == 900
    ok_json(resting.post("/api/tuning/revert"))
    assert all_registers(resting) == {1: FACTORY, 2: TUNED, 3: FACTORY}
    reverted = ok_json(resting.post("/api/tuning/revert"))
    assert reverted["gains"] == {str(i): FACTORY for i in (1, 2, 3)}
    assert all_registers(resting) == {1: FACTORY, 2: FACTORY, 3: FACTORY}
    answer = resting.post("/api/tuning/revert")
    assert answer.status_code == 409 and "revert" in answer.text, answer.text


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"p": 16384}, "p"),
        ({"i": -1}, "i"),
        ({"d": 20000}, "d"),
        ({"ff1": 1.5}, "ff1"),
        ({"ff2": "9"}, "ff2"),
        ({"p": True}, "p"),
        ({"wobble": 1}, "wobble"),
    ],
)
def test_a_bad_value_is_a_422_naming_the_field_and_nothing_is_written(resting, change, field):
    before = all_registers(resting)
    answer = resting.post("/api/servos/2/gains", json={**TUNED, **change})
    assert answer.status_code == 422, answer.text
    assert answer.json()["detail"].startswith(f"{field}: "), answer.text
    assert all_registers(resting) == before
    assert resting.app.state.controller.gains[2] == resting.app.state.controller.gains[1]
    assert resting.app.state.tuning.revertable is False


def test_a_missing_gain_is_named_and_nothing_is_written(resting):
    body = {k: v for k, v in TUNED.items() if k != "ff2"}
    answer = resting.post("/api/servos/2/gains", json=body)
    assert answer.status_code == 422 and answer.json()["detail"].startswith("ff2: "), answer.text
    assert registers(resting, 2) == FACTORY


def test_unknown_servos_are_404_and_a_write_needs_the_lease(resting):
    runs = len(ok_json(resting.get("/api/runs")))
    for answer in (
        resting.get("/api/servos/9/gains"),
        resting.post("/api/servos/9/gains", json=TUNED),
        resting.post("/api/servos/9/step", json={"step_rad": 0.02}),
    ):
        assert answer.status_code == 404 and "servo_id: 9" in answer.text, answer.text
    lease = resting.headers.pop("X-Lease")
    try:
        answer = resting.post("/api/servos/2/gains", json=TUNED)
        assert answer.status_code == 409 and "lease" in answer.text.lower(), answer.text
        answer = resting.post("/api/servos/2/step", json={"step_rad": 0.02})
        assert answer.status_code == 409 and "lease" in answer.text.lower(), answer.text
    finally:
        resting.headers["X-Lease"] = lease
    assert registers(resting, 2) == FACTORY
    assert len(ok_json(resting.get("/api/runs"))) == runs


@pytest.mark.slow
def test_gains_are_neither_read_nor_written_while_a_motion_runs(resting):
    ok_json(resting.post("/api/move", json={"position_m": [0.0, 0.0, -0.22], "duration_s": 60}))
    wait_for(
        lambda: ok_json(resting.get("/api/status"))["mode"] == "move",
        "the move to start",
        seen=lambda: ok_json(resting.get("/api/status"))["mode"],
    )
    for answer in (
        resting.post("/api/servos/2/gains", json=TUNED),
        resting.get("/api/servos/2/gains"),
        resting.post("/api/servos/2/step", json={"step_rad": 0.02}),
    ):
        assert answer.status_code == 409 and "move" in answer.text, answer.text
    assert registers(resting, 2) == FACTORY
    ok_json(resting.post("/api/estop"))  # ends the move
    ok_json(resting.post("/api/reset"))


@pytest.mark.slow
def test_a_goals_jog_standing_at_it_rests_but_a_held_jog_moves(resting):
    ok_json(resting.post("/api/servos/2/gains", json=TUNED))  # the goal's jog stands
    assert registers(resting, 2) == TUNED
    ok_json(resting.post("/api/jog", json={"velocity_m_s": [0.0, 0.0, 0.005]}))
    answer = resting.post("/api/servos/2/gains", json=FACTORY)  # queued after the jog's
    assert answer.status_code == 409 and "jog" in answer.text, answer.text
    answer = resting.post("/api/servos/2/step", json={"step_rad": 0.02})
    assert answer.status_code == 409, answer.text
    ok_json(resting.post("/api/jog", json={"velocity_m_s": [0.0, 0.0, 0.0]}))
    assert registers(resting, 2) == TUNED


def test_a_write_is_refused_while_a_procedure_holds_the_robot(resting):
    owner = resting.app.state.controller.owner
    claim = owner.claim("calibration run cal-test", "POST /api/calibration/cal-test/abort")
    try:
        answer = resting.post("/api/servos/2/gains", json=TUNED)
        assert answer.status_code == 409 and "cal-test" in answer.text, answer.text
        answer = resting.post("/api/servos/2/step", json={"step_rad": 0.02})
        assert answer.status_code == 409 and "cal-test" in answer.text, answer.text
    finally:
        owner.release(claim)
    assert registers(resting, 2) == FACTORY


@pytest.mark.slow  # a test run on the emulated bus
def test_a_write_is_refused_while_a_test_run_goes(resting):
    run = ok_json(resting.post("/api/tests/step", json={"size_m": 0.002, "duration_s": 20.0}))
    try:
        answer = resting.post("/api/servos/2/gains", json=TUNED)
        assert answer.status_code == 409 and run["run_id"] in answer.text, answer.text
        assert registers(resting, 2) == FACTORY
    finally:
        ok_json(resting.post(f"/api/runs/{run['run_id']}/abort"))


@pytest.mark.slow
def test_a_write_goes_to_the_config_file_and_its_revert_too(tmp_path):
    from app.config import load_settings

    config = tmp_path / "robot.toml"
    config.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    with make_client(tmp_path / "runs", config_path=config) as c:
        take_lease(c)
        written = ok_json(c.post("/api/servos/3/gains", json=TUNED))
        assert written["config_written"] == str(config)
        saved = {j.servo_id: j.gains.model_dump() for j in load_settings(config).hardware.joints}
        assert saved == {1: FACTORY, 2: FACTORY, 3: TUNED}
        assert load_settings(config).server.http_port == 8123
        ok_json(c.post("/api/tuning/revert"))
        saved = {j.servo_id: j.gains.model_dump() for j in load_settings(config).hardware.joints}
        assert saved == {1: FACTORY, 2: FACTORY, 3: FACTORY}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("servo_id", "body", "words"),
    [
        (2, {"step_rad": math.radians(6.0)}, "step_rad: "),
        (2, {"step_rad": 0.0}, "step_rad: 0.00 deg"),
        (2, {"step_rad": "0.05"}, "step_rad: "),
        (2, {"step_rad": 0.05, "duration_s": 9.0}, "duration_s: "),
        (3, {"step_rad": math.radians(3.0)}, "step_rad: the step's end: joint 3"),
    ],
)
def test_a_bad_step_is_a_422_naming_the_field_and_nothing_moves(resting, servo_id, body, words):
    before = ok_json(resting.get("/api/status"))
    runs = len(ok_json(resting.get("/api/runs")))
    answer = resting.post(f"/api/servos/{servo_id}/step", json=body)
    assert answer.status_code == 422, answer.text
    assert answer.json()["detail"].startswith(words), answer.text
    after = ok_json(resting.get("/api/status"))
    assert after["mode"] == before["mode"] and after["goal"] == before["goal"]
    assert after["joints"]["commanded_rad"] == before["joints"]["commanded_rad"]
    assert len(ok_json(resting.get("/api/runs"))) == runs


def step_and_check(client, servo_id: int, step_rad: float) -> dict:
    """Step ``servo_id``'s joint from rest at the home point; check that the record rises
    towards the goal and the other joints held; the answer."""
    before = np.array(ok_json(client.get("/api/status"))["joints"]["commanded_rad"])
    body = ok_json(client.post(f"/api/servos/{servo_id}/step", json={"step_rad": step_rad}))
    assert body["state"] == "done", body["reason"]
    joint = body["joint"]
    assert body["start_rad"] == pytest.approx(before.tolist(), abs=1e-9)
    t, goal, measured = (np.array(body[k]) for k in ("t_s", "goal_rad", "measured_rad"))
    assert len(t) == len(goal) == len(measured)  # a sample per tick (fewer on a loaded
    assert (t < 0).any() and (t >= 0).sum() > 10  # machine: its loop skips late ticks)
    start = before[joint - 1]
    assert goal[t < 0] == pytest.approx(start, abs=1e-9)  # the rest before the step
    assert goal[-1] == pytest.approx(start + step_rad, abs=1e-9)
    # the measured angle rises towards the goal and ends near it (the twin's P-only sag
    # under gravity: 0.3 to 0.6 deg at the poses here)
    sign = math.copysign(1.0, step_rad)
    early, late = measured[t < 0].mean(), measured[-10:].mean()
    assert sign * (late - early) > 0.8 * abs(step_rad), (early, late)
    assert abs(late - goal[-1]) < math.radians(1.0)
    assert sign * (measured[t > 0.02].min() - early) > -math.radians(0.3)  # no step back
    figures = body["figures"]
    assert 0.0 < figures["rise_time_s"] < 0.5
    assert figures["settling_s"] is not None and figures["overshoot_pct"] >= 0.0
    assert figures["moved_fraction"] == pytest.approx(1.0, abs=0.2)
    # the other joints held: the loop's commanded joints are the start's once more
    after = np.array(ok_json(client.get("/api/status"))["joints"]["commanded_rad"])
    others = [k for k in range(3) if k != joint - 1]
    assert after[others] == pytest.approx(before[others], abs=1e-6)
    assert after[joint - 1] == pytest.approx(start + step_rad, abs=1e-6)
    # a run like any other: listed, with its kind and its log
    run = ok_json(client.get(f"/api/runs/{body['run_id']}"))
    assert run["kind"] == "joint-step" and run["state"] == "done"
    assert run["params"]["servo_id"] == servo_id and "joint" in run["description"]
    return body


@pytest.mark.slow  # a step run on the emulated bus
def test_a_step_on_the_emulated_bus_rises_towards_its_goal(resting):
    step_and_check(resting, 2, math.radians(3.0))
    ok_json(resting.post("/api/goal", json={"position_m": list(HOME)}))


@pytest.mark.slow  # a step run on the emulated bus, stopped
def test_an_estop_during_a_step_ends_it_and_its_answer_says_so(resting):
    answers: list = []
    body = {"step_rad": math.radians(3.0), "duration_s": 5.0}
    asking = threading.Thread(
        target=lambda: answers.append(resting.post("/api/servos/2/step", json=body)),
        daemon=True,
    )
    asking.start()

    def running() -> bool:
        runs = ok_json(resting.get("/api/runs"))
        return any(r["kind"] == "joint-step" and r["state"] == "running" for r in runs)

    wait_for(running, "the step's run to start", seen=lambda: answers)
    ok_json(resting.post("/api/estop"))
    wait_for(lambda: answers, "the step's answer", 60.0)
    answer = ok_json(answers[0])
    assert answer["state"] == "aborted" and answer["reason"] == "e-stop", answer["reason"]
    assert len(answer["t_s"]) == len(answer["measured_rad"])  # what it recorded until then
    assert ok_json(resting.get(f"/api/runs/{answer['run_id']}"))["state"] == "aborted"
    ok_json(resting.post("/api/reset"))


@pytest.mark.slow  # the twin in its process, a step run on it
def test_a_step_on_the_twin_rises_towards_its_goal_and_the_gains_change_it(tmp_path):
    with make_client(tmp_path, backend="sim", safety=PATIENT) as twin:
        take_lease(twin)
        settle_at(twin, HOME)
        at_rest(twin)
        factory = step_and_check(twin, 1, -math.radians(4.0))
        assert factory["clock"] == "sim_time_s"  # the twin's own time
        settle_at(twin, HOME)
        at_rest(twin)
        # a stiffer servo: the twin's servo model uses the written registers
        ok_json(twin.post("/api/servos/1/gains", json={**FACTORY, "p": 2000}))
        bus = twin.app.state.backend.bus
        assert bus.read_gains()[0].p == 2000
        settle_at(twin, HOME)  # the stiffer joint sags less: it moves, then rests again
        stiff = step_and_check(twin, 1, -math.radians(4.0))
        assert stiff["figures"]["rise_time_s"] < factory["figures"]["rise_time_s"]
        ok_json(twin.post("/api/tuning/revert"))


@pytest.mark.slow  # the twin with a tool on a wrist, a step run on it
def test_a_step_with_a_tool_on_a_turned_wrist_moves_the_joint_alone(tmp_path):
    tool = {"offset_m": [0.03, 0.0, -0.04]}
    wrist = {"enabled": True}
    with make_client(tmp_path, backend="sim", tool=tool, wrist=wrist, safety=PATIENT) as twin:
        take_lease(twin)
        torque_on(twin)
        ok_json(twin.post("/api/goal", json={"position_m": [0.02, 0.0, -0.27], "phi_rad": 0.6}))

        def turned() -> bool:
            now = ok_json(twin.get("/api/status"))
            still = all(abs(v or 0.0) < 0.02 for v in now["joints"]["velocity_rad_s"])
            return still and now["mode"] == "idle" and abs(now["ee"]["phi_rad"] - 0.6) < 0.01

        wait_for(turned, "the tip at its goal, the wrist at 0.6 rad", 60.0, seen=lambda: "")
        before = ok_json(twin.get("/api/status"))
        body = step_and_check(twin, 1, math.radians(3.0))
        after = ok_json(twin.get("/api/status"))
        # the tips it commanded were at the wrist's angle: the wrist held, the tip moved
        # only by the joint's step (not by the tool turned back to 0)
        assert after["goal"]["phi_rad"] == pytest.approx(0.6)
        assert after["ee"]["phi_rad"] == pytest.approx(0.6, abs=0.01)
        moved = np.subtract(after["ee"]["commanded_m"], before["ee"]["commanded_m"])
        assert 0.001 < np.linalg.norm(moved) < 0.02, moved
        assert body["state"] == "done"
