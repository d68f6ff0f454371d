"""Identify the twin's servos from a step run and a chirp run (issue 21), and draw the Bode plot.

Usage: python benchmarks/identify_twin.py [--chirp-s 6] [--f1 8] [--png bode.png]

At (0, 0, -0.24) m: a 4 mm z step (1.5 s), then a 3 mm z chirp from 0.5 Hz to --f1 Hz over
--chirp-s s, both through the loop on the twin in its own process (the server's backend),
then app/tuning/identify.py per joint: the fitted K, wn, zeta, delay, -3 dB bandwidth and
RMSE, and the lag b = 2 zeta k / wn it implies against the motor's back-EMF damping
Kt Ke / R. Prints the machine's load: the loop's ticks, and so the data, depend on it.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.config import load_settings  # noqa: E402
from app.control.controller import Controller  # noqa: E402
from app.control.gravity import position_stiffness_nm_rad  # noqa: E402
from app.runs.logs import read_csv_rows  # noqa: E402
from app.runs.manager import RunManager  # noqa: E402
from app.runs.paths import ChirpParams, StepParams  # noqa: E402
from app.server.backends import open_backend  # noqa: E402
from app.tuning.identify import bode_figure, identify  # noqa: E402
from hardware.sim.xm430 import XM430_W210  # noqa: E402

HOME = (0.0, 0.0, -0.24)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chirp-s", type=float, default=6.0)
    parser.add_argument("--f1", type=float, default=8.0)
    parser.add_argument("--png", type=Path, default=Path("bode.png"))
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    settings = load_settings(
        hardware={"backend": "sim"}, runs={"folder": tempfile.mkdtemp(prefix="deltadash-id-")}
    )
    chirp = ChirpParams(amplitude_m=0.003, f0_hz=0.5, f1_hz=args.f1, duration_s=args.chirp_s)
    logs = {}
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            controller.set_torque(True).result(timeout=2.0)
            runs = RunManager(controller, settings.runs.folder_path)
            for kind, params in (
                ("step", StepParams(size_m=0.004, duration_s=1.5)),
                ("chirp", chirp),
            ):
                controller.set_goal(list(HOME)).result(timeout=2.0)
                time.sleep(1.5)  # settled, so both runs start alike
                run = runs.start(params, kind)
                run.done.wait()
                logs[kind] = run.folder / "log.csv"
                print(f"{kind}: {run.state}, {run.samples} ticks")
        finally:
            controller.stop()
    band = (chirp.f0_hz, chirp.f1_hz, chirp.duration_s)
    fits, bodes = identify(read_csv_rows(logs["step"]), read_csv_rows(logs["chirp"]), band)
    k = position_stiffness_nm_rad()
    p = XM430_W210
    print(
        f"P loop stiffness k {k:.2f} N m/rad; back-EMF damping Kt Ke / R "
        f"{p.torque_constant_nm_a * p.back_emf_v_s / p.resistance_ohm:.3f} N m s/rad"
    )
    for fit, bode in zip(fits, bodes, strict=True):
        m = fit.model
        print(
            f"joint {fit.joint}: K {m.gain:.3f} wn {m.wn_rad_s:.1f} rad/s zeta {m.zeta:.2f} "
            f"T {m.delay_s * 1e3:.1f} ms, -3 dB {m.bandwidth_hz():.2f} Hz, RMSE "
            f"{fit.rmse_rad * 1e3:.2f} mrad (nrmse {fit.nrmse:.2f}), b {m.damping_nms_rad(k):.3f}"
            f", {bode.freqs_hz.size} measured frequencies"
        )
    print(f"Bode plot: {bode_figure(fits, bodes, args.png)}")


if __name__ == "__main__":
    main()
