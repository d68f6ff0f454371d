"""The thesis's tracking test on the twin with the gains app/tuning/gains.py suggests.

Usage: python benchmarks/tuned_sinusoid.py [--seconds 3] [--bandwidth 20] [--lead 0.02]
       [--gravity-compensation]
       [--wn 53] [--zeta 0.75] [--delay 0.008]
       [--compare-feedforward [--gains P I D]]

The joint model is the one the identification fits on the twin (wn ~53 rad/s, zeta ~0.75,
T ~8 ms). The factory gains, then every candidate `app.tuning.twin_check.offer` tries for
the target bandwidth (tighter and tighter tick-noise D caps), are checked on the twin by
`twin_check.check` (simulated time): the thesis sinusoid without and with the loop's lead
(--lead), RMSE of FK of the encoders per axis, the share of time a PWM is at its limit,
the 20 mm z step's overshoot and the error at rest at five points; and the limits each
misses. --gravity-compensation: the goals shifted by the loop's gravity offset (as with
``[control] gravity_compensation = true``; it acts only on gains without I), and the
candidates tried both with and without I. The last line names the gains offered.

--compare-feedforward: then (or at once, for --gains P I D) the servos' own feed-forward
against the loop's lead time in the same conditions, with those P/I/D: the thesis
sinusoid (plain RMSE, no lead unless a row says so) with the Feedforward 1st/2nd gains the
rule gives for the model (FF1 = 4 a / (g n dt), FF2 = 4 / (g n dt^2)) or none, the
firmware's velocity-based Profile off (as the loop drives the servos: the goal is a step,
and FF1 / FF2, which act on the Profile's velocity and acceleration, act on nothing) or
set to k times the path's peak shaft speed and acceleration (FF1 and FF2, or FF1 alone),
and the loop's lead 0 to 40 ms with no feed-forward of the servo's. One row each.
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
from app.tuning.twin_check import (  # noqa: E402
    NO_PROFILE,
    Tracking,
    Verdict,
    check,
    offer,
    sinusoid,
    thesis_reference,
)
from hardware.bus import PositionGains  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402

LEADS_S = (0.0, 0.01, 0.015, 0.02, 0.022, 0.024, 0.026, 0.03, 0.04)
PROFILE_SCALES = (1.5, 3.0, 10.0)  # Profile limits: this many times the path's peaks


def row(name: str, g: PositionGains, v: Verdict) -> str:
    def mm(t):
        return " / ".join(f"{1e3 * x:.2f}" for x in t.rmse_m) + f" | {100 * t.at_limit:.1f} %"

    rest = " ".join(f"{1e3 * r:.2f}" for r in v.rest_m)
    return (
        f"| {name} | {g.p} {g.i} {g.d} | {mm(v.plain)} | {mm(v.lead)} | "
        f"{v.overshoot_pct:.1f} | {rest} | {', '.join(v.failed) or 'none'} |"
    )


def path_peaks() -> tuple[float, float]:
    """The thesis sinusoid's peak joint (= shaft) speed [rad/s] and acceleration
    [rad/s^2] over the three joints: IK at 1 kHz over one second (its period),
    central differences."""
    dt = 1e-3
    points = np.array([thesis_reference(t) for t in np.arange(0.0, 1.0 + 3 * dt, dt)])
    q = THESIS_DELTA.ik(points).joints
    v = np.gradient(q, dt, axis=0)
    a = np.gradient(v, dt, axis=0)
    return float(np.abs(v[2:-2]).max()), float(np.abs(a[2:-2]).max())


def ff_row(name: str, t: Tracking) -> str:
    rmse = " / ".join(f"{1e3 * x:.2f}" for x in t.rmse_m)
    return f"| {name} | {rmse} | {100 * t.peak_pwm:.0f} % | {100 * t.at_limit:.1f} % |"


def compare_feedforward(pid: PositionGains, plant: Plant, seconds: float, gravity: bool) -> None:
    """The servos' feed-forward against the loop's lead (module docstring), one row each."""
    rule = suggest(plant, Target(feedforward=True)).gains
    ff = replace(pid, feedforward_1st=rule.feedforward_1st, feedforward_2nd=rule.feedforward_2nd)
    off = replace(pid, feedforward_1st=0, feedforward_2nd=0)
    ff1 = replace(off, feedforward_1st=rule.feedforward_1st)
    v_peak, a_peak = path_peaks()
    print(
        f"\nP {pid.p}, I {pid.i}, D {pid.d}; FF1 {ff.feedforward_1st}, FF2 "
        f"{ff.feedforward_2nd} (the rule's for the model); path peaks {v_peak:.2f} rad/s, "
        f"{a_peak:.1f} rad/s^2 per joint"
    )
    print("| feed-forward | RMSE X / Y / Z [mm] | peak PWM | at limit |")
    print("|---|---|---|---|")

    def show(name, gains, lead_s=0.0, profile=NO_PROFILE):
        t = sinusoid(gains, seconds, lead_s, gravity=gravity, profile=profile)
        print(ff_row(name, t), flush=True)

    for lead in LEADS_S:
        show(f"loop lead {lead * 1e3:g} ms, servo FF off, Profile off", off, lead)
    show("servo FF1/FF2 on, Profile off, no lead", ff)
    for k in PROFILE_SCALES:
        profile = (k * v_peak, k * a_peak)
        what = f"Profile {k:g}x ({profile[0]:.1f} rad/s, {profile[1]:.0f} rad/s^2)"
        show(f"{what}, servo FF off, no lead", off, profile=profile)
        show(f"{what}, servo FF1 on (FF2 off), no lead", ff1, profile=profile)
        show(f"{what}, servo FF1/FF2 on, no lead", ff, profile=profile)
        show(f"{what}, servo FF1/FF2 on, loop lead 20 ms", ff, 0.02, profile)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="measured s")
    parser.add_argument("--bandwidth", type=float, default=20.0, help="target [Hz]")
    parser.add_argument("--lead", type=float, default=0.02, help="loop's lead [s]")
    parser.add_argument("--wn", type=float, default=53.0, help="identified wn [rad/s]")
    parser.add_argument("--zeta", type=float, default=0.75, help="identified damping")
    parser.add_argument("--delay", type=float, default=0.008, help="identified delay [s]")
    parser.add_argument("--gravity-compensation", action="store_true")
    parser.add_argument(
        "--compare-feedforward", action="store_true", help="servo FF1/FF2 against the lead"
    )
    parser.add_argument(
        "--gains", type=int, nargs=3, metavar=("P", "I", "D"), help="for the comparison alone"
    )
    args = parser.parse_args()
    gravity = args.gravity_compensation
    plant = Plant.of(JointModel(1.0, args.wn, args.zeta, args.delay))
    if args.gains is not None:
        if not args.compare_feedforward:
            parser.error("--gains is for --compare-feedforward")
        compare_feedforward(PositionGains(*args.gains), plant, args.seconds, gravity)
        return
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
    if args.compare_feedforward:
        compare_feedforward(found.gains[0], plant, args.seconds, gravity)


if __name__ == "__main__":
    main()
