"""The thesis's tracking test on the twin with the gains app/tuning/gains.py suggests.

Usage: python benchmarks/tuned_sinusoid.py [--seconds 3] [--bandwidth 20] [--lead 0.02]
       [--gravity-compensation]
       [--wn 53] [--zeta 0.75] [--delay 0.008]

The joint model is the one the identification fits on the twin (wn ~53 rad/s, zeta ~0.75,
T ~8 ms). The factory gains, then every candidate `app.tuning.twin_check.offer` tries for
the target bandwidth (tighter and tighter tick-noise D caps), are checked on the twin by
`twin_check.check` (simulated time): the thesis sinusoid without and with the loop's lead
(--lead), RMSE of FK of the encoders per axis, the share of time a PWM is at its limit,
the 20 mm z step's overshoot and the error at rest at five points; and the limits each
misses. --gravity-compensation: the goals shifted by the loop's gravity offset (as with
``[control] gravity_compensation = true``; it acts only on gains without I), and the
candidates tried both with and without I. The last line names the gains offered.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.tuning.gains import Plant, Target  # noqa: E402
from app.tuning.identify import JointModel  # noqa: E402
from app.tuning.twin_check import Verdict, check, offer  # noqa: E402
from hardware.bus import PositionGains  # noqa: E402


def row(name: str, g: PositionGains, v: Verdict) -> str:
    def mm(t):
        return " / ".join(f"{1e3 * x:.2f}" for x in t.rmse_m) + f" | {100 * t.at_limit:.1f} %"

    rest = " ".join(f"{1e3 * r:.2f}" for r in v.rest_m)
    return (
        f"| {name} | {g.p} {g.i} {g.d} | {mm(v.plain)} | {mm(v.lead)} | "
        f"{v.overshoot_pct:.1f} | {rest} | {', '.join(v.failed) or 'none'} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="measured s")
    parser.add_argument("--bandwidth", type=float, default=20.0, help="target [Hz]")
    parser.add_argument("--lead", type=float, default=0.02, help="loop's lead [s]")
    parser.add_argument("--wn", type=float, default=53.0, help="identified wn [rad/s]")
    parser.add_argument("--zeta", type=float, default=0.75, help="identified damping")
    parser.add_argument("--delay", type=float, default=0.008, help="identified delay [s]")
    parser.add_argument("--gravity-compensation", action="store_true")
    args = parser.parse_args()
    gravity = args.gravity_compensation
    plant = Plant.of(JointModel(1.0, args.wn, args.zeta, args.delay))
    print(
        "| gains | P I D | plain RMSE X / Y / Z [mm] | at limit | lead RMSE X / Y / Z [mm] "
        "| at limit | overshoot [%] | rest at 5 points [mm] | fails |"
    )
    factory = PositionGains()
    print(
        row("factory", factory, check(factory, args.lead, args.seconds, gravity=gravity)),
        flush=True,
    )
    found = offer(
        plant, Target(bandwidth_hz=args.bandwidth), args.lead, args.seconds, gravity=gravity
    )
    for c in found.tried:  # one plant for the three joints: the same gains on each
        target = c.target
        name = f"pwm_fraction {target.pwm_fraction:g}, model overshoot {target.overshoot_pct:g} %"
        name += "" if target.integral else ", no I"
        print(row(name, c.gains[0], c.verdict), flush=True)
    print(f"offered: {found.gains[0]} (pwm_fraction {found.target.pwm_fraction:g}): {found.reason}")


if __name__ == "__main__":
    main()
