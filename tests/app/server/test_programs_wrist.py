"""A G-code program with A words on the emulated robot with a wrist (the emulator runs
the fourth servo): checked through the API from the wrist's angle where it is, run end to
end, the wrist ending where the A words put it; /api/move turns it with the tip."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from hardware.dynamixel.control_table import RAD_PER_TICK
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

WRIST = {"enabled": True, "min_angle_rad": -1.0, "max_angle_rad": 2.0, "max_speed_rad_s": 2.0}
TOOL = {"offset_m": [0.02, 0.0, -0.03]}
# incremental from wherever the robot is: out 5 mm turning +40 deg, back turning -20 deg
PROGRAM = "G21 G91\nG1 F600 X5 A40\nG1 X-5 A-20\nM2\n"
TOLERANCE_RAD = 4 * RAD_PER_TICK


def _phi(client) -> float:
    return ok_json(client.get("/api/status"))["ee"]["phi_rad"]


@pytest.mark.slow  # the twin in its process and a run of seconds
def test_a_program_with_a_words_turns_the_wrist_on_the_twin(tmp_path: Path) -> None:
    with make_client(tmp_path, wrist=WRIST, tool=TOOL) as client:
        take_lease(client)
        ok_json(client.post("/api/torque", json={"enabled": True}))
        control = client.app.state.controller

        # holding the wrist where it is: commanded where it was read (the program starts
        # from the commanded angle; CI read it once before the hold had taken it up)
        def holding() -> bool:
            snap = control.snapshot()
            measured, commanded = snap.phi_measured_rad, snap.phi_commanded_rad
            return math.isfinite(measured) and abs(commanded - measured) <= TOLERANCE_RAD

        wait_for(holding, "the wrist read and held where it is")
        start = control.snapshot().phi_commanded_rad
        report = ok_json(client.post("/api/programs/check", json={"gcode": PROGRAM}))
        assert report["ok"], report["violations"]
        response = client.post("/api/programs/run", json={"gcode": PROGRAM})
        assert response.status_code == 200, response.text
        run_id = response.json()["run_id"]
        wait_for(
            lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running",
            "the program's run to end",
            seen=lambda: ok_json(client.get(f"/api/runs/{run_id}")),
        )
        run = ok_json(client.get(f"/api/runs/{run_id}"))
        assert run["state"] == "done", run["reason"]
        end = start + math.radians(20)
        assert control.snapshot().phi_commanded_rad == pytest.approx(end, abs=1e-9)
        wait_for(
            lambda: abs(_phi(client) - end) <= TOLERANCE_RAD,
            "the wrist at the program's last A on the twin",
            seen=lambda: _phi(client),
        )
        # and a typed move brings the tip and phi together
        tip = ok_json(client.get("/api/status"))["ee"]["position_m"]
        moved = client.post("/api/move", json={"position_m": tip, "phi_rad": -0.4})
        assert moved.status_code == 200, moved.text
        wait_for(
            lambda: abs(_phi(client) + 0.4) <= TOLERANCE_RAD,
            "the wrist at -0.4 rad after the move",
            seen=lambda: _phi(client),
        )
