"""The tuning API (issue 21): its refusals, apply and revert reaching the servos' registers
(the emulated bus: real packets, the emulator's control tables), the suggested gains being
the twin check's choice (a stand-in check: fast), an abort killing a real check's worker
process, and one whole run on the twin (identify, check, suggest, apply, revert)."""

from __future__ import annotations

import threading

import pytest

from app.tuning.gains import Plant, Target, predict, suggest
from app.tuning.identify import JointFit, JointModel
from app.tuning.procedure import TuningRun, gains_out
from app.tuning.twin_check import OfferJob, Tracking, Verdict, offer
from hardware.bus import PositionGains
from hardware.dynamixel.control_table import Reg
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}
REGISTERS = {
    "p": Reg.POSITION_P_GAIN,
    "i": Reg.POSITION_I_GAIN,
    "d": Reg.POSITION_D_GAIN,
    "ff1": Reg.FEEDFORWARD_1ST_GAIN,
    "ff2": Reg.FEEDFORWARD_2ND_GAIN,
}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("tune")) as c:
        yield c


def _registers(client, servo_id: int) -> dict[str, int]:
    table = client.app.state.backend.emulator.servo(servo_id).table
    return {name: table.get(reg) for name, reg in REGISTERS.items()}


def _done_run(client, joints=(1, 3)) -> TuningRun:
    """A finished run, as a run's thread leaves it, with gains suggested for two joints of
    different models (so each servo gets its own)."""
    manager = client.app.state.tuning
    ids = tuple(client.app.state.controller.servo_ids)
    run_id = "tune-test-" + "".join(map(str, joints))
    folder = manager.folder / run_id
    folder.mkdir(parents=True, exist_ok=True)
    gains = client.app.state.controller.gains
    run = TuningRun(run_id, joints, Target(), ids, gains, folder, state="done")
    for joint, wn in zip(joints, (55.0, 70.0), strict=False):
        plant = Plant.of(JointModel(1.0, wn, 0.75, 0.008))
        run.suggestions[ids[joint - 1]] = suggest(plant, Target(bandwidth_hz=15.0))
        run.predicted_now[ids[joint - 1]] = predict(plant, PositionGains()).as_dict()
    manager._runs[run.run_id] = run
    return run


def _fitted_run(client, joints=(1, 3), name="fitted") -> TuningRun:
    """A run as its thread leaves it after the fit (the step and chirp runs stood in for):
    two joints of different models."""
    manager = client.app.state.tuning
    ids = tuple(client.app.state.controller.servo_ids)
    run_id = f"tune-test-{name}"
    folder = manager.folder / run_id
    folder.mkdir(parents=True, exist_ok=True)
    gains = client.app.state.controller.gains
    run = TuningRun(run_id, joints, Target(), ids, gains, folder, state="fitting")
    for joint, wn in zip(joints, (55.0, 70.0), strict=False):
        run.fits.append(JointFit(joint, JointModel(1.0, wn, 0.75, 0.008), 1e-3, 0.1, 500))
    manager._runs[run.run_id] = run
    return run


CALM = Tracking((0.001, 0.001, 0.003), 0.6, 0.0)


class StandInCheck:
    """The twin check with `offer`'s own choice but stand-in verdicts: the first `fail`
    gain sets it is asked about fail (at_limit), the others pass. Records the jobs."""

    def __init__(self, fail: int) -> None:
        self.fail, self.asked, self.jobs = fail, [], []

    def verdict(self, gains, lead_s, seconds, limits, gravity) -> Verdict:
        self.asked.append(gains)
        failed = ("at_limit",) if len(self.asked) <= self.fail else ()
        return Verdict(CALM, CALM, lead_s, 1.0, (1e-4,) * 5, failed)

    def __call__(self, job: OfferJob):
        self.jobs.append(job)
        return offer(
            job.plants,
            job.target,
            job.lead_s,
            job.seconds,
            job.limits,
            job.gravity,
            job.current,
            check_fn=self.verdict,
        )


