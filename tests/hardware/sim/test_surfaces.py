"""Plates in the twin: the tip touches them, and the twin's contact force is MuJoCo's own,
checked against the plate's force law, the constraint forces on the plate's body, the
friction cone and the config that builds them. Simulated time throughout (the process
bus excepted: it follows the wall clock, so its test waits for states, never for time)."""

from __future__ import annotations

from collections.abc import Iterator

import mujoco
import numpy as np
import pytest

from app.config import ConfigError, load_settings
from app.server.backends import _twin
from hardware.sim import ProcessSimBus, SimBus, SimBusConfig
from hardware.sim.mjcf import TIP_GEOM, plate_name
from hardware.sim.surfaces import TIP_RADIUS_M, Plate, TwinContact
from hardware.sim.twin import DeltaTwin, TwinConfig, hold_command
from kinematics import THESIS_DELTA
from tests.support.wait import wait_for

UNDER_HOME = Plate(point_m=(0.0, 0.0, -0.26), stiffness_n_m=1.0e4, damping_n_s_m=20.0)


def command_tip(twin: DeltaTwin, tip_m) -> None:
    """Every servo holds the joints whose FK puts the tool tip at `tip_m` (wrist at 0)."""
    platform = np.asarray(tip_m, dtype=float) - np.array(twin.config.tip_offset_m)
    joints, ok = twin.mechanism.ik(platform)
    assert bool(ok)
    if twin.n_servos == 4:
        joints = np.append(joints, 0.0)
    twin.set_commands([hold_command(float(s)) for s in twin.shafts_of_joints(joints)])


def penetration_m(twin: DeltaTwin, plate: Plate) -> float:
    """The tip sphere's depth in the plate from geometry alone (its centre's height above
    the face, where the last step's contacts were computed), not MuJoCo's contact."""
    centre = twin.data.geom_xpos[twin.model.geom(TIP_GEOM).id]
    return TIP_RADIUS_M - float(plate.height_m(centre))


def plate_body_force(twin: DeltaTwin, index: int = 0) -> np.ndarray:
    """The constraint force on the plate's body (cfrc_ext after mj_rnePostConstraint),
    base frame [N]: a second reading of the same contact, by another MuJoCo route."""
    mujoco.mj_rnePostConstraint(twin.model, twin.data)
    return twin.data.cfrc_ext[twin.model.body(plate_name(index)).id, 3:].copy()


# -- the plate ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("normal", {"normal": (0.0, 0.0, 0.0)}),
        ("point_m", {"point_m": (0.0, float("nan"), 0.0)}),
        ("half_size_m", {"half_size_m": (0.1, 0.0)}),
        ("thickness_m", {"thickness_m": 0.0}),
        ("stiffness_n_m", {"stiffness_n_m": -1.0}),
        ("damping_n_s_m", {"damping_n_s_m": float("inf")}),
        ("friction", {"friction": -0.1}),
    ],
)
def test_a_bad_plate_is_refused_naming_the_field(field, kwargs) -> None:
    values = {"point_m": (0.0, 0.0, -0.26)} | kwargs
    with pytest.raises(ValueError, match=field):
        Plate(**values)


@pytest.mark.parametrize("normal", [(0, 0, 1), (0, 0, -2), (1, 0, 0), (0.3, -0.4, 0.8)])
def test_the_plate_frame_is_a_rotation_whose_z_is_the_unit_normal(normal) -> None:
    plate = Plate(point_m=(0.1, 0.0, -0.3), normal=normal)
    frame = plate.frame()
    unit = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)
    np.testing.assert_allclose(frame[:, 2], unit, atol=1e-12)
    np.testing.assert_allclose(plate.normal, unit, atol=1e-12)
    # the MJCF box's top face passes through the point, normal outwards
    twin = DeltaTwin(TwinConfig(plates=(plate,)))
    model, data = twin.model, twin.data
    geom = model.geom(plate_name(0)).id
    top = data.geom_xpos[geom] + data.geom_xmat[geom].reshape(3, 3)[:, 2] * model.geom_size[geom, 2]
    assert plate.height_m(top) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(data.geom_xmat[geom].reshape(3, 3)[:, 2], unit, atol=1e-9)


