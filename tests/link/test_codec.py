"""The link's JSON codec (app/link/codec.py): a record round-trips exactly, NaN and the
infinities included, and a message of the wrong shape is refused naming the field."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.control.state import ContactReading, Fault, RobotInfo, Snapshot, TouchResult, unread
from app.control.timing import TimingStats
from app.link.codec import CodecError, decode, encode
from hardware.bus import BusStats, PositionGains

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
vectors = st.lists(floats, min_size=3, max_size=3).map(np.array)


def same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and np.array_equal(a, b, equal_nan=True)
    if isinstance(a, float):
        return isinstance(b, float) and (a == b or (math.isnan(a) and math.isnan(b)))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(
            same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
        )
    return a == b


@st.composite
def snapshots(draw) -> Snapshot:
    readings = {name: draw(vectors) for name in unread()}
    return Snapshot(
        time_s=draw(floats),
        tick=draw(st.integers(0, 2**40)),
        mode=draw(st.sampled_from(["idle", "jog", "test", "hold-world"])),
        torque=draw(st.booleans()),
        faults=tuple(
            Fault(draw(st.text(max_size=8)), draw(st.text(max_size=40)), servo_id=sid)
            for sid in draw(st.lists(st.none() | st.integers(0, 252), max_size=3))
        ),
        warning=draw(st.none() | st.text(max_size=30)),
        joints_measured_rad=draw(vectors),
        point_measured_m=draw(vectors),
        goal_m=draw(vectors),
        readings=readings,
        moving=tuple(draw(st.lists(st.booleans(), min_size=3, max_size=3))),
        hardware_errors=(("overload",), (), ("electrical_shock", "motor_encoder")),
        torque_enabled=(True, None, False),
        phi_rad=draw(floats),
        extra=draw(st.none() | st.just({"goal_world_m": [1.0, 2.0, 3.0], "outside": False})),
        info=RobotInfo("sim", "the twin", (11, 12, 13)),
        gains=(PositionGains(), PositionGains(p=1000, i=5), PositionGains()),
        loop_total=TimingStats(200.0, 199.5, 5.0, 0.01, 0.2, 3.0, 1, 1000, 7.0),
        bus_stats=BusStats(transactions=5, discarded=1),
        source_id=draw(st.none() | st.text("abcdef0123", min_size=1, max_size=12)),
        source_t_s=draw(st.none() | st.floats(0, 1e6)),
        source_line=draw(st.none() | st.integers(1, 10**6)),
        contact=ContactReading(
            draw(vectors),
            draw(vectors),
            draw(st.booleans()),
            draw(st.none() | st.text(max_size=20)),
        ),
        touch=draw(
            st.none()
            | st.builds(
                TouchResult,
                st.sampled_from(["touching", "contact", "no contact", "stopped"]),
                vectors,
                vectors,
                floats,
                floats,
                vectors,
                st.none() | st.text("abcdef0123", min_size=1, max_size=12),
                vectors,
            )
        ),
    )


def _not_standard(token: str) -> None:
    raise AssertionError(f"{token} is not standard JSON")


@given(snapshots())
def test_a_snapshot_round_trips_field_by_field(snap: Snapshot) -> None:
    payload = encode(snap)
    json.loads(payload, parse_constant=_not_standard)  # standard JSON: no NaN, Infinity
    back = decode(Snapshot, payload)
    for field in dataclasses.fields(Snapshot):
        assert same(getattr(snap, field.name), getattr(back, field.name)), field.name


def test_a_missing_field_takes_its_default_and_a_wrong_one_is_named() -> None:
    assert decode(Snapshot, b'{"tick": 3}').tick == 3
    with pytest.raises(CodecError, match=r"Snapshot.goal_m: expected a list of numbers"):
        decode(Snapshot, b'{"goal_m": "here"}')
    with pytest.raises(CodecError, match=r"Snapshot.joints_measured_rad: expected a number"):
        decode(Snapshot, b'{"joints_measured_rad": [1, "x", 3]}')
    with pytest.raises(CodecError, match="TimingStats.target_hz: missing"):
        decode(Snapshot, b'{"loop_total": {}}')
    with pytest.raises(CodecError, match="not JSON"):
        decode(Snapshot, b"{")