@pytest.mark.slow  # a tuning run on the twin, its check in a worker
def test_gains_that_miss_the_goal_are_applied_only_when_the_operator_confirms(client):
    """Issue 28 point 5: a set with met_goal false was applied like any other. Now the
    409 says what it misses, and ``confirm_missed`` applies it."""
    manager = client.app.state.tuning
    run = _fitted_run(client, name="missed")
    manager.twin_check = StandInCheck(fail=1000)  # nothing passes
    try:
        manager._suggest(run)
    finally:
        manager.twin_check = None
    run.state = "done"
    body = ok_json(client.get(f"/api/tuning/{run.run_id}"))
    assert not body["checked"]["met_goal"]
    take_lease(client)
    torque_on(client)
    before = client.app.state.controller.gains
    refused = client.post(f"/api/tuning/{run.run_id}/apply")
    assert refused.status_code == 409, refused.text
    detail = refused.json()["detail"]
    assert "miss the goal" in detail and "at_limit" in detail and "confirm_missed" in detail
    assert client.app.state.controller.gains == before  # nothing written
    assert ok_json(client.get(f"/api/tuning/{run.run_id}"))["state"] == "done"
    bad = client.post(f"/api/tuning/{run.run_id}/apply", json={"confirm_missed": "yes"})
    assert bad.status_code == 422
    applied = ok_json(client.post(f"/api/tuning/{run.run_id}/apply", json={"confirm_missed": True}))
    assert applied["gains"] == body["suggested"] | {
        sid: g for sid, g in applied["gains"].items() if sid not in body["suggested"]
    }
    ok_json(client.post("/api/tuning/revert"))


@pytest.mark.slow
def test_the_suggested_gains_are_the_twin_checks_choice_never_a_failed_set(client):
    manager = client.app.state.tuning
    run = _fitted_run(client)
    ids = run.servo_ids
    check = StandInCheck(fail=2)
    manager.twin_check = check
    try:
        manager._suggest(run)
    finally:
        manager.twin_check = None
    run.state = "done"
    body = ok_json(client.get(f"/api/tuning/{run.run_id}"))
    (job,) = check.jobs
    assert set(job.plants) == {1, 3} and job.current[1] == PositionGains()
    assert job.lead_s == client.app.state.settings.runs.feedforward_lead_s
    checked = body["checked"]
    assert checked["met_goal"] and checked["chosen"] == 3
    failed = checked["candidates"][:2]
    chosen = checked["candidates"][2]
    assert all(c["failed"] == ["at_limit"] and not c["passes"] for c in failed)
    assert chosen["passes"] and "first of 3 tried to pass" in checked["reason"]
    # suggested: the chosen candidate's gains for the tuned servos, none of a failed one
    assert body["suggested"] == {sid: chosen["gains"][sid] for sid in (str(ids[0]), str(ids[2]))}
    for c in failed:
        assert all(body["suggested"][sid] != c["gains"][sid] for sid in body["suggested"])
    assert chosen["gains"][str(ids[1])] == FACTORY  # not tuned: checked with its own gains
    # the prediction is of the suggested gains, for the chosen candidate's target
    plant = Plant.of(JointModel(1.0, 55.0, 0.75, 0.008))
    target = Target(**{**vars(Target()), **chosen["target"]})
    assert body["predicted"][str(ids[0])]["suggested"]["overshoot_pct"] == pytest.approx(
        predict(plant, suggest(plant, target).gains).overshoot_pct
    )
    # what apply writes is what the check chose
    take_lease(client)
    torque_on(client)
    applied = ok_json(client.post(f"/api/tuning/{run.run_id}/apply"))
    assert applied["gains"] == chosen["gains"]
    ok_json(client.post("/api/tuning/revert"))


@pytest.mark.slow  # a worker process started, then killed
def test_an_abort_while_checking_kills_the_checks_worker_and_suggests_nothing(client):
    from app.procedures.lifecycle import Stopped

    manager = client.app.state.tuning
    run = _fitted_run(client, joints=(1, 2, 3), name="abort")
    ended: list[BaseException] = []

    def thread() -> None:  # the run's thread from its fit on (the real check, in a worker)
        try:
            manager._suggest(run)
        except BaseException as exc:
            ended.append(exc)

    worker = threading.Thread(target=thread, daemon=True)
    worker.start()

    def processes() -> list | None:
        workers = manager._workers
        executor = workers._executors[0] if workers is not None else None
        found = list(getattr(executor, "_processes", None) or {})
        return [executor._processes[pid] for pid in found] if found else None

    started = wait_for(processes, "the twin check's worker process to start", 120.0)
    assert run.state == "checking"
    take_lease(client)
    body = ok_json(client.post(f"/api/tuning/{run.run_id}/abort"))
    assert body["state"] == "aborted"
    wait_for(lambda: not worker.is_alive(), "the run's thread to end after the abort", 60.0)
    wait_for(
        lambda: not any(p.is_alive() for p in started), "the check's worker to be killed", 60.0
    )
    (exc,) = ended
    assert isinstance(exc, Stopped) and "nothing is suggested" in str(exc), exc
    body = ok_json(client.get(f"/api/tuning/{run.run_id}"))
    assert body["state"] == "aborted" and body["suggested"] == {} and body["checked"] is None
    assert manager._workers is None


