"""``deltadash calibrate --url``: on a server (the in-process app on the twin built wrong,
reached through the CLI's own HTTP helper): observability printed before the arm moves,
progress, the fit, then apply and the offsets written into the --write config."""

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
from app.config import load_settings
from app.server.backends import _calibrations
from hardware.encoder import RAD_PER_TICK
from tests.support.app_client import make_client

URL = "http://127.0.0.1"
OFFSETS_RAD = [math.radians(d) for d in (3.0, -2.0, 2.5)]
TWIN = {
    "true_joint_offsets_rad": OFFSETS_RAD,
    "measurement_frame_position_m": [0.1, -0.05, -0.5],
    "measurement_noise_m": 3e-4,
}
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}  # a starved simulator


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("cal")
    with make_client(folder, "sim", hardware={"sim": TWIN}, safety=PATIENT) as client:
        yield client


@pytest.fixture
def served(app, monkeypatch) -> TestClient:
    """The CLI's HTTP calls go to the in-process app, with the same HTTPErrors; torque on
    is asked again while the relaxed arm still swings past its limits (as a person would)."""

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


@pytest.mark.slow  # 16 poses on the twin
def test_calibrate_on_a_server_applies_and_writes_the_offsets(served, tmp_path, capsys):
    config = tmp_path / "robot.toml"
    args = ["calibrate", "--url", URL, "--poses", "16", "--take-over", "--json"]
    code = main([*args, "--write", str(config)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "condition number" in err and "unobservable: none" in err  # before the moves
    body = json.loads(out[: out.rindex("}") + 1])
    found = body["parameters"]["joint_offsets_rad"]
    np.testing.assert_allclose(found, OFFSETS_RAD, atol=math.radians(0.2))
    assert "applied" in out and f"joint zero offsets written to {config}" in err
    before, after = _calibrations(load_settings()), _calibrations(load_settings(config))
    for old, new, offset in zip(before, after, found, strict=True):
        assert math.isclose(new.to_rad(2000), old.to_rad(2000) + offset, abs_tol=RAD_PER_TICK)
    assert served.get("/api/lease").json()["held"] is False  # control given back


@pytest.mark.slow
def test_bad_poses_are_refused_naming_the_field(served, capsys):
    assert main(["calibrate", "--url", URL, "--poses", "3", "--take-over"]) == 2
    assert "poses" in capsys.readouterr().err


def test_motion_capture_without_a_stream_is_refused_saying_so(served, capsys):
    torque = served.get("/api/status").json()["torque"]
    code = main(
        ["calibrate", "--url", URL, "--poses", "16", "--take-over", "--measurement", "pose-input"]
    )
    err = capsys.readouterr().err
    assert code == 2 and "stream is none" in err and "body 'platform'" in err, err
    status = served.get("/api/status").json()
    assert status["mode"] == "idle" and status["torque"] == torque, status  # nothing done
