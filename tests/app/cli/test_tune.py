"""``deltadash tune --url``: on a server (the in-process app, reached through the CLI's own
HTTP helper): progress, the models and gains in plain units, --apply writing the servos'
registers, --revert; bad input refused naming the field; the twin check's candidates and
choice shown, and said when none met the goal. The emulated bus answers fast; the run's
identification and its twin check are stood in for (its thread leaves a done run with
the fit of a known model, and the check passes or fails gain sets as a test says), so
what is tested here is the command line's part; the real run on the twin is
tests/app/server/test_tuning_api.py's."""

from __future__ import annotations

import io
import json
import urllib.error
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.cli import run as cli_run
from app.tuning.gains import Plant, Target, suggest
from app.tuning.identify import JointFit, JointModel
from app.tuning.procedure import TuningManager, TuningRun, gains_out
from app.tuning.twin_check import OfferJob, Tracking, Verdict, offer
from hardware.bus import PositionGains
from tests.support.app_client import make_client

URL = "http://127.0.0.1"
MODEL = JointModel(1.0, 55.0, 0.75, 0.008)


FAILING: set[PositionGains] = set()  # gain sets the stand-in twin check fails
FAIL_ALL = {"on": False}
PASSING = Tracking((0.001, 0.001, 0.003), 0.6, 0.0)


def _stand_in_check(gains, lead_s, seconds, limits, gravity) -> Verdict:
    failed = ("rest_m",) if FAIL_ALL["on"] or any(g in FAILING for g in gains) else ()
    return Verdict(PASSING, PASSING, lead_s, 2.0, (1e-4, 2e-4, 1e-4, 1e-4, 3e-4), failed)


def _twin_check(job: OfferJob):
    return offer(
        job.plants,
        job.target,
        job.lead_s,
        job.seconds,
        job.limits,
        job.gravity,
        job.current,
        check_fn=_stand_in_check,
    )


def _identified(self: TuningManager, run: TuningRun) -> tuple[str, str | None]:
    """What a run's thread leaves (stands in for the step and chirp runs and the fit; the
    twin check's verdicts are `_stand_in_check`'s): the state it ends in."""
    run.fits = [JointFit(joint, MODEL, 1e-3, 0.1, 500) for joint in run.joints]
    self.twin_check = _twin_check
    self._suggest(run)
    return "done", None


@pytest.fixture(autouse=True)
def _checks_pass():
    FAILING.clear()
    FAIL_ALL["on"] = False
    yield
    FAILING.clear()
    FAIL_ALL["on"] = False


@pytest.fixture(scope="module")
def app(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("tune")) as client:
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
    monkeypatch.setattr(TuningManager, "_execute", _identified)
    return app


def _registers(app) -> list[PositionGains]:
    return app.app.state.backend.bus.read_gains()


@pytest.mark.slow
def test_tune_prints_the_model_and_gains_and_applies_them(served, capsys):
    ids = list(served.app.state.controller.servo_ids)
    code = main(["tune", "--url", URL, "--joints", "1", "3", "--bandwidth", "15", "--take-over"])
    out, err = capsys.readouterr()
    assert code == 0, err
    expected = suggest(Plant.of(MODEL), Target(bandwidth_hz=15.0)).gains
    shown = f"P {expected.p}, I {expected.i}, D {expected.d}"
    assert f"servo {ids[0]} (joint 1)" in out and f"servo {ids[2]} (joint 3)" in out
    assert f"servo {ids[1]} (joint 2)" not in out
    assert "wn 8.8 Hz" in out and "delay 8.0 ms" in out  # 55 rad/s, 8 ms: plain units
    assert out.count(f"suggested: {shown}") == 2
    assert "predicted suggested" in out and "predicted now" in out
    # the twin check: its candidate, chosen, why, and the goal met
    assert "checked on the twin, gains per servo 1/2/3 where they differ (lead 20 ms" in out
    assert (
        f" * 1: P {expected.p}/800/{expected.p}, I {expected.i}/0/{expected.i}, D {expected.d}/0/"
        f"{expected.d}: RMSE plain 1.00 / 1.00 / 3.00 mm" in out
    )
    assert "chosen: candidate 1: the first of 1 tried to pass every limit" in out
    assert "do NOT meet" not in out
    assert _registers(served) == [PositionGains()] * 3  # not applied without --apply
    assert served.get("/api/lease").json()["held"] is False  # control given back

    code = main(["tune", "--url", URL, "--joints", "2", "--bandwidth", "15", "--apply"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "applied" in out and f"servo {ids[1]}: {shown}" in out
    assert _registers(served) == [PositionGains(), expected, PositionGains()]

    assert main(["tune", "--url", URL, "--revert"]) == 0
    out, _ = capsys.readouterr()
    assert "reverted" in out
    assert _registers(served) == [PositionGains()] * 3


@pytest.mark.slow
def test_tune_json_is_the_apis_body(served, capsys):
    assert main(["tune", "--url", URL, "--joints", "2", "--json"]) == 0
    body = json.loads(capsys.readouterr().out)
    sid = str(served.app.state.controller.servo_ids[1])
    assert body["state"] == "done"
    assert body["suggested"][sid] == gains_out(suggest(Plant.of(MODEL), Target()).gains)


@pytest.mark.parametrize(
    ("args", "field"), [(["--joints", "4"], "joints"), (["--bandwidth", "0"], "bandwidth_hz")]
)
def test_bad_input_is_refused_naming_the_field(served, capsys, args, field):
    assert main(["tune", "--url", URL, "--take-over", *args]) == 2
    assert field in capsys.readouterr().err
    assert _registers(served) == [PositionGains()] * 3


def test_revert_with_nothing_applied_is_refused(served, capsys):
    assert main(["tune", "--url", URL, "--revert"]) == 2
    assert "revert" in capsys.readouterr().err


@pytest.mark.slow
def test_tune_suggests_the_checks_choice_never_a_set_it_failed(served, capsys):
    rule = suggest(Plant.of(MODEL), Target()).gains
    FAILING.add(rule)  # the rule's own first candidate fails on the twin
    assert main(["tune", "--url", URL, "--joints", "2", "--json"]) == 0
    body = json.loads(capsys.readouterr().out)
    sid = str(served.app.state.controller.servo_ids[1])
    checked = body["checked"]
    first, chosen = checked["candidates"][0], checked["candidates"][checked["chosen"] - 1]
    assert first["gains"][sid] == gains_out(rule) and first["failed"] == ["rest_m"]
    assert checked["chosen"] > 1 and checked["met_goal"] and chosen["passes"]
    assert body["suggested"][sid] == chosen["gains"][sid] != gains_out(rule)


@pytest.mark.slow  # a tuning run on the twin, through the CLI
def test_tune_says_when_no_candidate_met_the_goal(served, capsys):
    FAIL_ALL["on"] = True
    assert main(["tune", "--url", URL, "--joints", "1"]) == 0  # the closest is still offered
    out = capsys.readouterr().out
    assert "no candidate met the goal" in out
    assert "the suggested gains do NOT meet the goal on the twin" in out
    assert "misses rest_m" in out
