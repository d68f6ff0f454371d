"""The wrist's servo (the fourth on the bus) in the status and the servo panel's API, on the
emulated bus (real packets; the emulator's control tables read back): every servo listed
with its role while ``joints.servo_ids`` stays the legs', the wrist's readings, its gains
read and written (the legs' untouched, and kept by a leg's write), a step of phi recorded,
and a step past the wrist's limits refused naming the field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hardware.dynamixel.control_table import Reg
from tests.support.app_client import make_client, settle_at, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

WRIST = {"enabled": True, "min_angle_rad": -1.5, "max_angle_rad": 1.2}  # servo 4
FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}
TUNED = {"p": 1010, "i": 37, "d": 120, "ff1": 4, "ff2": 9}
REGISTERS = {
    "p": Reg.POSITION_P_GAIN,
    "i": Reg.POSITION_I_GAIN,
    "d": Reg.POSITION_D_GAIN,
    "ff1": Reg.FEEDFORWARD_1ST_GAIN,
    "ff2": Reg.FEEDFORWARD_2ND_GAIN,
}
HOME = (0.0, 0.0, -0.24)
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    folder = tmp_path_factory.mktemp("wrist-servo")
    with make_client(folder, wrist=WRIST, safety=PATIENT) as c:
        take_lease(c)
        torque_on(c)
        settle_at(c, HOME)
        yield c


def status(client) -> dict:
    return ok_json(client.get("/api/status"))


def registers(client, servo_id: int) -> dict[str, int]:
    table = client.app.state.backend.emulator.servo(servo_id).table
    return {name: table.get(reg) for name, reg in REGISTERS.items()}


def standing(client) -> bool:
    """The arm rests at its goal (a step starts only from rest)."""
    now = status(client)
    gap = np.subtract(now["goal"]["position_m"], now["ee"]["commanded_m"])
    still = all(abs(v or 0.0) < 0.02 for v in now["joints"]["velocity_rad_s"])
    return bool(np.abs(gap).max() < 1e-9) and still


def test_the_status_lists_every_servo_with_its_role(client) -> None:
    now = status(client)
    assert now["servos"] == [
        {"id": 1, "role": "leg", "joint": 1},
        {"id": 2, "role": "leg", "joint": 2},
        {"id": 3, "role": "leg", "joint": 3},
        {"id": 4, "role": "wrist", "joint": None},
    ]
    assert now["joints"]["servo_ids"] == [1, 2, 3]  # the legs', as before: tuning relies on it
    assert set(now["gains"]) == {"1", "2", "3"}
    wrist = now["wrist_servo"]
    assert wrist["servo_id"] == 4 and wrist["hardware_errors"] == []
    assert wrist["torque_enabled"] is True  # torque on holds the wrist with the legs
    # the emulator's servo 4 as read: its temperature and voltage registers' values
    emulated = client.app.state.backend.emulator.servo(4).table
    assert wrist["temperature_c"] == emulated.get(Reg.PRESENT_TEMPERATURE)
    assert wrist["voltage_v"] == pytest.approx(emulated.get(Reg.PRESENT_INPUT_VOLTAGE) / 10)
    assert wrist["position_rad"] == pytest.approx(now["ee"]["phi_rad"])


def test_without_a_wrist_the_status_has_the_legs_only(tmp_path) -> None:
    with make_client(tmp_path, backend="sim") as plain:
        now = status(plain)
        assert [s["role"] for s in now["servos"]] == ["leg", "leg", "leg"]
        assert now["wrist_servo"] is None
        missing = plain.get("/api/servos/4/gains")
        assert missing.status_code == 404 and "servo_id" in missing.json()["detail"]


def test_the_wrist_s_gains_are_read_and_written_the_legs_untouched(client) -> None:
    wait_for(lambda: standing(client), "the arm at rest")
    read = ok_json(client.get("/api/servos/4/gains"))
    assert (read["joint"], read["role"]) == (4, "wrist")
    assert read["limits_rad"] == {"min": -1.5, "max": 1.2}
    assert read["servo"] == FACTORY == registers(client, 4)

    written = ok_json(client.post("/api/servos/4/gains", json=TUNED))
    assert written["servo"] == TUNED == registers(client, 4)  # on the servo's registers
    assert written["config_written"] is None
    for leg in (1, 2, 3):
        assert registers(client, leg) == FACTORY
        assert status(client)["gains"][str(leg)] == FACTORY

    # a leg's write sends every servo's gains: the wrist keeps its own
    ok_json(client.post("/api/servos/2/gains", json={**FACTORY, "p": 900}))
    assert registers(client, 2)["p"] == 900 and registers(client, 4) == TUNED
    ok_json(client.post("/api/tuning/revert"))
    assert registers(client, 2) == FACTORY and registers(client, 4) == TUNED
    ok_json(client.post("/api/servos/4/gains", json=FACTORY))
    assert registers(client, 4) == FACTORY


def test_a_step_of_the_wrist_turns_phi_and_holds_the_platform(client) -> None:
    wait_for(lambda: standing(client), "the arm at rest", seen=lambda: status(client)["mode"])
    before = status(client)
    answer = ok_json(client.post("/api/servos/4/step", json={"step_rad": math.radians(3.0)}))
    assert answer["state"] == "done", answer["reason"]
    assert (answer["servo_id"], answer["joint"]) == (4, 4)
    goal, measured = np.degrees(answer["goal_rad"]), np.degrees(answer["measured_rad"])
    t = np.array(answer["t_s"])
    start = math.degrees(answer["start_rad"][0])
    assert start == pytest.approx(math.degrees(before["ee"]["phi_rad"]), abs=0.2)
    assert goal[t < 0] == pytest.approx(start, abs=1e-9)
    assert goal[-1] - start == pytest.approx(3.0, abs=1e-6)
    assert measured[-10:].mean() - measured[t < 0].mean() > 2.4  # the wrist followed
    after = status(client)
    moved = np.subtract(after["ee"]["platform_m"], before["ee"]["platform_m"])
    assert np.abs(moved).max() < 5e-4  # the legs held the platform
    run = ok_json(client.get(f"/api/runs/{answer['run_id']}"))
    assert run["kind"] == "joint-step" and run["params"]["joint"] == 4


def test_a_step_past_the_wrist_s_limits_is_refused_naming_the_field(client) -> None:
    ok_json(client.post("/api/goal", json={"position_m": list(HOME), "phi_rad": 1.15}))
    wait_for(lambda: abs(status(client)["ee"]["phi_rad"] - 1.15) < 0.01, "the wrist at 1.15 rad")
    wait_for(lambda: standing(client), "the arm at rest")
    runs_before = len(ok_json(client.get("/api/runs")))
    refused = client.post("/api/servos/4/step", json={"step_rad": math.radians(5.0)})
    assert refused.status_code == 422
    detail = refused.json()["detail"]
    assert detail.startswith("step_rad") and "wrist's limits" in detail
    assert len(ok_json(client.get("/api/runs"))) == runs_before  # nothing ran
    ok_json(client.post("/api/goal", json={"position_m": list(HOME), "phi_rad": 0.0}))
    wait_for(lambda: abs(status(client)["ee"]["phi_rad"]) < 0.01, "the wrist back at 0")
