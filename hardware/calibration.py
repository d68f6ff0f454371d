"""Joint calibration: zero offset, direction and limits per joint, and the homing procedure.

A joint angle theta [rad] is 0 with the upper link horizontal and positive pointing down
(the thesis's convention). The servo's raw position in ticks relates to it by

    ticks = zero_offset_ticks + direction * theta / RAD_PER_TICK

Records live in the app's TOML config under ``[[hardware.joints]]``; homing computes the
offsets from present positions while the links are held at a known pose (a horizontal jig
gives theta = 0 for every joint, hard stops give a known angle).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import tomli_w

from hardware.encoder import RAD_PER_TICK, TICKS_PER_REV
from hardware.errors import CalibrationError

SECTION = "hardware"
OTHER_KEYS = frozenset({"gains"})  # keys of a joint record that are not its calibration


@dataclass(frozen=True)
class JointCalibration:
    """One joint: servo id, zero offset [ticks], direction (+1/-1) and angle limits [rad]."""

    servo_id: int
    zero_offset_ticks: int = TICKS_PER_REV // 2
    direction: int = 1
    min_angle_rad: float = -math.pi / 2
    max_angle_rad: float = math.pi / 2

    def __post_init__(self) -> None:
        if not 0 <= self.servo_id <= 252:
            raise CalibrationError(f"servo_id {self.servo_id} outside 0..252")
        if self.direction not in (1, -1):
            raise CalibrationError(f"joint {self.servo_id}: direction {self.direction} not +1/-1")
        if not self.min_angle_rad < self.max_angle_rad:
            raise CalibrationError(
                f"joint {self.servo_id}: min_angle_rad {self.min_angle_rad} must be below "
                f"max_angle_rad {self.max_angle_rad}"
            )
        if self.max_angle_rad - self.min_angle_rad >= 2 * math.pi:
            raise CalibrationError(
                f"joint {self.servo_id}: range {self.min_angle_rad} .. {self.max_angle_rad} rad "
                "spans a turn or more (a servo's encoder tells positions apart within one turn)"
            )

    def to_ticks(self, theta_rad: float) -> int:
        """Joint angle [rad] -> raw servo position [ticks], rounded to the nearest tick."""
        return self.zero_offset_ticks + self.direction * round(theta_rad / RAD_PER_TICK)

    def to_rad(self, ticks: int | float) -> float:
        """Raw servo position [ticks] -> joint angle [rad]."""
        return self.direction * (ticks - self.zero_offset_ticks) * RAD_PER_TICK

    def clamp(self, theta_rad: float) -> float:
        """`theta_rad` limited to [min_angle_rad, max_angle_rad]."""
        return min(max(theta_rad, self.min_angle_rad), self.max_angle_rad)

    def tick_limits(self) -> tuple[int, int]:
        """The angle limits as (min, max) raw ticks, e.g. for the servo's position limits.

        Not wrapped into 0 .. 4095: a range past either end crosses the encoder's seam
        (hardware/seam.py says where each operating mode can go)."""
        ends = sorted((self.to_ticks(self.min_angle_rad), self.to_ticks(self.max_angle_rad)))
        return ends[0], ends[1]


def goal_ticks(joints: Sequence[JointCalibration], positions_rad: Sequence[float]) -> list[int]:
    """Goal joint angles [rad] to raw ticks, each clamped to its joint's limits.

    Raises:
        ValueError: a count that does not match the joints, or a non-finite angle.
    """
    if len(positions_rad) != len(joints):
        raise ValueError(f"{len(positions_rad)} goals for {len(joints)} joints")
    if not all(math.isfinite(p) for p in positions_rad):
        raise ValueError(f"non-finite goal {list(positions_rad)} rad")
    return [cal.to_ticks(cal.clamp(float(p))) for cal, p in zip(joints, positions_rad, strict=True)]


def home(
    calibrations: Sequence[JointCalibration],
    present_ticks: Mapping[int, int],
    known_angles_rad: Sequence[float] | float = 0.0,
) -> tuple[JointCalibration, ...]:
    """New calibrations whose zero offsets make `present_ticks` read `known_angles_rad`.

    present_ticks: servo id -> Present Position [ticks] while the links are held at the
    known pose; known_angles_rad: the pose's joint angles [rad] (one per joint, or one for
    all). Directions and limits are kept. Pure: nothing is read or written here.
    """
    angles = (
        [float(known_angles_rad)] * len(calibrations)
        if isinstance(known_angles_rad, int | float)
        else [float(a) for a in known_angles_rad]
    )
    if len(angles) != len(calibrations):
        raise CalibrationError(f"{len(angles)} known angles for {len(calibrations)} joints")
    homed = []
    for cal, theta in zip(calibrations, angles, strict=True):
        if cal.servo_id not in present_ticks:
            raise CalibrationError(f"no present position for servo {cal.servo_id}")
        offset = present_ticks[cal.servo_id] - cal.direction * round(theta / RAD_PER_TICK)
        homed.append(replace(cal, zero_offset_ticks=int(offset)))
    return tuple(homed)


def guided_homing(
    calibrations: Sequence[JointCalibration],
    read_ticks: Callable[[], Mapping[int, int]],
    known_angles_rad: Sequence[float] | float = 0.0,
    confirm: Callable[[str], object] = input,
) -> tuple[JointCalibration, ...]:
    """Ask the operator to hold the known pose, read the raw positions, return new records.

    read_ticks: returns servo id -> Present Position [ticks] (e.g. DynamixelBus.read_ticks,
    with torque off so the links can be placed by hand). `confirm` shows a prompt and waits.
    """
    confirm(
        "Torque is off. Place the upper links at the homing pose "
        f"(joint angles {known_angles_rad} rad; 0 = horizontal jig), then press Enter. "
    )
    return home(calibrations, read_ticks(), known_angles_rad)


def load(path: str | Path) -> tuple[JointCalibration, ...]:
    """The joint records in `path` (TOML, ``[[hardware.joints]]``), in joint order."""
    with open(path, "rb") as file:
        config = tomllib.load(file)
    return from_config(config)


def from_config(config: Mapping[str, Any]) -> tuple[JointCalibration, ...]:
    """The joint records of an already parsed config mapping."""
    joints = config.get(SECTION, {}).get("joints")
    if not joints:
        raise CalibrationError(f"no [[{SECTION}.joints]] records in the config")
    try:  # a joint's position gains (the app's tuning) are no part of its calibration
        return tuple(
            JointCalibration(**{k: v for k, v in joint.items() if k not in OTHER_KEYS})
            for joint in joints
        )
    except TypeError as exc:
        raise CalibrationError(f"bad [[{SECTION}.joints]] record: {exc}") from exc


def save(path: str | Path, calibrations: Sequence[JointCalibration]) -> None:
    """Write the joint records into `path`, keeping every other section of the file and
    each record's other keys (a servo's ``gains``), matched by servo id."""
    path = Path(path)
    write_config(path, merge_joints(read_config(path), calibrations))


def read_config(path: str | Path) -> dict[str, Any]:
    """The parsed TOML file at `path`; empty when there is none yet."""
    path = Path(path)
    if not path.exists():
        return {}
    with open(path, "rb") as file:
        return tomllib.load(file)


def merge_joints(config: dict[str, Any], calibrations: Sequence[JointCalibration]) -> dict:
    """`config` (a parsed TOML mapping, changed in place and returned) with the joint
    records of `calibrations` in ``[[hardware.joints]]``, each record's other keys (a
    servo's ``gains``) kept, matched by servo id."""
    section = config.setdefault(SECTION, {})
    before = {j.get("servo_id"): j for j in section.get("joints", []) if isinstance(j, dict)}
    section["joints"] = [{**before.get(cal.servo_id, {}), **asdict(cal)} for cal in calibrations]
    return config


def write_config(path: str | Path, config: dict[str, Any]) -> None:
    """Write `config` as TOML to `path`, atomically: a crash mid-write never leaves a half
    config."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as file:
        tomli_w.dump(config, file)
    tmp.replace(path)
