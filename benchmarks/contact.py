"""Contact on the MuJoCo twin (issue 33): the force estimate against MuJoCo's own contact
force, touch repeatability, the compliant press, and the collision stop.

All in simulated time (tests/support/twin_loop.py: the loop stepped by hand, one physics
period per tick), so the figures do not depend on the machine's load. The truth is the
twin's contact force (mj_contactForce on the tip's contacts, hardware/sim/twin.py).

1. Estimate at rest: presses of 1, 3 and 6 N held on a plate under points over the
   workspace (x, y in {-60, 0, 60} mm, plates at z = -0.22 and -0.29 m), plus a wall
   (normal -x) for a sideways force; after 1.5 s of settling, 0.5 s of ticks compared.
   Estimate moving: free motion (truth 0) along a 30 mm, 1 Hz sinusoid in x and z; and
   a 2 N press while the pressed point slides 20 mm along x at 20 mm/s.
2. Touch: 20 touches down on the plate at 10 mm/s to 2 N, retracting 2 mm between; the
   contact point's bias and spread and the true peak force: from 20 mm above with the
   twin's exact currents, then from 15-25 mm above with 5.4 mA of current noise.
3. Press vs position hold under drift: on the simulated drone (app/world/drone_sim.py
   defaults: 2 cm RMS drift, 2 deg tilt, gusts; the twin's base feels it), a wall fixed
   in the world 4 mm ahead of the tip; a 2 N compliant press into it riding the hold in
   the world, against the plain position hold at the press's mean point; the true
   force's RMS error and the tip's world position error across the wall's normal.
4. Collision: with [contact] collision_stop (4 N), a move down into the plate at 20 and
   100 mm/s; from the first true contact to the tick the loop faulted, and the true peak.

5. (``--cost``) the estimate's cost in the tick: the controller's step with and without
   it, the physics excluded, best of 3 alternating blocks (a ratio in the same run).

Usage: PYTHONPATH=$PWD python benchmarks/contact.py [--quick | --gains | --cost]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(_HERE.parent))

import numpy as np  # noqa: E402

from app.control import commands, contact_commands  # noqa: E402
from app.control.sources import Setpoint  # noqa: E402
from app.world.drone_sim import DroneSimParams  # noqa: E402
from app.world.service import WorldService  # noqa: E402
from hardware.sim.surfaces import TIP_RADIUS_M, Plate  # noqa: E402
from tests.support.twin_loop import TwinLoop  # noqa: E402

CURRENT_NOISE_A = 0.0054  # two Present Current units RMS, as a real XM430 reads at rest


def _truth(loop: TwinLoop) -> np.ndarray:
    return np.asarray(loop.bus.measure_contact().force_n, dtype=float)


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(values) ** 2)))


def estimate_at_rest(quick: bool) -> None:
    print("\n== 1a. force estimate at rest, against MuJoCo's contact force ==")
    errors, std_ratio = [], []
    xs = (0.0,) if quick else (-0.06, 0.0, 0.06)
    for plate_z in (-0.26, -0.30):
        for x in xs:
            for y in xs:
                loop = TwinLoop([Plate(point_m=(x, y, plate_z))])
                try:
                    loop.move_to((x, y, plate_z + 0.004))
                    for force in (1.0, 3.0, 6.0):
                        state, ctx, c = loop.state, loop.ctx, loop.settings.contact
                        contact_commands.press(state, ctx, c, [0, 0, -1], force)
                        loop.step(int(1.5 / loop.period_s))
                        for _ in range(int(0.5 / loop.period_s)):
                            loop.step()
                            est = loop.snapshot.contact
                            err = est.force_n - _truth(loop)
                            errors.append(err)
                            std_ratio.append(np.abs(err) / est.std_n)
                        commands.stop_source(state, state.source)
                        loop.step(20)
                finally:
                    loop.close()
    # a wall: the force sideways
    loop = TwinLoop([Plate(point_m=(0.05, 0.0, -0.24), normal=(-1.0, 0.0, 0.0))])
    try:
        loop.move_to((0.05 - 0.004, 0.0, -0.24))
        for force in (1.0, 3.0):
            contact_commands.press(loop.state, loop.ctx, loop.settings.contact, [1, 0, 0], force)
            loop.step(int(1.5 / loop.period_s))
            for _ in range(int(0.5 / loop.period_s)):
                loop.step()
                est = loop.snapshot.contact
                errors.append(est.force_n - _truth(loop))
                std_ratio.append(np.abs(errors[-1]) / est.std_n)
            commands.stop_source(loop.state, loop.state.source)
            loop.step(20)
    finally:
        loop.close()
    e = np.asarray(errors)
    size = np.linalg.norm(e, axis=1)
    print(f"ticks compared: {len(e)}")
    print(f"|error| RMS {_rms(size):.3f} N, max {size.max():.3f} N")
    print("per axis RMS (x, y, z): " + ", ".join(f"{_rms(e[:, k]):.3f}" for k in range(3)) + " N")
    ratio = np.asarray(std_ratio)
    print(
        f"within 1 sigma: {np.mean(ratio <= 1) * 100:.1f} % of axis values, 3 sigma: "
        f"{np.mean(ratio <= 3) * 100:.1f} %"
    )


class _Slide:
    """A press's inner source: the pressed point slides along x at ``speed`` [m/s]."""

    name = "slide"

    def __init__(self, start: np.ndarray, speed: float, length: float) -> None:
        self.start, self.speed, self.length, self.t = start.copy(), speed, length, 0.0

    def next(self, dt_s: float) -> Setpoint:
        self.t += dt_s
        s = min(self.length, self.speed * self.t)
        point = self.start + np.array([s, 0.0, 0.0])
        return Setpoint(point_m=point, goal_m=point, finished=s >= self.length)