# -- contact -----------------------------------------------------------------------------
def test_no_contact_and_no_force_above_the_plate() -> None:
    twin = DeltaTwin(TwinConfig(plates=(UNDER_HOME,)))
    command_tip(twin, (0.0, 0.0, -0.255))  # 5 mm above the face
    twin.advance(0.5)
    contact = twin.contact()
    assert not contact.in_contact and contact.point_m is None
    assert np.array_equal(contact.force_n, np.zeros(3))
    assert penetration_m(twin, UNDER_HOME) < -0.002  # it is really above (sagging a little)
    assert np.array_equal(plate_body_force(twin), np.zeros(3))


@pytest.mark.parametrize(
    ("stiffness", "wrist", "tip_offset"),
    [
        (1.0e4, False, (0.0, 0.0, 0.0)),
        (1.0e5, False, (0.0, 0.0, 0.0)),
        (3.0e3, True, (0.0, 0.01, -0.05)),
    ],
)
def test_pressing_follows_the_plate_stiffness_and_mujoco_agrees(
    stiffness, wrist, tip_offset
) -> None:
    # the tip sits on the platform, or on the wrist's body with one: other inverse masses,
    # the same force law
    plate = Plate(point_m=(0.0, 0.0, -0.26 + tip_offset[2]), stiffness_n_m=stiffness)
    joints = TwinConfig().joints
    if wrist:
        joints = (*joints, type(joints[0])(servo_id=4))
    twin = DeltaTwin(TwinConfig(plates=(plate,), joints=joints, tip_offset_m=tip_offset))
    command_tip(twin, (0.0, 0.0, plate.point_m[2] - 0.004))  # 4 mm into the plate
    twin.advance(1.5)
    # at rest, but for the soft friction's slow creep (MuJoCo's friction constraint slips
    # a little under any tangential load)
    assert np.abs(twin.joint_velocity_rad_s).max() < 1e-3
    contact = twin.contact()
    assert contact.in_contact
    depth = penetration_m(twin, plate)
    assert 1e-5 < depth < plate.thickness_m / 2
    # the force law: the tip pushes the plate down with stiffness * penetration
    assert contact.force_n[2] < -0.5
    assert -contact.force_n[2] == pytest.approx(stiffness * depth, rel=0.02)
    assert np.abs(contact.force_n[:2]).max() < 0.01 * abs(contact.force_n[2])
    # MuJoCo's constraint force on the plate's body says the same
    np.testing.assert_allclose(plate_body_force(twin), contact.force_n, rtol=1e-6, atol=1e-9)
    # and the solver's normal force row (elliptic cone: the first row of the contact)
    (i,) = range(twin.data.ncon)
    assert twin.data.efc_force[twin.data.contact[i].efc_address] == pytest.approx(
        -contact.force_n[2], rel=1e-9
    )
    # it acts under the tip, on the face (the contact point: between the two surfaces)
    tip = twin.data.geom_xpos[twin.model.geom(TIP_GEOM).id]
    assert contact.point_m is not None
    np.testing.assert_allclose(contact.point_m[:2], tip[:2], atol=1e-9)
    assert abs(plate.height_m(contact.point_m)) < depth


