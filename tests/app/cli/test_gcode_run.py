"""``deltadash gcode run FILE --url``: on a server (the in-process app, reached through
the CLI's own HTTP helper): takes the lease, runs the program, prints the error per line,
gives control back; a failing program is refused with its violations and nothing runs."""

from __future__ import annotations

import io
import os
import sys
import urllib.error
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.cli import run as cli_run
from app.cli.gcode import stop_words
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


# from where the robot rests: 2 mm out, a stop on line 3 (M0 or M1), 2 mm back
STOPPING = "G21 G91 F600\nG1 X2\n{stop}\nG1 X-2\nM2\n"
AT_M0 = "M0 at line 3: press Resume"


class Recorded:
    """The CLI's requests as sent (method, path, body), through to the app; ``on_paused``
    (n, headers) is called on the n-th answer that shows the run standing at ``paused``."""

    def __init__(self, paused: str, on_paused) -> None:
        self.sent: list[tuple[str, str, dict | None]] = []
        self.paused, self.on_paused, self.seen = paused, on_paused, 0
        self.seen_at_resume: list[int] = []

    def __call__(self, http):
        def recording(url, method="GET", body=None, headers=None):
            path = url.removeprefix(URL)
            self.sent.append((method, path, body))
            if path == "/api/programs/resume":
                self.seen_at_resume.append(self.seen)
            answer = http(url, method, body, headers)
            progress = answer.get("progress") if isinstance(answer, dict) else None
            if progress and progress.get("paused") == self.paused:
                self.seen += 1
                self.on_paused(self.seen, headers)
            return answer

        return recording

    def posted(self, path: str) -> list[dict | None]:
        return [body for method, p, body in self.sent if method == "POST" and p == path]


def test_stop_words_say_where_and_why_it_stands():
    standing = {"feed_rate": 0.0, "program_line": 3, "stop_line": 3}
    assert stop_words({**standing, "paused": AT_M0}) == "paused at M0, line 3"
    m1 = {**standing, "paused": "M1 (optional stop) at line 6: press Resume", "stop_line": 6}
    assert stop_words(m1) == "paused at M1 (optional stop), line 6"
    step = {**standing, "paused": "single step: stopped at the end of line 4", "stop_line": 4}
    assert stop_words(step) == "paused at a single step's end, line 4"
    paused = {**standing, "paused": "paused", "stop_line": None, "program_line": 5}
    assert stop_words(paused) == "paused at a pause from the page or the API, line 5"
    # moving, or braking to a stand: not standing yet
    assert stop_words({**standing, "paused": None, "feed_rate": 1.0}) is None
    assert stop_words({**standing, "paused": "pausing", "feed_rate": 0.4}) is None
    assert stop_words({**standing, "paused": AT_M0, "feed_rate": 0.2}) is None


@pytest.mark.slow  # a run of seconds
def test_at_m0_it_says_where_and_enter_on_its_terminal_resumes(
    served, tmp_path, monkeypatch, capsys
):
    master, slave = os.openpty()
    stdin = os.fdopen(slave, "r")
    monkeypatch.setattr(sys, "stdin", stdin)
    os.write(master, b"\n")  # typed before the stop: dropped, it resumes nothing

    def press_enter(seen: int, _headers) -> None:
        if seen == 2:  # the CLI has said the stop (at the first) and waits on its terminal
            os.write(master, b"\n")

    recorded = Recorded(AT_M0, press_enter)
    monkeypatch.setattr(cli_run, "_http", recorded(cli_run._http))
    try:
        program = _program(tmp_path, STOPPING.format(stop="M0"))
        code = main(["gcode", "run", program, "--url", URL, "--take-over"])
    finally:
        stdin.close()
        os.close(master)
    err = capsys.readouterr().err
    assert code == 0, err
    assert err.count("paused at M0, line 3: press Enter to resume, Ctrl-C to abort") == 1
    assert "resumed" in err
    # one resume, sent after the Enter of the second look (the early one was dropped)
    assert recorded.posted("/api/programs/resume") == [None]
    assert recorded.seen_at_resume == [2]
    (run_body,) = recorded.posted("/api/programs/run")
    assert "optional_stop" not in run_body  # M1 runs through unless asked
    assert _runs(served)[0]["state"] == "done"
    assert served.get("/api/lease").json()["held"] is False


