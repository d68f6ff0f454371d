"""GET /api/tuning: the tuning runs, newest first, as the dashboard's Tuning panel finds
the one to follow after a reload."""

from __future__ import annotations

from app.tuning.gains import Target
from app.tuning.procedure import TuningRun
from tests.support.app_client import make_client
from tests.support.wait import ok_json


def test_the_list_is_newest_first_with_state_joints_and_error(tmp_path) -> None:
    with make_client(tmp_path) as client:
        assert ok_json(client.get("/api/tuning")) == []
        manager = client.app.state.tuning
        ids = tuple(client.app.state.controller.servo_ids)
        gains = client.app.state.controller.gains
        for k, (joints, state, error) in enumerate(
            [((1,), "aborted", "aborted by the operator"), ((2, 3), "fitting", None)]
        ):
            run = TuningRun(f"tune-list-{k}", joints, Target(), ids, gains, tmp_path, state=state)
            run.error, run.created_unix_s = error, 1000.0 + k
            manager._runs[run.run_id] = run
        listed = ok_json(client.get("/api/tuning"))
    assert listed == [
        {
            "run_id": "tune-list-1",
            "state": "fitting",
            "joints": [2, 3],
            "met_goal": None,
            "error": None,
        },
        {
            "run_id": "tune-list-0",
            "state": "aborted",
            "joints": [1],
            "met_goal": None,
            "error": "aborted by the operator",
        },
    ]
