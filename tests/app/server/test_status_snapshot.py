"""GET /api/status is one tick's view: built from the published Snapshot (and the station's
e-stop receipts and pose status), never from live controller attributes."""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import replace

import numpy as np

from app.control.state import RobotInfo, Snapshot
from app.control.timing import TimingStats
from app.robot.estop import EstopReceipt, EstopReceipts
from app.server.api import serialize
from app.server.api.responses import JointsStatus, StatusOut
from hardware.bus import READINGS, BusStats, PositionGains


def _snapshot() -> Snapshot:
    window = TimingStats(200.0, 199.5, 5.01, 0.02, 0.3, 1.2, 4, 2000, 6.0)
    total = TimingStats(200.0, 199.9, 5.0, 0.02, 0.25, 3.4, 9, 12345, 8.0)
    return Snapshot(
        tick=12345,
        info=RobotInfo("emulated", "Protocol 2.0 emulator on /dev/pts/9", (11, 12, 13)),
        gains=(PositionGains(), PositionGains(p=1010, i=37, d=120), PositionGains()),
        loop_total=total,
        loop_window=window,
        bus_stats=BusStats(transactions=900, failed_tries=3, retries=2, failures=1),
        missed_reads=1,
    )


def test_the_status_of_a_snapshot_names_its_robot_gains_timing_and_bus():
    out = serialize.status(_snapshot())
    StatusOut.model_validate(out)
    assert (out["backend"], out["backend_description"]) == (
        "emulated",
        "Protocol 2.0 emulator on /dev/pts/9",
    )
    assert out["joints"]["servo_ids"] == [11, 12, 13]
    assert set(out["gains"]) == {"11", "12", "13"}
    assert out["gains"]["12"]["p"] == 1010 and out["gains"]["11"]["p"] == PositionGains().p
    loop = out["loop"]
    assert (loop["ticks"], loop["overruns"]) == (12345, 9)  # since start
    assert (loop["measured_hz"], loop["worst_ms"]) == (199.5, 1.2)  # the last 10 s
    assert out["bus"] == {
        "missed_reads": 1,
        "transactions": 900,
        "failed_tries": 3,
        "retries": 2,
        "failures": 1,
        "discarded": 0,
    }
    assert out["pose"] is None and out["estop_received_unix_s"] is None


def test_the_station_adds_its_estop_receipt_and_pose_status():
    receipt = EstopReceipt(1000.5, {"listener": 1000.5, "route": 1000.6})
    pose = {"source": "mavlink", "fresh": True}
    out = serialize.status(_snapshot(), receipt, pose)
    assert out["estop_received_unix_s"] == 1000.5
    assert out["estop_arrivals_unix_s"] == {"listener": 1000.5, "route": 1000.6}
    assert out["pose"] == pose


class _Loop:
    """Counts the e-stops asked of it."""

    running = True

    def __init__(self) -> None:
        self.stops = 0

    def estop(self) -> Future:
        self.stops += 1
        future: Future = Future()
        future.set_result("estopped")
        return future


def test_one_press_by_three_paths_is_one_receipt_and_three_stops():
    loop = _Loop()
    receipts = EstopReceipts(loop)
    assert receipts.latest() == EstopReceipt()
    for via in ("listener", "middleware", "route", "route"):
        assert receipts.press(via, "p1").result() == "estopped"
    first = receipts.latest()
    assert loop.stops == 4  # every request stops, whatever the bookkeeping says
    assert list(first.arrivals_unix_s) == ["listener", "middleware", "route"]
    assert first.received_unix_s == first.arrivals_unix_s["listener"]
    assert first.arrivals_unix_s["listener"] <= first.arrivals_unix_s["route"]
    receipts.press("route", "p2")
    second = receipts.latest()
    assert list(second.arrivals_unix_s) == ["route"]
    assert second.received_unix_s >= first.received_unix_s
    assert first.arrivals_unix_s.keys() == {"listener", "middleware", "route"}  # not changed


def test_presses_without_an_id_are_presses_of_their_own():
    receipts = EstopReceipts(_Loop())
    receipts.press("listener")
    first = receipts.latest()
    receipts.press("route")
    assert list(receipts.latest().arrivals_unix_s) == ["route"]
    assert receipts.latest() is not first


def test_every_servo_reading_reaches_the_status_and_its_schema():
    """A reading declared once (hardware/bus.py READINGS) is in the snapshot, in
    /api/status's joints, and in the response model with its unit: no layer lists them."""
    readings = {name: np.array([0.5, -0.25, np.nan]) for name in READINGS}
    out = serialize.status(replace(_snapshot(), readings=readings))
    StatusOut.model_validate(out)
    schema = JointsStatus.model_json_schema()["properties"]
    for name, (unit, _) in READINGS.items():
        assert out["joints"][name] == [0.5, -0.25, None]
        assert schema[name]["description"].endswith(f"[{unit}]")
    assert "pwm" in READINGS  # the last one added: Present PWM
