"""POST /api/programs/check: the report of a program, 422 for one that cannot be read;
in a worker process, 503 when none answers."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from tests.support.pids import say_pid
from tests.support.wait import ok_json, wait_for

START = [0.0, 0.0, -0.22]
GOOD = "G21 G90\nG1 F1200 X10 Y0 Z-220\nG3 X-10 Y0 R10\nG4 P0.1\nM2"


def check(client, gcode, **extra):
    return client.post("/api/programs/check", json={"gcode": gcode, **extra})


@pytest.mark.slow
def test_a_passing_program_answers_its_report(client):
    body = ok_json(check(client, GOOD, start_m=START))
    assert body["ok"] is True and body["violations"] == []
    assert body["length_m"] == pytest.approx(0.01 + np.pi * 0.01)
    assert body["duration_s"] > 0.1
    path = np.array(body["path_m"])
    assert path.shape[1] == 3 and 2 <= len(path) <= 2000
    np.testing.assert_allclose(path[0], START)
    np.testing.assert_allclose(path[-1], [-0.01, 0.0, -0.22], atol=1e-12)
    for key in ("peak_joint_speed_rad_s", "worst_dexterity", "worst_torque_ratio"):
        assert body[key] > 0


def test_a_failing_program_is_a_200_naming_line_kind_time_and_point(client):
    body = ok_json(check(client, "G90 G1 F1200 Z-220\nZ-40\nZ-220", start_m=START))
    assert body["ok"] is False
    first = body["violations"][0]
    assert set(first) == {"line", "kind", "message", "t_s", "point_m", "folded_under"}
    assert first["line"] == 2
    # line 2 climbs through joint 1's lower limit first (link up), the rest folded under it
    assert (first["kind"], first["folded_under"]) == ("joint_limit", None)
    assert "deg beyond its lower limit" in first["message"]
    assert all(v["folded_under"] == 0 for v in body["violations"][1:] if v["line"] == 2)
    assert {v["line"] for v in body["violations"]} <= {2, 3}
    ceiling = [v for v in body["violations"] if v["kind"] == "ceiling"]
    assert ceiling and ceiling[0]["point_m"][2] > -0.06


@pytest.mark.parametrize(
    ("gcode", "line", "word"),
    [("G21\nG1 F100 X1 A5", 2, "A5"), ("G1 F100 X1\n\nG92 X0", 3, "G92"), ("G1 (x", 1, "(")],
)
def test_a_program_that_cannot_be_read_is_a_422_naming_line_and_word(client, gcode, line, word):
    response = check(client, gcode, start_m=START)
    assert response.status_code == 422, response.text
    body = response.json()
    assert (body["line"], body["word"]) == (line, word)
    assert body["detail"].startswith(f"line {line}: {word}: ")


def test_a_bad_body_is_a_422_naming_the_field(client):
    response = client.post("/api/programs/check", json={"program": "G1"})
    assert response.status_code == 422
    assert "gcode" in response.json()["detail"]
    response = check(client, "G1", start_m=[0, 0])
    assert response.status_code == 422 and "start_m" in response.json()["detail"]


def test_without_a_start_the_check_starts_where_the_robot_is(client):
    status = ok_json(client.get("/api/status"))
    body = ok_json(check(client, "(nothing to do)"))
    np.testing.assert_allclose(body["start_m"], status["ee"]["position_m"], atol=5e-3)


def test_checks_beyond_the_concurrent_limit_are_a_503_not_a_queue(client, monkeypatch):
    """Each long check costs seconds of CPU and up to ~1 GB in a worker process: when the
    allowed number are running, another is refused at once, saying why."""
    workers = client.app.state.program_workers
    assert workers.slots == 2
    monkeypatch.setattr(workers, "_free", [])  # every slot running a check
    response = client.post("/api/programs/check", json={"gcode": "G4 P0.1"})
    assert response.status_code == 503, response.text
    assert "2 program checks are running" in response.json()["detail"]
    assert response.headers["retry-after"] == "5"
    monkeypatch.setattr(workers, "_free", [0, 1])
    assert ok_json(check(client, "G4 P0.1", start_m=START))["ok"]  # free again: answered


def test_the_check_runs_outside_the_server_process(client, monkeypatch):
    """The control loop's process never checks: here the check would fail, in the worker
    it answers."""
    from app.programs import workers

    def not_here(*_args, **_kwargs):
        raise AssertionError("the program was checked in the server's process")

    monkeypatch.setattr(workers, "check_program", not_here)
    assert ok_json(check(client, GOOD, start_m=START))["ok"] is True


def say_pid_then_wait(job) -> None:
    """In the worker, instead of the check: the pid to the file the program text names."""
    say_pid(job.text)
    while True:
        time.sleep(1.0)


@pytest.mark.slow  # a new worker process starts
def test_a_killed_check_worker_is_a_503_saying_so_and_the_next_check_works(
    client, monkeypatch, tmp_path
):
    from app.programs import workers

    pid_file = tmp_path / "pid"
    monkeypatch.setattr(workers, "run_check", say_pid_then_wait)
    answer: list = []
    request = threading.Thread(
        target=lambda: answer.append(check(client, str(pid_file), start_m=START)), daemon=True
    )
    request.start()
    wait_for(pid_file.exists, "the check's worker to say its pid", 180.0)
    os.kill(int(pid_file.read_text()), signal.SIGKILL)
    request.join(180.0)
    assert answer, "the request never came back"
    response = answer[0]
    assert response.status_code == 503, response.text
    assert "ended before answering" in response.json()["detail"]
    monkeypatch.undo()
    assert ok_json(check(client, GOOD, start_m=START))["ok"] is True