def test_friction_bounds_the_tangential_force_on_an_inclined_plate() -> None:
    tilt = np.radians(30.0)  # steeper than atan(mu): pushed straight down, the tip slides
    plate = Plate(point_m=(0.0, 0.0, -0.26), normal=(0.0, np.sin(tilt), np.cos(tilt)), friction=0.2)
    twin = DeltaTwin(TwinConfig(plates=(plate,)))
    command_tip(twin, (0.0, 0.0, -0.27))
    normal = np.array(plate.normal)
    ratios, start = [], None
    for _ in range(1500):
        twin.step()
        contact = twin.contact()
        if not contact.in_contact:
            continue
        if start is None:
            start = contact.point_m
        f_n = float(contact.force_n @ normal)
        f_t = float(np.linalg.norm(contact.force_n - f_n * normal))
        assert f_n <= 0.0  # the tip only pushes into the plate
        if -f_n > 0.05:
            ratios.append(f_t / -f_n)
    assert ratios and max(ratios) <= plate.friction * (1 + 1e-6)
    assert max(ratios) > 0.95 * plate.friction  # it slid: the cone's edge was reached
    # down the slope: a normal leaning towards +y lowers the face towards +y
    assert twin.contact().point_m[1] > start[1] + 0.002


def test_a_frictionless_plate_pushes_along_its_normal_only() -> None:
    tilt = np.radians(20.0)
    plate = Plate(point_m=(0.0, 0.0, -0.26), normal=(np.sin(tilt), 0.0, np.cos(tilt)), friction=0.0)
    twin = DeltaTwin(TwinConfig(plates=(plate,)))
    command_tip(twin, (0.0, 0.0, -0.266))
    twin.advance(0.5)
    contact = twin.contact()
    assert contact.in_contact
    along = float(contact.force_n @ np.array(plate.normal))
    np.testing.assert_allclose(contact.force_n, along * np.array(plate.normal), atol=1e-9)


def test_the_existing_geoms_still_collide_with_nothing() -> None:
    twin = DeltaTwin(TwinConfig(plates=(UNDER_HOME,)))
    model = twin.model
    tip = model.geom(TIP_GEOM).id
    plates = {model.geom(plate_name(0)).id}
    for g in range(model.ngeom):
        for h in range(model.ngeom):
            collide = (model.geom_contype[g] & model.geom_conaffinity[h]) or (
                model.geom_contype[h] & model.geom_conaffinity[g]
            )
            assert bool(collide) == ({g, h} == {tip} | plates and g != h)


# -- the buses ---------------------------------------------------------------------------
def test_the_sim_bus_measures_the_contact_at_the_last_read() -> None:
    bus = SimBus(
        SimBusConfig(twin=TwinConfig(plates=(UNDER_HOME,)), realtime=False, torque_on_at_start=True)
    )
    bus.connect()
    bus.write_goal(list(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.266])).joints))
    bus.advance(1.0)
    bus.read_state()
    pressed = bus.measure_contact(at_last_read=True)
    assert pressed.in_contact and pressed.force_n[2] < -1.0
    assert isinstance(pressed, TwinContact)
    np.testing.assert_array_equal(bus.measure_contact().force_n, bus.twin.contact().force_n)
    bus.write_goal(list(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.25])).joints))  # lift
    bus.advance(0.5)
    assert not bus.measure_contact().in_contact
    np.testing.assert_array_equal(bus.measure_contact(at_last_read=True).force_n, pressed.force_n)
    bus.read_state()
    assert not bus.measure_contact(at_last_read=True).in_contact
    bus.disconnect()


@pytest.fixture
def process_bus() -> Iterator[ProcessSimBus]:
    bus = ProcessSimBus(
        SimBusConfig(twin=TwinConfig(plates=(UNDER_HOME,)), torque_on_at_start=True)
    )
    bus.connect()
    yield bus
    bus.disconnect()


