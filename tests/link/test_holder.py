"""Who holds a robot node's link (app/robot/holder.py), on a clock the test moves."""

from __future__ import annotations

import pytest

from app.link.protocol import LinkRefused
from app.robot.holder import LinkHolder


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_one_station_at_a_time_and_a_take_over_is_explicit() -> None:
    holder = LinkHolder(0.06, Clock())
    assert holder.take("a") is None
    holder.require("a")
    with pytest.raises(LinkRefused, match="station a holds") as refused:
        holder.take("b")
    assert refused.value.holder == "a"
    with pytest.raises(LinkRefused, match=r"take it first \(station a holds it\)"):
        holder.require("b")
    assert holder.take("b", take_over=True) == "a"
    with pytest.raises(LinkRefused):
        holder.require("a")
    assert holder.view().takeovers == 1


def test_a_silent_holder_loses_the_link_once_and_the_next_station_needs_no_take_over():
    clock = Clock()
    holder = LinkHolder(0.06, clock)
    holder.take("a")
    clock.t += 0.05
    holder.heartbeat("a")
    clock.t += 0.05  # 50 ms since the last heartbeat: still alive
    assert holder.check_lost() is None
    clock.t += 0.02  # 70 ms: lost, said once
    assert holder.check_lost() == "a"
    assert holder.check_lost() is None
    view = holder.view()
    assert view.holder is None and view.lost and view.losses == 1
    with pytest.raises(LinkRefused) as refused:
        holder.require("a")  # its authority is gone with its heartbeat
    assert refused.value.holder is None
    assert holder.take("b") is None  # no take-over: nobody holds it


def test_a_link_in_one_process_is_never_lost() -> None:
    clock = Clock()
    holder = LinkHolder(None, clock)
    holder.take("station")
    clock.t += 3600.0
    assert holder.check_lost() is None
    holder.require("station")
