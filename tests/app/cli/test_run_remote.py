"""`deltadash run sinusoid --url` takes the control lease before it commands."""

from __future__ import annotations

from app.cli import run
from app.runs.trajectories import SinusoidParams


def test_remote_run_takes_the_lease_and_sends_it_with_every_request(monkeypatch):
    calls: list[tuple[str, str, dict]] = []

    def fake_http(url, method="GET", body=None, headers=None):
        calls.append((method, url, dict(headers or {})))
        if url.endswith("/api/lease"):
            return {"lease_id": "secret-id", "holder": body["client"], "timeout_s": 30.0}
        if url.endswith("/api/tests/sinusoid"):
            return {"run_id": "r1"}
        if "/api/runs/" in url:
            return {"run_id": "r1", "state": "done", "reason": None}
        return {"accepted": True}

    monkeypatch.setattr(run, "_http", fake_http)
    result = run._remote("http://robot:8000", SinusoidParams(), token="tok-12345", take_over=True)
    assert result["state"] == "done"
    (method, url, headers), *rest = calls
    assert (method, url) == ("POST", "http://robot:8000/api/lease")
    assert headers == {"authorization": "Bearer tok-12345"}
    assert rest, calls
    for _, url, headers in rest:
        assert headers == {"authorization": "Bearer tok-12345", "x-lease": "secret-id"}, url
