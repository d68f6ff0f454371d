"""A paused program's log is bounded (app/runs/recorder.py): while it stands (M0, Pause)
one row a second is kept, marked with why it stands; a pause longer than
``runs.max_pause_s`` aborts the run, saying so. On simulated time (the loop in lockstep,
tests/support/sim_time.py): a pause of seconds costs no wall-clock wait."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.config import ConfigError, load_settings
from app.runs.logs import read_csv_rows
from app.runs.recorder import PAUSED_ROW_EVERY_S
from tests.support.app_client import cleared, make_client
from tests.support.lease import take_lease
from tests.support.sim_time import elapse
from tests.support.wait import ok_json, wait_for

MAX_PAUSE_S = 3.0
# from where the robot rests: 2 mm out at 6 mm/s, an M0 on line 3, 2 mm back
PROGRAM = "G21 G91 F360\nG1 X2\nM0\nG1 X-2\nM2"


@pytest.fixture(scope="module")
def shared(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, sim_time=True, runs={"max_pause_s": MAX_PAUSE_S}) as client:
        take_lease(client)
        yield client


@pytest.fixture
def fresh(shared: TestClient) -> Iterator[TestClient]:
    cleared(shared)
    ok_json(shared.post("/api/torque", json={"enabled": True}))
    yield shared
    for run in ok_json(shared.get("/api/runs")):
        if run["state"] == "running":
            shared.post(f"/api/runs/{run['run_id']}/abort")


def _run(client: TestClient, run_id: str) -> dict:
    return ok_json(client.get(f"/api/runs/{run_id}"))


def _at_m0(client: TestClient) -> str:
    response = client.post("/api/programs/run", json={"gcode": PROGRAM})
    assert response.status_code == 200, response.text
    run_id = response.json()["run_id"]
    wait_for(
        lambda: (
            (_run(client, run_id)["progress"] or {}).get("paused") == "M0 at line 3: press Resume"
        ),
        "the M0's stop",
    )
    return run_id


def _rows(client: TestClient, run_id: str) -> list[dict]:
    run = wait_for(lambda: (r := _run(client, run_id))["state"] != "running" and r, "its end")
    folder = client.app.state.settings.runs.folder_path / run_id
    wait_for(lambda: (folder / "log.csv").exists() and run["samples"], "the log")
    return read_csv_rows(folder / "log.csv")


def _healthy(row: dict) -> bool:
    return not (row["overrun"] or row["stale"] or row["faults"])


@pytest.mark.slow  # seconds of a run (simulated)
def test_a_pause_over_max_pause_s_aborts_the_run_and_its_log_keeps_a_row_a_second(fresh):
    run_id = _at_m0(fresh)
    wait_for(lambda: _run(fresh, run_id)["state"] != "running", "the pause's limit")
    run = _run(fresh, run_id)
    assert run["state"] == "aborted"
    assert run["reason"].startswith("paused 3 s (M0 at line 3: press Resume), over the limit")
    assert "runs.max_pause_s" in run["reason"]
    rows = _rows(fresh, run_id)
    assert len(rows) == run["samples"]
    standing = [r for r in rows if r["paused"]]
    moving = [r for r in rows if not r["paused"]]
    period = 1.0 / fresh.app.state.settings.loop.rate_hz
    # moving: every tick is a row (one period apart); standing: one a second (the healthy
    # ones), from the M0's tick to the abort just past 3 s: t0, t0 + 1, + 2, + 3
    steps = [b["t_s"] - a["t_s"] for a, b in zip(moving, moving[1:], strict=False)]
    assert steps and max(steps) == pytest.approx(period, abs=1e-6)
    kept = [r["t_s"] for r in standing if _healthy(r)]
    assert len(kept) == 4, kept
    gaps = [b - a for a, b in zip(kept, kept[1:], strict=False)]
    assert gaps == [pytest.approx(PAUSED_ROW_EVERY_S, abs=period + 1e-6)] * 3
    assert all(r["paused"] == "M0 at line 3: press Resume" for r in standing)
    # the bound: a 3 s stand wrote 4 rows, not 3 s x 200 Hz = 600
    assert len(standing) < 10


@pytest.mark.slow
def test_a_pause_under_the_limit_resumes_and_the_run_finishes_every_tick_logged_again(fresh):
    run_id = _at_m0(fresh)
    elapse(MAX_PAUSE_S / 2)  # under the limit: it still stands
    assert _run(fresh, run_id)["state"] == "running"
    ok_json(fresh.post("/api/programs/resume"))
    rows = _rows(fresh, run_id)
    run = _run(fresh, run_id)
    assert run["state"] == "done", run["reason"]
    last_standing = max(i for i, r in enumerate(rows) if r["paused"])
    after = rows[last_standing + 1 :]
    period = 1.0 / fresh.app.state.settings.loop.rate_hz
    steps = [b["t_s"] - a["t_s"] for a, b in zip(after, after[1:], strict=False)]
    assert len(after) > 10 and max(steps) == pytest.approx(period, abs=1e-6)
    assert sum(1 for r in rows if r["paused"] and _healthy(r)) <= MAX_PAUSE_S / 2 + 2


@pytest.mark.parametrize("value", [0, -1, 100_000])
def test_max_pause_s_out_of_range_is_refused_naming_it(value):
    with pytest.raises(ConfigError, match="max_pause_s"):
        load_settings(runs={"max_pause_s": value})
