"""The MuJoCo twin: the Delta's mechanism stepped together with XM430-W210 models, three for
the legs and, with a wrist, a fourth turning the tool about the platform's z.

Every physics step the servos read their shafts (joint angle mapped through the joint
calibration: shaft = zero offset + direction * theta), run their firmware and motor for one
control period, and the torques they produce drive the motor hinges for the next step.
The twin knows nothing of wall time; hardware.sim.sim_bus runs it in real time, tests and
benchmarks run it as fast as it goes.

A moving base (the drone) is simulated in the base frame (hardware.sim.base_frame):
gravity becomes R^T (g - a_base), and a turning base adds Euler, centrifugal and Coriolis
forces on every moving body.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np

from hardware.base_motion import BaseMotion
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import RAD_PER_TICK, OperatingMode
from hardware.shaft_motion import MotionCommand
from hardware.sim.base_frame import apply_frame_forces
from hardware.sim.masses import THESIS_MASSES, DeltaMasses
from hardware.sim.mjcf import (
    MOTOR_JOINTS,
    PLATFORM_JOINTS,
    WRIST_JOINT,
    SimOptions,
    build_mjcf,
    mechanism,
)
from hardware.sim.xm430 import XM430_W210, ServoOutput, Xm430, Xm430Params
from kinematics import THESIS_DELTA, PerLegRotaryDelta, RotaryDelta

DEFAULT_JOINTS = tuple(JointCalibration(servo_id=i) for i in (1, 2, 3))
SETTLE_STEPS = 200


@dataclass(frozen=True)
class TwinConfig:
    """What to simulate: the design, its masses, solver options, servos and calibrations.

    The servo's control period is the physics timestep (sim.timestep_s), so one step runs
    the firmware once. joints: one calibration per leg, leg order, and a fourth for the
    wrist (phi [rad] about the platform's z); with four, `masses` without a wrist get
    `WRIST_XM430`'s (an XM430-W210 on the platform, hardware/sim/masses.py).

    true_robot: the robot as built, when it is not the design (None: exactly `robot`):
    each leg its own L, l, R, r and base angle, and joint offsets o_i that turn the
    mechanism against what its servo reports (theta_i = q_i + o_i, see
    kinematics.per_leg). The controller keeps `robot`; a calibration finds the difference.
    """

    robot: RotaryDelta = THESIS_DELTA
    masses: DeltaMasses = THESIS_MASSES
    sim: SimOptions = field(default_factory=SimOptions)
    servo: Xm430Params = XM430_W210
    joints: tuple[JointCalibration, ...] = DEFAULT_JOINTS
    true_robot: PerLegRotaryDelta | None = None

    def __post_init__(self) -> None:
        if len(self.joints) not in (3, 4):
            raise ValueError(
                f"{len(self.joints)} joint calibrations: three legs, and a fourth for a wrist"
            )
        if self.has_wrist and not self.masses.has_wrist:
            object.__setattr__(self, "masses", self.masses.with_wrist())
        if self.masses.has_wrist and not self.has_wrist:
            raise ValueError("masses with a wrist need a fourth joint calibration for it")

    @property
    def has_wrist(self) -> bool:
        """A fourth servo turns a wrist on the platform."""
        return len(self.joints) == 4

    @property
    def built(self) -> RotaryDelta | PerLegRotaryDelta:
        """The robot as built: `true_robot`, or `robot` when that is None."""
        return self.robot if self.true_robot is None else self.true_robot

    @property
    def joint_offsets_rad(self) -> np.ndarray:
        """The true joint offsets o_i [rad], shape (3,) (zeros for the exact twin)."""
        if self.true_robot is None:
            return np.zeros(3)
        return np.array(self.true_robot.joint_offsets_rad)


def hold_command(shaft_rad: float) -> MotionCommand:
    """Factory settings, torque on, holding `shaft_rad` [rad]."""
    return MotionCommand(True, OperatingMode.POSITION, goal_position_rad=shaft_rad)


class DeltaTwin:
    """The simulated robot. Not thread-safe: one owner steps it (see SimBus)."""

    def __init__(self, config: TwinConfig | None = None) -> None:
        self.config = cfg = config or TwinConfig()
        servo = cfg.servo
        if abs(servo.control_period_s - cfg.sim.timestep_s) > 1e-12:
            servo = replace(servo, control_period_s=cfg.sim.timestep_s)
        self.mechanism = mechanism(cfg.built)  # true geometry, angles theta = qpos
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(cfg.built, cfg.masses, cfg.sim))
        self.data = mujoco.MjData(self.model)
        m = self.model
        driven = MOTOR_JOINTS + ((WRIST_JOINT,) if cfg.has_wrist else ())
        self.n_servos = n = len(driven)
        self._motor_q = np.array([m.joint(j).qposadr[0] for j in driven])
        self._motor_v = np.array([m.joint(j).dofadr[0] for j in driven])
        m.dof_frictionloss[self._motor_v] = servo.coulomb_friction_nm  # gearbox, sticks at rest
        self._platform_q = np.array([m.joint(j).qposadr[0] for j in PLATFORM_JOINTS])
        base = m.body("base").id
        self._moving_bodies = np.array([b for b in range(m.nbody) if b not in (0, base)])
        self._sign = np.array([c.direction for c in cfg.joints], dtype=float)
        # shaft = zero + sign * q with q = theta - o: a joint offset shifts each shaft's zero
        zero = np.array([c.zero_offset_ticks * RAD_PER_TICK for c in cfg.joints])
        offsets = np.zeros(n)
        offsets[:3] = cfg.joint_offsets_rad  # the wrist has none
        self._zero = zero - self._sign * offsets
        self.servos = [Xm430(servo) for _ in range(n)]
        self.commands: list[MotionCommand] = []
        self.set_base_motion()
        self.reset()

    # -- state -------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated time since reset [s]."""
        return float(self.data.time)

    @property
    def joints_rad(self) -> np.ndarray:
        """The mechanism's true joint angles theta [rad] (and the wrist's phi last), shape
        (n_servos,); with joint offsets o_i the servos report theta - o
        (`joints_of_shafts(shaft_rad)`)."""
        return self.data.qpos[self._motor_q].copy()

    @property
    def joint_velocity_rad_s(self) -> np.ndarray:
        """Joint speeds [rad/s], shape (n_servos,)."""
        return self.data.qvel[self._motor_v].copy()

    @property
    def platform_m(self) -> np.ndarray:
        """True platform centre in the base frame [m], shape (3,)."""
        return self.data.qpos[self._platform_q].copy()

    @property
    def shaft_rad(self) -> np.ndarray:
        """Servo shaft angles [rad] (raw ticks * 2 pi / 4096, unquantized), (n_servos,)."""
        return self._zero + self._sign * self.joints_rad

    @property
    def shaft_rad_s(self) -> np.ndarray:
        """Servo shaft speeds [rad/s], shape (n_servos,)."""
        return self._sign * self.joint_velocity_rad_s

    @property
    def outputs(self) -> list[ServoOutput]:
        """Each servo's last output: torque, current, PWM, temperature, error bits."""
        return [s.last for s in self.servos]

    def shafts_of_joints(self, joints_rad: Sequence[float]) -> np.ndarray:
        """Shaft angles [rad] of true joint angles theta [rad], through the calibrations
        and the joint offsets (unrounded)."""
        return self._zero + self._sign * np.asarray(joints_rad, dtype=float)

    def joints_of_shafts(self, shaft_rad: Sequence[float]) -> np.ndarray:
        """True joint angles theta [rad] of shaft angles [rad], through the calibrations
        and the joint offsets."""
        return self._sign * (np.asarray(shaft_rad, dtype=float) - self._zero)

    # -- control -----------------------------------------------------------------------
    def reset(self, joints_rad: Sequence[float] | np.ndarray | None = None) -> None:
        """Place the arm at rest at `joints_rad` [rad] (default: the assembled home), every
        servo holding it with factory settings; temperatures and latched errors are kept.
        With a wrist, a fourth value is its phi [rad] (three: phi = 0)."""
        mujoco.mj_resetData(self.model, self.data)
        if joints_rad is not None:
            self._assemble(np.asarray(joints_rad, dtype=float))
        mujoco.mj_forward(self.model, self.data)
        shafts = self.shaft_rad
        for servo, shaft in zip(self.servos, shafts, strict=True):
            servo.reset(float(shaft))
        self.commands = [hold_command(float(s)) for s in shafts]

    def set_commands(self, commands: Sequence[MotionCommand]) -> None:
        """What each servo's control table asks for (shaft angles [rad]), leg order (the
        wrist last)."""
        if len(commands) != self.n_servos:
            raise ValueError(f"{len(commands)} commands for {self.n_servos} servos")
        self.commands = list(commands)

    def set_base_motion(self, motion: BaseMotion | None = None) -> None:
        """How the base (the drone) moves; holds until set again (default: at rest, level)."""
        self.base_motion = motion = motion or BaseMotion()
        self.model.opt.gravity[:] = motion.effective_gravity()
        self.data.xfrc_applied[:] = 0.0

    def step(self, n: int = 1) -> None:
        """Advance `n` physics steps, running the servos' firmware once per step."""
        model, data = self.model, self.data
        qpos, qvel, ctrl = data.qpos, data.qvel, data.ctrl
        # plain floats: NumPy's per-call overhead would dominate at three or four servos
        legs = [
            (
                self.servos[k],
                int(self._motor_q[k]),
                int(self._motor_v[k]),
                float(self._sign[k]),
                float(self._zero[k]),
            )
            for k in range(self.n_servos)
        ]
        commands = self.commands
        rotating = self.base_motion.rotating
        for _ in range(n):
            if rotating:
                apply_frame_forces(model, data, self._moving_bodies, self.base_motion)
            for k, (servo, iq, iv, sign, zero) in enumerate(legs):
                out = servo.step(commands[k], zero + sign * qpos[iq], sign * qvel[iv])
                ctrl[k] = sign * out.torque_nm
            mujoco.mj_step(model, data)

    def step_torques(self, torques_nm: Sequence[float], n: int = 1) -> None:
        """Advance `n` physics steps with the motor torques [N m] (joint sign) imposed and
        the servos bypassed: for checking the mechanism against a dynamics model."""
        self.data.ctrl[:] = torques_nm
        for _ in range(n):
            mujoco.mj_step(self.model, self.data)

    def advance(self, duration_s: float) -> None:
        """Advance by `duration_s` [s], rounded to whole physics steps."""
        self.step(max(0, round(duration_s / self.model.opt.timestep)))

    def constraint_error_m(self) -> float:
        """Largest distance [m] between a rod's end and its platform joint, now."""
        mujoco.mj_kinematics(self.model, self.data)  # site positions after mj_step are stale
        gaps = [
            self.data.site(f"rod_end_{i}").xpos - self.data.site(f"ankle_{i}").xpos
            for i in (1, 2, 3)
        ]
        return float(max(np.linalg.norm(g) for g in gaps))

    def _assemble(self, joints: np.ndarray) -> None:
        """Close the chains at `joints`: pin motors and platform (FK), let the knees settle."""
        legs, phi = joints[:3], float(joints[3]) if joints.size > 3 else 0.0
        point, ok = self.mechanism.fk(legs)
        if not bool(ok):
            raise ValueError(f"joints {joints.tolist()} rad have no forward kinematics")
        gravity = self.model.opt.gravity.copy()
        self.model.opt.gravity[:] = 0.0
        data = self.data
        joints = np.append(legs, phi) if self.n_servos == 4 else legs
        for _ in range(SETTLE_STEPS):
            data.qpos[self._motor_q] = joints
            data.qpos[self._platform_q] = point
            data.qvel[:] = 0.0
            mujoco.mj_step(self.model, data)
        data.qpos[self._motor_q] = joints
        data.qpos[self._platform_q] = point
        data.qvel[:] = 0.0
        data.time = 0.0
        self.model.opt.gravity[:] = gravity
