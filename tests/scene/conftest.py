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
from tests.app.conftest import wait_for  # noqa: F401 - shared with the scene's tests


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    settings = load_settings(hardware={"backend": "emulated"}, runs={"folder": str(folder)},
                             server={"viser_port": 0})  # fmt: skip
    opener = functools.partial(open_backend, emulator_in_process=True)
    with TestClient(create_app(settings, backend_opener=opener)) as client:
        yield client


@pytest.fixture
def scene(app_client):
    """The running Scene, with e-stop and faults cleared and torque on."""
    app = app_client.app
    controller = app.state.controller
    controller.reset().result(timeout=5)
    controller.set_torque(True).result(timeout=5)
    scene = app.state.scene
    scene.panel.message = scene.goals.message = ""
    return scene


def measured(client: TestClient) -> np.ndarray:
    return np.array(client.get("/api/status").json()["ee"]["position_m"], dtype=float)