def test_status_shows_the_factory_gains_per_servo(client):
    status = ok_json(client.get("/api/status"))
    ids = status["joints"]["servo_ids"]
    assert status["gains"] == {str(i): FACTORY for i in ids}
    assert all(_registers(client, i) == FACTORY for i in ids)


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"joints": [4]}, "joints"),
        ({"joints": [1, 1]}, "joints"),
        ({"joints": []}, "joints"),
        ({"joints": ["1"]}, "joints"),
        ({"target": {"bandwidth_hz": -1.0}}, "bandwidth_hz"),
        ({"target": {"overshoot_pct": 90.0}}, "overshoot_pct"),
        ({"target": {"wobble": 1}}, "wobble"),
        ({"jonts": [1]}, "jonts"),
    ],
)
def test_bad_input_is_a_422_naming_the_field_and_nothing_moves(client, body, field):
    take_lease(client)
    torque_on(client)
    answer = client.post("/api/tuning/run", json=body)
    assert answer.status_code == 422, answer.text
    assert field in answer.text
    assert client.app.state.tuning.running() is False


def test_a_run_needs_the_lease_and_torque(client):
    client.headers.pop("X-Lease", None)
    answer = client.post("/api/tuning/run", json={"joints": [1]})
    assert answer.status_code == 409 and "lease" in answer.text.lower(), answer.text
    take_lease(client)
    ok_json(client.post("/api/torque", json={"enabled": False}))
    answer = client.post("/api/tuning/run", json={"joints": [1]})
    assert answer.status_code == 409 and "torque" in answer.text, answer.text
    assert client.app.state.tuning.running() is False


def test_unknown_runs_are_404_and_revert_without_apply_is_409(client):
    take_lease(client)
    assert client.get("/api/tuning/nope").status_code == 404
    assert client.post("/api/tuning/nope/apply").status_code == 404
    answer = client.post("/api/tuning/revert")
    assert answer.status_code == 409 and "revert" in answer.text, answer.text


def test_apply_writes_each_servos_registers_and_revert_restores_them(client):
    take_lease(client)
    torque_on(client)
    run = _done_run(client)
    ids = run.servo_ids
    body = ok_json(client.get(f"/api/tuning/{run.run_id}"))
    suggested = body["suggested"]
    assert set(suggested) == {str(ids[0]), str(ids[2])}
    assert suggested[str(ids[0])] != suggested[str(ids[2])]  # two models, two sets
    assert all(0 <= v <= 16383 for g in suggested.values() for v in g.values())

    applied = ok_json(client.post(f"/api/tuning/{run.run_id}/apply"))
    expected = {str(ids[0]): suggested[str(ids[0])], str(ids[1]): FACTORY}
    expected[str(ids[2])] = suggested[str(ids[2])]
    assert applied["gains"] == expected
    # the servos' own registers hold them, read from the emulator's control tables
    for sid in ids:
        assert _registers(client, sid) == expected[str(sid)], sid
    assert ok_json(client.get("/api/status"))["gains"] == expected
    again = client.post(f"/api/tuning/{run.run_id}/apply")
    assert again.status_code == 409 and "applied already" in again.text
    # a run is refused while tuned gains are in use: its model would not be a P loop's
    refused = client.post("/api/tuning/run", json={"joints": [1]})
    assert refused.status_code == 409 and "revert" in refused.text, refused.text

    reverted = ok_json(client.post("/api/tuning/revert"))
    assert reverted["gains"] == {str(i): FACTORY for i in ids}
    for sid in ids:
        assert _registers(client, sid) == FACTORY, sid
    assert ok_json(client.get("/api/status"))["gains"] == reverted["gains"]
    assert client.post("/api/tuning/revert").status_code == 409  # nothing more to revert


def test_a_run_not_done_cannot_be_applied(client):
    take_lease(client)
    run = _done_run(client, joints=(2,))
    run.state = "failed"
    answer = client.post(f"/api/tuning/{run.run_id}/apply")
    assert answer.status_code == 409 and "failed" in answer.text
    assert ok_json(client.get("/api/status"))["gains"]["1"] == FACTORY


# What this test looks at is the identification and the gains, not the loop's health: a
# simulator starved on a loaded 2-core machine may stall for seconds without faulting.
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}


