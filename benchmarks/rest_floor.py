"""The error at rest against the encoder's tick: is 0.2 mm at five points a loop's to win?

Usage: python benchmarks/rest_floor.py [--p 800 1000 1010 1095]

For each Position P gain (no I, no D), the twin's true platform error at rest after a 1 s
move to each of `app.tuning.twin_check`'s five points and 1.5 s at rest, the goals carrying
the loop's gravity offset (``[control] gravity_compensation``), as `twin_check.rest`
measures it; then the same with a host-side trim at rest: from 0.2 s after the move, every
50 ms each servo goal moves one tick towards the joint's ideal tick (IK of the goal, no
offset) while the encoder reads another, up to 3 ticks (an integral on the encoder, at the
host). Printed beside them, per point, the platform's displacement for one encoder tick of
its largest joint (FK's Jacobian column times 2 pi / 4096): the floor an encoder-closed
loop works at. Simulated time, no wall clock: the figures do not depend on the load.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.tuning.twin_check import (  # noqa: E402
    HOME_M,
    RATE_HZ,
    REST_POINTS_M,
    _blend,
    _offset,
    _per_tick,
    command,
    joint_gains,
    rest,
)
from hardware.bus import PositionGains  # noqa: E402
from hardware.dynamixel.control_table import RAD_PER_TICK  # noqa: E402
from hardware.sim.twin import DeltaTwin  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402

TRIM_AFTER_S = 0.2  # after the move, before the trim acts
TRIM_EVERY = 10  # loop ticks between trim steps (50 ms at 200 Hz)
TRIM_MAX_TICKS = 3


def tick_at_platform_m(point: np.ndarray) -> float:
    """The largest platform displacement [m] one joint's encoder tick makes at `point`."""
    q = THESIS_DELTA.ik(point).joints
    moved = []
    for i in range(3):
        dq = np.zeros(3)
        dq[i] = RAD_PER_TICK
        moved.append(np.linalg.norm(THESIS_DELTA.fk(q + dq).points - point))
    return float(max(moved))


def rest_trimmed(gains: PositionGains, move_s: float = 1.0, rest_s: float = 1.5) -> list[float]:
    """`twin_check.rest` with the gravity offset and the host's trim at rest (docstring)."""
    joint = joint_gains(gains)
    twin, robot = DeltaTwin(), THESIS_DELTA
    offset = _offset(joint, True)
    per_tick = _per_tick(twin)
    out = []
    for point in REST_POINTS_M:
        goal = np.array(point)
        q = robot.ik(HOME_M).joints
        twin.reset(q)
        trim = np.zeros(3)
        for k in range(round((move_s + rest_s) * RATE_HZ) + 1):
            target = HOME_M + _blend(k / RATE_HZ / move_s) * (goal - HOME_M)
            q = robot.ik(target, near=q).joints
            shifted = q + offset.offset_rad(q) if offset is not None else q
            ticks = np.round(twin.shafts_of_joints(shifted) / RAD_PER_TICK)
            if k / RATE_HZ > move_s + TRIM_AFTER_S and k % TRIM_EVERY == 0:
                ideal = np.round(twin.shafts_of_joints(q) / RAD_PER_TICK)
                reading = np.round(twin.shaft_rad / RAD_PER_TICK)
                trim = np.clip(trim + np.sign(ideal - reading), -TRIM_MAX_TICKS, TRIM_MAX_TICKS)
            twin.set_commands(
                [
                    command(float((t + d) * RAD_PER_TICK), g)
                    for t, d, g in zip(ticks, trim, joint, strict=True)
                ]
            )
            twin.step(per_tick)
        out.append(float(np.linalg.norm(twin.platform_m - goal)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--p", type=int, nargs="+", default=[800, 900, 1000, 1010, 1073, 1095])
    args = parser.parse_args()
    floor = [tick_at_platform_m(np.array(p)) for p in REST_POINTS_M]
    print("one tick of the largest joint at the platform [mm]:", fmt(floor))
    print("| P | rest at 5 points, offset [mm] | worst | with the host's trim [mm] | worst |")
    print("| --- | --- | --- | --- | --- |")
    for p in args.p:
        gains = PositionGains(p=p)
        plain, trimmed = rest(gains, gravity=True), rest_trimmed(gains)
        print(
            f"| {p} | {fmt(plain)} | {max(plain) * 1e3:.3f} | {fmt(trimmed)} | "
            f"{max(trimmed) * 1e3:.3f} |",
            flush=True,
        )


def fmt(values_m: list[float]) -> str:
    return " ".join(f"{v * 1e3:.3f}" for v in values_m)


if __name__ == "__main__":
    main()
