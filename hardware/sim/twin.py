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

from hardware.base_motion import BaseMotion, rotation
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import RAD_PER_TICK, OperatingMode
from hardware.shaft_motion import MotionCommand
from hardware.sim.base_frame import apply_frame_forces
from hardware.sim.masses import THESIS_MASSES, DeltaMasses
from hardware.sim.mjcf import (
    MOTOR_JOINTS,
    PLATFORM_JOINTS,
    TIP_GEOM,
    WRIST_JOINT,
    SimOptions,
    build_mjcf,
    mechanism,
    plate_name,
)
from hardware.sim.surfaces import CONTACT_IMPEDANCE, Plate, TwinContact
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

    tip_offset_m: the tool tip in the platform frame at wrist angle 0 [m] ([tool]
    offset_m), where the sphere that touches the plates sits; plates: surfaces fixed in
    the base frame (hardware.sim.surfaces), none by default.
    """

    robot: RotaryDelta = THESIS_DELTA
    masses: DeltaMasses = THESIS_MASSES
    sim: SimOptions = field(default_factory=SimOptions)
    servo: Xm430Params = XM430_W210
    joints: tuple[JointCalibration, ...] = DEFAULT_JOINTS
    true_robot: PerLegRotaryDelta | None = None
    tip_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    plates: tuple[Plate, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "plates", tuple(self.plates))
        if not all(isinstance(p, Plate) for p in self.plates):
            raise ValueError("plates: each must be a hardware.sim.surfaces.Plate")
        offset = tuple(float(v) for v in self.tip_offset_m)
        if len(offset) != 3 or not all(np.isfinite(offset)):
            raise ValueError(f"tip_offset_m: must be three finite numbers [m], got {offset}")
        object.__setattr__(self, "tip_offset_m", offset)
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
        self.model = mujoco.MjModel.from_xml_string(
            build_mjcf(cfg.built, cfg.masses, cfg.sim, cfg.plates, cfg.tip_offset_m)
        )
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._tip = m.geom(TIP_GEOM).id
        # the plates' solref, written for a unit inverse mass, scaled for the tip body's
        # and the plate's inverse masses A_t, A_p (body_invweight0). The contact's
        # regularizer is R = (1 - d)/d (A_t + A_p) (efc_diagApprox); the plate, put back
        # before every step, feels f in it as a free body would, so at rest the tip's
        # equation leaves f (R + A_p) = a_ref = k' p / d: k' = k ((1 - d) A_t + A_p),
        # `direct_solref` of A_t + A_p / (1 - d) (hardware.sim.surfaces)
        tip_body = m.geom_bodyid[self._tip]
        self._plate_bodies = [m.body(plate_name(i)).id for i in range(len(cfg.plates))]
        for i, plate in enumerate(cfg.plates):
            a_t = float(m.body_invweight0[tip_body, 0])
            a_p = float(m.body_invweight0[self._plate_bodies[i], 0])
            inverse_mass = a_t + a_p / (1.0 - CONTACT_IMPEDANCE)
            m.geom_solref[m.geom(plate_name(i)).id] = plate.direct_solref(inverse_mass)
        # each plate's freejoint (kinematic: hardware.sim.mjcf._plates_xml) and its motion
        # in the base frame: position [m], rotation (3, 3), velocity [m/s], angular
        # velocity [rad/s] (base frame), as configured until moved
        self._plate_q = [int(m.joint(plate_name(i)).qposadr[0]) for i in range(len(cfg.plates))]
        self._plate_v = [int(m.joint(plate_name(i)).dofadr[0]) for i in range(len(cfg.plates))]
        self._plate_motion = [
            (np.array(p.point_m), p.frame(), np.zeros(3), np.zeros(3)) for p in cfg.plates
        ]
        self._world_anchor: tuple[np.ndarray, np.ndarray] | None = None
        # their paths (qpos adr, time set [s], position, quaternion, velocity, angular
        # velocity in the plate frame), put back before every step: the tip's push would
        # otherwise accumulate in them (F t^2 / 2 M)
        self._plate_paths: list[tuple[int, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
        self._plate_paths = [
            (q, 0.0, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3))
            for q in self._plate_q
        ]
        driven = MOTOR_JOINTS + ((WRIST_JOINT,) if cfg.has_wrist else ())
        self.n_servos = n = len(driven)
        self._motor_q = np.array([m.joint(j).qposadr[0] for j in driven])
        self._motor_v = np.array([m.joint(j).dofadr[0] for j in driven])
        m.dof_frictionloss[self._motor_v] = servo.coulomb_friction_nm  # gearbox, sticks at rest
        self._platform_q = np.array([m.joint(j).qposadr[0] for j in PLATFORM_JOINTS])
        base = m.body("base").id
        fixed = {0, base, *self._plate_bodies}  # the plates are kinematic: no frame forces
        self._moving_bodies = np.array([b for b in range(m.nbody) if b not in fixed])
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
        for i in range(len(self._plate_motion)):  # the plates stay where they were put
            self._place_plate(i)
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
        """How the base (the drone) moves; holds until set again (default: at rest, level).

        With `motion.position_m` the plates fixed in the world move to base^-1 * base_0 *
        plate (base = the pose given, base_0 the first one given since the last motion
        without a position: the world anchor, hardware.sim.surfaces.Plate.fixed_in) at the
        velocity of a world-fixed point seen from the moving base, -w x p - R^T v (w the
        base's angular velocity, base frame; v its origin's velocity, world), and keep that
        velocity until the next call; without a position they go back where configured,
        still, and the anchor is forgotten."""
        self.base_motion = motion = motion or BaseMotion()
        self.model.opt.gravity[:] = motion.effective_gravity()
        self.data.xfrc_applied[:] = 0.0
        self._follow_base(motion)

    @property
    def world_anchor(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The base pose in the world at which the world-fixed plates sit where configured:
        (position [m] (3,), rotation base to world (3, 3)); None until a base motion with a
        position is set (set_base_motion)."""
        if self._world_anchor is None:
            return None
        return self._world_anchor[0].copy(), self._world_anchor[1].copy()

    def set_plate_pose(
        self,
        index: int,
        point_m: Sequence[float],
        normal: Sequence[float],
        velocity_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        angular_velocity_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Move plate `index` (config order) now: its touched face through `point_m` [m]
        with outward normal `normal` (any non-zero length), both (3,) in the base frame as
        `Plate` has them (its in-face axes as `Plate.frame`), moving on at `velocity_m_s`
        [m/s] and turning at `angular_velocity_rad_s` [rad/s] (base frame, about the
        point) until moved again: MuJoCo integrates the kinematic plate, and the contact's
        damping sees the relative speed. A world-fixed plate is moved again by the next
        base motion with a position (set_base_motion).

        Raises:
            ValueError: naming the index (not a plate) or the field (not three finite
            numbers, a zero normal).
        """
        count = len(self.config.plates)
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise ValueError(f"plate index: must be an integer, got {index!r}")
        if not 0 <= int(index) < count:
            raise ValueError(f"plate index: {index} is not one of the twin's {count} plates")
        index = int(index)
        plate = self.config.plates[index]
        moved = replace(plate, point_m=point_m, normal=normal)  # type: ignore[arg-type]
        velocity = _vector("velocity_m_s", velocity_m_s)
        turning = _vector("angular_velocity_rad_s", angular_velocity_rad_s)
        self._plate_motion[index] = (np.array(moved.point_m), moved.frame(), velocity, turning)
        self._place_plate(index)
        mujoco.mj_kinematics(self.model, self.data)

    def plate_pose(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Where plate `index` is now in the base frame: a point of its touched face [m]
        (the body's origin) and its unit normal, both (3,): its path at the twin's time,
        where the next physics step puts its freejoint (MuJoCo's qpos after a step also
        holds the step's push on it, undone before the next: `_hold_plates`). Raises
        IndexError for no such plate."""
        point, quaternion = self._plate_at(index, self.data.time)
        return point, rotation(quaternion.tolist())[:, 2]

    def _follow_base(self, motion: BaseMotion) -> None:
        """Move the world-fixed plates with the base (set_base_motion)."""
        world = [i for i, p in enumerate(self.config.plates) if p.fixed_in == "world"]
        if motion.position_m is None:
            self._world_anchor = None
            for i in world:
                plate = self.config.plates[i]
                still = (np.array(plate.point_m), plate.frame(), np.zeros(3), np.zeros(3))
                self._plate_motion[i] = still
                self._place_plate(i)
            return
        origin, turn = np.array(motion.position_m), rotation(motion.attitude_wxyz)
        if self._world_anchor is None:
            self._world_anchor = (origin, turn)
        anchor_origin, anchor_turn = self._world_anchor
        w = np.array(motion.angular_velocity_rad_s, dtype=float)
        v = turn.T @ np.array(motion.velocity_m_s)
        for i in world:
            plate = self.config.plates[i]
            point_world = anchor_origin + anchor_turn @ np.array(plate.point_m)
            point = turn.T @ (point_world - origin)
            frame = turn.T @ anchor_turn @ plate.frame()
            self._plate_motion[i] = (point, frame, -np.cross(w, point) - v, -w)
            self._place_plate(i)

    def _place_plate(self, index: int) -> None:
        """Write plate `index`'s stored motion into its freejoint's qpos and qvel (linear
        velocity in the world, i.e. the base frame; angular in the plate's own frame)."""
        point, frame, velocity, turning = self._plate_motion[index]
        q, v = self._plate_q[index], self._plate_v[index]
        self.data.qpos[q : q + 3] = point
        quaternion = np.empty(4)
        mujoco.mju_mat2Quat(quaternion, np.ascontiguousarray(frame).reshape(9))
        self.data.qpos[q + 3 : q + 7] = quaternion
        local = frame.T @ turning
        self.data.qvel[v : v + 3] = velocity
        self.data.qvel[v + 3 : v + 6] = local
        self._plate_paths[index] = (
            q,
            self.time_s,
            np.array(point, dtype=float),
            quaternion,
            np.array(velocity, dtype=float),
            local,
        )

    def _hold_plates(self) -> None:
        """Put every plate where its path has it now, at its speed: position p + v t,
        attitude q * exp(w t / 2) (w constant in the plate frame), t since it was set."""
        data = self.data
        qpos, qvel, now = data.qpos, data.qvel, data.time
        for index, ((q, *_, velocity, local), v) in enumerate(
            zip(self._plate_paths, self._plate_v, strict=True)
        ):
            qpos[q : q + 3], qpos[q + 3 : q + 7] = self._plate_at(index, now)
            qvel[v : v + 3] = velocity
            qvel[v + 3 : v + 6] = local

    def _plate_at(self, index: int, now: float) -> tuple[np.ndarray, np.ndarray]:
        """Plate `index`'s path at time `now` [s]: position (3,) [m], quaternion (4,)."""
        _, since, point, quaternion, velocity, local = self._plate_paths[index]
        tau = now - since
        rate = float(np.linalg.norm(local))
        if rate == 0.0:
            return point + velocity * tau, quaternion.copy()
        half = 0.5 * rate * tau
        turned = np.empty(4)
        step = np.array([np.cos(half), *(np.sin(half) / rate * local)])
        mujoco.mju_mulQuat(turned, quaternion, step)
        return point + velocity * tau, turned

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
        plates = bool(self._plate_paths)
        for _ in range(n):
            if plates:  # kinematic: each step starts where their paths have them
                self._hold_plates()
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
            self._hold_plates()
            mujoco.mj_step(self.model, self.data)

    def advance(self, duration_s: float) -> None:
        """Advance by `duration_s` [s], rounded to whole physics steps."""
        self.step(max(0, round(duration_s / self.model.opt.timestep)))

    def contact(self) -> TwinContact:
        """MuJoCo's own contact force of the last physics step: what the tip applies on the
        plates, in the base frame (MuJoCo's world).

        For each contact of the tip geom, mj_contactForce gives the force in the contact
        frame (normal first, from geom1 to geom2: the force geom1 applies on geom2); it is
        rotated to the world by the frame's rows, signed as the tip's force on the plate
        and summed. point_m is the force-weighted mean of the contact points (their plain
        mean while the force is zero), None without contact. Shapes: force (3,) [N],
        point (3,) [m]."""
        model, data = self.model, self.data
        force, moment, weight, points = np.zeros(3), np.zeros(3), 0.0, []
        wrench = np.zeros(6)
        for i in range(data.ncon):
            c = data.contact[i]
            if self._tip not in (c.geom1, c.geom2) or c.exclude or c.efc_address < 0:
                continue
            mujoco.mj_contactForce(model, data, i, wrench)
            on_geom2 = c.frame.reshape(3, 3).T @ wrench[:3]
            # MuJoCo orders a pair by geom type (sphere before box): the tip is geom1
            force += on_geom2 if c.geom1 == self._tip else -on_geom2
            normal = abs(float(wrench[0]))
            moment += normal * c.pos
            weight += normal
            points.append(c.pos.copy())
        if not points:
            return TwinContact.none()
        point = moment / weight if weight > 0.0 else np.mean(points, axis=0)
        return TwinContact(force, point, True)

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
        data.qvel[:] = 0.0  # the plates too: reset() puts them back in motion
        data.time = 0.0
        self.model.opt.gravity[:] = gravity


def _vector(name: str, values: Sequence[float]) -> np.ndarray:
    """Three finite numbers as an array (3,); ValueError naming `name` otherwise."""
    try:
        out = np.array([float(v) for v in values])
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be three numbers, got {values!r}") from None
    if out.shape != (3,) or not np.isfinite(out).all():
        raise ValueError(f"{name}: must be three finite numbers, got {out.tolist()}")
    return out
