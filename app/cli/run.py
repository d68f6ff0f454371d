"""``deltadash run sinusoid``: the thesis's tracking test from the command line.

Its options speak mm, degrees and Hz, as ik, fk, gcode and the page do (``--si``: metres and
radians); a decimal comma is a decimal point (app/cli/numbers.py). What it sends to the
server and what it runs are SI, as the API.

Against a running server (``--url``), or headless: an in-process controller on the
simulated robot, no server needed. Prints the per-axis statistics and where the log and
report are.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from app.cli.numbers import number
from app.cli.progress import Progress
from app.runs.health import summary
from app.runs.trajectories import SinusoidParams

_D = SinusoidParams()
FILES = ("log.mcap", "log.ros2.mcap", "log.csv", "report.png", "report.pdf")


# The run options speak mm and degrees as ik, fk, gcode and the page do; --si: metres, radians
# (option -> (the SinusoidParams field, "length" / "angle" / its fixed unit)).
_OPTIONS = {
    "amplitude": ("amplitude_m", "length"),
    "frequency": ("frequency_hz", "Hz"),
    "phase": ("phase_rad", "angle"),
    "offset": ("offset_m", "length"),
}
_SCALE = {"length": (1e-3, "mm", "m"), "angle": (math.pi / 180, "deg", "rad")}
# A length option whose every non-zero value is under this [mm] reads as metres typed where
# mm are expected (--amplitude 0.05 0.05 0.08): refused, with the mm to give and --si named.
# Below an encoder count at the tip (0.3-0.45 mm on the twin) a run measures nothing anyway;
# with --si such a value is taken as given.
METRES_LIKELY_MM = 0.5
_EPILOG = (
    "Lengths are mm and angles degrees, as for ik, fk and gcode (--si: metres and radians; "
    "frequencies are Hz, durations s either way); a decimal comma is read as a decimal point "
    f"(12,5 is 12.5). A length option whose non-zero values are all under {METRES_LIKELY_MM:g} "
    "mm looks like metres and is refused (give mm, or add --si). --json prints SI, as the API."
)


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    run = commands.add_parser("run", help="run a test trajectory and print its error stats")
    kinds = run.add_subparsers(dest="kind", required=True)
    sine = kinds.add_parser(
        "sinusoid",
        help="per-axis sinusoid (thesis ch. 6.1 defaults), in mm, deg and Hz",
        description="p(t) = offset + amplitude sin(2 pi frequency t + phase), per axis "
        "(x, y, z in the base frame), for --duration s; then the error statistics.",
        epilog=_EPILOG,
    )
    for name, (field, kind) in _OPTIONS.items():
        sine.add_argument(
            f"--{name}",
            type=number,
            nargs=3,
            metavar=("X", "Y", "Z"),
            help=f"per axis {_unit_help(kind)} (default {_default(field, kind)})",
        )
    sine.add_argument(
        "--duration",
        type=number,
        default=_D.duration_s,
        metavar="S",
        help="the timed part [s] (default %(default)g)",
    )
    sine.add_argument(
        "--phi-amplitude",
        type=number,
        metavar="A",
        help="with a [wrist]: the wrist's sinusoid amplitude [deg; rad with --si] (default 0: "
        "left alone)",
    )
    sine.add_argument(
        "--phi-frequency",
        type=number,
        default=_D.phi_frequency_hz,
        metavar="F",
        help="the wrist's sinusoid frequency [Hz] (default %(default)g)",
    )
    sine.add_argument(
        "--si",
        action="store_true",
        help="lengths in metres and angles in radians instead of mm and deg",
    )
    sine.add_argument("--feedforward", action="store_true", help="command the path ahead")
    sine.add_argument("--url", help="a running server, e.g. http://127.0.0.1:8000")
    token = os.environ.get("DELTADASH_TOKEN")
    sine.add_argument("--token", default=token, help="the server's token ($DELTADASH_TOKEN)")
    sine.add_argument(
        "--take-over", action="store_true", help="take control from another client that holds it"
    )
    sine.add_argument("--backend", default="emulated", help="headless backend (default emulated)")
    sine.add_argument("--json", action="store_true", help="print the run as JSON")
    sine.set_defaults(handler=run_sinusoid)
    return run


def _unit_help(kind: str) -> str:
    if kind in _SCALE:
        _, shown, si = _SCALE[kind]
        return f"[{shown}; {si} with --si]"
    return f"[{kind}]"


def _default(field: str, kind: str) -> str:
    """SinusoidParams' default of ``field`` as the help shows it (in mm or deg)."""
    values = getattr(_D, field)
    if kind in _SCALE:
        factor, shown, _ = _SCALE[kind]
        return " ".join(f"{v / factor:g}" for v in values) + f" {shown}"
    return " ".join(f"{v:g}" for v in values) + f" {kind}"


