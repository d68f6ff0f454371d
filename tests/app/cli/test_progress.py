"""Progress on stderr (app/cli/progress.py) and its use by ``run`` and ``design synth``."""

from __future__ import annotations

import io
import re

from app.cli import main, run
from app.cli.progress import Progress
from app.runs.trajectories import SinusoidParams


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _percentages(text: str) -> list[int]:
    return [int(p) for p in re.findall(r": (\d+)% \(", text)]


def test_a_pipe_gets_a_line_per_step_and_per_phase_never_a_bar():
    stream = io.StringIO()
    with Progress(20.0, "run r1", "s", stream=stream) as bar:
        for tenth in range(0, 201, 7):
            bar.update_to(tenth / 10, phase="test" if tenth > 100 else "approach")
        bar.update_to(20.0, phase="stop")
    text = stream.getvalue()
    assert "\r" not in text
    percents = _percentages(text)
    assert percents == sorted(percents) and percents[0] == 0 and percents[-1] == 100
    assert set(range(0, 101, 10)) <= set(percents)
    assert "approach" in text and "test" in text and "stop" in text
    assert len(text.splitlines()) <= 11 + 3  # a step or a phase change, not every update


def test_a_terminal_gets_a_bar_that_reaches_the_total_even_when_it_grows():
    stream = Terminal()
    with Progress(5.0, "run r1", "s", stream=stream) as bar:
        bar.update_to(2.0, phase="approach")
        bar.update_to(7.5, phase="test", total=8.0)
        bar.update_to(8.0)
    text = stream.getvalue()
    assert "\r" in text and "8.0/8.0 s" in text and "100%" in text


def test_remote_run_shows_the_servers_progress_on_stderr(monkeypatch, capsys):
    states = iter(
        [
            {
                "state": "running",
                "progress": {"phase": "approach", "elapsed_s": 1.0, "duration_s": 10.0},
            },
            {
                "state": "running",
                "progress": {"phase": "test", "elapsed_s": 6.0, "duration_s": 10.0},
            },
            {"state": "done", "reason": None},
        ]
    )

    def fake_http(url, method="GET", body=None, headers=None):
        if url.endswith("/api/lease") and method == "POST":
            return {"lease_id": "id", "holder": "deltadash run", "timeout_s": 30.0}
        if url.endswith("/api/tests/sinusoid"):
            return {"run_id": "r1"}
        if url.endswith("/api/runs/r1"):
            return {"run_id": "r1", **next(states)}
        return {"accepted": True}

    monkeypatch.setattr(run, "_http", fake_http)
    monkeypatch.setattr(run.time, "sleep", lambda s: None)
    assert run._remote("http://robot", SinusoidParams())["state"] == "done"
    captured = capsys.readouterr()
    assert "run r1: 10% (1.0 of 10.0 s), approach" in captured.err
    assert "run r1: 60% (6.0 of 10.0 s), test" in captured.err
    assert captured.out == ""  # stdout stays for the result


def test_synth_reports_generations_on_stderr_and_keeps_stdout_for_json(capsys):
    argv = ["design", "synth", "--json", "--popsize", "5", "--maxiter", "10"]
    main(argv)
    captured = capsys.readouterr()
    assert captured.out.lstrip().startswith("{")
    percents = _percentages(captured.err)
    assert percents and percents == sorted(percents) and "gen" in captured.err
