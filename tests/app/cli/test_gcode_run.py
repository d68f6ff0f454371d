"""``deltadash gcode run FILE --url``: on a server (the in-process app, reached through
the CLI's own HTTP helper): takes the lease, runs the program, prints the error per line,
gives control back; a failing program is refused with its violations and nothing runs."""

from __future__ import annotations

import io
import urllib.error
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.cli import run as cli_run
from tests.support.app_client import make_client

URL = "http://127.0.0.1"
PROGRAM = "G21 G90 G17\nG0 X0 Y0 Z-230\nG1 F1500 X10\nG3 X-10 Y0 R10\nG1 X0\nM2\n"
FAILING = "G21 G90\nG1 F1200 X0 Y0 Z-220\nZ-40\nZ-220\nM2\n"


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        yield client


@pytest.fixture
def served(app, monkeypatch) -> TestClient:
    """The CLI's HTTP calls go to the in-process app, with the same HTTPErrors."""

    def http(url, method="GET", body=None, headers=None):
        response = app.request(method, url, json=body, headers=headers or {})
        if response.status_code >= 400:
            raise urllib.error.HTTPError(
                url, response.status_code, response.reason_phrase, {}, io.BytesIO(response.content)
            )
        return response.json()

    monkeypatch.setattr(cli_run, "_http", http)
    return app


def _program(tmp_path, text: str) -> str:
    path = tmp_path / "program.ngc"
    path.write_text(text)
    return str(path)


def _runs(app: TestClient) -> list[dict]:
    return app.get("/api/runs").json()


@pytest.mark.slow  # a run of seconds
def test_a_program_runs_and_its_error_per_line_is_printed(served, tmp_path, capsys):
    before = len(_runs(served))
    code = main(["gcode", "run", _program(tmp_path, PROGRAM), "--url", URL, "--take-over"])
    out, err = capsys.readouterr()
    assert code == 0, err
    runs = _runs(served)
    assert len(runs) == before + 1 and runs[0]["kind"] == "program"
    per_line = runs[0]["stats"]["program"]["lines"]
    assert [e["line"] for e in per_line] == [2, 3, 4, 5]
    assert "tracking error per program line" in out
    table = out.split("tracking error per program line:")[1].splitlines()[2:]
    printed = {int(row.split()[0]): float(row.split()[2]) for row in table if row.strip()}
    assert printed == {e["line"]: pytest.approx(e["rmse_m"] * 1e3, abs=6e-4) for e in per_line}
    assert "G3 X-10 Y0 R10" in out  # each line with its program text
    assert served.get("/api/lease").json()["held"] is False  # control given back


@pytest.mark.slow
def test_a_failing_program_is_refused_with_its_violations_and_nothing_runs(
    served, tmp_path, capsys
):
    before = len(_runs(served))
    code = main(["gcode", "run", _program(tmp_path, FAILING), "--url", URL, "--take-over"])
    err = capsys.readouterr().err
    assert code == 2
    assert "error: 422 line 3: " in err and "  line 3: " in err
    assert len(_runs(served)) == before
    assert served.get("/api/lease").json()["held"] is False


def test_control_held_by_another_client_needs_take_over(served, tmp_path, capsys):
    other = served.post("/api/lease", json={"client": "dashboard-cd34"}).json()["lease_id"]
    try:
        code = main(["gcode", "run", _program(tmp_path, PROGRAM), "--url", URL])
        err = capsys.readouterr().err
        assert code == 2 and "--take-over" in err and "dashboard-cd34" in err
        assert served.get("/api/lease").json()["holder"] == "dashboard-cd34"
    finally:
        served.delete("/api/lease", headers={"x-lease": other})


def test_a_missing_file_is_exit_2(tmp_path, capsys):
    assert main(["gcode", "run", str(tmp_path / "none.ngc"), "--url", URL]) == 2
    assert "none.ngc" in capsys.readouterr().err
