"""Who holds a robot node's link (app/robot/holder.py), on a clock the test moves: one
station at a time, take-over explicit, a silent holder lost, and only messages the holder
signed with its key (app/link/protocol.py ``sign``), each taken once."""

from __future__ import annotations

import pytest

from app.link.protocol import LinkRefused, sign
from app.robot.holder import LinkHolder


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Station:
    """A station's side: its key from the take, its sequence numbers."""

    def __init__(self, holder: LinkHolder, name: str, take_over: bool = False) -> None:
        self.holder, self.name = holder, name
        taken = holder.take(name, take_over)
        self.took_over_from, self.key = taken.took_over_from, taken.key
        self.seq = self.beats = 0

    def command(self, op: str = "torque", body: bytes = b'{"enabled":true}') -> None:
        self.seq += 1
        self.holder.require(
            self.name, op, self.seq, sign(self.key, self.name, op, self.seq, body), body
        )

    def beat(self) -> bool:
        self.beats += 1
        mac = sign(self.key, self.name, "heartbeat", self.beats)
        return self.holder.heartbeat(self.name, self.beats, mac)


def test_one_station_at_a_time_and_a_take_over_is_explicit() -> None:
    holder = LinkHolder(0.06, Clock())
    a = Station(holder, "a")
    assert a.took_over_from is None
    a.command()
    with pytest.raises(LinkRefused, match="station a holds") as refused:
        holder.take("b")
    assert refused.value.holder == "a"
    with pytest.raises(LinkRefused, match=r"take it first \(station a holds it\)"):
        holder.require("b", "torque", 1, "00", b"")
    b = Station(holder, "b", take_over=True)
    assert b.took_over_from == "a" and b.key != a.key
    with pytest.raises(LinkRefused):
        a.command()
    b.command()
    assert holder.view().takeovers == 1


def test_only_the_holders_signed_messages_count_each_once() -> None:
    holder = LinkHolder(0.06, Clock())
    a = Station(holder, "a")
    body = b'{"point_m":[0,0,-0.24]}'
    mac = sign(a.key, "a", "goal", 1, body)
    holder.require("a", "goal", 1, mac, body)
    with pytest.raises(LinkRefused, match="not signed"):  # the same message again: a replay
        holder.require("a", "goal", 1, mac, body)
    with pytest.raises(LinkRefused, match="not signed"):  # the body changed on the way
        holder.require("a", "goal", 2, sign(a.key, "a", "goal", 2, body), b'{"point_m":[1,0,0]}')
    with pytest.raises(LinkRefused, match="not signed"):  # signed for another op
        holder.require("a", "torque", 3, sign(a.key, "a", "goal", 3, body), body)
    with pytest.raises(LinkRefused, match="not signed"):  # a peer that knows only the id
        holder.require("a", "goal", 4, sign(b"guessed", "a", "goal", 4, body), body)
    # commands in flight together may arrive out of order: each is taken once
    for seq in (7, 5, 6):
        holder.require("a", "goal", seq, sign(a.key, "a", "goal", seq, body), body)


def test_a_silent_holder_loses_the_link_once_and_forged_beats_do_not_keep_it() -> None:
    clock = Clock()
    holder = LinkHolder(0.06, clock)
    a = Station(holder, "a")
    clock.t += 0.05
    assert a.beat()
    assert not holder.heartbeat("a", 99, "forged")  # a peer beating under a's id
    clock.t += 0.05  # 50 ms since a's last heartbeat: still alive
    assert holder.check_lost() is None
    clock.t += 0.02  # 70 ms: lost, said once
    assert holder.check_lost() == "a"
    assert holder.check_lost() is None
    view = holder.view()
    assert view.holder is None and view.lost and view.losses == 1
    with pytest.raises(LinkRefused) as refused:
        a.command()  # its authority went with its heartbeat
    assert refused.value.holder is None
    assert Station(holder, "b").took_over_from is None  # nobody held it: no take-over


def test_a_link_in_one_process_is_never_lost() -> None:
    clock = Clock()
    holder = LinkHolder(None, clock)
    station = Station(holder, "station")
    clock.t += 3600.0
    assert holder.check_lost() is None
    station.command()
