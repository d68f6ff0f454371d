"""The wrist in the control loop: four servos read and written each tick, phi commanded
directly through its calibration, its limits and speed enforced by the gate."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from app.config import ConfigError, load_settings
from app.control import commands
from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.control.sources import Setpoint
from app.control.wrist import WristBus
from hardware.bus import ServoBus
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.twin import TwinConfig
from tests.support.app_client import make_client
from tests.support.fake_bus import HOME_RAD, FakeBus
from tests.support.wait import ok_json, wait_for

# the wrist mounted reversed, its zero a quarter turn off the encoder's middle
WRIST = {
    "enabled": True,
    "servo_id": 4,
    "zero_offset_ticks": 1024,
    "direction": -1,
    "min_angle_rad": -1.0,
    "max_angle_rad": 2.0,
    "max_speed_rad_s": 2.0,
}
SETTINGS = load_settings(wrist=WRIST)


def test_without_a_wrist_section_the_bus_has_the_three_legs() -> None:
    plain = load_settings()
    assert not plain.wrist.enabled
    assert [j.servo_id for j in plain.bus_joints()] == [1, 2, 3]
    assert [j.servo_id for j in SETTINGS.bus_joints()] == [1, 2, 3, 4]
    calibration = SETTINGS.bus_joints()[3].calibration()
    assert (calibration.zero_offset_ticks, calibration.direction) == (1024, -1)
    assert calibration.to_ticks(0.5) == 1024 - round(0.5 / RAD_PER_TICK)


@pytest.mark.parametrize(
    ("wrist", "field"),
    [
        ({"enabled": True, "servo_id": 2}, "wrist.servo_id 2 is a leg's servo id"),
        ({"min_angle_rad": 1.0, "max_angle_rad": 0.5}, "min_angle_rad must be below"),
        ({"min_angle_rad": -3.2, "max_angle_rad": 3.2}, "less than a turn"),
        ({"max_speed_rad_s": 0}, "wrist.max_speed_rad_s"),
        ({"direction": 2}, "wrist.direction"),
    ],
)
def test_a_bad_wrist_section_is_refused_naming_the_field(wrist: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        load_settings(wrist=wrist)


def test_the_gate_checks_phi_against_the_wrist_s_limits() -> None:
    gate = Controller(SETTINGS, SimBus(SimBusConfig(realtime=False)), "sim").gate
    assert gate.check_phi(2.0) == 2.0 and gate.check_phi(-1.0) == -1.0
    with pytest.raises(GoalRejected, match=r"phi_rad: 114.6 deg outside the wrist's limits"):
        gate.check_phi(2.0 + 1e-9 + 0.0)  # just past the limit: 2.0 rad = 114.59 deg
    with pytest.raises(GoalRejected, match="phi_rad: must be finite"):
        gate.check_phi(math.nan)
    with pytest.raises(GoalRejected, match="phi_rad: expected a number"):
        gate.check_phi("left")
    assert gate.wrist_max_step_rad == pytest.approx(2.0 / 200)  # speed * period
    plain = Controller(load_settings(), SimBus(SimBusConfig(realtime=False)), "sim").gate
    assert plain.check_phi(0.0) == 0.0
    with pytest.raises(GoalRejected, match="no wrist axis is configured"):
        plain.check_phi(0.1)


class RecordingBus:
    """A ServoBus wrapper that records every goal written (four values per write)."""

    def __init__(self, bus: ServoBus) -> None:
        self.bus = bus
        self.goals: list[list[float]] = []

    def __getattr__(self, name: str):
        return getattr(self.bus, name)

    def write_goal(self, positions_rad) -> None:
        self.goals.append([float(v) for v in positions_rad])
        self.bus.write_goal(positions_rad)


@pytest.fixture
def twin_bus() -> Iterator[SimBus]:
    joints = tuple(j.calibration() for j in SETTINGS.bus_joints())
    bus = SimBus(SimBusConfig(twin=TwinConfig(joints=joints), torque_on_at_start=False))
    bus.connect()
    yield bus
    bus.disconnect()


@pytest.fixture
def controller(twin_bus: SimBus) -> Iterator[tuple[Controller, RecordingBus]]:
    recording = RecordingBus(twin_bus)
    control = Controller(SETTINGS, recording, "sim")  # type: ignore[arg-type]
    control.start()
    try:
        yield control, recording
    finally:
        control.stop()


def phi_seen(control: Controller) -> dict:
    snap = control.snapshot()
    keys = ("phi_measured_rad", "phi_commanded_rad", "phi_goal_rad", "mode", "warning")
    return {k: getattr(snap, k) for k in keys} | {"faults": [f.reason for f in snap.faults]}


@pytest.mark.slow
def test_the_loop_turns_the_wrist_to_phi_at_its_speed_and_holds_it(controller) -> None:
    control, recording = controller
    assert isinstance(control.servos, WristBus) and control.bus is recording
    wait_for(lambda: np.isfinite(control.snapshot().phi_measured_rad), "the wrist read")
    with pytest.raises(MotionRefused, match="torque is off"):
        control.turn_wrist(1.5).result(timeout=10)
    control.set_torque(True).result(timeout=10)
    start = len(recording.goals)
    assert control.turn_wrist(1.5).result(timeout=10) == 1.5
    wait_for(
        lambda: abs(control.snapshot().phi_measured_rad - 1.5) <= 3 * RAD_PER_TICK,
        "the wrist at 1.5 rad",
        seen=lambda: phi_seen(control),
    )
    goals = np.array(recording.goals[start:])
    assert goals.shape[1] == 4  # every write carries the three legs and the wrist
    steps = np.abs(np.diff(goals[:, 3]))
    assert steps.max() <= 2.0 / 200 + 1e-12  # the wrist's speed limit, per tick
    assert goals[-1, 3] == pytest.approx(1.5)
    assert np.abs(goals[:, :3] - goals[0, :3]).max() == 0.0  # the legs held their command
    snap = control.snapshot()
    assert snap.phi_commanded_rad == snap.phi_goal_rad == 1.5
    # and it holds there: the goal stays, the twin's wrist stays within a few ticks
    tick = snap.tick
    wait_for(lambda: control.snapshot().tick > tick + 40, "40 more ticks")
    assert control.snapshot().phi_measured_rad == pytest.approx(1.5, abs=3 * RAD_PER_TICK)
    assert not control.snapshot().faults


def test_a_setpoint_beyond_the_wrist_s_limits_is_never_written(controller) -> None:
    control, recording = controller
    control.set_torque(True).result(timeout=10)
    held = control.snapshot().phi_commanded_rad

    class TooFar:
        name = "test"

        def next(self, dt_s: float) -> Setpoint:
            return Setpoint(point_m=np.array([0.0, 0.0, -0.24]), phi_rad=2.5)

    start = len(recording.goals)
    control.submit(lambda: setattr(control.state, "source", TooFar())).result(timeout=10)
    wait_for(
        lambda: (control.snapshot().warning or "").startswith("holding: phi_rad"),
        "the gate's refusal of phi 2.5 rad",
        seen=lambda: phi_seen(control),
    )
    assert "outside the wrist's limits" in control.snapshot().warning
    assert recording.goals[start:] == []  # not the legs' part either
    assert control.snapshot().phi_commanded_rad == held
    with pytest.raises(GoalRejected, match="outside the wrist's limits"):
        control.turn_wrist(-1.2)


@pytest.mark.slow
def test_the_server_with_a_wrist_drives_four_servos_on_the_twin(tmp_path: Path) -> None:
    with make_client(tmp_path, backend="sim", wrist=WRIST) as client:
        control = client.app.state.controller
        assert client.app.state.node.controller.bus.ids == (1, 2, 3, 4)
        control.set_torque(True).result(timeout=10)
        control.turn_wrist(-0.5).result(timeout=10)
        wait_for(
            lambda: abs(control.snapshot().phi_measured_rad + 0.5) <= 3 * RAD_PER_TICK,
            "the wrist at -0.5 rad on the twin in its process",
            seen=lambda: phi_seen(control),
        )
        assert ok_json(client.get("/api/status"))["mode"] == "idle"


def wrist_fake() -> tuple[Controller, FakeBus]:
    """An unstarted controller over a fake four-servo bus, the wrist at 0.3 rad."""
    fake = FakeBus(errors=((), (), (), ()))
    fake.position = np.array([*HOME_RAD, 0.3])
    control = Controller(SETTINGS, fake, "fake")  # type: ignore[arg-type]
    control.step()
    return control, fake


def goals(fake: FakeBus) -> list[tuple[float, ...]]:
    return [call[1] for call in fake.calls if call[0] == "write_goal"]


def test_torque_on_holds_the_wrist_where_it_is_and_e_stop_keeps_its_command() -> None:
    control, fake = wrist_fake()
    assert control.snapshot().phi_measured_rad == 0.3
    assert math.isnan(control.snapshot().phi_commanded_rad)
    commands.torque_to(control.state, control.ctx, control.servos, True)
    assert goals(fake) == [(*HOME_RAD, 0.3)]  # one write: three legs and the wrist, as read
    control.state.phi_goal_rad = 0.5
    for _ in range(5):
        control.step()
    phi = control.snapshot().phi_commanded_rad
    assert phi == pytest.approx(0.3 + 5 * 2.0 / 200)  # five ticks at the wrist's speed
    fake.position[3] = 0.2  # pushed back: e-stop holds the command, not the measurement
    control.step()
    commands.estop_now(control.state, control.ctx, control.servos)
    assert goals(fake)[-1][3] == pytest.approx(phi + 2.0 / 200)
    assert control.state.phi_goal_rad is None  # stopped: the wrist does not turn on
    # torque off forgets the wrist's command: torque on again holds it where it is read
    commands.reset_now(control.state, control.ctx, control.servos)
    commands.torque_to(control.state, control.ctx, control.servos, False)
    fake.position[3] = -0.4
    control.step()
    commands.torque_to(control.state, control.ctx, control.servos, True)
    assert goals(fake)[-1][3] == -0.4


def test_a_hardware_error_of_the_wrist_faults_the_loop_and_reset_reboots_it() -> None:
    control, fake = wrist_fake()
    fake.errors = ((), (), (), ("Overload Error",))
    control.step()
    (fault,) = control.snapshot().faults
    assert fault.servo_id == 4 and "Overload" in fault.reason
    assert control.state.joints is not None and not control.state.joints.faulted
    control.state.torque = True
    outcome = control._reset_now()
    assert outcome == {"rebooted": [4]} and ("reboot", (4,)) in fake.calls
    assert not control.state.torque  # a reboot leaves torque off


def test_without_a_wrist_the_loop_writes_three_goals_and_refuses_a_phi() -> None:
    fake = FakeBus()
    control = Controller(load_settings(), fake, "fake")  # type: ignore[arg-type]
    control.step()
    assert control.wrist is None and control.servos is fake
    commands.torque_to(control.state, control.ctx, control.servos, True)
    assert goals(fake) == [HOME_RAD]
    assert math.isnan(control.snapshot().phi_measured_rad)
    with pytest.raises(GoalRejected, match="no wrist axis is configured"):
        control.turn_wrist(0.2)


def test_a_wrist_that_does_not_follow_trips_the_following_error_as_joint_4() -> None:
    now = [0.0]
    fake = FakeBus(errors=((), (), (), ()))
    fake.position = np.array([*HOME_RAD, 0.0])
    control = Controller(SETTINGS, fake, "fake", clock=lambda: now[0])  # type: ignore[arg-type]
    control.step()
    commands.torque_to(control.state, control.ctx, control.servos, True)
    fake.stuck = True  # nothing moves: the legs hold still, the wrist is left behind
    control.state.phi_goal_rad = 1.0
    while not control.snapshot().faults:
        assert now[0] < 5.0, phi_seen(control)
        now[0] += 0.005
        control.step()
    (fault,) = control.snapshot().faults
    assert fault.source == "following" and fault.reason.startswith("joint 4 lags")
    # 20 deg (the limit) reached at 0.35 rad / (2 rad/s), then held 0.5 s
    assert now[0] == pytest.approx(0.35 / 2.0 + 0.5, abs=0.02)
