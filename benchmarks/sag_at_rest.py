"""The error at rest after a move, gravity compensation off and on, on the twin.

Usage: python benchmarks/sag_at_rest.py [--move-s 1.0] [--rest-s 1.5] [--payload 0]

From the home point (0, 0, -0.24) m the platform moves to each of five points across the
workspace along a minimum-jerk line (--move-s), streamed through IK at 200 Hz as Goal
Position ticks with the factory gains (P 800), then rests (--rest-s). With compensation
each goal is shifted by app/control/gravity.py's offset, as the loop does with
``[control] gravity_compensation = true``. Printed per point: the true platform's distance
from the goal (what a motion-capture system sees) and FK of the encoder angles minus the
goal (what /api/status shows), in mm. Simulated time, no wall clock: the figures do not
depend on the machine's load.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.control.gravity import gravity_offset  # noqa: E402
from hardware.dynamixel.control_table import RAD_PER_TICK  # noqa: E402
from hardware.sim.masses import DeltaMasses  # noqa: E402
from hardware.sim.twin import DeltaTwin, TwinConfig, hold_command  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402

HOME = np.array([0.0, 0.0, -0.24])
POINTS = (
    (0.0, 0.0, -0.20),
    (0.06, 0.0, -0.24),
    (-0.04, 0.05, -0.22),
    (-0.03, -0.06, -0.27),
    (0.05, 0.05, -0.29),
)
RATE_HZ = 200


def blend(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def at_rest_after_move(
    twin: DeltaTwin, goal: np.ndarray, compensate: bool, move_s: float, rest_s: float
) -> tuple[float, float]:
    """(true, encoder-FK) distance [m] from `goal` at the end of the rest."""
    robot = THESIS_DELTA
    offset = gravity_offset(robot, twin.config.masses.payload_kg)
    q = robot.ik(HOME).joints
    twin.reset(q)
    steps = round((move_s + rest_s) * RATE_HZ)
    per_tick = round(1.0 / RATE_HZ / twin.model.opt.timestep)
    for k in range(steps + 1):
        point = HOME + blend(k / RATE_HZ / move_s) * (goal - HOME)
        q = robot.ik(point, near=q).joints
        servo = q + offset.offset_rad(q) if compensate else q
        ticks = np.round(twin.shafts_of_joints(servo) / RAD_PER_TICK)
        twin.set_commands([hold_command(float(t * RAD_PER_TICK)) for t in ticks])
        twin.step(per_tick)
    encoder = np.round(twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK
    fk = robot.fk(twin.joints_of_shafts(encoder)).points
    return float(np.linalg.norm(twin.platform_m - goal)), float(np.linalg.norm(fk - goal))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--move-s", type=float, default=1.0)
    parser.add_argument("--rest-s", type=float, default=1.5)
    parser.add_argument("--payload", type=float, default=0.0, help="payload [kg]")
    args = parser.parse_args()
    twin = DeltaTwin(TwinConfig(masses=DeltaMasses(payload_kg=args.payload)))
    print(
        f"error at rest [mm] after a {args.move_s} s move, {args.rest_s} s rest, P 800, "
        f"payload {args.payload} kg; true platform | FK of encoders"
    )
    print(f"{'point [mm]':>22} | {'off':>13} | {'on':>13}")
    worst = {False: 0.0, True: 0.0}
    for point in POINTS:
        goal = np.array(point)
        cells = []
        for compensate in (False, True):
            true_m, fk_m = at_rest_after_move(twin, goal, compensate, args.move_s, args.rest_s)
            worst[compensate] = max(worst[compensate], true_m)
            cells.append(f"{true_m * 1e3:5.2f} | {fk_m * 1e3:5.2f}")
        label = ", ".join(f"{v * 1e3:g}" for v in point)
        print(f"{label:>22} | {cells[0]:>13} | {cells[1]:>13}")
    print(f"worst true error: off {worst[False] * 1e3:.2f} mm, on {worst[True] * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
