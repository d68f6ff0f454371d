"""A running server on the emulated bus (real dynamixel-sdk over a pty), shared per module."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import cleared, make_client
from tests.support.lease import take_lease


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs")) as test_client:
        take_lease(test_client)
        yield test_client


@pytest.fixture
def fresh(client: TestClient) -> TestClient:
    """The shared client with e-stop and faults cleared and torque off."""
    return cleared(client)
