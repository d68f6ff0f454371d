"""``deltadash tune``: identify each joint's servo loop and suggest gains (issue 21).

On a running server (--url): take control, turn torque on, start a tuning run
(POST /api/tuning/run: the arm moves to the runs' start point, records a step and a chirp
run, fits each joint's model K wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-sT}), show the
progress, then the models and the suggested gains with what they are predicted to do.
--apply makes the servos use them (POST /api/tuning/{run_id}/apply); --revert alone puts
back the gains in use before the last apply (POST /api/tuning/revert).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

_EPILOG = (
    "Exit 0: gains suggested (and applied when asked) or reverted; 1: the run failed; "
    "2: bad input or the server refused; 130: Ctrl-C (the run is aborted: the arm holds)."
)
STAGES = ("planned", "moving", "step", "chirp", "fitting")


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "tune",
        help="identify the joints' servo loops and suggest (and apply) position gains",
        description=__doc__,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--url", default="http://127.0.0.1:8000", help="the server (default %(default)s)"
    )
    parser.add_argument(
        "--joints", type=int, nargs="+", default=[1, 2, 3], help="joints to tune (default 1 2 3)"
    )
    parser.add_argument(
        "--bandwidth", type=float, default=20.0, help="target bandwidth [Hz] (default 20)"
    )
    parser.add_argument(
        "--overshoot", type=float, default=5.0, help="largest step overshoot [%%] (default 5)"
    )
    parser.add_argument("--apply", action="store_true", help="apply the suggested gains")
    parser.add_argument(
        "--revert", action="store_true", help="only put back the gains before the last apply"
    )
    parser.add_argument(
        "--token", default=os.environ.get("DELTADASH_TOKEN"), help="the server's token"
    )
    parser.add_argument(
        "--take-over", action="store_true", help="take control from another client that holds it"
    )
    parser.add_argument("--json", action="store_true", help="print the run as JSON (SI)")
    parser.set_defaults(handler=run)
    return parser


def _gains(g: dict[str, int]) -> str:
    return f"P {g['p']}, I {g['i']}, D {g['d']}, FF1 {g['ff1']}, FF2 {g['ff2']}"


def _number(value: Any, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def format_result(body: dict[str, Any]) -> str:
    """The run for a person: per servo, the model in Hz and ms, the suggested gains (the
    XM430's register units) and the predicted bandwidth, margin and overshoot now and
    with them."""
    lines = [f"state: {body['state']}" + (f" ({body['error']})" if body.get("error") else "")]
    for sid, model in sorted(body.get("model", {}).items(), key=lambda kv: int(kv[0])):
        lines.append(
            f"servo {sid} (joint {model['joint']}): model K {model['gain']:.3f}, "
            f"wn {model['wn_rad_s'] / (2 * 3.141592653589793):.1f} Hz, zeta "
            f"{model['zeta']:.2f}, delay {model['delay_s'] * 1e3:.1f} ms, -3 dB "
            f"{_number(model['bandwidth_hz'], '.1f')} Hz, fit RMSE "
            f"{model['rmse_rad'] * 1e3:.2f} mrad"
        )
        if sid in body.get("suggested", {}):
            lines.append(f"  suggested: {_gains(body['suggested'][sid])}")
        predicted = body.get("predicted", {}).get(sid)
        if predicted:
            for label, key in (("now", "current"), ("suggested", "suggested")):
                p = predicted.get(key)
                if p:
                    lines.append(
                        f"  predicted {label}: -3 dB {_number(p['bandwidth_hz'], '.1f')} Hz, "
                        f"phase margin {_number(p['phase_margin_deg'], '.0f')} deg, "
                        f"step overshoot {_number(p['overshoot_pct'], '.1f')} %, peak PWM "
                        f"{_number(p['peak_pwm_fraction'] * 100, '.0f')} %"
                    )
            if not predicted.get("meets_target", True):
                lines.append("  (the target could not be met: the closest gains are shown)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from app.cli import run as cli_run

    url = args.url.rstrip("/")

    def work(headers: dict[str, str], problems: list[str]) -> int:
        if args.revert:
            body = cli_run._http(f"{url}/api/tuning/revert", "POST", None, headers)
            _print_gains("reverted", body)
            return 0
        return _tune(url, headers, args)

    return cli_run.under_control(
        url, args.token, args.take_over, work, "interrupted (the tuning run was aborted)"
    )


def _print_gains(what: str, body: dict[str, Any]) -> None:
    print(f"{what}: the servos now use")
    for sid, g in sorted(body["gains"].items(), key=lambda kv: int(kv[0])):
        print(f"  servo {sid}: {_gains(g)}")
    if body.get("config_written"):
        print(f"the server wrote {body['config_written']}", file=sys.stderr)


def _tune(url: str, headers: dict[str, str], args: argparse.Namespace) -> int:
    """Run, show, and apply when asked; the exit code."""
    from app.cli import run as cli_run
    from app.cli.progress import Progress

    cli_run._http(f"{url}/api/torque", "POST", {"enabled": True}, headers)
    request = {
        "joints": args.joints,
        "target": {"bandwidth_hz": args.bandwidth, "overshoot_pct": args.overshoot},
    }
    run_id = cli_run._http(f"{url}/api/tuning/run", "POST", request, headers)["run_id"]
    try:
        body = cli_run._http(f"{url}/api/tuning/{run_id}", headers=headers)
        with Progress(len(STAGES), f"tuning {run_id}", "stages") as bar:
            while body["state"] in STAGES:
                bar.update_to(STAGES.index(body["state"]), body["state"])
                time.sleep(0.5)
                body = cli_run._http(f"{url}/api/tuning/{run_id}", headers=headers)
    except BaseException:  # Ctrl-C (or a lost server) while it runs: stop the arm there
        problems: list[str] = []
        path = f"/api/tuning/{run_id}/abort"
        cli_run._try(problems, f"abort tuning {run_id}", url, path, "POST", headers)
        for problem in problems:
            print(f"error: {problem}", file=sys.stderr)
        raise
    print(json.dumps(body, indent=1) if args.json else format_result(body))
    code = 0 if body["state"] == "done" else 1
    if code == 0 and args.apply:
        applied = cli_run._http(f"{url}/api/tuning/{run_id}/apply", "POST", None, headers)
        _print_gains("applied", applied)
    return code
