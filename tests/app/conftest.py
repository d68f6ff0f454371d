"""A running server on the emulated bus (real dynamixel-sdk over a pty), shared per module."""

from __future__ import annotations

import functools
import tempfile
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend
from tests.support.wait import wait_for  # noqa: F401 - re-exported for other folders' tests


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
        yield test_client


@pytest.fixture
def fresh(client: TestClient) -> TestClient:
    """The shared client with e-stop and faults cleared and torque off."""
    client.post("/api/reset")
    client.post("/api/torque", json={"enabled": False})
    return client


def ticks(client: TestClient) -> int:
    return client.get("/api/status").json()["loop"]["ticks"]