def _si(option: str, values: list[float] | None, kind: str, si: bool) -> tuple[float, ...] | None:
    """An option's values in SI (None: not given). Refuses (ValueError) a length in mm whose
    every non-zero value is under METRES_LIKELY_MM: metres given where mm are expected."""
    if values is None:
        return None
    if kind not in _SCALE or si:
        return tuple(values)
    factor, shown, _ = _SCALE[kind]
    moving = [abs(v) for v in values if v != 0.0]
    if kind == "length" and moving and max(moving) < METRES_LIKELY_MM:
        given = " ".join(f"{v:g}" for v in values)
        as_mm = " ".join(f"{v * 1e3:g}" for v in values)
        raise ValueError(
            f"--{option} {given}: every non-zero value under {METRES_LIKELY_MM:g} mm looks like "
            "metres; "
            f"the run options are in mm: for {given} m give --{option} {as_mm}, or add --si"
        )
    return tuple(v * factor for v in values)


def _params(args: argparse.Namespace) -> SinusoidParams:
    """The run's parameters in SI from the options (mm and deg, or SI with ``--si``);
    an option not given is SinusoidParams' default. Raises ValueError (see ``_si``)."""
    given = {}
    for name, (field, kind) in _OPTIONS.items():
        value = _si(name, getattr(args, name), kind, args.si)
        if value is not None:
            given[field] = value
    phi = None if args.phi_amplitude is None else [args.phi_amplitude]
    phi_rad = _si("phi-amplitude", phi, "angle", args.si)
    if phi_rad is not None:
        given["phi_amplitude_rad"] = phi_rad[0]
    return replace(
        _D,
        duration_s=args.duration,
        feedforward=args.feedforward,
        phi_frequency_hz=args.phi_frequency,
        **given,
    )


def _http(
    url: str, method: str = "GET", body: dict | None = None, headers: dict | None = None
) -> Any:
    data = None if body is None else json.dumps(body).encode()
    headers = {"content-type": "application/json", **(headers or {})}
    request = urllib.request.Request(url, data=data, method=method, headers=headers)
    with urllib.request.urlopen(request, timeout=10) as response:
        return json.load(response)


def _take_control(url: str, token: str | None, take_over: bool) -> dict[str, str]:
    """Take the control lease; the headers every later request sends (token, lease id).
    Says on stderr whom it took control from; LeaseRefused when another client holds it
    and ``take_over`` is false."""
    headers = {"authorization": f"Bearer {token}"} if token else {}
    body = {"client": "deltadash run", "take_over": take_over}
    try:
        lease = _http(f"{url}/api/lease", "POST", body, headers)
    except urllib.error.HTTPError as exc:
        if exc.code == 409:
            held_by = _detail(exc).split(";")[0]  # the server's hint names its own field
            raise LeaseRefused(f"{held_by}; add --take-over to take it") from None
        raise
    previous = lease.get("took_over_from")
    if previous:
        since = time.strftime("%H:%M:%S", time.localtime(previous["since_s"]))
        print(f"took control from {previous['holder']!r} (held since {since})", file=sys.stderr)
    return {**headers, "x-lease": lease["lease_id"]}


class LeaseRefused(Exception):
    """Another client holds control and --take-over was not given."""


def _detail(exc: urllib.error.HTTPError) -> str:
    try:
        return str(json.load(exc).get("detail"))
    except (ValueError, AttributeError, OSError):
        return exc.reason


