"""An app with its 3D scene on a free port, the servo emulator in-process; one per module."""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend
from tests.support.lease import take_lease
from tests.support.wait import WAIT_S, ok_json, wait_for


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    settings = load_settings(hardware={"backend": "emulated"}, runs={"folder": str(folder)},
                             server={"viser_port": 0})  # fmt: skip
    opener = functools.partial(open_backend, emulator_in_process=True)
    with TestClient(create_app(settings, backend_opener=opener)) as client:
        take_lease(client)
        yield client


@pytest.fixture
def scene(app_client):
    """The running Scene, with e-stop and faults cleared and torque on."""
    app = app_client.app
    controller = app.state.controller
    controller.reset().result(timeout=WAIT_S)
    controller.set_torque(True).result(timeout=WAIT_S)
    scene = app.state.scene
    scene.panel.message = scene.goals.message = ""
    return scene


def measured(client: TestClient) -> np.ndarray:
    return np.array(ok_json(client.get("/api/status"))["ee"]["position_m"], dtype=float)


def wait_at(client: TestClient, point_m, what: str, within_m: float = 2e-3) -> None:
    """Wait until /api/status measures the platform within ``within_m`` of ``point_m``;
    a timeout says where it was, the mode and any warning or fault."""

    def seen() -> dict:
        status = ok_json(client.get("/api/status"))
        keys = ("mode", "torque", "warning", "faults")
        return {"measured_m": status["ee"]["position_m"], **{k: status[k] for k in keys}}

    wait_for(lambda: np.linalg.norm(measured(client) - point_m) < within_m,
             f"{what} ({within_m * 1e3:g} mm of {list(point_m)} m)", seen=seen)  # fmt: skip
