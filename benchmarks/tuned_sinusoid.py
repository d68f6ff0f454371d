"""The thesis's tracking test on the twin with the gains app/tuning/gains.py suggests.

Usage: python benchmarks/tuned_sinusoid.py [--seconds 4] [--bandwidths 10 20 30]
       [--wn 53] [--zeta 0.75] [--delay 0.008]

The joint model is the one the identification fits on the twin (tests/tuning/
test_identify.py's step and chirp runs: wn ~53 rad/s, zeta ~0.75, T ~8 ms); for each
target bandwidth the suggested gains (the same for the three joints) are written to the
twin's servo models and the sinusoid of benchmarks/sim_sinusoid.py (X, Y 5 cm at 1 Hz, Z
8 cm at 2 Hz, in phase) is streamed at 200 Hz, goals as they are (no lead). Reported: the
gains, RMSE of FK of the encoders against the reference [mm], the peak PWM and the share
of servo periods at the PWM limit, and the error at rest [mm] 1 s after the path stops.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.tuning.gains import Plant, Target, suggest  # noqa: E402
from app.tuning.identify import JointModel  # noqa: E402
from hardware.bus import PositionGains  # noqa: E402
from hardware.dynamixel.control_table import RAD_PER_TICK  # noqa: E402
from hardware.sim.twin import DeltaTwin, hold_command  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sim_sinusoid import THESIS_RMSE_MM, reference  # noqa: E402


def command(shaft_rad: float, gains: PositionGains):
    return replace(
        hold_command(shaft_rad),
        position_p=gains.p,
        position_i=gains.i,
        position_d=gains.d,
        feedforward_1st=gains.feedforward_1st,
        feedforward_2nd=gains.feedforward_2nd,
    )


def run(gains: PositionGains, seconds: float, warmup: float = 1.0) -> dict[str, float]:
    twin, robot = DeltaTwin(), THESIS_DELTA
    q = robot.ik(reference(0.0, 0.0)).joints
    twin.reset(q)
    errors, peak, saturated, periods = [], 0.0, 0, 0
    for k in range(round((seconds + warmup) * 200)):
        q = robot.ik(reference(k / 200, 0.0), near=q).joints
        ticks = np.round(twin.shafts_of_joints(q) / RAD_PER_TICK)
        twin.set_commands([command(float(t * RAD_PER_TICK), gains) for t in ticks])
        for _ in range(5):
            twin.step()
            if twin.time_s < warmup:
                continue
            encoder = np.round(twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK
            errors.append(
                robot.fk(twin.joints_of_shafts(encoder)).points - reference(twin.time_s, 0)
            )
            pwm = [abs(o.pwm) / 885 for o in twin.outputs]
            peak = max(peak, *pwm)
            saturated += any(p >= 0.999 for p in pwm)
            periods += 1
    # rest: hold the last goal 1 s, then the error of the encoders' FK from it
    goal = robot.fk(q).points
    for _ in range(1000):
        twin.step()
    encoder = np.round(twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK
    rest = float(np.linalg.norm(robot.fk(twin.joints_of_shafts(encoder)).points - goal))
    rmse = np.sqrt(np.mean(np.square(errors), axis=0)) * 1e3
    return {
        "x": rmse[0],
        "y": rmse[1],
        "z": rmse[2],
        "peak_pwm": peak,
        "saturated": saturated / periods,
        "rest_mm": rest * 1e3,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="measured s")
    parser.add_argument("--bandwidths", type=float, nargs="+", default=[10.0, 20.0, 30.0])
    parser.add_argument("--wn", type=float, default=53.0, help="identified wn [rad/s]")
    parser.add_argument("--zeta", type=float, default=0.75, help="identified damping")
    parser.add_argument("--delay", type=float, default=0.008, help="identified delay [s]")
    args = parser.parse_args()
    plant = Plant.of(JointModel(1.0, args.wn, args.zeta, args.delay))
    print(
        f"thesis Table 6.1 RMSE [mm]: X {THESIS_RMSE_MM[0]}, Y {THESIS_RMSE_MM[1]}, "
        f"Z {THESIS_RMSE_MM[2]}; in phase, {args.seconds:g} s measured"
    )
    rows = [("factory", PositionGains())]
    for f in args.bandwidths:
        rows.append((f"{f:g} Hz", suggest(plant, Target(bandwidth_hz=f)).gains))
    print("gains | P I D FF1 FF2 | RMSE X Y Z [mm] | peak PWM | at limit | rest [mm]")
    for name, g in rows:
        r = run(g, args.seconds)
        print(
            f"{name} | {g.p} {g.i} {g.d} {g.feedforward_1st} {g.feedforward_2nd} | "
            f"{r['x']:.2f} {r['y']:.2f} {r['z']:.2f} | {100 * r['peak_pwm']:.0f} % | "
            f"{100 * r['saturated']:.1f} % | {r['rest_mm']:.3f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