def _remote(
    url: str,
    params: SinusoidParams,
    token: str | None = None,
    take_over: bool = False,
    problems: list[str] | None = None,
) -> dict[str, Any]:
    """Run on a server: take control, torque on, start, follow the run to its end, give
    control back. Interrupted (Ctrl-C) while the run goes, it aborts the run first; what
    it could not do at exit goes to ``problems``."""
    problems = [] if problems is None else problems
    headers = _take_control(url, token, take_over)
    running = None  # the run to abort if this ends before it does
    try:
        _http(f"{url}/api/torque", "POST", {"enabled": True}, headers)
        body = {
            "amplitude_m": params.amplitude_m,
            "frequency_hz": params.frequency_hz,
            "phase_rad": params.phase_rad,
            "offset_m": params.offset_m,
            "duration_s": params.duration_s,
            "feedforward": params.feedforward,
        }
        if params.moves_wrist:  # an older server without a wrist knows no phi fields
            body["phi_amplitude_rad"] = params.phi_amplitude_rad
            body["phi_frequency_hz"] = params.phi_frequency_hz
        run_id = running = _http(f"{url}/api/tests/sinusoid", "POST", body, headers)["run_id"]
        with Progress(_expected_s(params), f"run {run_id}", "s") as bar:
            while (run := _http(f"{url}/api/runs/{run_id}", headers=headers))["state"] == "running":
                _show(bar, run.get("progress"))
                time.sleep(0.25)
        running = None
    finally:
        if running is not None:
            _try(
                problems, f"abort run {running}", url, f"/api/runs/{running}/abort", "POST", headers
            )
        _try(problems, "give control back", url, "/api/lease", "DELETE", headers)
    base = f"{url}/api/runs/{run_id}"
    run["files"] = {name: f"{base}/{name}" for name in FILES}
    return run


