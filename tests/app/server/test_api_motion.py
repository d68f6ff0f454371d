"""The loop on the emulated bus: reaching goals, jogging, moves, e-stop, faults."""

from __future__ import annotations

import numpy as np
import pytest

from hardware.dynamixel.control_table import Reg
from tests.support.app_client import robot_seen, settle_at, ticks, torque_on, unmoved
from tests.support.wait import ok_json, wait_for


def _status(client):
    return ok_json(client.get("/api/status"))


def _near(client, target, tol_m=1e-3) -> bool:
    measured = _status(client)["ee"]["position_m"]
    return None not in measured and np.linalg.norm(np.subtract(measured, target)) < tol_m


def test_status_has_the_fixed_fields(client):
    status = _status(client)
    for key in ("mode", "backend", "faults"):
        assert key in status
    assert len(status["joints"]["position_rad"]) == 3
    assert len(status["ee"]["position_m"]) == 3 and len(status["goal"]["position_m"]) == 3
    for key in ("target_hz", "measured_hz", "jitter_p99_ms", "overruns"):
        assert key in status["loop"]
    assert status["loop"]["target_hz"] == 200.0


@pytest.mark.slow
def test_goal_is_reached_and_the_loop_keeps_counting(fresh):
    assert fresh.post("/api/torque", json={"enabled": True}).status_code == 200
    goal = [0.03, -0.02, -0.23]
    assert fresh.post("/api/goal", json={"position_m": goal}).status_code == 200
    wait_for(
        lambda: _near(fresh, goal),
        "the platform to reach the goal",
        seen=lambda: robot_seen(fresh),
    )
    status = _status(fresh)
    assert status["mode"] == "jog" and status["faults"] == []
    assert status["goal"]["position_m"] == goal
    before = status["loop"]["ticks"]
    wait_for(lambda: _status(fresh)["loop"]["ticks"] > before + 20, "more ticks")


def _robot(client) -> dict:
    status = _status(client)
    return {
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "torque": status["torque"],
        "mode": status["mode"],
    }


@pytest.mark.slow
def test_a_refused_goal_moves_nothing(fresh):
    """A goal the gate refuses (422) leaves the goal and the command as they were: nothing
    is queued before the checks (issue 29, break 13: no test watched the robot after a
    422 with torque on)."""
    home = [0.0, 0.0, -0.22]
    settle_at(fresh, home)
    wait_for(
        # to 1e-12 m: the approach's last ticks move it by nanometres, which `unmoved` sees
        lambda: np.allclose(_robot(fresh)["commanded_m"], home, rtol=0, atol=1e-12),
        "the approach to the goal done",
        seen=lambda: _robot(fresh),
    )
    before = _robot(fresh)
    response = fresh.post("/api/goal", json={"position_m": [0.4, 0.0, -0.2]})
    assert response.status_code == 422, response.text
    now = ticks(fresh)
    wait_for(lambda: ticks(fresh) > now + 40, "40 more ticks")
    after = _robot(fresh)
    assert unmoved(before, after), (before, after)


