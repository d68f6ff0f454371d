"""Hold-in-world on the twin with a tool and a wrist (issue 19): under drone yaw the tip and
the tool's world heading are held; latency compensation holds the tip better than the
thesis's plain method. Figures: benchmarks/hold_heading.py (docs/performance.md)."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TOOL = {"offset_m": [0.0, 0.0, -0.05]}
WRIST = {"enabled": True, "min_angle_rad": -1.5, "max_angle_rad": 1.5}
# a loaded machine stalls the simulator for tenths of a second: these tests check the hold,
# not the stale-feedback and following-error guards (tested elsewhere)
SAFETY = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
YAW_DEG = 10.0  # RMS: a lively yaw, so the heading and the tip's lever show


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    runs = tmp_path_factory.mktemp("runs")
    with make_client(runs, "sim", tool=TOOL, wrist=WRIST, safety=SAFETY) as test_client:
        take_lease(test_client)
        yield test_client


def _hold(client, compensate: bool) -> dict:
    client.post("/api/reset")
    torque_on(client)
    ok_json(client.post("/api/goal", json={"position_m": [0.0, 0.0, -0.29]}))
    body = {"duration_s": 3.0, "yaw_deg": YAW_DEG, "seed": 2, "latency_compensation": compensate}
    run_id = ok_json(client.post("/api/tests/hold", json=body))["run_id"]
    wait_for(lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running", "the run")
    run = ok_json(client.get(f"/api/runs/{run_id}"))
    assert run["state"] == "done", run
    rows = csv.DictReader(io.StringIO(client.get(f"/api/runs/{run_id}/log.csv").text))
    world = run["stats"]["world"] | {"health": run["stats"]["health"]}
    return world, [r for r in rows if r["phase"] == "hold"]


STARVED_GAP_MS = 250.0  # a pause this long, or
STARVED_STALE_MS = 250.0  # the simulator's time standing this long, spoils a 3 s hold


def _starved(world: dict) -> list[str]:
    """What of a run's loop health makes its tip figures say nothing of the method: the
    loop paused, or the simulator stood still, for a quarter of a second (two suites and
    CPU hogs on two cores did that). The health's own limits (20 ms, 1 %) are tighter: a
    quiet 2-core machine passes them narrowly or not, and the comparison still holds
    there (docs/performance.md, "Hold-in-world with a tool and a wrist")."""
    health = world["health"]
    out = []
    if health["longest_gap_ms"] > STARVED_GAP_MS:
        out.append(f"the loop paused {health['longest_gap_ms']:.0f} ms")
    if health["longest_stale_ms"] > STARVED_STALE_MS:
        out.append(f"the simulator stood {health['longest_stale_ms']:.0f} ms")
    return out


def _heading_errors(rows: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(with the wrist, had it stayed at its first angle) heading errors [rad] per row: the
    tool's heading less the wrist's reading is the base's own heading (its yaw, level)."""
    goal, seen, phi = (
        np.array([float(r[k]) for r in rows])
        for k in ("world_heading_goal_rad", "world_heading_measured_rad", "phi_measured_rad")
    )
    wrapped = lambda a: (a + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    return wrapped(goal - seen), wrapped(goal - (seen - phi + phi[0]))


@pytest.mark.slow  # two end-to-end runs of seconds on the twin
def test_compensated_hold_keeps_the_tip_better_and_the_heading(client):
    (plain, plain_rows), (compensated, compensated_rows) = _hold(client, False), _hold(client, True)

    def tip_rmse(world: dict) -> float:
        return math.sqrt(sum(world[a]["rmse_m"] ** 2 for a in "xyz"))

    for world, rows in ((plain, plain_rows), (compensated, compensated_rows)):
        heading = world["heading"]
        assert heading["samples"] > 0 and heading["limited_s"] == 0.0
        # the wrist turned against the yaw: less heading error than a wrist left alone
        turned, unturned = _heading_errors(rows)
        rms = [float(np.sqrt(np.mean(e**2))) for e in (turned, unturned)]
        assert rms[0] < rms[1], rms
    # two real-time runs compared: only meaningful when neither starved (CI once saw the
    # compensated hold at 48 mm against 20 mm with both suites of two clones side by side)
    if starved := _starved(plain) + _starved(compensated):
        pytest.skip(f"the tip comparison: the simulator starved ({'; '.join(starved)})")
    assert tip_rmse(compensated) < tip_rmse(plain), (tip_rmse(compensated), tip_rmse(plain))


@pytest.mark.slow
def test_a_heading_is_refused_without_a_wrist(tmp_path):
    with make_client(tmp_path) as plain:
        take_lease(plain)
        plain.post("/api/torque", json={"enabled": True})
        body = {"position_m": [0.0, 0.0, 1.2], "heading_rad": 0.5, "source": "simulated"}
        response = plain.post("/api/hold", json=body)
        assert response.status_code == 422, response.text
        assert "heading_rad" in response.text and "wrist" in response.text
        assert ok_json(plain.get("/api/status"))["mode"] != "hold-world"
