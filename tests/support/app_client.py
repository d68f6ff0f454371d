"""The app in-process under FastAPI's TestClient, and waits on what /api/status says.

The 3D scene (viser) is off unless a test turns it on (``server={"scene": True}``): only
tests/scene/ and the browser tests look at it, and it costs every other app a web server
and a display-rate thread. When on, it takes a free port, never the default 8080.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any, Literal
from urllib.parse import urljoin

import numpy as np
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend
from tests.support.server import COMMAND_WAIT_S
from tests.support.sim_time import driving
from tests.support.wait import ok_json, wait_for

REAL_TIME_ENV = "DELTADASH_TEST_REAL_TIME"
# the Host the test client sends: a name of this machine (app/origins.py refuses "testserver")
LOCAL = "http://127.0.0.1"


class LocalClient(TestClient):
    """A ``TestClient`` that calls the app as ``127.0.0.1``, WebSockets included (Starlette's
    own sends ``Host: testserver``, which the server refuses as another machine's name)."""

    def __init__(self, app: Any, **kwargs: Any) -> None:
        super().__init__(app, base_url=kwargs.pop("base_url", LOCAL), **kwargs)

    def websocket_connect(self, url: str, *args: Any, **kwargs: Any) -> Any:
        return super().websocket_connect(urljoin("ws://127.0.0.1", url), *args, **kwargs)


class SimTimeClient(LocalClient):
    """A `LocalClient` of an app whose loop runs on simulated time: inside its ``with``
    block its clock is the one waits drive (tests/support/sim_time.py)."""

    def __enter__(self) -> SimTimeClient:
        super().__enter__()
        self._driving = driving(self.app.state.backend.sim_clock)
        self._driving.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._driving.__exit__(*exc)
        super().__exit__(*exc)


def make_client(
    runs_folder: Path,
    backend: Literal["emulated", "sim"] = "emulated",
    config_path: Path | None = None,
    sim_time: bool | None = None,
    **overrides,
) -> TestClient:
    """A client of an app with its runs under ``runs_folder`` (a tmp_path); ``with`` starts it.

    ``backend`` "emulated" runs the servo emulator in-process (for fault injection), "sim"
    the MuJoCo twin. ``overrides`` are settings sections, merged over these defaults.
    ``config_path``: the config file the app says it runs from (an applied calibration is
    written there); the settings do not come from it. ``sim_time``: the loop runs on
    simulated time, driven by the test's waits (tests/support/sim_time.py); by default
    it does, unless ``$DELTADASH_TEST_REAL_TIME`` is 1 (the whole suite in real time, to
    compare); False where real time is the point.
    """
    hardware = {"backend": backend, **overrides.pop("hardware", {})}
    server = {
        "scene": False,
        "viser_port": 0,
        "command_timeout_s": COMMAND_WAIT_S,
        **overrides.pop("server", {}),
    }
    runs = {"folder": str(runs_folder), **overrides.pop("runs", {})}
    link = {"robot": "in-process", **overrides.pop("link", {})}
    settings = load_settings(hardware=hardware, server=server, runs=runs, link=link, **overrides)
    if sim_time is None:
        sim_time = os.environ.get(REAL_TIME_ENV) != "1"
    opener = functools.partial(
        open_backend, emulator_in_process=backend == "emulated", sim_time=sim_time
    )
    kind = SimTimeClient if sim_time else LocalClient
    return kind(create_app(settings, backend_opener=opener, config_path=config_path))


def cleared(client: TestClient) -> TestClient:
    """``client`` with e-stop and faults cleared and torque off (a module's shared app)."""
    client.post("/api/reset")
    client.post("/api/torque", json={"enabled": False})
    return client


def ticks(client: TestClient) -> int:
    return ok_json(client.get("/api/status"))["loop"]["ticks"]


def measured(client: TestClient) -> np.ndarray:
    """The platform's measured position [m], shape (3,)."""
    return np.array(ok_json(client.get("/api/status"))["ee"]["position_m"], dtype=float)


def robot_seen(client: TestClient) -> dict:
    """What a failed wait on the robot reports: where it is, its mode, faults and warning."""
    status = ok_json(client.get("/api/status"))
    keys = ("mode", "torque", "estopped", "faults", "warning")
    ee, joints = status["ee"], status["joints"]
    return {
        "measured_m": ee["position_m"],
        "commanded_m": ee["commanded_m"],
        "joints_rad": joints["position_rad"],
        **{k: status[k] for k in keys},
    }


def wait_at(client: TestClient, point_m, what: str, within_m: float = 2e-3) -> None:
    """Wait until /api/status measures the platform within ``within_m`` of ``point_m``;
    a timeout says where it was, the mode and any warning or fault."""

    def seen() -> dict:
        status = ok_json(client.get("/api/status"))
        keys = ("mode", "torque", "warning", "faults")
        return {"measured_m": status["ee"]["position_m"], **{k: status[k] for k in keys}}

    wait_for(
        lambda: np.linalg.norm(measured(client) - point_m) < within_m,
        f"{what} ({within_m * 1e3:g} mm of {list(point_m)} m)",
        seen=seen,
    )


def torque_on(client: TestClient) -> None:
    """Torque on, waiting while it is refused because a relaxed arm is still swinging past
    its joint limits (it is accepted once the arm is back inside them)."""
    answers: list = []

    def accepted() -> bool:
        answers.append(client.post("/api/torque", json={"enabled": True}))
        if answers[-1].status_code == 409 and "outside its limits" in answers[-1].text:
            return False
        # a starved emulator can miss its reply to every try of a write (503, "servo bus:
        # ... no status packet"): the server says so and changes nothing; ask again
        if answers[-1].status_code == 503 and "servo bus" in answers[-1].text:
            return False
        ok_json(answers[-1])
        return True

    wait_for(accepted, "torque on to be accepted", seen=lambda: answers[-1].text)


def settle_at(client: TestClient, point_m, within_m: float = 0.003) -> None:
    """Torque on, a goal at ``point_m`` [m], and wait for a defined pose: the approach done
    (commanded there), the platform measured within ``within_m`` of it and the joints still.

    Runs plan from the commanded point and refuse to start from a robot still moving (after
    torque on the arm may still be falling), so a test that starts one settles here first.
    """
    torque_on(client)
    ok_json(client.post("/api/goal", json={"position_m": list(point_m)}))

    def status() -> dict:
        return ok_json(client.get("/api/status"))

    def settled() -> bool:
        now = status()
        commanded = np.linalg.norm(np.subtract(now["ee"]["commanded_m"], point_m)) < 1e-4
        near = np.linalg.norm(np.subtract(now["ee"]["position_m"], point_m)) < within_m
        still = all(abs(v or 0.0) < 0.02 for v in now["joints"]["velocity_rad_s"])  # rad/s
        return commanded and near and still

    def seen() -> dict:
        now = status()
        return {
            "commanded_m": now["ee"]["commanded_m"],
            "measured_m": now["ee"]["position_m"],
            "velocity_rad_s": now["joints"]["velocity_rad_s"],
            "mode": now["mode"],
        }

    wait_for(
        settled,
        f"the robot settled at {list(point_m)} m (within {within_m * 1e3:g} mm, joints still)",
        seen=seen,
    )


def unmoved(before: dict, after: dict) -> bool:
    """Same torque, mode, goal and commanded point (to 1 nm: a holding jog's ruckig output
    can differ in the last bits between ticks)."""
    same = all(before[k] == after[k] for k in ("torque", "mode"))

    def close(a, b) -> bool:  # null (unknown, e.g. no goal with torque off) only equals null
        if a is None or b is None:
            return a is b
        return np.allclose(np.array(a, float), np.array(b, float), rtol=0, atol=1e-9)

    return same and all(close(before[k], after[k]) for k in ("goal_m", "commanded_m"))
