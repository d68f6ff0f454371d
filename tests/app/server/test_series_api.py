"""GET /api/runs/{run_id}/series: a run's recorded signals for replay, decimated to a cap,
on runs saved on disk before the start. The values are checked against the run's CSV."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.runs.logs import read_csv_rows
from app.runs.series import MAX_POINTS, SeriesError, series, stride_for
from tests.support.app_client import make_client
from tests.support.saved_runs import HEALTHY, save_run, synthetic_rows
from tests.support.wait import ok_json

RUN = "20260101-100000-aaaa"


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    rows = synthetic_rows(error_m=0.002)
    for index, row in enumerate(rows):  # joints as a run records them
        row["measured_q1_rad"] = 0.001 * index
    run = save_run(folder, RUN, rows, HEALTHY)
    return folder, run


@pytest.fixture(scope="module")
def client(saved) -> Iterator[TestClient]:
    with make_client(saved[0]) as test_client:
        yield test_client


def test_the_series_is_every_tick_of_the_csv_when_under_the_cap(client, saved):
    csv_rows = read_csv_rows(saved[1].folder / "log.csv")
    body = ok_json(client.get(f"/api/runs/{RUN}/series?max_points={len(csv_rows)}"))
    assert body["run_id"] == RUN and body["kind"] == "sinusoid" and body["stride"] == 1
    assert body["samples"] == len(csv_rows)
    assert body["t_s"] == pytest.approx([r["t_s"] for r in csv_rows])
    signals = body["signals"]
    for axis in "xyz":
        goal = [r[f"goal_{axis}_m"] for r in csv_rows]
        measured = [r[f"measured_{axis}_m"] for r in csv_rows]
        assert signals[f"goal_{axis}_m"] == pytest.approx(goal)
        assert signals[f"measured_{axis}_m"] == pytest.approx(measured)
        # the error as the report has it: goal - measured
        error = [g - m for g, m in zip(goal, measured, strict=True)]
        assert signals[f"error_{axis}_m"] == pytest.approx(error)
    assert signals["measured_q1_rad"] == pytest.approx([r["measured_q1_rad"] for r in csv_rows])
    # what the run never recorded is not there (no hold: no world frame; no wrist)
    assert "world_goal_x_m" not in signals and "phi_goal_rad" not in signals
    assert "measured_q2_rad" not in signals


def test_a_long_run_is_decimated_to_at_most_max_points_of_recorded_ticks(client, saved):
    csv_rows = read_csv_rows(saved[1].folder / "log.csv")
    body = ok_json(client.get(f"/api/runs/{RUN}/series?max_points=100"))
    stride = math.ceil(len(csv_rows) / 100)
    assert body["stride"] == stride and len(body["t_s"]) <= 100
    kept = csv_rows[::stride]  # recorded ticks, not averages
    assert body["t_s"] == pytest.approx([r["t_s"] for r in kept])
    assert body["signals"]["goal_x_m"] == pytest.approx([r["goal_x_m"] for r in kept])


@pytest.mark.parametrize(
    ("run_id", "status"),
    [("20991231-000000-zzzz", 404), ("..x", 404), ("not a run", 404), ("compare", 404)],
)
def test_an_unknown_run_is_refused_with_404_naming_it(client, run_id, status):
    response = client.get(f"/api/runs/{run_id}/series")
    assert response.status_code == status, response.text
    assert "run" in response.json()["detail"]


@pytest.mark.parametrize("max_points", [MAX_POINTS + 1, 9, 0, -5, "many"])
def test_a_size_over_the_cap_or_not_a_number_is_refused_with_422(client, max_points):
    response = client.get(f"/api/runs/{RUN}/series?max_points={max_points}")
    assert response.status_code == 422, response.text
    assert "max_points" in response.text


def test_stride_keeps_at_most_the_cap_and_refuses_a_cap_under_one():
    assert [stride_for(n, 100) for n in (0, 1, 100, 101, 200, 201)] == [1, 1, 1, 2, 2, 3]
    with pytest.raises(SeriesError, match="max_points"):
        stride_for(10, 0)
    assert series([], 10)["t_s"] == []