@pytest.mark.slow  # a step and a chirp run on the twin, then the twin check's candidates
def test_a_run_on_the_twin_identifies_checks_suggests_applies_and_reverts(tmp_path):
    with make_client(tmp_path, backend="sim", safety=PATIENT) as twin:
        take_lease(twin)
        torque_on(twin)
        run_id = ok_json(twin.post("/api/tuning/run", json={"joints": [1, 2, 3]}))["run_id"]

        def ended() -> dict | None:
            body = ok_json(twin.get(f"/api/tuning/{run_id}"))
            return body if body["state"] in ("done", "failed") else None

        body = wait_for(
            ended,
            f"tuning run {run_id} to end",
            600.0,
            poll_s=0.5,
            seen=lambda: ok_json(twin.get(f"/api/tuning/{run_id}")),
        )
        assert body["state"] == "done", body
        ids = [str(i) for i in twin.app.state.controller.servo_ids]
        assert set(body["model"]) == set(body["suggested"]) == set(body["predicted"]) == set(ids)
        # checked on the twin (in a worker process) before it was suggested
        checked = body["checked"]
        chosen = checked["candidates"][checked["chosen"] - 1]
        assert body["suggested"] == chosen["gains"]
        assert chosen["passes"] == checked["met_goal"]
        if checked["met_goal"]:  # the first to pass: every one tried before it failed
            assert checked["chosen"] == len(checked["candidates"])
            assert not any(c["passes"] for c in checked["candidates"][:-1])
        else:
            assert checked["reason"].startswith("no candidate met the goal"), checked
        assert checked["lead_s"] == twin.app.state.settings.runs.feedforward_lead_s
        for sid in ids:
            model, predicted = body["model"][sid], body["predicted"][sid]
            assert 4.0 < model["bandwidth_hz"] < 15.0, model  # the factory loop's
            assert predicted["meets_target"], predicted  # the chosen candidate's target
            after, before = predicted["suggested"], predicted["current"]
            assert after["overshoot_pct"] <= chosen["target"]["overshoot_pct"]
            assert after["bandwidth_hz"] > before["bandwidth_hz"], predicted
        assert {"bode.png", "result.json"} <= set(body["files"])
        png = twin.get(f"/api/tuning/{run_id}/bode.png")
        assert png.status_code == 200 and png.content.startswith(b"\x89PNG")

        if not checked["met_goal"]:  # applied only when confirmed (issue 28)
            assert twin.post(f"/api/tuning/{run_id}/apply").status_code == 409
        ok_json(twin.post(f"/api/tuning/{run_id}/apply", json={"confirm_missed": True}))
        bus = twin.app.state.backend.bus  # the twin's servo models, in their process
        for sid, gains in zip(ids, bus.read_gains(), strict=True):
            assert gains_out(gains) == body["suggested"][sid], sid
        ok_json(twin.post("/api/tuning/revert"))
        assert bus.read_gains() == [PositionGains()] * 3


@pytest.mark.slow
def test_apply_writes_the_config_and_a_server_started_from_it_uses_the_gains(tmp_path):
    from app.config import load_settings
    from hardware.calibration import load, save

    config = tmp_path / "robot.toml"
    config.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    with make_client(tmp_path / "first", config_path=config) as first:
        take_lease(first)
        torque_on(first)
        run = _done_run(first)
        applied = ok_json(first.post(f"/api/tuning/{run.run_id}/apply"))
        assert applied["config_written"] == str(config)
        expected = applied["gains"]
    settings = load_settings(config)
    assert settings.server.http_port == 8123
    written = {str(j.servo_id): j.gains.model_dump() for j in settings.hardware.joints}
    assert written == expected
    # the calibration's own reader and writer leave the gains alone
    calibrations = load(config)
    save(config, calibrations)
    assert load_settings(config).hardware.joints == settings.hardware.joints

    joints = [j.model_dump() for j in settings.hardware.joints]
    with make_client(tmp_path / "second", hardware={"joints": joints}) as second:
        assert ok_json(second.get("/api/status"))["gains"] == expected
        for sid in run.servo_ids:
            assert _registers(second, sid) == expected[str(sid)], sid


def test_config_gains_out_of_the_registers_range_are_refused_naming_the_field():
    from app.config import ConfigError, load_settings

    joints = [{"servo_id": i, "gains": {"p": 20000}} for i in (1, 2, 3)]
    with pytest.raises(ConfigError, match=r"hardware\.joints\.0\.gains\.p: .* 16383"):
        load_settings(hardware={"joints": joints})


def test_gains_do_not_change_while_a_motion_runs(client):
    take_lease(client)
    torque_on(client)
    run = _done_run(client, joints=(1, 2, 3))
    ok_json(client.post("/api/move", json={"position_m": [0.0, 0.0, -0.26], "duration_s": 60}))
    wait_for(
        lambda: ok_json(client.get("/api/status"))["mode"] != "idle",
        "the move to start",
        seen=lambda: ok_json(client.get("/api/status"))["mode"],
    )
    answer = client.post(f"/api/tuning/{run.run_id}/apply")
    assert answer.status_code == 409 and "rests" in answer.text, answer.text
    ids = run.servo_ids
    assert all(_registers(client, sid) == FACTORY for sid in ids)
    assert ok_json(client.get("/api/status"))["gains"] == {str(i): FACTORY for i in ids}
    assert run.state == "done"  # still offered
    ok_json(client.post("/api/estop"))  # ends the move
    ok_json(client.post("/api/reset"))