@pytest.mark.slow
def test_jog_steps_add_up_and_clamp_at_the_boundary(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    start = np.array([0.0, 0.0, -0.22])
    fresh.post("/api/goal", json={"position_m": start.tolist()})
    for _ in range(3):
        assert fresh.post("/api/jog", json={"delta_m": [0.01, 0.0, 0.0]}).status_code == 200
    target = start + [0.03, 0.0, 0.0]
    wait_for(lambda: _near(fresh, target), "three jog steps", seen=lambda: robot_seen(fresh))
    response = fresh.post("/api/jog", json={"delta_m": [1.0, 0.0, 0.0]})
    assert response.status_code == 200  # clamped, not refused
    clamped = response.json()["result"]
    from kinematics import THESIS_DELTA

    assert THESIS_DELTA.reachable(clamped) and clamped[0] < 1.0


@pytest.mark.slow
def test_move_cartesian_and_joint_space(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    goal = [-0.02, 0.02, -0.25]
    response = fresh.post("/api/move", json={"position_m": goal, "duration_s": 0.5})
    assert response.status_code == 200, response.text
    assert response.json()["result"]["duration_s"] >= 0.5
    wait_for(lambda: _near(fresh, goal), "the Cartesian move", seen=lambda: robot_seen(fresh))
    wait_for(
        lambda: _status(fresh)["mode"] == "idle",
        "the move to finish",
        seen=lambda: robot_seen(fresh),
    )
    joints = [0.4, 0.5, 0.6]
    assert fresh.post("/api/move", json={"joints_rad": joints}).status_code == 200

    def at_joints() -> bool:
        measured = _status(fresh)["joints"]["position_rad"]
        return np.allclose(measured, joints, atol=0.01)

    wait_for(at_joints, "the joint-space move", seen=lambda: robot_seen(fresh))


def test_estop_stops_and_nothing_moves_until_reset(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    fresh.post("/api/goal", json={"position_m": [0.0, 0.04, -0.2]})
    assert fresh.post("/api/estop").status_code == 200
    status = _status(fresh)
    assert status["mode"] == "estop" and status["estopped"]
    for path, body in (
        ("/api/goal", {"position_m": [0, 0, -0.22]}),
        ("/api/jog", {"delta_m": [0.01, 0, 0]}),
        ("/api/move", {"position_m": [0, 0, -0.22]}),
        ("/api/torque", {"enabled": True}),
    ):
        response = fresh.post(path, json=body)
        assert response.status_code == 409, response.text
        assert "reset" in response.json()["detail"]
    held = _status(fresh)["joints"]["commanded_rad"]
    assert fresh.post("/api/reset").status_code == 200
    assert _status(fresh)["mode"] == "idle"
    assert _status(fresh)["joints"]["commanded_rad"] == held  # reset moves nothing


HARDWARE_ERROR_BITS = {  # Hardware Error Status (70) bit -> its name
    0: "input_voltage",
    2: "overheating",
    3: "motor_encoder",
    4: "electrical_shock",
    5: "overload",
}


@pytest.mark.slow
@pytest.mark.parametrize("bit", HARDWARE_ERROR_BITS, ids=HARDWARE_ERROR_BITS.values())
def test_hardware_error_faults_with_servo_and_reason_and_reset_reboots(client, fresh, bit):
    emulator = client.app.state.backend.emulator
    name = HARDWARE_ERROR_BITS[bit]
    torque_on(fresh)
    emulator.inject(1, boot_s=0.2)  # the servo is deaf while it boots
    try:
        emulator.raise_hardware_error(1, 1 << bit)
        wait_for(lambda: _status(fresh)["mode"] == "fault", "the hardware error fault")
        (fault,) = _status(fresh)["faults"]  # that error alone, named from its register
        assert fault["servo_id"] == 1 and fault["reason"] == f"servo 1: hardware error {name}"
        assert fresh.post("/api/goal", json={"position_m": [0, 0, -0.22]}).status_code == 409
        result = ok_json(fresh.post("/api/reset"))["result"]
        assert result["rebooted"] == [1]
        wait_for(lambda: _status(fresh)["faults"] == [], "the fault to clear")
        assert _status(fresh)["mode"] == "idle" and not _status(fresh)["torque"]
        after = ticks(fresh)
        wait_for(lambda: ticks(fresh) > after + 20, "more ticks after the reset")
        assert _status(fresh)["faults"] == []  # no fault made of a stale reply follows
        torque_on(fresh)
        assert emulator.servo(1).table.get(Reg.TORQUE_ENABLE) == 1
    finally:
        emulator.clear_faults()


def test_a_servo_shut_down_by_an_overload_shows_torque_off(client, fresh):
    emulator = client.app.state.backend.emulator
    torque_on(fresh)
    status = _status(fresh)
    assert status["torque"] and status["joints"]["torque_enabled"] == [True, True, True]
    try:
        emulator.raise_hardware_error(1, 1 << 5)  # overload: the servo's Shutdown drops torque
        wait_for(lambda: _status(fresh)["mode"] == "fault", "the overload fault")
        status = _status(fresh)
        assert emulator.servo(1).table.get(Reg.TORQUE_ENABLE) == 0
        assert status["torque"] is False  # the arm is not held, whatever was asked
        assert status["joints"]["torque_enabled"] == [False, True, True]
        assert status["joints"]["hardware_errors"] == [["overload"], [], []]
        (fault,) = status["faults"]  # the shutdown is visible, and why
        assert fault["servo_id"] == 1 and fault["reason"] == "servo 1: hardware error overload"
    finally:
        emulator.clear_faults()
    ok_json(fresh.post("/api/reset"))
    wait_for(lambda: _status(fresh)["faults"] == [], "the fault to clear")


@pytest.mark.slow
def test_missed_reads_fault_after_the_limit(client, fresh, monkeypatch):
    # each missed read waits out the emulated bus's reply wait on its every try (wall
    # time): two reads of one try each, not the config's ten of three, are this test's
    misses = client.app.state.node.controller.state.misses
    monkeypatch.setattr(misses, "limit", 2)
    monkeypatch.setattr(client.app.state.backend.bus.link, "max_tries", 1)
    emulator = client.app.state.backend.emulator
    emulator.inject(3, unplugged=True)
    try:
        wait_for(lambda: _status(fresh)["mode"] == "fault", "the bus fault")
        status = _status(fresh)
        fault = status["faults"][0]
        assert fault["source"] == "bus" and "3" in fault["reason"]
        assert status["bus"]["missed_reads"] >= 2
    finally:
        emulator.clear_faults()
    fresh.post("/api/reset")
    wait_for(lambda: _status(fresh)["faults"] == [], "the bus to recover")
