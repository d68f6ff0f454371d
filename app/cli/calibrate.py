"""``deltadash calibrate``: kinematic calibration (issue 20, docs/calibration.md).

On a running server (--url): take control, turn torque on, start a calibration run
(POST /api/calibration/run), show the identification's observability before the arm
moves and the progress while it does, then the fit. Offline (--from-csv FILE): fit pairs
of joint values and external measurements (columns q0_rad, q1_rad, q2_rad, x_m, y_m, z_m
and an optional set = fit | holdout; a run's pairs.csv is one) on the config's robot.

--measurement pose-input (with --url): the platform is measured by your motion capture,
streamed to the server's pose input as body "platform" (UDP JSON on [world] udp_port, or
POST/WebSocket /api/mav/pose; docs/calibration.md); the default, external, is the
backend's own measurement (the simulated robot's).

--probe --plate-z MM (with --url): no motion capture; the run touches a flat plate whose
height in the base frame is MM millimetres (negative: below the base) and fits from the
touch heights alone, saying which parameter combinations heights cannot pin
(--fit-plate-z also fits an error of the stated height). The simulated robot has a probe.

--write CONFIG saves the fitted joint offsets as new zero offsets in the config's
[[hardware.joints]] and, for --parameters geometry, each leg's fitted L, l, R, r as its
[robot.legs] (with --url the server's controller uses them at once too, through POST
/api/calibration/{run_id}/apply). A fit worse than the current model on the held-out
poses is never written.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

from app.cli.numbers import number

_EPILOG = (
    "Exit 0: fitted (and written when asked); 1: the run failed or the fit was refused; "
    "2: bad input or the server refused; 130: Ctrl-C (the run is aborted: the arm holds)."
)


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "calibrate",
        help="find the robot's joint offsets (and geometry) from external measurements",
        description=__doc__,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--url", default="http://127.0.0.1:8000", help="the server (default %(default)s)"
    )
    parser.add_argument("--poses", type=int, default=40, help="poses to visit (default 40)")
    parser.add_argument(
        "--parameters",
        choices=("offsets", "geometry"),
        default="offsets",
        help="offsets: joint offsets and measurement frame; geometry: also each leg's L, l, R",
    )
    parser.add_argument(
        "--measurement",
        choices=("external", "pose-input"),
        default="external",
        help="what measures the platform: the backend's own (default: the simulated "
        "robot's) or motion capture streamed to the pose input as body 'platform'",
    )
    parser.add_argument(
        "--probe",
        action="store_true",
        help="touch a flat plate at --plate-z instead of measuring the platform (z only)",
    )
    parser.add_argument(
        "--plate-z",
        type=number,
        metavar="MM",
        help="the plate's height in the base frame [mm] (negative), with --probe",
    )
    parser.add_argument(
        "--fit-plate-z", action="store_true", help="with --probe: fit an error of --plate-z too"
    )
    parser.add_argument("--from-csv", metavar="FILE", help="fit these pairs offline")
    parser.add_argument("--config", help="TOML config of the robot (offline fit)")
    parser.add_argument("--write", metavar="CONFIG", help="save the joint offsets to CONFIG")
    parser.add_argument(
        "--token", default=os.environ.get("DELTADASH_TOKEN"), help="the server's token"
    )
    parser.add_argument(
        "--take-over", action="store_true", help="take control from another client that holds it"
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON (SI)")
    parser.set_defaults(handler=run)
    return parser


def run(args: argparse.Namespace) -> int:
    if args.probe and args.from_csv:
        print(
            "error: --probe: touches are taken on a server (--url), not from --from-csv",
            file=sys.stderr,
        )
        return 2
    if args.measurement != "external" and (args.probe or args.from_csv):
        print(
            "error: --measurement: a probe run measures by its touches, and --from-csv "
            "reads its measurements from the file",
            file=sys.stderr,
        )
        return 2
    if (args.plate_z is not None or args.fit_plate_z) and not args.probe:
        print("error: --plate-z, --fit-plate-z: only with --probe", file=sys.stderr)
        return 2
    if args.probe and (args.plate_z is None or not math.isfinite(args.plate_z)):
        print("error: --plate-z: --probe needs the plate's height [mm]", file=sys.stderr)
        return 2
    if args.from_csv:
        return _offline(args)
    return _remote(args)


def format_result(body: dict[str, Any]) -> str:
    """The result in mm and degrees for a person."""
    lines = [f"state: {body['state']}" + (f" ({body['error']})" if body.get("error") else "")]
    if body.get("condition_number") is not None:
        lines.append(f"condition number: {body['condition_number']:.1f}")
    lines.append("unobservable: " + (", ".join(body.get("unobservable") or []) or "none"))
    for combination in body.get("unobservable_combinations") or []:
        lines.append(f"  not pinned: {combination}")
    if body.get("plate_error_m") is not None:
        lines.append(f"plate height error: {body['plate_error_m'] * 1e3:+.3f} mm")
    params = body.get("parameters")
    if params:
        offsets = ", ".join(f"{math.degrees(v):+.3f}" for v in params["joint_offsets_rad"])
        lines.append(f"joint offsets: {offsets} deg")
        if body.get("parameters_fitted") == "geometry":
            for key in ("L_m", "l_m", "R_m", "r_m"):
                values = ", ".join(f"{v * 1e3:.3f}" for v in params[key])
                lines.append(f"{key[0]}: {values} mm")
    for label, key in (
        ("RMSE before (fit poses)", "rmse_before_m"),
        ("RMSE after (fit poses)", "rmse_after_m"),
        ("RMSE before (held out)", "holdout_rmse_before_m"),
        ("RMSE after (held out)", "holdout_rmse_m"),
    ):
        if body.get(key) is not None:
            lines.append(f"{label}: {body[key] * 1e3:.3f} mm")
    return "\n".join(lines)


def _offline(args: argparse.Namespace) -> int:
    from app.calibration.fit import CalibrationError, fit
    from app.calibration.pairs import read_pairs
    from app.calibration.procedure import per_leg
    from app.config import ConfigError, load_settings

    try:
        settings = load_settings(args.config)  # with [robot.legs]: a fit from those legs
        nominal = per_leg(settings.robot.build())
        pairs = read_pairs(args.from_csv)
        result = fit(nominal, pairs.joints, pairs.measured, pairs.holdout, args.parameters)
    except (ConfigError, CalibrationError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    obs = result.observability
    body = {
        "state": "done" if result.better else "refused",
        "error": None if result.better else "worse than the current model on held-out poses",
        "parameters_fitted": args.parameters,
        "parameters": result.parameters_out(),
        "rmse_before_m": result.rmse_before_m,
        "rmse_after_m": result.rmse_after_m,
        "holdout_rmse_before_m": result.holdout_before_m,
        "holdout_rmse_m": result.holdout_rmse_m,
        "condition_number": obs.condition_number,
        "singular_values": obs.singular_values.tolist(),
        "unobservable": list(obs.unobservable),
        "measurement_frame": {
            "position_m": list(result.frame.position_m),
            "rpy_rad": list(result.frame.rpy_rad),
        },
    }
    code = _show(body, args.json)
    if code == 0 and args.write:
        robot = result.robot if args.parameters == "geometry" else None
        code = _write(args.write, body["parameters"]["joint_offsets_rad"], robot)
    return code


def _show(body: dict[str, Any], as_json: bool) -> int:
    print(json.dumps(body, indent=1) if as_json else format_result(body))
    return 0 if body["state"] in ("done", "applied") else 1


def _write(config: str, offsets_rad: list[float], robot: Any = None) -> int:
    """Save ``offsets_rad`` into CONFIG's joint zero offsets (relative to what it holds)
    and, for a geometry fit, ``robot``'s legs (a PerLegRotaryDelta) as [robot.legs]."""
    from app.calibration.procedure import write_calibration
    from app.config import ConfigError, load_settings

    try:
        settings = load_settings(config if Path(config).exists() else None)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    joints = [joint.calibration() for joint in settings.hardware.joints]
    write_calibration(Path(config), joints, offsets_rad, robot)
    what = "joint zero offsets" + (" and [robot.legs]" if robot is not None else "")
    print(f"{what} written to {config}", file=sys.stderr)
    return 0


