"""MJCF of a rotary Delta generated from its geometry and mass model (any design).

Tree: base -> three upper links on hinges (the motor axes) -> one lower link per leg on a
universal joint at the knee (two hinges: one parallel to the motor axis, one perpendicular
to it and the rod); the platform hangs off the base on three slide joints, which keeps its
orientation fixed exactly as the parallelograms do, with no extra constraint rows. Each
leg's chain is closed by a `connect` equality between the rod's end and the platform's
ball-joint site. With a wrist in the mass model (`DeltaMasses.with_wrist`), a wrist body
turns on the platform about its z axis (hinge `wrist`, a fourth actuator). The file is
written in an assembled pose with joint `ref` values, so qpos of the motor hinges is the
thesis's theta and qpos of the slides is the platform centre in the base frame [m].

A ``PerLegRotaryDelta`` builds each leg from its own L, l, R, r and base angle (a robot
built wrong on purpose); its joint offsets are no part of the mechanism (they sit between
the mechanism and the servos, see hardware.sim.twin), so the motor hinges' qpos are the
mechanism's true angles theta_i.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hardware.sim.masses import THESIS_MASSES, DeltaMasses
from hardware.sim.surfaces import CONTACT_GROUP, CONTACT_IMPEDANCE, TIP_RADIUS_M, Plate
from kinematics import PerLegRotaryDelta, RotaryDelta

MOTOR_JOINTS = ("motor_1", "motor_2", "motor_3")
WRIST_JOINT = "wrist"  # the wrist's hinge about the platform's z (qpos = phi [rad])
PLATFORM_JOINTS = ("platform_x", "platform_y", "platform_z")
TIP_GEOM = "tip"  # the tool tip's sphere, the only geom that touches the plates
PLATE_MASS_KG = 100.0  # a kinematic plate's mass (_plates_xml)


def plate_name(index: int) -> str:
    """The body and geom name of plate `index` (0-based, the config's order)."""
    return f"plate_{index}"


@dataclass(frozen=True)
class SimOptions:
    """Solver settings of the generated model.

    timestep_s: physics step [s]; home_m: the assembled platform centre [m] (must be
    reachable); eq_timeconst_s: the connect constraints' solref time constant [s] (MuJoCo's
    default 0.02 lets the chain stretch by millimetres; it is raised to 2 timesteps if set
    below); eq_solimp: constraint impedance (d0, dwidth); rod_radius_m: display only.
    """

    timestep_s: float = 0.001
    home_m: tuple[float, float, float] = (0.0, 0.0, -0.24)
    eq_timeconst_s: float = 0.002
    eq_solimp: tuple[float, float] = (0.99, 0.999)
    rod_radius_m: float = 0.003


def _quat_of(matrix: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation matrix (det +1)."""
    m = matrix
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    x = math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0
    y = math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0
    z = math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0
    x = math.copysign(x, m[2, 1] - m[1, 2])
    y = math.copysign(y, m[0, 2] - m[2, 0])
    z = math.copysign(z, m[1, 0] - m[0, 1])
    return w, x, y, z


def _fmt(values) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


def _upper_frame(alpha: float, theta: float) -> np.ndarray:
    """Upper link frame in the base: x along the link, y along the motor axis (Rz Ry)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    return rz @ ry


def _lower_frame(rod_dir_upper: np.ndarray) -> np.ndarray:
    """Lower link frame in the upper link's: x along the rod, z the universal joint's 2nd axis."""
    e1 = rod_dir_upper / np.linalg.norm(rod_dir_upper)
    e3 = np.cross(e1, [0.0, 1.0, 0.0])
    e3 /= np.linalg.norm(e3)
    return np.column_stack([e1, np.cross(e3, e1), e3])


def mechanism(robot: RotaryDelta | PerLegRotaryDelta) -> PerLegRotaryDelta:
    """The mechanism's per-leg geometry: ``robot`` without joint offsets."""
    if isinstance(robot, RotaryDelta):
        return PerLegRotaryDelta.from_symmetric(robot)
    return robot.with_values(joint_offsets_rad=(0.0, 0.0, 0.0))


def _leg_xml(
    robot: PerLegRotaryDelta,
    masses: DeltaMasses,
    leg: int,
    theta: float,
    home,
    rod_radius: float,
) -> str:
    """One leg: upper link on the motor hinge, lower link on the knee's universal joint."""
    alpha = robot.angles_rad[leg]
    L, l, n = robot.L[leg], robot.l[leg], leg + 1
    hip = robot.R[leg] * np.array([math.cos(alpha), math.sin(alpha), 0.0])
    upper = _upper_frame(alpha, theta)
    knee = hip + upper @ [L, 0.0, 0.0]
    ankle = np.asarray(home) + robot.r[leg] * np.array([math.cos(alpha), math.sin(alpha), 0.0])
    lower = _lower_frame(upper.T @ (ankle - knee))
    m_up = masses.upper_kg
    # about the link's centre of mass (MuJoCo's convention); the hinge adds m (L/2)^2
    i_up = max(masses.upper_inertia(L) - m_up * L * L / 4.0, 1e-9)
    m_lo = masses.lower_kg
    i_lo = m_lo * l * l / 12.0
    axis_a = lower.T @ [0.0, 1.0, 0.0]  # the motor-axis-parallel hinge, in the lower frame
    return f"""
    <body name="upper_{n}" pos="{_fmt(hip)}" quat="{_fmt(_quat_of(upper))}">
      <joint name="motor_{n}" type="hinge" axis="0 1 0" ref="{theta:.12g}"
             armature="{masses.armature_kgm2:.6g}"/>
      <inertial pos="{L / 2:.12g} 0 0" mass="{max(m_up, 1e-6):.6g}"
                diaginertia="{i_up / 100:.6g} {i_up:.6g} {i_up:.6g}"/>
      <geom type="capsule" fromto="0 0 0 {L:.12g} 0 0" size="0.006" mass="0" rgba=".3 .5 .8 1"/>
      <body name="lower_{n}" pos="{L:.12g} 0 0" quat="{_fmt(_quat_of(lower))}">
        <joint name="knee_{n}_a" type="hinge" axis="{_fmt(axis_a)}"/>
        <joint name="knee_{n}_b" type="hinge" axis="0 0 1"/>
        <inertial pos="{l / 2:.12g} 0 0" mass="{max(m_lo, 1e-6):.6g}"
                  diaginertia="{i_lo / 1000:.6g} {i_lo:.6g} {i_lo:.6g}"/>
        <geom type="capsule" fromto="0 0 0 {l:.12g} 0 0" size="{rod_radius:.6g}" mass="0"
              rgba=".2 .2 .2 1"/>
        <site name="rod_end_{n}" pos="{l:.12g} 0 0"/>
      </body>
    </body>"""


def _tip_xml(tip_offset_m) -> str:
    """The tool tip: a small sphere that collides with the plates only (CONTACT_GROUP)."""
    return f"""
          <geom name="{TIP_GEOM}" type="sphere" size="{TIP_RADIUS_M:.6g}" pos="{_fmt(tip_offset_m)}"
                contype="{CONTACT_GROUP}" conaffinity="0" condim="3" mass="0" rgba="1 .1 .1 1"/>"""


def _plates_xml(plates) -> str:
    """Each plate a body with a box geom, its top face through the plate's point (the
    body's origin, its z the normal).

    The body is free (a freejoint) but kinematic: `PLATE_MASS_KG`, its gravity
    compensated, put back on its path before each step (DeltaTwin.step): it keeps the
    pose and velocity the twin gives it (DeltaTwin.set_plate_pose). A plate that moves in
    the base frame (a wall fixed in the world under a drifting drone) moves with a
    velocity, so the contact's damping sees the true relative speed, which a mocap body
    (no velocity in MuJoCo) would not. Within a step the contact force accelerates it as
    a free body; the solref allows for that (DeltaTwin). A far heavier plate (1e6 kg
    and up) upsets MuJoCo's solver: the tip then chatters on it or bounces off. Its
    solref is written for a unit inverse mass (`Plate.direct_solref(1)`); the twin
    scales it by the tip's and the plate's body_invweight0 once the model is compiled.
    priority="1": the contact takes the plate's friction, solref and solimp, not a mix
    with the tip's."""
    d = CONTACT_IMPEDANCE
    inertia = PLATE_MASS_KG * 0.01  # spherical (no gyroscopic torque while it turns)
    out = []
    for i, plate in enumerate(plates):
        frame = plate.frame()
        half = plate.thickness_m / 2.0
        k, b = plate.direct_solref(1.0)
        condim = 3 if plate.friction > 0.0 else 1
        out.append(f"""
    <body name="{plate_name(i)}" pos="{_fmt(plate.point_m)}" quat="{_fmt(_quat_of(frame))}"
          gravcomp="1">
      <freejoint name="{plate_name(i)}"/>
      <inertial pos="0 0 0" mass="{PLATE_MASS_KG:.6g}"
                diaginertia="{inertia:.6g} {inertia:.6g} {inertia:.6g}"/>
      <geom name="{plate_name(i)}" type="box" pos="0 0 {-half:.12g}"
            size="{plate.half_size_m[0]:.12g} {plate.half_size_m[1]:.12g} {half:.12g}"
            contype="0" conaffinity="{CONTACT_GROUP}" condim="{condim}" priority="1"
            friction="{max(plate.friction, 1e-5):.12g} 0 0" solref="{k:.12g} {b:.12g}"
            solimp="{d} {d} 0.001 0.5 2" rgba=".5 .6 .5 .6"/>
    </body>""")
    return "".join(out)


def _platform_xml(
    robot: PerLegRotaryDelta, masses: DeltaMasses, home, tip_offset_m=(0.0, 0.0, 0.0)
) -> str:
    """The platform on three slides (qpos = its centre [m]) with its ball-joint sites."""
    x, y, z = home
    ankle_xy = [
        r * np.array([math.cos(a), math.sin(a), 0.0])
        for r, a in zip(robot.r, robot.angles_rad, strict=True)
    ]
    ankles = "".join(
        f'\n        <site name="ankle_{i + 1}" pos="{_fmt(xy)}"/>' for i, xy in enumerate(ankle_xy)
    )
    # the wrist's turning part is its own body; the wrist servo's case is the platform's
    m_plat = masses.platform_total_kg - masses.wrist_kg
    # a disc; its rotation is locked by the slides, so only A + B >= C must hold
    radius = max(robot.r)
    i_plat = m_plat * radius**2 / 2.0
    # with a wrist the tool turns with it: the tip sits on the wrist's body
    tip = _tip_xml(tip_offset_m)
    wrist = _wrist_xml(masses, tip) if masses.has_wrist else ""
    tip = "" if masses.has_wrist else tip
    return f"""
      <body name="platform" pos="{x:.12g} {y:.12g} {z:.12g}">
        <joint name="platform_x" type="slide" axis="1 0 0" ref="{x:.12g}"/>
        <joint name="platform_y" type="slide" axis="0 1 0" ref="{y:.12g}"/>
        <joint name="platform_z" type="slide" axis="0 0 1" ref="{z:.12g}"/>
        <inertial pos="0 0 0" mass="{m_plat:.6g}"
                  diaginertia="{i_plat * 0.51:.6g} {i_plat * 0.51:.6g} {i_plat:.6g}"/>
        <geom type="cylinder" size="{max(radius, 0.01):.6g} 0.003" mass="0" rgba=".8 .4 .2 1"/>
        <site name="platform_centre" pos="0 0 0"/>{ankles}{tip}{wrist}
      </body>"""


def _wrist_xml(masses: DeltaMasses, tip: str = "") -> str:
    """The wrist: horn and tool turning about the platform's z on a hinge (qpos = phi [rad]),
    driven like the legs (the servo's rotor as the hinge's armature)."""
    m = max(masses.wrist_kg, 1e-6)
    i_z = max(masses.wrist_inertia_kgm2, 1e-9)
    return f"""
        <body name="wrist" pos="0 0 0">
          <joint name="{WRIST_JOINT}" type="hinge" axis="0 0 1"
                 armature="{masses.armature_kgm2:.6g}"/>
          <inertial pos="0 0 0" mass="{m:.6g}" diaginertia="{i_z / 2:.6g} {i_z / 2:.6g} {i_z:.6g}"/>
          <geom type="box" size="0.02 0.003 0.003" pos="0.01 0 -0.006" mass="0" rgba=".9 .8 .1 1"/>
          <site name="wrist_tool" pos="0 0 0"/>{tip}
        </body>"""


def build_mjcf(
    robot: RotaryDelta | PerLegRotaryDelta,
    masses: DeltaMasses = THESIS_MASSES,
    options: SimOptions | None = None,
    plates: Sequence[Plate] = (),
    tip_offset_m: Sequence[float] = (0.0, 0.0, 0.0),
) -> str:
    """The MJCF text of `robot` with `masses`, assembled at `options.home_m`, with
    `plates` (placed in the base frame; the twin may move them) and the tool tip (a
    sphere of `TIP_RADIUS_M` at `tip_offset_m` [m], the platform frame at wrist angle 0)
    that touches them.

    A per-leg robot's joint offsets are left out: the hinges' qpos are true angles.
    The plates' stiffness and damping hold once scaled by the tip's and the plate's
    inverse masses (hardware.sim.twin does it; hardware.sim.surfaces explains)."""
    opt = options or SimOptions()
    described = robot
    robot = mechanism(robot)
    joints, ok = robot.ik(np.asarray(opt.home_m, dtype=float))
    if not bool(ok):
        raise ValueError(f"home {opt.home_m} m is outside the workspace of {described}")
    legs = "".join(
        _leg_xml(robot, masses, i, float(joints[i]), opt.home_m, opt.rod_radius_m) for i in range(3)
    )
    connects = "".join(f'\n    <connect site1="rod_end_{i}" site2="ankle_{i}"/>' for i in (1, 2, 3))
    driven = MOTOR_JOINTS + ((WRIST_JOINT,) if masses.has_wrist else ())
    motors = "".join(f'\n    <motor name="{j}" joint="{j}" gear="1"/>' for j in driven)
    timeconst = max(opt.eq_timeconst_s, 2.0 * opt.timestep_s)
    platform = _platform_xml(robot, masses, opt.home_m, tip_offset_m)
    base_r = max(robot.R)
    return f"""<mujoco model="delta">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{opt.timestep_s:.9g}" integrator="implicitfast" gravity="0 0 -9.81"
          cone="elliptic"/>
  <default>
    <geom contype="0" conaffinity="0"/>
    <equality solref="{timeconst:.6g} 1" solimp="{opt.eq_solimp[0]} {opt.eq_solimp[1]} 0.001"/>
  </default>
  <worldbody>
    <body name="base">
      <inertial pos="0 0 0" mass="{3 * masses.servo_kg + 1e-3:.6g}" diaginertia="1e-3 1e-3 1e-3"/>
      <geom type="cylinder" size="{base_r:.6g} 0.004" mass="0" rgba=".7 .7 .7 .5"/>{legs}{platform}
    </body>{_plates_xml(plates)}
  </worldbody>
  <equality>{connects}
  </equality>
  <actuator>{motors}
  </actuator>
</mujoco>
"""
