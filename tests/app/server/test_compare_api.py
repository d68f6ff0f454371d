"""GET /api/runs/compare and /api/runs/compare.png on runs saved on disk before the start."""

from __future__ import annotations

import io
from collections.abc import Iterator

import matplotlib.image
import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client
from tests.support.saved_runs import HEALTHY, UNHEALTHY, save_run, synthetic_rows
from tests.support.wait import ok_json

QUIET, LOADED, OLD = "20260101-100000-aaaa", "20260101-110000-bbbb", "20260101-090000-cccc"


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    save_run(folder, QUIET, synthetic_rows(error_m=0.001), HEALTHY)
    save_run(folder, LOADED, synthetic_rows(error_m=0.004), UNHEALTHY)
    save_run(folder, OLD, synthetic_rows(error_m=0.002))  # from before health was kept
    with make_client(folder) as test_client:
        yield test_client


def test_compare_gives_each_runs_figures_side_by_side_in_the_order_asked(client):
    body = ok_json(client.get(f"/api/runs/compare?ids={LOADED},{QUIET},{OLD}"))
    assert body["ids"] == [LOADED, QUIET, OLD]
    runs = {run["run_id"]: run for run in body["runs"]}
    rows = {row["label"]: row for row in body["rows"]}
    for index, run_id in enumerate(body["ids"]):
        tracking = runs[run_id]["stats"]["tracking"]
        for axis in "xyz":
            rmse = rows[f"RMSE {axis}"]
            assert rmse["unit"] == "mm"
            assert rmse["values"][index] == pytest.approx(tracking[axis]["rmse_m"] * 1e3)
        assert rows["test"]["values"][index] == runs[run_id]["description"]
    assert rows["RMSE x"]["values"][0] > rows["RMSE x"]["values"][1]  # 4 mm against 1 mm
    verdicts = rows["verdict"]["values"]
    assert verdicts[0].startswith("NOT HEALTHY") and "318 ms" in verdicts[0]
    assert verdicts[1:] == ["healthy", "not checked"]
    assert rows["loop rate"]["values"] == [141.2, 50.0, None]
    assert "amplitude 50 / 50 / 80 mm" in rows["test"]["values"][0]
    assert body["plot"] == f"/api/runs/compare.png?ids={LOADED}%2C{QUIET}%2C{OLD}"


@pytest.mark.slow
def test_compare_plot_is_a_png_of_the_overlaid_errors(client):
    body = ok_json(client.get(f"/api/runs/compare?ids={QUIET},{LOADED}"))
    response = client.get(body["plot"])
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    image = matplotlib.image.imread(io.BytesIO(response.content), format="png")
    assert image.shape[0] > 200 and image.shape[1] > 600


@pytest.mark.parametrize(
    ("ids", "status", "words"),
    [
        (f"{QUIET},nope,{LOADED},gone", 404, ["'nope'", "'gone'"]),
        (QUIET, 422, ["ids", "2 or more"]),
        (f"{QUIET},{QUIET}", 422, ["ids", "got 1"]),
        (",".join(f"run{i}" for i in range(9)), 422, ["at most 8", "got 9"]),
    ],
)
def test_compare_refuses_unknown_ids_and_fewer_than_two(client, ids, status, words):
    for path in ("/api/runs/compare", "/api/runs/compare.png"):
        response = client.get(path, params={"ids": ids})
        assert response.status_code == status, response.text
        detail = response.json()["detail"]
        assert all(word in detail for word in words), detail


def test_compare_without_ids_is_422(client):
    assert client.get("/api/runs/compare").status_code == 422


def test_the_run_list_says_each_test_in_words_and_no_progress_once_ended(client):
    runs = {run["run_id"]: run for run in ok_json(client.get("/api/runs"))}
    assert {QUIET, LOADED, OLD} <= set(runs)
    for run in runs.values():
        assert "feed-forward on, lead 20 ms" in run["description"]
        assert run["progress"] is None