def estimate_moving(quick: bool) -> None:
    print("\n== 1b. force estimate while moving ==")
    loop = TwinLoop([Plate(point_m=(0.0, 0.0, -0.30))])  # out of the way
    try:
        for axis, name in ((0, "x"), (2, "z")):
            loop.move_to((0.0, 0.0, -0.24))
            errors = []
            start = loop.state.start_m.copy()
            t = 0.0
            for _ in range(int((1.0 if quick else 3.0) / loop.period_s)):
                t += loop.period_s
                goal = start.copy()
                goal[axis] += 0.03 * math.sin(2 * math.pi * t)
                loop.state.source = _Fixed(goal)
                loop.step()
                errors.append(loop.snapshot.contact.force_n - _truth(loop))
            loop.state.source = None
            size = np.linalg.norm(np.asarray(errors)[100:], axis=1)
            print(
                f"free, 30 mm 1 Hz sinusoid along {name}: |error| RMS {_rms(size):.3f} N, "
                f"max {size.max():.3f} N (truth 0)"
            )
    finally:
        loop.close()
    loop = TwinLoop([Plate(point_m=(0.0, 0.0, -0.26))])
    try:
        loop.move_to((-0.01, 0.0, -0.256))
        start = loop.state.start_m.copy()
        slide = _Slide(start, 0.02, 0.02)
        state, ctx, c = loop.state, loop.ctx, loop.settings.contact
        contact_commands.press(state, ctx, c, [0, 0, -1], 2.0, inner=None)
        loop.step(int(1.5 / loop.period_s))
        state.source.inner = slide  # the pressed point now slides
        errors = []
        while state.source is not None and not slide.t >= 1.0:
            loop.step()
            errors.append(loop.snapshot.contact.force_n - _truth(loop))
        size = np.linalg.norm(np.asarray(errors), axis=1)
        print(
            f"2 N press sliding 20 mm along x at 20 mm/s (friction 0.5): |error| RMS "
            f"{_rms(size):.3f} N, max {size.max():.3f} N"
        )
    finally:
        loop.close()


class _Fixed:
    name = "bench"

    def __init__(self, point: np.ndarray) -> None:
        self.point = point

    def next(self, dt_s: float) -> Setpoint:
        return Setpoint(point_m=self.point, goal_m=self.point)


def touches(quick: bool) -> None:
    print("\n== 2. touch repeatability ==")
    plate_z = -0.26
    surface = plate_z + TIP_RADIUS_M
    rng = np.random.default_rng(0)
    for noise_a, varied in ((0.0, False), (CURRENT_NOISE_A, True)):
        loop = TwinLoop([Plate(point_m=(0.0, 0.0, plate_z))], bus={"current_noise_a": noise_a})
        try:
            points, peaks = [], []
            for _ in range(5 if quick else 20):
                above = rng.uniform(0.015, 0.025) if varied else 0.02
                loop.move_to((0.0, 0.0, plate_z + above))
                c = loop.settings.contact
                contact_commands.touch(
                    loop.state, loop.ctx, c, [0, 0, -1], force_n=2.0, retract_m=0.002
                )
                peak = [0.0]

                def watch(t: TwinLoop, peak: list = peak) -> None:
                    peak[0] = max(peak[0], -float(_truth(t)[2]))

                loop.run_until(lambda t: t.state.source is None, 10.0, each=watch)
                touch = loop.snapshot.touch
                assert touch is not None and touch.outcome == "contact", touch
                points.append(touch.contact_point_m[2])
                peaks.append(peak[0])
            z, p = np.asarray(points), np.asarray(peaks)
            how = (
                f"current noise {noise_a * 1e3:.1f} mA RMS, start 15-25 mm above"
                if varied
                else "no current noise, start 20 mm above"
            )
            print(
                f"{len(z)} touches at 10 mm/s to 2 N ({how}): contact z bias "
                f"{(z.mean() - surface) * 1e6:+.0f} um, std {z.std() * 1e6:.1f} um, range "
                f"{np.ptp(z) * 1e6:.1f} um; true peak mean {p.mean():.2f} N, max {p.max():.2f} N"
            )
        finally:
            loop.close()


