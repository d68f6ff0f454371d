"""The motion owner (app/control/owner.py): while a claim holds the robot only its thread
may move it, and an ended (aborted) claim's thread never again."""

from __future__ import annotations

import threading

import pytest

from app.control.errors import MotionRefused
from app.control.owner import MotionOwner


def _in_thread(function) -> BaseException | None:
    """What ``function()`` raised in a thread of its own (None: nothing)."""
    raised: list[BaseException] = []

    def body() -> None:
        try:
            function()
        except BaseException as exc:  # noqa: BLE001 - handed back to the test
            raised.append(exc)

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    return raised[0] if raised else None


def test_anyone_moves_with_no_claim_and_only_the_claims_thread_with_one():
    owner = MotionOwner()
    owner.check()
    assert owner.busy() is None
    claim = owner.claim("tuning run t1", "POST /api/tuning/t1/abort")
    with pytest.raises(MotionRefused, match=r"tuning run t1 .*POST /api/tuning/t1/abort"):
        owner.check()
    assert _in_thread(lambda: (owner.bind(claim), owner.check())) is None
    assert "tuning run t1" in (owner.busy() or "")
    with pytest.raises(MotionRefused, match="tuning run t1"):
        owner.claim("calibration run c1", "POST /api/calibration/c1/abort")


def test_an_ended_claims_thread_is_refused_and_release_runs_then_under_the_lock():
    owner = MotionOwner()
    claim = owner.claim("calibration run c1", "POST /api/calibration/c1/abort")
    bound, go = threading.Event(), threading.Event()
    seen: list[BaseException | None] = []

    def procedure() -> None:
        owner.bind(claim)
        bound.set()
        go.wait()
        try:
            owner.check()
            seen.append(None)
        except MotionRefused as exc:
            seen.append(exc)

    thread = threading.Thread(target=procedure)
    thread.start()
    bound.wait()
    calls: list[str | None] = []
    owner.release(claim, then=lambda: calls.append(owner.busy()))
    assert calls == [None]  # then() ran, with the claim already gone
    go.set()
    thread.join()
    assert isinstance(seen[0], MotionRefused) and "aborted" in str(seen[0])
    owner.check()  # everyone else moves again
    owner.release(claim)  # a second release does nothing


def test_a_mover_without_a_claim_answers_busy_after_the_claim_and_stops_new_claims():
    owner = MotionOwner()
    running: dict[str, str | None] = {"why": "run r1 is in progress; abort it first"}
    owner.add_mover(lambda: running["why"])
    assert owner.busy() == "run r1 is in progress; abort it first"
    with pytest.raises(MotionRefused, match="^run r1 is in progress; abort it first$"):
        owner.claim("calibration run c1", "POST /api/calibration/c1/abort")
    owner.check()  # a mover that holds no claim refuses no motion command itself
    running["why"] = None
    claim = owner.claim("calibration run c1", "POST /api/calibration/c1/abort")
    running["why"] = "run r2 is in progress; abort it first"  # started by the claim's thread
    assert owner.busy() == (
        "calibration run c1 is in progress; POST /api/calibration/c1/abort to stop it"
    )
    owner.release(claim)
    assert owner.busy() == "run r2 is in progress; abort it first"
