"""`deltadash serve` on the simulator, with its 3D scene, shared by a module's page tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.support.browser import PATIENT_SIM_ENV
from tests.support.server import Server, serve


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    # the page links and embeds the scene, so this server starts it
    with serve(tmp_path_factory.mktemp("dashboard"), scene=True, **PATIENT_SIM_ENV) as served:
        yield served
