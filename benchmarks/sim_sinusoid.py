"""The thesis's tracking test (ch. 6.1, Table 6.1) run on the simulator.

Usage: python benchmarks/sim_sinusoid.py [--seconds 10] [--warmup 1] [--payload 0]

X 5 cm at 1 Hz, Y 5 cm at 1 Hz, Z 8 cm at 2 Hz about (0, 0, -0.24) m, streamed through IK
at 200 Hz as Goal Position with the factory gains (P 800, I 0, D 0, no feed-forward, no
profile) at 12 V. The thesis does not give the X/Y phase: both a circle (Y a quarter period
behind X) and a diagonal line (in phase) are run. Errors are reported two ways: FK of the
encoder angles minus the reference (what Table 6.1 measured, from the servos' readings),
and the true platform minus the reference (what a motion-capture system would see).
Nothing here is tuned to the thesis's figures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hardware.dynamixel.control_table import RAD_PER_TICK  # noqa: E402
from hardware.sim.masses import DeltaMasses  # noqa: E402
from hardware.sim.twin import DeltaTwin, TwinConfig, hold_command  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402

THESIS_RMSE_MM = (8.081, 8.716, 14.721)


def reference(t: float, phase: float) -> np.ndarray:
    w = 2.0 * np.pi
    return np.array(
        [0.05 * np.sin(w * t), 0.05 * np.sin(w * t + phase), -0.24 + 0.08 * np.sin(2 * w * t)]
    )


def run(phase: float, seconds: float, warmup: float, payload_kg: float) -> dict[str, np.ndarray]:
    """RMSE [m] per axis of FK-of-encoder and true platform, and the peak PWM fraction."""
    twin = DeltaTwin(TwinConfig(masses=DeltaMasses(payload_kg=payload_kg)))
    robot = THESIS_DELTA
    q = robot.ik(reference(0.0, phase)).joints
    twin.reset(q)
    fk_errors, true_errors, pwm = [], [], 0.0
    for k in range(round((seconds + warmup) * 200)):
        q = robot.ik(reference(k / 200, phase), near=q).joints
        ticks = np.round(twin.shafts_of_joints(q) / RAD_PER_TICK)
        twin.set_commands([hold_command(float(t * RAD_PER_TICK)) for t in ticks])
        for _ in range(5):
            twin.step()
            if twin.time_s < warmup:
                continue
            goal = reference(twin.time_s, phase)
            encoder = np.round(twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK
            fk_errors.append(robot.fk(twin.joints_of_shafts(encoder)).points - goal)
            true_errors.append(twin.platform_m - goal)
            pwm = max(pwm, max(abs(o.pwm) for o in twin.outputs) / 885)
    return {
        "fk": np.sqrt(np.mean(np.square(fk_errors), axis=0)),
        "true": np.sqrt(np.mean(np.square(true_errors), axis=0)),
        "mean": np.mean(fk_errors, axis=0),
        "pwm": np.array(pwm),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measured s")
    parser.add_argument("--warmup", type=float, default=1.0, help="s left out at the start")
    parser.add_argument("--payload", type=float, default=0.0, help="payload [kg]")
    args = parser.parse_args()
    print(
        f"thesis Table 6.1 RMSE [mm]: X {THESIS_RMSE_MM[0]}, Y {THESIS_RMSE_MM[1]}, "
        f"Z {THESIS_RMSE_MM[2]}"
    )
    print(f"payload {args.payload} kg, {args.seconds:g} s measured after {args.warmup:g} s")
    for name, phase in (("circle (Y 90 deg behind X)", np.pi / 2), ("in phase (diagonal)", 0.0)):
        result = run(phase, args.seconds, args.warmup, args.payload)
        fk, true = result["fk"] * 1e3, result["true"] * 1e3
        print(f"{name}: peak PWM {100 * float(result['pwm']):.0f} %")
        print(f"  RMSE FK of encoders [mm]  X {fk[0]:6.2f}  Y {fk[1]:6.2f}  Z {fk[2]:6.2f}")
        print(f"  RMSE true platform [mm]   X {true[0]:6.2f}  Y {true[1]:6.2f}  Z {true[2]:6.2f}")
        mean = result["mean"] * 1e3
        print(f"  mean error FK [mm]        X {mean[0]:6.2f}  Y {mean[1]:6.2f}  Z {mean[2]:6.2f}")


if __name__ == "__main__":
    main()
