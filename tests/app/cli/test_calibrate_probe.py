"""``deltadash calibrate --probe --plate-z MM``: a probe run on a server (the in-process
app on the twin built wrong, no motion capture), through the CLI's own HTTP helper."""

from __future__ import annotations

import io
import json
import math
import urllib.error
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.cli import run as cli_run
from tests.support.app_client import make_client

URL = "http://127.0.0.1"
OFFSETS_RAD = [math.radians(d) for d in (3.0, -2.0, 2.5)]
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}  # a starved simulator


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("probe-cli")
    twin = {"true_joint_offsets_rad": OFFSETS_RAD}
    with make_client(folder, "sim", hardware={"sim": twin}, safety=PATIENT) as client:
        yield client


@pytest.fixture
def served(app, monkeypatch) -> TestClient:
    """The CLI's HTTP calls go to the in-process app, with the same HTTPErrors; torque on
    is asked again while the relaxed arm still swings past its limits."""

    def http(url, method="GET", body=None, headers=None):
        response = app.request(method, url, json=body, headers=headers or {})
        for _ in range(600):
            if not (response.status_code == 409 and "outside its limits" in response.text):
                break
            response = app.request(method, url, json=body, headers=headers or {})
        if response.status_code >= 400:
            raise urllib.error.HTTPError(
                url, response.status_code, response.reason_phrase, {}, io.BytesIO(response.content)
            )
        return response.json()

    monkeypatch.setattr(cli_run, "_http", http)
    return app


@pytest.mark.slow
def test_a_probe_run_finds_the_offsets_in_millimetres_in(served, capsys) -> None:
    args = ["calibrate", "--url", URL, "--take-over", "--probe", "--plate-z", "-250"]
    code = main([*args, "--poses", "32", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    body = json.loads(out)
    assert body["source"] == "probe" and body["plate_z_m"] == pytest.approx(-0.25)
    np.testing.assert_allclose(
        body["parameters"]["joint_offsets_rad"], OFFSETS_RAD, atol=math.radians(0.1)
    )
    assert "unobservable: none" in err  # before the touches


@pytest.mark.slow
def test_what_heights_cannot_pin_is_printed(served, capsys) -> None:
    args = ["calibrate", "--url", URL, "--take-over", "--probe", "--plate-z", "-250"]
    main([*args, "--poses", "60", "--parameters", "geometry", "--fit-plate-z"])
    out, err = capsys.readouterr()
    condition = err.split("condition number ")[1].split(",")[0]
    assert float(condition) > 1e6 and "plate_z" in err  # a direction no touch can see
    assert "not pinned: " in out and "plate height error: " in out


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--probe"], "--plate-z"),
        (["--plate-z", "-250"], "--plate-z"),
        (["--probe", "--plate-z", "-250", "--from-csv", "x.csv"], "--probe"),
        (["--probe", "--plate-z", "250"], "plate_z_m"),
        (["--probe", "--plate-z", "-250", "--measurement", "pose-input"], "--measurement"),
        (["--from-csv", "x.csv", "--measurement", "pose-input"], "--measurement"),
    ],
)
def test_bad_probe_arguments_are_refused_naming_them(served, capsys, args, field) -> None:
    assert main(["calibrate", "--url", URL, "--take-over", *args]) == 2
    assert field in capsys.readouterr().err
