"""A running server on the emulated bus (real dynamixel-sdk over a pty), shared per module."""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Callable, Iterator

import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend

WAIT_S = 30.0  # generous bound for convergence on a loaded 2-core machine; not a timing test


def wait_for(condition: Callable[[], bool], what: str, timeout_s: float = WAIT_S) -> None:
    """Poll ``condition`` until true; fail naming ``what`` if it never becomes true."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if condition():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


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