@pytest.mark.slow
def test_the_process_bus_shares_the_contact_in_its_frame(process_bus: ProcessSimBus) -> None:
    bus = process_bus
    assert not bus.measure_contact().in_contact and bus.measure_contact().point_m is None
    bus.write_goal(list(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.266])).joints))

    before: list[tuple[float, float]] = []  # (sim time [s], force z [N]) of earlier reads

    def pressing_at_rest() -> bool:
        """In contact, still, and the force as it was 0.1 s of simulated time before (a
        momentary stop, a bounce's turning point, is not rest)."""
        state = bus.read_state()
        contact = bus.measure_contact(at_last_read=True)
        if not contact.in_contact or np.abs(state.velocity_rad_s).any():
            before.clear()
            return False
        before.append((state.sim_time_s, float(contact.force_n[2])))
        old = [f for t, f in before if t < state.sim_time_s - 0.1]
        return bool(old) and abs(old[-1] - contact.force_n[2]) < 0.005 * abs(contact.force_n[2])

    wait_for(pressing_at_rest, "the tip to press the plate and settle")
    contact = bus.measure_contact(at_last_read=True)
    platform = bus.measure_platform(at_last_read=True)  # no noise: the true centre
    depth = TIP_RADIUS_M - float(UNDER_HOME.height_m(platform))
    assert -contact.force_n[2] == pytest.approx(UNDER_HOME.stiffness_n_m * depth, rel=0.05)
    assert contact.point_m is not None
    np.testing.assert_allclose(contact.point_m[:2], platform[:2], atol=1e-6)


# -- the config --------------------------------------------------------------------------
PLATES = """
[hardware]
sim_process = false
[tool]
offset_m = [0.0, 0.0, -0.03]
[[hardware.sim.plates]]
point_m = [0.0, 0.0, -0.29]
stiffness_n_m = 20000.0
damping_n_s_m = 10.0
friction = 0.3
[[hardware.sim.plates]]
point_m = [0.1, 0.0, -0.25]
normal = [-1.0, 0.0, 0.0]
half_size_m = [0.05, 0.02]
thickness_m = 0.01
"""


def test_a_config_with_plates_builds_a_twin_that_touches_them(tmp_path) -> None:
    path = tmp_path / "plates.toml"
    path.write_text(PLATES)
    bus = _twin(load_settings(path), realtime=False)
    twin = bus.twin
    assert twin.config.tip_offset_m == (0.0, 0.0, -0.03)
    floor, wall = twin.config.plates
    assert floor == Plate(
        point_m=(0.0, 0.0, -0.29), stiffness_n_m=2.0e4, damping_n_s_m=10.0, friction=0.3
    )
    assert wall.normal == (-1.0, 0.0, 0.0) and wall.half_size_m == (0.05, 0.02)
    command_tip(twin, (0.0, 0.0, -0.294))
    twin.advance(1.0)
    contact = twin.contact()
    assert contact.in_contact
    assert -contact.force_n[2] == pytest.approx(2.0e4 * penetration_m(twin, floor), rel=0.02)


def test_the_default_config_has_no_plates() -> None:
    settings = load_settings(hardware={"sim_process": False})
    assert settings.hardware.sim.plates == []
    assert _twin(settings, realtime=False).twin.config.plates == ()


@pytest.mark.parametrize(
    ("line", "field"),
    [
        ("stiffness_n_m = 0.0", "plates.0.stiffness_n_m"),
        ("normal = [0.0, 0.0, 0.0]", "plates.0.normal"),
        ("friction = -1.0", "plates.0.friction"),
        ("half_size_m = [0.1, -0.1]", "plates.0.half_size_m"),
        ("colour = 'red'", "plates.0.colour"),
    ],
)
def test_a_bad_plate_in_the_config_is_refused_naming_the_field(tmp_path, line, field) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f"[[hardware.sim.plates]]\npoint_m = [0.0, 0.0, -0.26]\n{line}\n")
    with pytest.raises(ConfigError, match=rf"hardware\.sim\.{field}"):
        load_settings(path)
    path.write_text("[[hardware.sim.plates]]\nnormal = [0.0, 0.0, 1.0]\n")
    with pytest.raises(ConfigError, match=r"hardware\.sim\.plates\.0\.point_m"):
        load_settings(path)
