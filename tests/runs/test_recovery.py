"""A run a crash left "running" is listed as interrupted when the app next starts, with
stats from its logged ticks, a report and a finished MCAP log; one still being written by
a live process is left alone. In-process (the real kill -9 is in test_crash.py)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader, make_reader

from app.runs.logs import COLUMNS, RunLog
from app.runs.run import Run
from tests.support.app_client import make_client
from tests.support.wait import ok_json, wait_for

ERROR_X_M = 0.001  # measured x lags the goal by 1 mm on every tick


def _row(k: int) -> dict:
    row = dict.fromkeys(COLUMNS)
    goal = (0.01 * (k % 50) / 50, 0.0, -0.24)
    row.update({"t_s": k * 0.005, "phase": "approach" if k < 100 else "timed", "mode": "test"})
    for axis, value in zip("xyz", goal, strict=True):
        row[f"goal_{axis}_m"] = value
        row[f"measured_{axis}_m"] = value - (ERROR_X_M if axis == "x" else 0.0)
    row["faults"] = ""
    row["gap_ms"] = 60.0 if k == 300 else 5.0  # one pause of the loop, logged
    return row


def _record(folder: Path, run_id: str) -> Run:
    run = Run(run_id, "sinusoid", {"feedforward": False}, {"loop_rate_hz": 200.0}, folder)
    run.samples = 250  # as a record saved mid-run says
    run.write()
    return run


@pytest.fixture(scope="module")
def restarted(tmp_path_factory):
    """A runs folder with a crashed run (its MCAP cut inside a message), a run whose log
    a live writer holds, a record of a newer version and a broken one; then the app."""
    root = tmp_path_factory.mktemp("recovery")
    runs = root / "runs"
    # the crashed run: logs as the last commit left them, then cut inside the next write
    writing = RunLog(root / "scratch", {"run_id": "crashed"})
    for k in range(600):
        writing.write(_row(k))
        if k == 449:
            writing._flush()
    mcap, csv = writing.mcap_path.read_bytes(), writing.csv_path.read_bytes()
    writing.close()
    crashed = runs / "20270115-080000-dead"
    crashed.mkdir(parents=True)
    cut = mcap[: len(mcap) - 100]  # into the last message (the trailer is 50 bytes)
    (crashed / "log.mcap").write_bytes(cut)
    (crashed / "log.csv").write_bytes(csv)
    _record(crashed, crashed.name)
    # a run another process is writing now
    live = runs / "20270115-090000-beef"
    live_log = RunLog(live, {"run_id": live.name})
    _record(live, live.name)
    # a record of a newer version (a field this one does not know) and a broken one
    newer = runs / "20270115-070000-cafe"
    newer.mkdir()
    data = {**Run(newer.name, "step", {}, {}, newer, state="done").as_dict(), "later": 1}
    (newer / "run.json").write_text(json.dumps(data))
    (runs / "20270115-060000-0bad").mkdir()
    (runs / "20270115-060000-0bad" / "run.json").write_text('{"run_id": "0bad", "kin')
    with make_client(runs) as client:
        yield client, {"cut": cut, "crashed": crashed.name, "live": live.name, "newer": newer}
    live_log.close()


@pytest.mark.slow
def test_a_crashed_run_is_interrupted_with_stats_from_its_logged_ticks(restarted):
    client, seen = restarted
    runs = {r["run_id"]: r for r in ok_json(client.get("/api/runs"))}
    run = runs[seen["crashed"]]
    assert run["state"] == "interrupted" and "server stopped" in run["reason"]
    assert run["samples"] == 449  # the committed 450 ticks less the message the cut split
    assert run["started_at_utc"].endswith("Z") and run["ended_at"] is not None
    tracking = run["stats"]["tracking"]
    assert tracking["x"]["mean_m"] == pytest.approx(ERROR_X_M, abs=1e-12)
    assert tracking["y"]["rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert 0 < tracking["samples"] < 449 - 100  # the approach is not scored
    health = run["stats"]["health"]  # judged from the logged ticks too
    assert not health["ok"] and health["longest_gap_ms"] == pytest.approx(60.0)
    assert any("paused 60 ms" in reason for reason in health["reasons"])
    saved = json.loads((client.app.state.runs.folder / run["run_id"] / "run.json").read_text())
    assert saved["state"] == "interrupted"  # once: a later start does not redo it


@pytest.mark.slow  # an app restarted on the twin
def test_a_crashed_runs_files_are_served_and_its_mcap_is_whole(restarted):
    client, seen = restarted
    base = f"/api/runs/{seen['crashed']}"
    mcap = client.get(f"{base}/log.mcap")
    assert mcap.status_code == 200 and mcap.headers["content-type"] == "application/vnd.mcap"
    for reader in (make_reader, NonSeekingReader):
        messages = list(reader(io.BytesIO(mcap.content)).iter_messages())
        assert len(messages) == 449
        assert json.loads(messages[-1][2].data) == _row(448)
    assert make_reader(io.BytesIO(mcap.content)).get_summary().statistics.message_count == 449
    assert client.get(f"{base}/log.cut.mcap").content == seen["cut"]  # kept as it was
    assert client.get(f"{base}/log.csv").text.count("\n") == 451  # header and 450 rows
    _reported(client, seen["crashed"])  # drawn after start-up, in a thread
    png = client.get(f"{base}/report.png")
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"


def _reported(client, run_id: str) -> None:
    wait_for(
        lambda: ok_json(client.get(f"/api/runs/{run_id}"))["has_report"],
        "the interrupted run's report drawn",
    )


@pytest.mark.slow
def test_run_files_are_inline_with_their_media_type_and_answer_head(restarted):
    client, seen = restarted
    _reported(client, seen["crashed"])
    base = f"/api/runs/{seen['crashed']}"
    for name, media_type in (
        ("report.png", "image/png"),
        ("report.pdf", "application/pdf"),  # drawn from the logged ticks too
        ("log.csv", "text/csv; charset=utf-8"),
        ("log.mcap", "application/vnd.mcap"),
    ):
        got, head = client.get(f"{base}/{name}"), client.head(f"{base}/{name}")
        for response in (got, head):
            assert response.status_code == 200, (name, response.text)
            assert response.headers["content-type"] == media_type
            assert response.headers["content-disposition"].startswith("inline;")
            assert f"{seen['crashed']}-{name}" in response.headers["content-disposition"]
            assert int(response.headers["content-length"]) == len(got.content)
        assert head.content == b""
    assert client.head(f"/api/runs/{seen['live']}/report.pdf").status_code == 404  # not yet
    assert client.head(f"{base}/secrets.txt").status_code == 404


def test_a_run_a_live_process_writes_is_left_running(restarted):
    client, seen = restarted
    run = ok_json(client.get(f"/api/runs/{seen['live']}"))
    assert run["state"] == "running" and run["stats"]["tracking"] is None


def test_records_of_other_versions_load_and_broken_ones_are_left_out(restarted):
    client, seen = restarted
    listed = [r["run_id"] for r in ok_json(client.get("/api/runs"))]
    assert seen["newer"].name in listed and "0bad" not in listed
