"""`deltadash run sinusoid --url`: takes the control lease before it commands (over another
holder only with --take-over, saying whose it was) and gives it back at the end."""

from __future__ import annotations

import io
import urllib.error
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.cli import run
from app.runs.trajectories import SinusoidParams
from tests.support.app_client import make_client


def test_remote_run_takes_the_lease_and_sends_it_with_every_request(monkeypatch):
    calls: list[tuple[str, str, dict]] = []

    def fake_http(url, method="GET", body=None, headers=None):
        calls.append((method, url, dict(headers or {})))
        if url.endswith("/api/lease") and method == "POST":
            return {"lease_id": "secret-id", "holder": body["client"], "timeout_s": 30.0}
        if url.endswith("/api/tests/sinusoid"):
            return {"run_id": "r1"}
        if "/api/runs/" in url:
            return {"run_id": "r1", "state": "done", "reason": None}
        return {"accepted": True}

    monkeypatch.setattr(run, "_http", fake_http)
    result = run._remote("http://robot:8000", SinusoidParams(), token="tok-12345", take_over=True)
    assert result["state"] == "done"
    assert result["files"]["report.pdf"] == "http://robot:8000/api/runs/r1/report.pdf"
    (method, url, headers), *rest = calls
    assert (method, url) == ("POST", "http://robot:8000/api/lease")
    assert headers == {"authorization": "Bearer tok-12345"}
    assert rest, calls
    for _, url, headers in rest:
        assert headers == {"authorization": "Bearer tok-12345", "x-lease": "secret-id"}, url
    assert rest[-1][:2] == ("DELETE", "http://robot:8000/api/lease")  # control given back


def test_an_interrupted_remote_run_is_aborted_before_control_is_given_back(monkeypatch):
    calls: list[tuple[str, str]] = []

    def fake_http(url, method="GET", body=None, headers=None):
        calls.append((method, url.removeprefix("http://robot")))
        if url.endswith("/api/lease") and method == "POST":
            return {"lease_id": "id", "holder": "deltadash run", "timeout_s": 30.0}
        if url.endswith("/api/tests/sinusoid"):
            return {"run_id": "r1"}
        if url.endswith("/api/runs/r1"):
            raise KeyboardInterrupt  # Ctrl-C while following the run
        return {"accepted": True}

    monkeypatch.setattr(run, "_http", fake_http)
    problems: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        run._remote("http://robot", SinusoidParams(), problems=problems)
    assert calls[-2:] == [("POST", "/api/runs/r1/abort"), ("DELETE", "/api/lease")]
    assert problems == []


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        yield client


def through(app: TestClient):
    """run._http over the in-process app: the same answers and HTTPErrors as over a socket."""

    def http(url, method="GET", body=None, headers=None):
        response = app.request(method, url, json=body, headers=headers or {})
        if response.status_code >= 400:
            raise urllib.error.HTTPError(
                url, response.status_code, response.reason_phrase, {}, io.BytesIO(response.content)
            )
        return response.json()

    return http


def test_take_over_is_needed_to_take_control_and_says_whom_it_was_taken_from(
    app, monkeypatch, capsys
):
    monkeypatch.setattr(run, "_http", through(app))
    dashboard = app.post("/api/lease", json={"client": "dashboard-ab12"}).json()["lease_id"]
    with pytest.raises(run.LeaseRefused) as refused:
        run._take_control("http://127.0.0.1", None, take_over=False)
    assert "'dashboard-ab12'" in str(refused.value) and "--take-over" in str(refused.value)
    assert app.post("/api/reset", headers={"x-lease": dashboard}).status_code == 200  # still held

    headers = run._take_control("http://127.0.0.1", None, take_over=True)
    assert "took control from 'dashboard-ab12'" in capsys.readouterr().err
    assert app.post("/api/reset", headers={"x-lease": dashboard}).status_code == 409
    assert app.post("/api/reset", headers=headers).status_code == 200
    assert app.get("/api/lease").json()["holder"] == "deltadash run"


def test_taking_free_control_names_nobody(app, monkeypatch, capsys):
    monkeypatch.setattr(run, "_http", through(app))
    headers = run._take_control("http://127.0.0.1", None, take_over=True)  # from whoever
    assert app.delete("/api/lease", headers=headers).status_code == 200
    capsys.readouterr()
    run._take_control("http://127.0.0.1", None, take_over=True)
    assert "took control" not in capsys.readouterr().err