@pytest.mark.slow
def test_without_a_terminal_it_says_how_to_resume_and_waits_for_another_client(
    served, tmp_path, monkeypatch, capsys
):
    stdin = io.StringIO("\n\n")  # a pipe: never read as a resume
    monkeypatch.setattr(sys, "stdin", stdin)

    def resume_elsewhere(seen: int, headers) -> None:
        if seen == 3:  # it has said so and kept waiting: the page (with control) resumes
            assert served.post("/api/programs/resume", headers=headers).status_code == 200

    recorded = Recorded(AT_M0, resume_elsewhere)
    monkeypatch.setattr(cli_run, "_http", recorded(cli_run._http))
    program = _program(tmp_path, STOPPING.format(stop="M0"))
    code = main(["gcode", "run", program, "--url", URL, "--take-over"])
    err = capsys.readouterr().err
    assert code == 0, err
    said = "paused at M0, line 3: stdin is not a terminal: resume it from the page's program row"
    assert err.count(said) == 1 and "POST /api/programs/resume; Ctrl-C aborts" in err
    assert recorded.seen >= 3
    assert recorded.posted("/api/programs/resume") == []  # the CLI resumed nothing itself
    assert stdin.read() == "\n\n"  # nor read its input
    assert _runs(served)[0]["state"] == "done"


@pytest.mark.slow
def test_optional_stop_makes_m1_stop_and_ctrl_c_there_aborts_the_run(
    served, tmp_path, monkeypatch, capsys
):
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))

    def ctrl_c(seen: int, _headers) -> None:
        if seen == 2:
            raise KeyboardInterrupt

    at_m1 = "M1 (optional stop) at line 3: press Resume"
    recorded = Recorded(at_m1, ctrl_c)
    monkeypatch.setattr(cli_run, "_http", recorded(cli_run._http))
    program = _program(tmp_path, STOPPING.format(stop="M1"))
    code = main(["gcode", "run", program, "--url", URL, "--take-over", "--optional-stop"])
    err = capsys.readouterr().err
    assert code == 130, err
    (run_body,) = recorded.posted("/api/programs/run")
    assert run_body["optional_stop"] is True
    assert "paused at M1 (optional stop), line 3: stdin is not a terminal" in err
    run = _runs(served)[0]
    assert recorded.posted(f"/api/runs/{run['run_id']}/abort") == [None]
    assert run["state"] == "aborted" and run["params"]["optional_stop"] is True
    assert served.get("/api/lease").json()["held"] is False


@pytest.mark.slow
def test_ctrl_d_on_its_terminal_at_a_stop_leaves_it_waiting_for_another_client(
    served, tmp_path, monkeypatch, capsys
):
    master, slave = os.openpty()
    stdin = os.fdopen(slave, "r")
    monkeypatch.setattr(sys, "stdin", stdin)

    def ctrl_d_then_resume_elsewhere(seen: int, headers) -> None:
        if seen == 2:
            os.write(master, b"\x04")  # Ctrl-D: the terminal's input ends, no Enter
        if seen == 5:
            assert served.post("/api/programs/resume", headers=headers).status_code == 200

    recorded = Recorded(AT_M0, ctrl_d_then_resume_elsewhere)
    monkeypatch.setattr(cli_run, "_http", recorded(cli_run._http))
    try:
        program = _program(tmp_path, STOPPING.format(stop="M0"))
        code = main(["gcode", "run", program, "--url", URL, "--take-over"])
    finally:
        stdin.close()
        os.close(master)
    err = capsys.readouterr().err
    assert code == 0, err
    ended = "paused at M0, line 3: stdin has ended (Ctrl-D): resume it from the page's"
    assert err.index("press Enter to resume") < err.index(ended)
    assert recorded.posted("/api/programs/resume") == []
    assert recorded.seen >= 5 and _runs(served)[0]["state"] == "done"