def _drift_run(
    press: bool, hold_s: float, goal_world: np.ndarray | None, seed: int, gain: float | None = None
) -> dict:
    """One hold on the simulated drone (thesis test 6.2's drift) against a wall fixed in
    the world 4 mm ahead of the tip along x: a compliant press of 2 N into it (``press``)
    or the plain position hold at ``goal_world`` [m]. The truth: MuJoCo's contact force
    along the wall's normal and the tip's world position across it."""
    wall = Plate(point_m=(0.004, 0.0, -0.24), normal=(-1.0, 0.0, 0.0), fixed_in="world")
    contact = {} if gain is None else {"admittance_m_per_n_s": gain}
    loop = TwinLoop([wall], contact=contact)
    try:
        loop.move_to((0.0, 0.0, -0.24))
        service = WorldService(loop.controller)
        provider = service.provider(DroneSimParams(seed=seed))
        hold = service.hold_source(goal_world, provider, compensate=True)
        hold.duration_s = hold_s + hold.approach_s
        state, ctx, c = loop.state, loop.ctx, loop.settings.contact
        if press:
            contact_commands.press(state, ctx, c, [1, 0, 0], 2.0, inner=hold, frame="world")
        else:
            commands.begin_motion(state, hold)
        forces, across, world, offsets = [], [], [], []

        def watch(t: TwinLoop) -> None:
            snap = t.snapshot
            extra = snap.extra or {}
            if snap.phase == "approach" or hold.t_s < hold.approach_s + 2.0:
                return  # the blend-in and the press's ramp: not measured
            _, normal = t.bus.twin.plate_pose(0)
            forces.append(-float(np.dot(_truth(t), normal)))  # pushed into the wall [N]
            measured = extra.get("measured_world_m")
            if measured is not None:
                error = np.asarray(measured) - hold.goal_world
                across.append(error[1:])  # world y, z: across the wall's normal (world x)
                world.append(np.asarray(measured))
            offsets.append(getattr(t.state.source, "s", 0.0))  # the press's offset [m]

        loop.run_until(lambda t: t.state.source is None, hold_s + 10.0, each=watch)
        faults = [f.reason for f in loop.state.faults]
        return {
            "forces": np.asarray(forces),
            "across": np.asarray(across),
            "world": np.asarray(world),
            "offset_m": float(np.mean(offsets)) if offsets else 0.0,
            "goal": hold.goal_world.copy(),
            "faults": faults,
        }
    finally:
        loop.close()


def drift(quick: bool) -> None:
    print("\n== 3. compliant press vs position hold on the simulated drone (thesis 6.2 drift) ==")
    hold_s = 8.0 if quick else 30.0
    pressed = _drift_run(True, hold_s, None, seed=0)
    f = pressed["forces"]
    print(
        f"press 2 N into a world-fixed wall, {hold_s:.0f} s ({len(f)} ticks): force mean "
        f"{f.mean():.2f} N, RMS error {_rms(f - 2.0):.2f} N, min {f.min():.2f} N, max "
        f"{f.max():.2f} N; across the normal RMS {_rms(pressed['across']) * 1e3:.2f} mm; "
        f"faults: {pressed['faults'] or 'none'}"
    )
    # the plain hold commands the point the press commanded on average (its hold's goal
    # shifted by its mean offset along the wall's normal, world x): 2 N at rest
    goal = pressed["goal"] + np.array([pressed["offset_m"], 0.0, 0.0])
    plain = _drift_run(False, hold_s, goal, seed=0)
    f = plain["forces"]
    print(
        f"plain position hold at the press's mean commanded point (offset "
        f"{pressed['offset_m'] * 1e3:.2f} mm): force mean {f.mean():.2f} N, "
        f"RMS error (to 2 N) {_rms(f - 2.0):.2f} N, min {f.min():.2f} N, max {f.max():.2f} N, "
        f"in contact {np.mean(f > 0.05) * 100:.0f} % of ticks; across the normal RMS "
        f"{_rms(plain['across']) * 1e3:.2f} mm; faults: {plain['faults'] or 'none'}"
    )


