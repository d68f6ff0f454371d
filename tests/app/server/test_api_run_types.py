"""GET /api/tests (the run types the page's form is made from) and every type's preview
check, POST /api/tests/<name>/check, in-process on the simulator."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.runs.types import RUN_TYPES
from tests.app.server.test_api_dashboard import hold_at_centre
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim") as test_client:
        take_lease(test_client)
        hold_at_centre(test_client)
        yield test_client


def test_the_listing_is_the_registry_with_its_schemas(client: TestClient) -> None:
    listed = ok_json(client.get("/api/tests"))
    assert [t["name"] for t in listed] == list(RUN_TYPES)
    for entry in listed:
        run_type = RUN_TYPES[entry["name"]]
        assert entry["start"] == f"/api/tests/{run_type.name}"
        assert entry["check"] == f"/api/tests/{run_type.name}/check"
        assert entry["schema"] == run_type.request.model_json_schema()
        # every default the page shows is the model's own
        for name, field in run_type.request.model_fields.items():
            if not field.is_required():
                assert entry["schema"]["properties"][name]["default"] == field.default


def test_the_waypoints_example_is_a_body_the_api_takes(client: TestClient) -> None:
    """The page's first waypoint rows are the schema's example: a run it can start."""
    schema = next(t for t in ok_json(client.get("/api/tests")) if t["name"] == "waypoints")
    body = {k: schema["schema"]["properties"][k]["examples"][0] for k in ("points_m", "times_s")}
    checked = ok_json(client.post("/api/tests/waypoints/check", json=body))
    assert checked["feasible"] is True, checked["detail"]
    # the square's 30 mm side in 1 s, minimum-jerk: 1.875 * 0.03 m/s at its fastest
    assert checked["peak_speed_m_s"] == pytest.approx(1.875 * 0.03)
    assert 0 < checked["peak_joint_speed_rad_s"] < checked["joint_speed_limit_rad_s"]


@pytest.mark.parametrize(
    ("name", "body", "speed_m_s"),
    [
        # a chirp's fastest: a (2 pi f1), 10 mm at 2 Hz
        ("chirp", {"amplitude_m": 0.01, "f0_hz": 0.5, "f1_hz": 2.0, "duration_s": 2}, None),
        ("step", {"size_m": 0.004, "duration_s": 1.0}, 0.0),
        ("sinusoid", {"duration_s": 2}, 2 * math.pi * 2 * 0.08),
    ],
)
def test_each_type_previews_without_starting(
    client: TestClient, name: str, body: dict, speed_m_s: float | None
) -> None:
    runs_before = len(ok_json(client.get("/api/runs")))
    checked = ok_json(client.post(f"/api/tests/{name}/check", json=body))
    assert checked["feasible"] is True, checked["detail"]
    if speed_m_s is not None:
        assert checked["peak_speed_m_s"] == pytest.approx(speed_m_s)
    if name == "step":  # its jump is the servo's: no path joint speed to show
        assert checked["peak_joint_speed_rad_s"] is None
    else:
        assert checked["peak_joint_speed_rad_s"] > 0
    assert len(ok_json(client.get("/api/runs"))) == runs_before


def test_an_infeasible_chirp_is_said_and_a_bad_body_named(client: TestClient) -> None:
    far = {"amplitude_m": 0.2, "axis": 0, "duration_s": 2}  # 200 mm sideways: outside
    checked = ok_json(client.post("/api/tests/chirp/check", json=far))
    assert checked["feasible"] is False and "infeasible" in checked["detail"]
    refused = client.post("/api/tests/step/check", json={"size_m": 0.5})
    assert refused.status_code == 422 and "size_m" in refused.json()["detail"]
    unordered = {"points_m": [[0, 0, -0.24], [0.01, 0, -0.24]], "times_s": [0, 0]}
    refused = client.post("/api/tests/waypoints/check", json=unordered)
    assert refused.status_code == 422 and "times_s" in refused.json()["detail"]
