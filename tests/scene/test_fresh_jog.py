"""The scene's jog on the MuJoCo twin after torque off and on: a step moves by the step.

Issue 14 point 2: the panel used to jog from the goal it last knew, so after the arm had
fallen with torque off, one +X 5 mm step flew ~15 cm back up to the old goal. Now the step
is resolved in the control thread from what the loop commands then (the measured point,
after torque on), and status says the motion started from the measured position.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import WAIT_S, ok_json, wait_for


@pytest.fixture(scope="module")
def sim_client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(
        tmp_path_factory.mktemp("runs"), backend="sim", server={"scene": True}
    ) as client:
        take_lease(client)  # for the HTTP goal; the panel is driven from Python, unguarded
        yield client


def status(client: TestClient) -> dict:
    return ok_json(client.get("/api/status"))


def still(client: TestClient, within_m: float = 2e-4) -> list[float] | None:
    """The measured point once two reads 0.1 s of loop time apart agree; None while moving."""
    first = status(client)
    wait_for(lambda: status(client)["time_s"] > first["time_s"] + 0.1, "0.1 s of loop time")
    a = np.array(first["ee"]["position_m"], dtype=float)
    b = np.array(status(client)["ee"]["position_m"], dtype=float)
    return b.tolist() if np.linalg.norm(b - a) < within_m else None


@pytest.mark.slow  # end to end on the twin
def test_scene_jog_after_torque_off_and_on_moves_by_the_step_only(sim_client) -> None:
    client, app = sim_client, sim_client.app
    controller, panel = app.state.controller, app.state.scene.panel
    controller.reset().result(timeout=WAIT_S)
    torque_on(client)  # the twin's arm may still be swinging from its start
    ok_json(client.post("/api/goal", json={"position_m": [0.005, 0.01, -0.241]}))
    wait_for(
        lambda: (
            np.linalg.norm(np.subtract(status(client)["ee"]["position_m"], [0.005, 0.01, -0.241]))
            < 3e-3
        ),
        "the arm at the old goal",
    )

    controller.set_torque(False).result(timeout=WAIT_S)
    wait_for(lambda: status(client)["ee"]["position_m"][2] < -0.3, "the relaxed arm to fall")
    torque_on(client)  # accepted once the swinging arm is back inside its joint limits
    before = np.array(wait_for(lambda: still(client), "the arm to come to rest with torque on"))
    assert status(client)["goal"]["position_m"] == pytest.approx(
        status(client)["ee"]["commanded_m"]
    ), "goal must be the held point, not the old goal"

    panel.jog((1, 0, 0), step_mm=5.0)
    wait_for(lambda: status(client)["mode"] == "jog", "the jog to start")
    after = np.array(wait_for(lambda: still(client), "the jog to end"))
    moved = np.linalg.norm(after - before)
    print(f"scene +X 5 mm after torque off/on moved {moved * 1e3:.1f} mm")
    assert moved < 0.010, f"moved {moved * 1e3:.1f} mm for a 5 mm step"
    assert after[0] - before[0] > 0.002  # and it did step +X
    assert "measured position" in (status(client)["notice"] or "")
    assert panel.message == ""