def tick_cost(ticks: int = 2000) -> None:
    """The estimate's cost in the tick: the controller's step (the physics excluded) with
    the estimator and without, alternating blocks, holding still and moving."""
    print(f"\n== 5. the estimate's cost per tick ({ticks} ticks each way, best of 3 blocks) ==")
    loop = TwinLoop([])
    try:
        monitor = loop.state.contact_monitor
        estimator = monitor.estimator
        for label in ("holding", "moving"):
            best = {"with": math.inf, "without": math.inf}
            for _ in range(3):
                for way in ("with", "without"):
                    monitor.estimator = estimator if way == "with" else None
                    if label == "moving":
                        start = loop.state.start_m.copy()
                        loop.state.source = _Fixed(start)
                    spent = 0.0
                    for k in range(ticks // 3):
                        if label == "moving":
                            loop.state.source.point = start + [0.01 * math.sin(k * 0.03), 0, 0]
                        loop.bus.advance(loop.period_s)
                        loop.now_s += loop.period_s
                        t0 = time.perf_counter()
                        loop.controller.step()
                        spent += time.perf_counter() - t0
                    best[way] = min(best[way], spent / (ticks // 3))
            loop.state.source = None
            monitor.estimator = estimator
            ratio = best["with"] / best["without"]
            print(
                f"{label}: tick {best['without'] * 1e6:.0f} us without the estimate, "
                f"{best['with'] * 1e6:.0f} us with it (x{ratio:.2f}; "
                f"{(best['with'] - best['without']) * 1e6:.0f} us of a 5,000 us period)"
            )
    finally:
        loop.close()


def gain_sweep(hold_s: float) -> None:
    print(f"\n== 3b. the press's admittance gain under the same drift ({hold_s:.0f} s each) ==")
    for gain in (0.01, 0.02, 0.04, 0.08):
        f = _drift_run(True, hold_s, None, seed=0, gain=gain)["forces"]
        print(
            f"k_a {gain:.2f} m/(N s): force RMS error {_rms(f - 2.0):.3f} N, min {f.min():.2f} "
            f"N, max {f.max():.2f} N"
        )


def collisions(quick: bool) -> None:
    print("\n== 4. collision stop (force-limited motion, collision_force_n 4 N) ==")
    plate_z = -0.26
    for speed in (0.02, 0.1):
        loop = TwinLoop(
            [Plate(point_m=(0.0, 0.0, plate_z))],
            contact={"collision_stop": True, "collision_force_n": 4.0},
        )
        try:
            loop.move_to((0.0, 0.0, -0.24))
            start = loop.state.start_m.copy()
            commands.move(loop.state, loop.ctx, start + [0, 0, -0.04], 0.04 / speed, False)
            peak, touched = [0.0], [math.nan]

            def watch(t: TwinLoop, peak: list = peak, touched: list = touched) -> None:
                force = -float(_truth(t)[2])
                peak[0] = max(peak[0], force)
                if force > 0 and math.isnan(touched[0]):
                    touched[0] = t.now_s

            loop.run_until(lambda t: bool(t.state.faults), 10.0, each=watch)
            stopped = loop.now_s
            loop.step(int(0.5 / loop.period_s), each=watch)
            rest = -float(_truth(loop)[2])
            print(
                f"{speed * 1e3:.0f} mm/s: contact to stop {(stopped - touched[0]) * 1e3:.0f} ms, "
                f"true peak {peak[0]:.2f} N, 0.5 s later {rest:.2f} N; "
                f"fault: {loop.state.faults[0].reason}"
            )
        finally:
            loop.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer points and touches")
    parser.add_argument(
        "--gains", action="store_true", help="only the press's gain sweep under drift (8 s each)"
    )
    parser.add_argument("--cost", action="store_true", help="only the estimate's cost per tick")
    args = parser.parse_args()
    if args.gains:
        gain_sweep(8.0)
        return
    if args.cost:
        tick_cost()
        return
    print(
        f"{platform.node()} {platform.machine()} {os.cpu_count()} CPUs, "
        f"python {platform.python_version()}; simulated time (figures do not depend on load)"
    )
    started = time.monotonic()
    estimate_at_rest(args.quick)
    estimate_moving(args.quick)
    touches(args.quick)
    drift(args.quick)
    collisions(args.quick)
    print(f"\n({time.monotonic() - started:.0f} s of wall time)")


if __name__ == "__main__":
    main()
