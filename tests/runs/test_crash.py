"""kill -9 of `deltadash serve` in the middle of a run, then a restart on the same runs
folder: the run is listed as interrupted with stats and files, and the MCAP file the kill
left opens in the mcap package's standard readers."""

from __future__ import annotations

import io
import json
import math
import os
import signal
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import NonSeekingReader, make_reader

from tests.support.server import Server, serve, wait_for

START_M = [0.0, 0.0, -0.24]


def _send(server: Server, method: str, path: str, body: dict | None, lease: str) -> Any:
    """(status, JSON body) of a command with the lease."""
    request = urllib.request.Request(
        server.url + path,
        data=json.dumps(body or {}).encode(),
        method=method,
        headers={"Content-Type": "application/json", "X-Lease": lease},
    )
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, json.load(response)
    except urllib.error.HTTPError as error:
        return error.code, json.load(error)


def _settled(server: Server) -> bool:
    status = server.get("/api/status")
    commanded = math.dist(status["ee"]["commanded_m"] or [9, 9, 9], START_M) < 1e-4
    near = math.dist(status["ee"]["position_m"], START_M) < 0.003
    still = all(abs(v or 0.0) < 0.02 for v in status["joints"]["velocity_rad_s"])
    return commanded and near and still


def _start_run(server: Server) -> str:
    """Take control, settle the twin at START_M and start a 20 s sinusoid; its run id."""
    lease = server.post("/api/lease", {"client": "crash test", "take_over": True})["lease_id"]
    answers: list = []

    def torque_on() -> bool:  # refused while the relaxed arm swings past its joint limits
        answers.append(_send(server, "POST", "/api/torque", {"enabled": True}, lease))
        return answers[-1][0] == 200

    wait_for(torque_on, "torque on to be accepted")  # seen: answers[-1]
    assert _send(server, "POST", "/api/goal", {"position_m": START_M}, lease)[0] == 200
    wait_for(lambda: _settled(server), f"the twin settled at {START_M}")
    status, body = _send(server, "POST", "/api/tests/sinusoid", {"duration_s": 20.0}, lease)
    assert status == 200, body
    return body["run_id"]


def _listed(server: Server, run_id: str) -> dict:
    return next(r for r in server.get("/api/runs") if r["run_id"] == run_id)


def _read(path_or_bytes: Path | bytes) -> tuple[int, int]:
    """Messages the seeking and non-seeking mcap readers read."""
    data = path_or_bytes if isinstance(path_or_bytes, bytes) else path_or_bytes.read_bytes()
    return (
        sum(1 for _ in make_reader(io.BytesIO(data)).iter_messages()),
        sum(1 for _ in NonSeekingReader(io.BytesIO(data)).iter_messages()),
    )


@pytest.mark.slow  # two server starts on the twin and seconds of a run
def test_a_run_killed_with_its_server_is_interrupted_after_a_restart(tmp_path: Path) -> None:
    with serve(tmp_path) as server:
        run_id = _start_run(server)
        record = tmp_path / "runs" / run_id / "run.json"

        def saved() -> dict:
            return json.loads(record.read_text())

        # the live count is in the run list, and the record on disk follows it
        wait_for(lambda: _listed(server, run_id)["samples"] > 400, "400 samples listed")
        wait_for(lambda: saved()["samples"] > 200, "run.json saying 200 samples")
        assert _listed(server, run_id)["state"] == saved()["state"] == "running"
        assert saved()["started_at_utc"].endswith("Z")
        on_disk = saved()["samples"]
        os.kill(server.process.pid, signal.SIGKILL)
        server.process.wait(timeout=30)
    killed = tmp_path / "runs" / run_id / "log.mcap"
    seeking, streaming = _read(killed)  # the file as the kill left it
    assert seeking == streaming >= on_disk  # every sample the record counted was logged

    with serve(tmp_path) as again:
        run = _listed(again, run_id)
        assert run["state"] == "interrupted" and "server stopped" in run["reason"], run
        assert run["samples"] == seeking
        for axis in "xyz":
            assert math.isfinite(run["stats"]["tracking"][axis]["rmse_m"])
        wait_for(lambda: _listed(again, run_id)["has_report"], "the report drawn after start-up")
        base = f"{again.url}/api/runs/{run_id}"
        for name in ("log.mcap", "log.csv", "report.png", "log.cut.mcap"):
            with urllib.request.urlopen(f"{base}/{name}", timeout=10) as response:
                assert response.status == 200, name
                if name == "log.mcap":
                    assert _read(response.read()) == (seeking, seeking)  # finished whole
                if name == "log.cut.mcap":
                    assert _read(response.read()) == (seeking, seeking)  # kept as it was
