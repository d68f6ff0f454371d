"""Ctrl-C during ``deltadash calibrate --url`` / ``deltadash tune --url`` aborts the run on
the server (the arm holds, the robot is free) and gives control back; exit 130. The run's
thread is stood in for by one that waits until the run is aborted (a run that would go on
for ever without the abort), so what is tested is the command line's part; the abort
itself on the twin is tests/app/server/test_procedure_abort.py's."""

from __future__ import annotations

import io
import urllib.error
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.calibration.procedure import CalibrationManager
from app.cli import main
from app.cli import run as cli_run
from app.cli.progress import Progress
from app.tuning.procedure import TuningManager
from tests.support.app_client import make_client

URL = "http://127.0.0.1"
WAIT_S = 60.0


def _until_aborted(self, run) -> tuple[str, str | None]:
    """A run's thread that moves nothing and ends only when the run is aborted."""
    assert run.aborted.wait(WAIT_S), "the run was not aborted"
    return "failed", "aborted by the operator"  # an aborted run stays aborted


def _interrupt(*_args, **_kwargs) -> None:
    """Ctrl-C, as the progress bar is updated (while the command follows the run)."""
    raise KeyboardInterrupt


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("interrupt")) as client:
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
    # the emulated bus has no external measurement (a run would be refused at its start):
    # one that answers, as the stood-in thread measures nothing anyway
    monkeypatch.setitem(app.app.state.calibration.measures, "external", lambda _: np.zeros(3))
    monkeypatch.setattr(CalibrationManager, "_execute", _until_aborted)
    monkeypatch.setattr(TuningManager, "_execute", _until_aborted)
    return app


@pytest.mark.slow
def test_ctrl_c_in_calibrate_aborts_the_run(served, monkeypatch, capsys) -> None:
    monkeypatch.setattr(Progress, "update_to", _interrupt)
    code = main(["calibrate", "--url", URL, "--poses", "12", "--take-over"])
    _, err = capsys.readouterr()
    assert code == 130, err
    (run,) = served.app.state.calibration.list()
    assert run.state == "aborted", run.view()
    assert "error" not in err, err
    assert served.get("/api/lease").json()["held"] is False  # control given back


def test_ctrl_c_in_tune_aborts_the_run(served, monkeypatch, capsys) -> None:
    monkeypatch.setattr(Progress, "update_to", _interrupt)
    code = main(["tune", "--url", URL, "--joints", "1", "--take-over"])
    _, err = capsys.readouterr()
    assert code == 130, err
    (run,) = served.app.state.tuning._runs.values()
    assert run.state == "aborted", run.view()
    assert "error" not in err, err
    assert served.get("/api/lease").json()["held"] is False
