"""``deltadash gcode check FILE``: a G-code program checked on the virtual robot, offline;
``deltadash gcode run FILE``: run on a server.

check: the program is planned and every loop sample checked as the server's
``POST /api/programs/check`` does (app/programs/check.py), with the config's robot and
limits (the default config's without ``--config``), from ``programs.start_m`` or
``--start``. No server, no robot: nothing moves. The report is text in mm (per-line
violations) or, with ``--json``, the API's answer (SI). With ``--dry-run`` the path is
also played on a headless twin (app/programs/dry_run.py): the predicted error per line.
Exit 0: the program passes; 1: it has violations; 2: it cannot be read (its line and
word) or bad input (or too long for the dry run).

run: ``POST /api/programs/run`` on a running server (``--url``): takes the control
lease (as ``deltadash run`` does), turns torque on, starts the program (the server
checks it first: a failing program is refused with its violations), follows it with a
progress bar naming the line in execution, gives control back and prints the error per
program line. Where the program stops (M0; M1 with ``--optional-stop``; a pause or a
single step from the page or the API) it says where and why on stderr and waits, as
LinuxCNC waits for Cycle Start: on a terminal Enter resumes it (``POST
/api/programs/resume``; what was typed before the stop is dropped, so a stray Enter never
starts the robot); otherwise it says how to resume from the page or the API and keeps
waiting. Ctrl-C aborts the run, standing or not. Exit 0: done; 1: the run did not finish
(aborted, e-stop); 2: refused (violations, unreadable, control held by another client) or
bad input; 3: the run could not be aborted or control given back at exit; 130: Ctrl-C
(the run is aborted first).

Only the standard library is imported at module level (``deltadash --help`` stays fast).
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
    "Exit 0: the program passes every check; 1: it has violations; 2: it cannot be read "
    "(the line and word are named) or bad input. The subset and the frames: docs/gcode.md."
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``gcode`` and its ``check`` on the app's sub-command parsers."""
    gcode = commands.add_parser(
        "gcode",
        help="check a G-code program on the virtual robot before it moves",
        description="G-code programs (the subset in docs/gcode.md).",
    )
    sub = gcode.add_subparsers(dest="gcode_command", required=True, metavar="SUBCOMMAND")
    check = sub.add_parser(
        "check",
        help="plan a program and check every loop sample (offline)",
        description="Plan FILE and check every sample of its timed path at the loop rate: "
        "workspace with margin and ceiling, IK on the followed branch, joint limits, joint "
        "speed and acceleration, singularity margin, servo torque.",
        epilog=_EPILOG,
    )
    check.add_argument("file", metavar="FILE", help="the program (text)")
    check.add_argument("--json", action="store_true", help="the report as JSON (SI units)")
    check.add_argument("--config", help="TOML config: robot, limits, [programs]")
    check.add_argument(
        "--start",
        nargs=3,
        type=number,
        metavar=("X_MM", "Y_MM", "Z_MM"),
        help="where the tool starts, in millimetres in the base frame (z < 0 below the "
        "base), e.g. --start 0 0 -240 (default programs.start_m, which is in metres)",
    )
    check.add_argument(
        "--work-offset",
        nargs=3,
        type=number,
        metavar=("X_MM", "Y_MM", "Z_MM"),
        help="G54: the program origin in the base frame, in millimetres "
        "(default programs.work_offset_m)",
    )
    check.add_argument(
        "--dry-run",
        action="store_true",
        help="also play the path on a headless twin: the predicted tracking error per line "
        "(programs up to programs.dry_run_max_s)",
    )
    check.add_argument(
        "--feedforward", action="store_true", help="the dry run with feed-forward, as a run"
    )
    check.set_defaults(handler=_check)
    run = sub.add_parser(
        "run",
        help="run a program on a running server (checked there first)",
        description="Take control of the server at --url, turn torque on and run FILE "
        "(POST /api/programs/run: the server checks it from where the robot is and refuses "
        "it with its violations if it fails); print the error per program line at the end. "
        "At an M0 (an M1 with --optional-stop) it says where it stopped and waits: on a "
        "terminal Enter resumes, Ctrl-C aborts.",
        epilog="Exit 0: done; 1: the run did not finish; 2: refused or bad input; 3: the run "
        "could not be aborted or control given back; 130: Ctrl-C (the run is aborted).",
    )
    run.add_argument("file", metavar="FILE", help="the program (text)")
    run.add_argument(
        "--url", default="http://127.0.0.1:8000", help="the server (default %(default)s)"
    )
    run.add_argument("--feedforward", action="store_true", help="command the path ahead")
    run.add_argument(
        "--token", default=os.environ.get("DELTADASH_TOKEN"), help="the server's token"
    )
    run.add_argument(
        "--take-over", action="store_true", help="take control from another client that holds it"
    )
    run.add_argument(
        "--work-offset",
        nargs=3,
        type=number,
        metavar=("X", "Y", "Z"),
        help="G54: the program origin in the base frame [mm] (default programs.work_offset_m)",
    )
    run.add_argument(
        "--optional-stop",
        action="store_true",
        help="M1 stops the program as M0 does (off: M1 runs through)",
    )
    run.add_argument("--json", action="store_true", help="print the run as JSON")
    run.set_defaults(handler=_run)


