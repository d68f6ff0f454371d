"""An app with its 3D scene on a free port, the servo emulator in-process; one per module."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import WAIT_S


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs"), server={"scene": True}) as client:
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