def under_control(
    url: str,
    token: str | None,
    take_over: bool,
    work: Callable[[dict[str, str], list[str]], int],
    interrupted: str,
) -> int:
    """Take the control lease of the server at ``url``, do ``work(headers, problems)``
    (its exit code; it aborts what it started when interrupted), give control back.

    Returns the exit code: ``work``'s; 2 after a refused lease, an HTTP error (its code and
    the server's detail) or a connection error; 130 on Ctrl-C (``interrupted`` is printed).
    What could not be done at the end (``problems``) is printed as errors."""
    problems: list[str] = []
    code = 0
    try:
        headers = _take_control(url, token, take_over)
        try:
            code = work(headers, problems)
        finally:
            _try(problems, "give control back", url, "/api/lease", "DELETE", headers)
    except LeaseRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    except urllib.error.HTTPError as exc:
        print(f"error: {exc.code} {_detail(exc)}", file=sys.stderr)
        code = 2
    except (urllib.error.URLError, OSError) as exc:
        print(f"error: {url}: {exc}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print(interrupted, file=sys.stderr)
        code = 130
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    return code


def _try(problems: list[str], what: str, url: str, path: str, method: str, headers: dict) -> None:
    try:
        _http(f"{url}{path}", method, None, headers)
    except (urllib.error.URLError, OSError, ValueError) as exc:
        problems.append(f"could not {what}: {exc}")


def _headless(
    params: SinusoidParams, backend: str, problems: list[str] | None = None
) -> dict[str, Any]:
    """Run on an in-process controller; a robot not made safe at exit (torque off failed)
    goes to ``problems``."""
    from app.config import load_settings
    from app.control.controller import Controller
    from app.runs.manager import RunManager
    from app.server.backends import open_backend

    problems = [] if problems is None else problems
    settings = load_settings(hardware={"backend": backend})
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            controller.set_torque(True).result(timeout=2.0)
            wait_at_rest(controller)  # the plan starts where the arm is: let it settle
            runs = RunManager(controller, settings.runs.folder_path)
            run = runs.start_sinusoid(params)
            with Progress(_expected_s(params), f"run {run.run_id}", "s") as bar:
                while not run.done.wait(0.25):
                    _show(bar, runs.progress(run.run_id))
        finally:
            unsafe = controller.stop()
            if unsafe:
                problems.append(f"{unsafe}: the servos may still hold torque")
    result = run.as_dict()
    result["files"] = {name: str(run.folder / name) for name in FILES}
    return result


REST_WINDOW_S = 0.3  # loop time over which the arm must stand still [s]
# ... moving less than this [m]: half the run's start tolerance (2 mm, app/runs/manager.py),
# more than an encoder count's flicker at rest (0.3-0.45 mm at the tip on the twin)
REST_TOL_M = 1e-3
REST_DEADLINE_S = 20.0  # wall time to wait for that after torque on [s]


def wait_at_rest(
    controller: Any,
    window_s: float = REST_WINDOW_S,
    tol_m: float = REST_TOL_M,
    deadline_s: float = REST_DEADLINE_S,
    clock: Callable[[], float] = time.monotonic,
) -> np.ndarray:
    """Wait until the measured tool tip moved less than ``tol_m`` [m] over ``window_s`` of
    loop time (snapshots' ``time_s``, so a loaded machine only makes it slower), as a
    person waits for the arm to settle after torque on before starting a test from where
    it is. Returns the point at rest (3,) [m].

    Raises MotionRefused when it has not settled within ``deadline_s`` of ``clock`` [s]
    (saying how far it moved in the last window), or when the loop faulted meanwhile.
    """
    from app.control.errors import MotionRefused

    started = clock()
    window: list[tuple[float, np.ndarray]] = []
    moved = float("nan")
    while True:
        snap = controller.snapshot()
        if snap.mode in ("fault", "estop"):
            raise MotionRefused(f"the loop is in {snap.mode} while waiting for the arm to settle")
        point = np.asarray(snap.point_measured_m, dtype=np.float64)
        if np.isfinite(point).all() and (not window or snap.time_s > window[-1][0]):
            window.append((snap.time_s, point))
            # keep the oldest sample that still makes the window span window_s
            while len(window) > 2 and window[-1][0] - window[1][0] >= window_s:
                window.pop(0)
            moved = max(float(np.linalg.norm(p - point)) for _, p in window)
            if window[-1][0] - window[0][0] >= window_s and moved < tol_m:
                return point
        if clock() - started > deadline_s:
            shown = "?" if not math.isfinite(moved) else f"{moved * 1e3:.2f}"
            raise MotionRefused(
                f"the arm did not come to rest within {deadline_s:g} s after torque on (it "
                f"moved {shown} mm in the last {window_s:g} s of loop time; at rest is under "
                f"{tol_m * 1e3:g} mm): nothing was started"
            )
        time.sleep(0.02)


def _expected_s(params: SinusoidParams) -> float:
    """The bar's length before the server says (its plan adds an approach and a stop)."""
    return params.duration_s


def _show(bar: Progress, progress: dict[str, Any] | None) -> None:
    """Move the bar to a run's progress (GET /api/runs/{id}'s ``progress``), if known."""
    if progress and progress.get("duration_s"):
        done = progress.get("elapsed_s") or 0.0
        bar.update_to(done, progress.get("phase"), total=progress["duration_s"])


def print_stats(run: dict[str, Any]) -> None:
    from app.runs.describe import describe

    print(f"run {run['run_id']}: {run['state']}" + (f" ({run['reason']})" if run["reason"] else ""))
    print(f"test: {describe(run['kind'], run['params'], run.get('conditions'))}")
    tracking = run.get("stats", {}).get("tracking")
    if tracking:
        print(f"{'axis':>4} {'mean mm':>9} {'RMSE mm':>9} {'std mm':>9} {'max mm':>9} {'<1mm':>6}")
        for axis in "xyz":
            s = tracking[axis]
            print(
                f"{axis:>4} {s['mean_m'] * 1e3:9.3f} {s['rmse_m'] * 1e3:9.3f} "
                f"{s['std_m'] * 1e3:9.3f} {s['max_abs_m'] * 1e3:9.3f} "
                f"{s['share_under_1mm']:6.1%}"
            )
    if run.get("stats"):
        print(summary(run["stats"].get("health")))
    for name, where in run["files"].items():
        print(f"{name:>10}: {where}")


def run_sinusoid(args: argparse.Namespace) -> int:
    """Exit 0: done; 1: the run did not finish (aborted); 2: refused or bad input;
    3: the robot could not be made safe at exit (or the run not stopped); 130: Ctrl-C."""
    from app.control.errors import GoalRejected, MotionRefused

    problems: list[str] = []
    code = 0
    try:
        params = _params(args)
        if args.url:
            run = _remote(args.url.rstrip("/"), params, args.token, args.take_over, problems)
        else:
            run = _headless(params, args.backend, problems)
    except (GoalRejected, MotionRefused, ValueError, LeaseRefused) as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    except urllib.error.HTTPError as exc:
        print(f"error: {exc.code} {_detail(exc)}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        code = 130
    else:
        print(json.dumps(run, indent=1)) if args.json else print_stats(run)
        code = 0 if run["state"] == "done" else 1
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    return 3 if problems else code