def _mm(point: Any) -> str:
    return "(" + ", ".join(f"{v * 1e3:.3f}" for v in point) + ") mm"


def format_report(name: str, report: dict[str, Any], settings: Any) -> str:
    """The report as text, lengths in mm (one line per violation)."""
    violations = report["violations"]
    lines = {v["line"] for v in violations}
    folded = sum(1 for v in violations if v.get("folded_under") is not None)
    verdict = (
        "PASSES"
        if report["ok"]
        else f"FAILS: {len(violations)} violations on {len(lines)} line(s)"
        + (
            f": {len(violations) - folded} first cause(s), {folded} folded under them"
            if folded
            else ""
        )
    )
    ratio = report["worst_torque_ratio"]
    out = [
        f"{name}: {verdict}",
        f"  {report['lines']} lines, {report['segments']} segments, "
        f"{report['duration_s']:.3f} s, path {report['length_m'] * 1e3:.1f} mm, "
        f"{report['samples']} samples every {report['period_s'] * 1e3:.1f} ms",
        f"  peak joint speed {report['peak_joint_speed_rad_s'] or 0:.2f} rad/s "
        f"(limit {settings.limits.joint_speed_rad_s:.2f}), "
        f"peak joint acceleration {report['peak_joint_acceleration_rad_s2'] or 0:.0f} rad/s^2 "
        f"(limit {settings.programs.joint_acceleration_rad_s2:.0f})",
        f"  worst 1/cond(J) {report['worst_dexterity'] or 0:.3f} "
        f"(min {settings.limits.min_dexterity}), worst torque ratio "
        + ("n/a" if ratio is None else f"{ratio:.2f}")
        + f" (limit {settings.programs.max_torque_ratio:.2f})",
    ]
    out += [f"  note: {note}" for note in report["notes"]]
    out += [format_violation(v) for v in violations]
    return "\n".join(out)


def format_violation(v: dict[str, Any]) -> str:
    """One violation as a report line, folded as the page folds it: a move's first cause
    at ``  line N: ...``, the others of its line (``folded_under`` set) under it, indented
    and marked ``|_`` (a consequence, or more on the same line)."""
    text = f"{v['kind']} at t = {v['t_s']:.3f} s, {_mm(v['point_m'])}: {v['message']}"
    if v.get("folded_under") is not None:
        return f"      |_ {text}"
    return f"  line {v['line']}: {text}"


def read_program(path: str) -> str:
    """A program file's text (UTF-8, which ASCII G-code is). ValueError naming the file and
    the line of the first byte that is not UTF-8; OSError as the system says it."""
    data = Path(path).read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ValueError(
            f"{path}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8 text "
            "(save the program as UTF-8 or plain ASCII)"
        ) from None


def format_line_errors(per_line: list[dict[str, Any]], text: str, title: str) -> str:
    """The error per program line as a table in mm, each row with the line's own text."""
    from app.programs.tokens import program_lines

    source = program_lines(text)
    out = [title, f"  {'line':>5} {'samples':>7} {'RMSE mm':>8} {'max mm':>8}  program"]
    for e in per_line:
        words = source[e["line"] - 1].strip() if 0 < e["line"] <= len(source) else ""
        # a line a late tick crossed whole has no sample and no error (null)
        rmse, worst = (
            f"{e[k] * 1e3:8.3f}" if e[k] is not None else f"{'-':>8}" for k in ("rmse_m", "max_m")
        )
        out.append(f"  {e['line']:>5} {e['samples']:>7} {rmse} {worst}  {words[:50]}")
    return "\n".join(out)