def _remote(args: argparse.Namespace) -> int:
    from app.cli import run as cli_run
    from app.cli.progress import Progress

    url = args.url.rstrip("/")

    def work(headers: dict[str, str], problems: list[str]) -> int:
        running = None  # the run to abort if this ends (Ctrl-C) before it does
        try:
            if args.measurement == "pose-input":  # before torque on: nothing to measure by
                stream = cli_run._http(f"{url}/api/mav/pose?body=platform", headers=headers)
                if stream["state"] != "ok":
                    print(
                        f"error: --measurement pose-input: the platform marker's stream is "
                        f"{stream['state']} (body 'platform' on the pose input; "
                        f"{stream['accepted']} samples taken, {stream['dropped']} dropped, "
                        f"{stream.get('udp_errors') or 0} datagrams refused); start it first "
                        "(docs/calibration.md)",
                        file=sys.stderr,
                    )
                    return 2
            cli_run._http(f"{url}/api/torque", "POST", {"enabled": True}, headers)
            request: dict[str, Any] = {"poses": args.poses, "parameters": args.parameters}
            if args.probe:
                request |= {
                    "source": "probe",
                    "plate_z_m": args.plate_z * 1e-3,
                    "fit_plate_z": bool(args.fit_plate_z),
                }
            elif args.measurement != "external":
                request["measurement"] = args.measurement
            run_id = cli_run._http(f"{url}/api/calibration/run", "POST", request, headers)["run_id"]
            running = run_id
            body = cli_run._http(f"{url}/api/calibration/{run_id}", headers=headers)
            condition = body["condition_number"]
            print(
                f"calibration {run_id}: {body['progress']['poses']} poses "
                f"({body['holdout_poses']} held out), condition number "
                f"{'inf' if condition is None else f'{condition:.1f}'}, unobservable: "
                f"{', '.join(body['unobservable']) or 'none'}",
                file=sys.stderr,
            )
            with Progress(body["progress"]["poses"], f"calibration {run_id}", "poses") as bar:
                while body["state"] in ("planned", "moving", "fitting"):
                    bar.update_to(body["progress"]["pose"], body["state"])
                    time.sleep(0.5)
                    body = cli_run._http(f"{url}/api/calibration/{run_id}", headers=headers)
            running = None
            code = _show(body, args.json)
            if code == 0 and args.write:
                code = _apply(url, run_id, headers, args)
        finally:
            if running is not None:  # the arm stops and holds where it is
                path = f"/api/calibration/{running}/abort"
                cli_run._try(problems, f"abort calibration {running}", url, path, "POST", headers)
        return code

    return cli_run.under_control(
        url, args.token, args.take_over, work, "interrupted (the calibration run was aborted)"
    )


def _apply(url: str, run_id: str, headers: dict[str, str], args: argparse.Namespace) -> int:
    """POST apply; the server writes its own config when it has one, else we write --write."""
    from app.cli import run as cli_run
    from kinematics import PerLegRotaryDelta

    body = cli_run._http(f"{url}/api/calibration/{run_id}/apply", "POST", None, headers)
    print(f"applied: the controller uses joint offsets {body['joint_offsets_rad']} rad")
    model = body.get("robot") or {}
    if model.get("kind") == "per-leg":
        print(f"applied: the controller's robot has per-leg geometry ({model['origin']})")
    if body.get("config_written"):
        print(f"the server wrote {body['config_written']}", file=sys.stderr)
        return 0
    robot = None
    if args.parameters == "geometry":
        legs = {name: model[f"{name}_m"] for name in ("L", "l", "R", "r")}
        robot = PerLegRotaryDelta(**legs, angles_rad=model["angles_rad"])
    return _write(args.write, body["joint_offsets_rad"], robot)
