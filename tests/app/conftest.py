"""A running server on the emulated bus (real dynamixel-sdk over a pty), shared per module."""

from __future__ import annotations

import functools
import tempfile
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


def make_client(runs_folder=None, **overrides) -> TestClient:
    """A client of an app on the emulated bus, the emulator in-process for fault injection."""
    folder = runs_folder or tempfile.mkdtemp(prefix="deltadash-runs-")
    settings = load_settings(
        hardware={"backend": "emulated"}, runs={"folder": str(folder)}, **overrides
    )
    opener = functools.partial(open_backend, emulator_in_process=True)
    return TestClient(create_app(settings, backend_opener=opener))


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with make_client() as test_client:
        take_lease(test_client)
        yield test_client


@pytest.fixture
def fresh(client: TestClient) -> TestClient:
    """The shared client with e-stop and faults cleared and torque off."""
    client.post("/api/reset")
    client.post("/api/torque", json={"enabled": False})
    return client


def ticks(client: TestClient) -> int:
    return ok_json(client.get("/api/status"))["loop"]["ticks"]


def settle_at(client: TestClient, point_m, within_m: float = 0.003) -> None:
    """Torque on, a goal at ``point_m`` [m], and wait for a defined pose: the approach done
    (commanded there), the platform measured within ``within_m`` of it and the joints still.

    Runs plan from the commanded point and refuse to start from a robot still moving (after
    torque on the arm may still be falling), so a test that starts one settles here first.
    """
    ok_json(client.post("/api/torque", json={"enabled": True}))
    ok_json(client.post("/api/goal", json={"position_m": list(point_m)}))

    def status() -> dict:
        return ok_json(client.get("/api/status"))

    def settled() -> bool:
        now = status()
        commanded = np.linalg.norm(np.subtract(now["ee"]["commanded_m"], point_m)) < 1e-4
        near = np.linalg.norm(np.subtract(now["ee"]["position_m"], point_m)) < within_m
        still = all(abs(v or 0.0) < 0.02 for v in now["joints"]["velocity_rad_s"])  # rad/s
        return commanded and near and still

    def seen() -> dict:
        now = status()
        return {"commanded_m": now["ee"]["commanded_m"], "measured_m": now["ee"]["position_m"],
                "velocity_rad_s": now["joints"]["velocity_rad_s"], "mode": now["mode"]}  # fmt: skip

    wait_for(settled, f"the robot settled at {list(point_m)} m (within {within_m * 1e3:g} mm, "
             "joints still)", seen=seen)  # fmt: skip


def robot_seen(client: TestClient) -> dict:
    """What a failed wait on the robot reports: where it is, its mode, faults and warning."""
    status = ok_json(client.get("/api/status"))
    keys = ("mode", "torque", "estopped", "faults", "warning")
    ee, joints = status["ee"], status["joints"]
    return {"measured_m": ee["position_m"], "commanded_m": ee["commanded_m"],
            "joints_rad": joints["position_rad"], **{k: status[k] for k in keys}}  # fmt: skip
