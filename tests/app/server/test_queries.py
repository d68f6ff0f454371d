"""Issue 28 point 2: a costly read (``/api/workspace/nearest`` for a far point, a refused
goal's 422) ran in the loop's process and slowed the loop. Workspace queries now run in
worker processes, at most ``slots`` at a time, and a repeated query is answered from the
kept answers (app/server/queries.py). The loop's rate under a flood is measured in
benchmarks/loop_read_flood.py, not here."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from app.control.commands import CommandContext
from app.server import sections
from app.server.queries import WAIT_S, QueriesBusy, WorkspaceQueries
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import wait_for

FAR = np.array([0.6, 0.5, -0.1])


@pytest.fixture(scope="module")
def gate():
    return CommandContext.from_settings(load_settings()).gate


@pytest.fixture
def queries() -> Iterator[WorkspaceQueries]:
    queries = WorkspaceQueries(load_settings(), slots=1, timeout_s=60)
    yield queries
    queries.close()


def _pid(_gate) -> int:
    return os.getpid()


@pytest.mark.slow
def test_a_query_is_answered_in_another_process_as_in_this_one(queries, gate):
    assert queries._workers.call(_pid, gate) != os.getpid()
    here = sections.nearest(gate, FAR, 0.0)
    there = queries.nearest(gate, FAR, 0.0)
    np.testing.assert_allclose(there, here, atol=1e-12)
    assert gate.inside(there)


@pytest.mark.slow
def test_a_repeated_query_is_answered_from_the_kept_answers(queries, gate):
    first = queries.nearest(gate, FAR, 0.0)
    asked = queries.asked
    np.testing.assert_array_equal(queries.nearest(gate, FAR, 0.0), first)
    assert queries.asked == asked  # no worker was asked again
    queries.nearest(gate, FAR + 1e-3, 0.0)
    assert queries.asked == asked + 1
    cut = queries.section(gate, "xy", -0.24, 0.0)
    again = queries.section(gate, "xy", -0.2401, 0.0)  # the same 1 mm level
    assert again is cut and cut.reachable.any()


@pytest.mark.slow
def test_a_query_waits_its_turn_and_one_beyond_the_queue_is_refused_at_once(gate, release):
    queries = WorkspaceQueries(load_settings(), slots=1, timeout_s=60, queue=1, wait_s=60)
    try:
        blocked = threading.Thread(target=queries.call, args=(_hold, release), daemon=True)
        blocked.start()
        wait_for(lambda: not queries._workers._free, "the only worker busy")
        waited: list = []
        waiting = threading.Thread(
            target=lambda: waited.append(queries.nearest(gate, FAR + 2e-3, 0.0)), daemon=True
        )
        waiting.start()  # takes the one place in the queue
        wait_for(lambda: not queries._places._value, "the queue full")
        with pytest.raises(QueriesBusy, match="busy"):
            queries.nearest(gate, FAR + 3e-3, 0.0)
        Path(release).touch()  # the worker is free: the waiting query's turn
        waiting.join(timeout=120)
        np.testing.assert_allclose(waited[0], sections.nearest(gate, FAR + 2e-3, 0.0))
        blocked.join()
    finally:
        queries.close()


@pytest.mark.slow
def test_a_query_that_waited_too_long_is_refused(gate, release):
    queries = WorkspaceQueries(load_settings(), slots=1, timeout_s=60, queue=1, wait_s=0.0)
    try:
        blocked = threading.Thread(target=queries.call, args=(_hold, release), daemon=True)
        blocked.start()
        wait_for(lambda: not queries._workers._free, "the only worker busy")
        with pytest.raises(QueriesBusy, match="busy"):
            queries.nearest(gate, FAR + 4e-3, 0.0)
        Path(release).touch()
        blocked.join()
    finally:
        queries.close()


def _hold(release: str) -> None:
    """In the worker: keep it busy until the test creates the file ``release`` (60 s at
    most, so a failed test leaves no worker behind)."""
    import time
    from pathlib import Path

    end = time.monotonic() + 60.0
    while not Path(release).exists() and time.monotonic() < end:
        time.sleep(0.01)


@pytest.fixture
def release(tmp_path) -> Iterator[str]:
    """The file whose creation lets :func:`_hold` end; created at the end in any case."""
    path = tmp_path / "release"
    yield str(path)
    path.touch()


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        take_lease(client)
        yield client


@pytest.mark.slow
def test_the_routes_answer_from_the_workers_and_say_when_busy(client, release):
    app = client.app
    queries = app.state.queries
    asked = queries.asked
    far = {"x_m": 0.55, "y_m": 0.45, "z_m": -0.12}
    answer = client.get("/api/workspace/nearest", params=far).json()
    assert queries.asked == asked + 1 and not answer["inside"]
    refused = client.post("/api/goal", json={"position_m": [0.55, 0.45, -0.12]})
    assert refused.status_code == 422
    np.testing.assert_allclose(refused.json()["nearest_m"], answer["nearest_m"], atol=1e-12)
    assert queries.asked == asked + 1  # the same point: the kept answer

    queries.wait_s = 0.0  # no waiting for the worker here: busy at once
    blockers = [
        threading.Thread(target=queries.call, args=(_hold, release), daemon=True)
        for _ in range(queries._workers.slots)
    ]
    for blocker in blockers:
        blocker.start()
    wait_for(lambda: not queries._workers._free, "every worker busy")
    busy = client.get("/api/workspace/nearest", params={**far, "x_m": 0.56})
    assert busy.status_code == 503 and "busy" in busy.json()["detail"]
    assert busy.headers["retry-after"] == "1"
    # a refused goal is still a 422, with the gate's own nearest workspace point
    still = client.post("/api/goal", json={"position_m": [0.56, 0.45, -0.12]})
    assert still.status_code == 422 and len(still.json()["nearest_m"]) == 3
    Path(release).touch()
    for blocker in blockers:
        blocker.join()
    queries.wait_s = WAIT_S
