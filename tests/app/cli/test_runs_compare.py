"""`deltadash runs compare`: the table from a runs folder and from a server agree."""

from __future__ import annotations

import io
import json
import urllib.error

import pytest

from app.cli import main
from app.cli import runs as runs_cli
from app.runs.describe import number
from tests.support.app_client import make_client
from tests.support.saved_runs import HEALTHY, UNHEALTHY, save_run, synthetic_rows

A, B = "20260101-100000-aaaa", "20260101-110000-bbbb"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    save_run(folder, A, synthetic_rows(error_m=0.001), HEALTHY)
    save_run(folder, B, synthetic_rows(error_m=0.004), UNHEALTHY)
    return folder


def saved_stats(folder, run_id):
    return json.loads((folder / run_id / "run.json").read_text())["stats"]["tracking"]


@pytest.mark.slow
def test_compare_prints_each_runs_figures_in_its_column(folder, capsys, tmp_path):
    plot = tmp_path / "compare.png"
    assert main(["runs", "compare", A, B, "--folder", str(folder), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    lines = {line.split("  ")[0].strip(): line.split() for line in out.splitlines() if line}
    for axis in "xyz":
        cells = lines[f"RMSE {axis} [mm]"]
        expected = [number(saved_stats(folder, i)[axis]["rmse_m"] * 1e3) for i in (A, B)]
        assert cells[-2:] == expected
    assert lines[""] == [A, B]  # the header: a column per run, in the order asked
    assert f"{B} verdict: NOT HEALTHY" in out and "318 ms" in out
    assert f"{A} test: sinusoid per axis" in out and "amplitude 50 / 50 / 80 mm" in out
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("ids", "words"),
    [([A, "nope"], ["'nope'", "no run"]), ([A], ["2 or more"]), ([A, A], ["got 1"])],
)
def test_compare_refuses_unknown_ids_and_fewer_than_two(folder, capsys, ids, words):
    assert main(["runs", "compare", *ids, "--folder", str(folder)]) == 2
    err = capsys.readouterr().err
    assert all(word in err for word in words), err


@pytest.mark.slow
def test_compare_from_a_server_prints_the_same_table(folder, capsys, monkeypatch, tmp_path):
    assert main(["runs", "compare", A, B, "--folder", str(folder), "--json"]) == 0
    local = json.loads(capsys.readouterr().out)
    with make_client(folder) as app:

        def get(url, token):
            response = app.get(url)
            if response.status_code >= 400:
                raise urllib.error.HTTPError(
                    url, response.status_code, "", {}, io.BytesIO(response.content)
                )
            return response.content

        monkeypatch.setattr(runs_cli, "_get", get)
        plot = tmp_path / "remote.png"
        args = [
            "runs",
            "compare",
            A,
            B,
            "--url",
            "http://127.0.0.1",
            "--json",
            "--plot",
            str(plot),
        ]
        assert main(args) == 0
        assert json.loads(capsys.readouterr().out) == local
        assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert main(["runs", "compare", A, "gone", "--url", "http://127.0.0.1"]) == 2
        assert "404 no run 'gone'" in capsys.readouterr().err
