"""Contact in the loop on the twin (issue 33), simulated time, checked against MuJoCo's own
contact force: touch, the compliant press, force-limited motion (collision stop), the force
limit and a lost estimate."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands, contact_commands
from app.control.errors import MotionRefused
from app.control.sources import Setpoint
from hardware.sim.surfaces import TIP_RADIUS_M, Plate
from tests.support.twin_loop import TwinLoop

PLATE_Z_M = -0.26
SURFACE_Z_M = PLATE_Z_M + TIP_RADIUS_M  # the tip's centre at first contact
HOME_M = (0.0, 0.0, -0.24)


@pytest.fixture(scope="module")
def loop():
    twin = TwinLoop([Plate(point_m=(0.0, 0.0, PLATE_Z_M))])
    yield twin
    twin.close()


@pytest.fixture
def home(loop):
    if loop.state.faults:
        commands.reset_now(loop.state, loop.ctx, loop.controller.joint_bus)
        loop.step(5)
    loop.move_to(HOME_M)
    return loop


def _touch(loop, **values):
    settings = loop.settings.contact
    contact_commands.touch(loop.state, loop.ctx, settings, [0, 0, -1], **values)
    peak = [0.0]

    def watch(twin: TwinLoop) -> None:
        peak[0] = max(peak[0], -float(twin.bus.measure_contact().force_n[2]))

    loop.run_until(lambda t: t.state.source is None, 10.0, each=watch)
    return loop.snapshot.touch, peak[0]


def test_a_touch_finds_the_plate_and_stops_at_its_set_force(home) -> None:
    touch, true_peak = _touch(home, force_n=2.0)
    assert touch.outcome == "contact"
    assert touch.contact_point_m[2] == pytest.approx(SURFACE_Z_M, abs=2e-4)
    # the estimate at the end against MuJoCo's contact force, within 3 sigma
    truth = home.bus.measure_contact().force_n
    reading = home.snapshot.contact
    assert reading.valid
    assert abs(reading.force_n[2] - truth[2]) <= 3 * reading.std_n[2], (reading, truth)
    # the true force reached the set force and overshot it by less than 1 N
    assert 2.0 - 3 * reading.std_n[2] <= true_peak <= 3.0


def test_touches_repeat_to_a_tenth_of_a_millimetre(home) -> None:
    points = []
    for _ in range(4):
        home.move_to(HOME_M)
        touch, _ = _touch(home, force_n=2.0, retract_m=0.002)
        assert touch.outcome == "contact"
        assert -touch.force_n[2] >= 2.0  # the force it stood at, not after the retract
        # retracted to 2 mm short of the surface found: off the plate, MuJoCo says
        home.step(int(0.3 / home.period_s))  # the arm settles on the retract's end
        assert home.snapshot.point_measured_m[2] == pytest.approx(SURFACE_Z_M + 0.002, abs=3e-4)
        assert not home.bus.measure_contact().in_contact
        points.append(touch.contact_point_m[2])
    assert np.ptp(points) < 1e-4, points


def test_a_force_past_the_limit_faults_and_holds_where_measured(home) -> None:
    class Shove:
        """A source that presses (as a touch does) and drives the tip into the plate."""

        name, presses = "shove", True

        def __init__(self, start):
            self.point = np.asarray(start, dtype=float).copy()

        def next(self, dt_s):
            self.point[2] -= 0.02 * dt_s  # 20 mm/s down, past any force
            return Setpoint(point_m=self.point.copy())

    commands.begin_motion(home.state, Shove(home.state.start_m))
    peak = [0.0]

    def watch(twin: TwinLoop) -> None:
        peak[0] = max(peak[0], -float(twin.bus.measure_contact().force_n[2]))

    home.run_until(lambda t: bool(t.state.faults), 10.0, each=watch)
    fault = home.state.faults[0]
    assert fault.kind == "force limit", fault
    assert "15 N" in fault.reason and "mm" in fault.reason
    held = home.state.commanded_rad.copy()
    home.step(100)
    assert np.array_equal(home.state.commanded_rad, held)  # nothing more is written
    limit = home.settings.contact.force_limit_n
    assert peak[0] <= limit + 3.0, peak  # the overshoot past the limit is bounded


@pytest.mark.parametrize("speed_m_s", [0.02, 0.1])
def test_force_limited_motion_stops_a_collision(speed_m_s) -> None:
    loop = TwinLoop(
        [Plate(point_m=(0.0, 0.0, PLATE_Z_M))],
        contact={"collision_stop": True, "collision_force_n": 4.0},
    )
    try:
        loop.move_to(HOME_M)
        start = loop.state.start_m.copy()
        duration = 0.04 / speed_m_s  # 40 mm down, 19 mm of it below the surface
        commands.move(loop.state, loop.ctx, start + [0, 0, -0.04], duration, False)
        peak, touched = [0.0], [math.nan]

        def watch(twin: TwinLoop) -> None:
            force = -float(twin.bus.measure_contact().force_n[2])
            peak[0] = max(peak[0], force)
            if force > 0 and math.isnan(touched[0]):
                touched[0] = twin.now_s

        loop.run_until(lambda t: bool(t.state.faults), 10.0, each=watch)
        stopped = loop.now_s
        fault = loop.state.faults[0]
        assert fault.kind == "collision" and "N at (" in fault.reason, fault
        assert stopped - touched[0] < 0.5
        assert peak[0] < 4.0 + 10.0 * speed_m_s / 0.02  # bounded, more at speed
    finally:
        loop.close()


def test_a_lost_estimate_stops_a_touch(home) -> None:
    contact_commands.touch(home.state, home.ctx, home.settings.contact, [0, 0, -1])
    home.step(10)
    monitor = home.state.contact_monitor
    real = monitor.estimator

    class Broken:
        def estimate(self, joints, **_):
            got = real.estimate(joints)
            return type(got)(reason="current of joint 2 not read")

    monitor.estimator = Broken()
    try:
        home.step(2)
    finally:
        monitor.estimator = real
    fault = home.state.faults[0]
    assert fault.kind == "estimate" and "current of joint 2" in fault.reason
    assert home.snapshot.touch.outcome == "stopped"


def test_a_press_holds_its_set_force_against_the_twin(home) -> None:
    home.move_to((0.0, 0.0, -0.255))
    contact_commands.press(home.state, home.ctx, home.settings.contact, [0, 0, -1], 3.0)
    home.step(int(2.0 / home.period_s))  # settle
    forces = []
    home.step(int(1.0 / home.period_s), each=lambda t: forces.append(t.bus.measure_contact()))
    true = np.array([-f.force_n[2] for f in forces])
    assert home.state.source is not None and not home.state.faults
    assert np.sqrt(np.mean((true - 3.0) ** 2)) < 0.3, true
    commands.stop_source(home.state, home.state.source)


def test_the_example_config_s_plate_and_wall_are_where_a_touch_finds_them() -> None:
    """examples/contact.toml (docs/contact.md's "try it"): a touch down finds the plate's
    face plus the tip's radius, a touch along +x the wall's."""
    settings = load_settings(Path(__file__).parents[2] / "examples" / "contact.toml")
    loop = TwinLoop(settings.hardware.sim.build_plates())
    try:
        found = []
        for start, direction in (((0.0, 0.0, -0.24), [0, 0, -1]), ((0.07, 0.0, -0.22), [1, 0, 0])):
            loop.move_to(start)
            contact_commands.touch(loop.state, loop.ctx, loop.settings.contact, direction)
            loop.run_until(lambda t: t.state.source is None, 10.0)
            touch = loop.snapshot.touch
            assert touch.outcome == "contact", touch
            found.append(touch.contact_point_m)
        assert found[0][2] == pytest.approx(-0.26 + TIP_RADIUS_M, abs=3e-4)
        assert found[1][0] == pytest.approx(0.09 - TIP_RADIUS_M, abs=3e-4)
    finally:
        loop.close()


def test_a_touch_that_starts_pressing_is_refused_and_moves_nothing(home) -> None:
    """At rest on the plate, 1-2 N on it: a touch would tare that away and find nothing;
    refused, the command unchanged. Sideways (nothing along +x) it may start."""
    home.move_to((0.0, 0.0, SURFACE_Z_M - 0.002))  # 2 mm into the plate's spring
    assert home.snapshot.contact.force_n[2] < -1.0
    held = home.state.commanded_rad.copy()
    with pytest.raises(MotionRefused, match="already pushes"):
        contact_commands.touch(home.state, home.ctx, home.settings.contact, [0, 0, -1])
    home.step()
    assert np.array_equal(home.state.commanded_rad, held) and home.state.source is None
    contact_commands.touch(
        home.state, home.ctx, home.settings.contact, [1, 0, 0], max_travel_m=0.002
    )
    assert home.state.source is not None
    commands.stop_source(home.state, home.state.source)