def _start_refusal(gate: Any, start_mm: list[float]) -> str | None:
    """Why ``--start`` (mm) cannot be where the tool is (None: it can): outside the
    workspace, with the same point read as metres suggested when that is inside."""
    import numpy as np

    point = np.asarray(start_mm) * 1e-3
    if gate.inside(point):
        return None
    given = " ".join(f"{v:g}" for v in start_mm)
    why = (
        f"--start {given}: ({', '.join(f'{v:.3f}' for v in start_mm)}) mm is outside the "
        f"workspace (kept {gate.margin_m * 1e3:.1f} mm from its edge, below the ceiling "
        f"z = {gate.z_max_m * 1e3:.1f} mm); --start is in millimetres"
    )
    as_metres = np.asarray(start_mm, dtype=np.float64)
    if np.isfinite(as_metres).all() and gate.inside(as_metres):
        why += f": for {given} m give --start " + " ".join(f"{v * 1e3:g}" for v in start_mm)
    return why


def _check(args: argparse.Namespace) -> int:
    from app.config import ConfigError, load_settings
    from app.control.commands import CommandContext
    from app.programs.check import check_program
    from app.programs.dry_run import DryRunRefused, dry_run
    from app.programs.errors import ProgramError

    try:
        settings = load_settings(args.config)
        text = read_program(args.file)
    except (ConfigError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for flag, given in (("--start", args.start), ("--work-offset", args.work_offset)):
        if given is not None and not all(math.isfinite(v) for v in given):
            print(f"error: {flag}: expected 3 finite numbers in mm, got {given}", file=sys.stderr)
            return 2
    gate = CommandContext.from_settings(settings).gate
    start = None if args.start is None else [v * 1e-3 for v in args.start]
    if start is not None and (refusal := _start_refusal(gate, args.start)):
        print(f"error: {refusal}", file=sys.stderr)
        return 2
    offset = None if args.work_offset is None else [v * 1e-3 for v in args.work_offset]
    try:
        checked = check_program(text, settings, gate=gate, start_m=start, work_offset_m=offset)
    except ProgramError as exc:
        if args.json:
            print(json.dumps({"detail": str(exc), "line": exc.line or None, "word": exc.word}))
        print(f"error: {args.file}: {exc}", file=sys.stderr)
        return 2
    report = checked.report
    body = report.to_dict()
    predicted = None
    if args.dry_run:
        try:
            predicted = dry_run(checked, settings, feedforward=args.feedforward).to_dict()
        except DryRunRefused as exc:
            print(f"error: {args.file}: dry run: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(body if predicted is None else {**body, "dry_run": predicted}))
    else:
        print(format_report(args.file, body, settings))
        if predicted is not None:
            rmse = ", ".join(f"{v * 1e3:.3f}" for v in predicted["rmse_m"])
            title = (
                f"dry run on the twin: RMSE x, y, z {rmse} mm, max {predicted['max_m'] * 1e3:.3f}"
                " mm; predicted per line:"
            )
            print(format_line_errors(predicted["lines"], text, title))
    return 0 if report.ok else 1


POLL_S = 0.25  # how often the run is looked at [s]


def stop_words(progress: dict[str, Any]) -> str | None:
    """Where and why a running program stands, in words (``progress``: a run's progress
    from ``GET /api/runs/{id}``): "paused at M0, line 3"; None while it moves (or brakes
    to a stand)."""
    paused = progress.get("paused")
    if not paused or paused == "pausing" or progress.get("feed_rate") != 0.0:
        return None
    line = progress.get("stop_line")
    line = progress.get("program_line") if line is None else line
    if paused.startswith("M0"):
        what = "M0"
    elif paused.startswith("M1"):
        what = "M1 (optional stop)"
    elif paused.startswith("single step"):
        what = "a single step's end"
    else:
        what = "a pause from the page or the API"
    return f"paused at {what}" + ("" if line is None else f", line {line}")


def _say(text: str) -> None:
    """A line on stderr, above the progress bar on a terminal."""
    if sys.stderr.isatty():
        from tqdm import tqdm

        tqdm.write(text, file=sys.stderr)
    else:
        print(text, file=sys.stderr, flush=True)


def _terminal() -> bool:
    isatty = getattr(sys.stdin, "isatty", None)
    return bool(isatty is not None and isatty())


def _drop_typed() -> None:
    """Drop what was typed on the terminal before a stop (a stray Enter resumes nothing)."""
    import contextlib
    import termios

    with contextlib.suppress(OSError, ValueError, termios.error):
        termios.tcflush(sys.stdin.fileno(), termios.TCIFLUSH)


def _enter_pressed(timeout_s: float) -> bool:
    """Whether a line was entered on stdin (a terminal) within ``timeout_s`` [s]; it is
    read. EOFError at the end of its input (Ctrl-D): no Enter can come from it."""
    import select

    ready, _, _ = select.select([sys.stdin], [], [], timeout_s)
    if not ready:
        return False
    if sys.stdin.readline() == "":
        raise EOFError
    return True


def _resume(url: str, headers: dict[str, str]) -> None:
    """``POST /api/programs/resume``; a refusal (the run ended meanwhile, control taken
    by another client) is said, and the program keeps standing."""
    import urllib.error

    from app.cli import run as cli_run

    try:
        cli_run._http(f"{url}/api/programs/resume", "POST", None, headers)
    except urllib.error.HTTPError as exc:
        _say(f"resume refused: {exc.code} {_refusal(exc).get('detail', exc.reason)}")
    else:
        _say("resumed")


def _follow(url: str, body: dict[str, Any], headers: dict[str, str], problems: list[str]):
    """Start the program, follow it to its end (aborting it if interrupted); the run.
    At a stop, say where and why; on a terminal Enter resumes it (module doc)."""
    from app.cli import run as cli_run
    from app.cli.progress import Progress

    running = None
    terminal = _terminal()
    no_enter = "stdin is not a terminal"  # why Enter cannot resume it here
    said: str | None = None  # the stop last said (once per stop)
    try:
        cli_run._http(f"{url}/api/torque", "POST", {"enabled": True}, headers)
        run_id = running = cli_run._http(f"{url}/api/programs/run", "POST", body, headers)["run_id"]
        with Progress(1.0, f"program {run_id}", "s") as bar:  # its length: when known
            while (run := cli_run._http(f"{url}/api/runs/{run_id}", headers=headers))[
                "state"
            ] == "running":
                progress = run.get("progress") or {}
                if progress.get("duration_s"):
                    line = progress.get("program_line")
                    label = f"line {line}" if line is not None else progress.get("phase")
                    bar.update_to(
                        progress.get("elapsed_s") or 0.0, label, total=progress["duration_s"]
                    )
                stop = stop_words(progress)
                if stop is not None and stop != said:
                    if terminal:
                        _drop_typed()
                        _say(f"{stop}: press Enter to resume, Ctrl-C to abort")
                    else:
                        _say(
                            f"{stop}: {no_enter}: resume it from the page's "
                            "program row (Take control, then Resume) or with POST "
                            "/api/programs/resume; Ctrl-C aborts"
                        )
                said = stop
                if stop is not None and terminal:
                    try:
                        if _enter_pressed(POLL_S):
                            _resume(url, headers)
                        continue
                    except EOFError:  # its input ended (Ctrl-D): wait as without one
                        terminal, said = False, None
                        no_enter = "stdin has ended (Ctrl-D)"
                        continue
                time.sleep(POLL_S)
        running = None
        return run
    finally:
        if running is not None:
            cli_run._try(
                problems, f"abort run {running}", url, f"/api/runs/{running}/abort", "POST", headers
            )


def _run(args: argparse.Namespace) -> int:
    import urllib.error

    from app.cli import run as cli_run

    try:
        text = read_program(args.file)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    url = args.url.rstrip("/")
    # its name in the server's program library: the file's (a label, no folder)
    body: dict[str, Any] = {
        "gcode": text,
        "feedforward": args.feedforward,
        "name": Path(args.file).name[:120] or "unnamed",
    }
    if args.work_offset is not None:
        body["work_offset_m"] = [v * 1e-3 for v in args.work_offset]
    if args.optional_stop:
        body["optional_stop"] = True
    problems: list[str] = []
    code = 0
    try:
        headers = cli_run._take_control(url, args.token, args.take_over)
        try:
            run = _follow(url, body, headers, problems)
        finally:
            cli_run._try(problems, "give control back", url, "/api/lease", "DELETE", headers)
    except cli_run.LeaseRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    except urllib.error.HTTPError as exc:
        refusal = _refusal(exc)
        print(f"error: {exc.code} {refusal.get('detail', exc.reason)}", file=sys.stderr)
        for v in refusal.get("violations") or []:
            if "kind" not in v:  # a body field the server refused: its detail says it
                continue
            print(format_violation(v), file=sys.stderr)
        code = 2
    except (urllib.error.URLError, OSError) as exc:
        print(f"error: {url}: {exc}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        code = 130
    else:
        base = f"{url}/api/runs/{run['run_id']}"
        run["files"] = {name: f"{base}/{name}" for name in cli_run.FILES}
        if args.json:
            print(json.dumps(run, indent=1))
        else:
            cli_run.print_stats(run)
            per_line = (run.get("stats") or {}).get("program", {}).get("lines") or []
            print(format_line_errors(per_line, text, "tracking error per program line:"))
        code = 0 if run["state"] == "done" else 1
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    return 3 if problems else code


def _refusal(exc: Any) -> dict[str, Any]:
    try:
        body = json.load(exc)
    except (ValueError, AttributeError, OSError):
        return {}
    return body if isinstance(body, dict) else {}
