"""An app with the Foxglove live server on a free port, the servo emulator in-process,
and a tool offset (so the tip is its own frame); one per module."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client
from tests.support.lease import take_lease

TOOL_OFFSET_M = (0.0, 0.0, -0.03)


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(
        tmp_path_factory.mktemp("runs"),
        tool={"offset_m": list(TOOL_OFFSET_M)},
        foxglove={"enabled": True, "port": 0},
    ) as client:
        take_lease(client)
        yield client


@pytest.fixture
def url(app_client) -> str:
    """The live server's address."""
    return f"ws://127.0.0.1:{app_client.app.state.foxglove.port}"
