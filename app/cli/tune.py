"""``deltadash tune``: identify each joint's servo loop and suggest gains (issue 21).

On a running server (--url): take control, turn torque on, start a tuning run
(POST /api/tuning/run: the arm moves to the runs' start point, records a step and a chirp
run, fits each joint's model K wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-sT}), show the
progress, then the models, the candidate gains checked on the twin (the thesis sinusoid
plain and with the loop's lead, a 20 mm z step, rest at five points) and the suggested
gains (the check's choice, with why) with what the model predicts of them.
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

from app.cli.numbers import number
from app.procedures.states import TUNING_RUNNING

_EPILOG = (
    "Exit 0: gains suggested (and applied when asked) or reverted; 1: the run failed; "
    "2: bad input or the server refused; 130: Ctrl-C (the run is aborted: the arm holds)."
)
STAGES = TUNING_RUNNING  # the running states, in order: the progress bar's stages


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
        "--bandwidth", type=number, default=20.0, help="target bandwidth [Hz] (default 20)"
    )
    parser.add_argument(
        "--overshoot", type=number, default=5.0, help="largest step overshoot [%%] (default 5)"
    )
    parser.add_argument("--apply", action="store_true", help="apply the suggested gains")
    parser.add_argument(
        "--confirm-missed",
        action="store_true",
        help="with --apply: apply them even when they miss the goal on the twin",
    )
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
    if body.get("checked"):
        lines += format_checked(body["checked"])
    return "\n".join(lines)


def _per_servo(gains: dict[str, dict[str, int]], key: str) -> str:
    values = [gains[sid][key] for sid in sorted(gains, key=int)]
    return str(values[0]) if len(set(values)) == 1 else "/".join(map(str, values))


def _mm(values: list[float]) -> str:
    return " / ".join(f"{v * 1e3:.2f}" for v in values)


def format_checked(checked: dict[str, Any]) -> list[str]:
    """The twin check for a person: a line per candidate (P, I, D per servo where they
    differ; RMSE x / y / z in mm plain and with lead; PWM at its limit; step overshoot;
    the worst error at rest; what it misses), which was chosen and why, and whether it
    meets issue 21's goal."""
    limits = checked["limits"]
    ids = "/".join(sorted(checked["candidates"][0]["gains"], key=int))
    lines = [
        f"checked on the twin, gains per servo {ids} where they differ (lead "
        f"{checked['lead_s'] * 1e3:g} ms, gravity offset "
        f"{'on' if checked['gravity_compensation'] else 'off'}; goal: RMSE x, y < "
        f"{limits['rmse_xy_m'] * 1e3:g} mm, z < {limits['rmse_z_m'] * 1e3:g} mm, PWM at its "
        f"limit <= {limits['at_limit'] * 100:g} %, overshoot <= {limits['overshoot_pct']:g} %, "
        f"rest < {limits['rest_m'] * 1e3:g} mm, 70 mm go-to overshoot <= "
        f"{limits['long_overshoot_m'] * 1e3:g} mm and within {limits['settle_band_m'] * 1e3:g} mm "
        f"in {limits['settle_s']:g} s):"
    ]
    for c in checked["candidates"]:
        g = c["gains"]
        at_limit = max(c["plain"]["at_limit"], c["lead"]["at_limit"]) * 100
        mark = "*" if c["candidate"] == checked["chosen"] else " "
        long = c.get("long_move") or {"overshoot_m": [], "settle_s": []}
        lines.append(
            f" {mark}{c['candidate']:>2}: P {_per_servo(g, 'p')}, I {_per_servo(g, 'i')}, "
            f"D {_per_servo(g, 'd')}: RMSE plain {_mm(c['plain']['rmse_m'])} mm, lead "
            f"{_mm(c['lead']['rmse_m'])} mm, at limit {at_limit:.1f} %, overshoot "
            f"{c['overshoot_pct']:.1f} %, rest <= {max(c['rest_m']) * 1e3:.2f} mm, go-to "
            f"overshoot {max(long['overshoot_m'], default=0.0) * 1e3:.2f} mm, settled in "
            f"{max(long['settle_s'], default=0.0):.2f} s; "
            f"misses {', '.join(c['failed']) or 'nothing'}"
        )
    lines.append(f"chosen: candidate {checked['chosen']}: {checked['reason']}")
    if not checked["met_goal"]:
        lines.append("the suggested gains do NOT meet the goal on the twin (see what they miss)")
    return lines


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
        confirm = {"confirm_missed": True} if args.confirm_missed else None
        applied = cli_run._http(f"{url}/api/tuning/{run_id}/apply", "POST", confirm, headers)
        _print_gains("applied", applied)
    return code
