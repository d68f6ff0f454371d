"""The 3D scene obeys the same authority as the API (issue 14, point 1): with a token set,
a plain WebSocket client on the viser port could switch torque off, jog, reset and drag
the goal. Here such a client speaks viser's own protocol, as a browser would."""

from __future__ import annotations

import functools
import threading
from collections.abc import Iterator

import msgspec
import numpy as np
import pytest
import viser
from fastapi.testclient import TestClient
from viser import _messages
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from app.config import load_settings
from app.scene.access import LOCKED
from app.server import create_app
from app.server.backends import open_backend
from tests.support.app_client import LocalClient, unmoved
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TOKEN = "scene-access-token"
GOAL = [0.0, 0.01, -0.23]


class RawClient:
    """A plain WebSocket client on the viser port: it sends viser's messages and reads
    (and drops) what the server sends; no browser, and it never typed the token."""

    def __init__(self, port: int) -> None:
        protocol = Subprotocol(f"viser-v{viser.__version__}")
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[protocol], max_size=None)
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        # viser counts a client as connected from its first camera message
        self.send(
            _messages.ViewerCameraMessage(
                (1.0, 0.0, 0.0, 0.0),
                (0.5, -0.6, 0.1),
                1.3,
                0.01,
                100.0,
                800,
                1280,
                (0.0, 0.0, -0.2),
                (0.0, 0.0, 1.0),
            )
        )

    def _drain(self) -> None:
        try:
            while True:
                self.ws.recv()
        except Exception:  # closed
            return

    def send(self, message: _messages.Message) -> None:
        self.ws.send(msgspec.msgpack.encode(message.as_serializable_dict()))

    def set(self, handle, value) -> None:
        """What the browser sends when its operator clicks a button or types in a field."""
        self.send(_messages.GuiUpdateMessage(handle._impl.uuid, {"value": value}))

    def drag_goal(self, point) -> None:
        name = "/goal/gizmo"
        self.send(_messages.TransformControlsDragStartMessage(name))
        self.send(_messages.TransformControlsUpdateMessage(name, (1.0, 0, 0, 0), tuple(point)))
        self.send(_messages.TransformControlsDragEndMessage(name))

    def close(self) -> None:
        self.ws.close()


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    settings = load_settings(
        hardware={"backend": "emulated"},
        runs={"folder": str(folder)},
        link={"robot": "in-process"},
        server={"viser_port": 0, "token": TOKEN},
    )
    opener = functools.partial(open_backend, emulator_in_process=True)
    with LocalClient(create_app(settings, backend_opener=opener)) as client:
        take_lease(client, "browser", token=TOKEN)  # a browser holds control
        yield client


@pytest.fixture
def scene(app_client):
    """The scene, with the robot held at GOAL by the browser (the HTTP client)."""
    take_lease(app_client, "browser", token=TOKEN)
    ok_json(app_client.post("/api/reset"))
    ok_json(app_client.post("/api/torque", json={"enabled": True}))
    ok_json(app_client.post("/api/goal", json={"position_m": GOAL}))
    wait_for(
        lambda: np.allclose(robot(app_client)["commanded_m"], GOAL, atol=1e-6),
        "the approach to the goal done",
        seen=lambda: robot(app_client),
    )
    return app_client.app.state.scene


@pytest.fixture
def raw(scene) -> Iterator[tuple[RawClient, int]]:
    """A plain WebSocket client, connected, with its own Control folder built."""
    before = set(scene.server.get_clients())
    client = RawClient(scene.server.get_port())
    try:
        new = wait_for(lambda: set(scene.server.get_clients()) - before, "the client connected")
        client_id = next(iter(new))
        wait_for(lambda: built(scene, client_id), "its own folders built")
        yield client, client_id
    finally:
        client.close()


def built(scene, client_id: int) -> bool:
    """The client's own Control, Jog, Goal points and sinusoid folders are there."""
    return all(
        handle is not None
        for handle in (
            scene.access.handle(client_id, "take"),
            scene.panel.handle(client_id, "jog"),
            scene.panel.handle(client_id, "go_to"),
            scene.tests.handle(client_id, "start"),
        )
    )


def robot(client: TestClient) -> dict:
    status = ok_json(client.get("/api/status"))
    return {
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "torque": status["torque"],
        "mode": status["mode"],
    }


def refused_once_more(scene, client_id: int, act) -> None:
    count = scene.access.refused(client_id)
    act()
    wait_for(lambda: scene.access.refused(client_id) > count, "the command refused")


@pytest.mark.slow
def test_a_websocket_client_without_the_token_cannot_move_the_robot(scene, raw, app_client):
    client, client_id = raw
    panel, before = scene.panel, robot(app_client)
    refused_once_more(scene, client_id, lambda: client.set(panel.gui_torque, "off"))
    assert scene.access.message(client_id) == LOCKED
    jog, start = panel.handle(client_id, "jog"), scene.tests.handle(client_id, "start")
    refused_once_more(scene, client_id, lambda: client.set(jog, "+Z"))
    refused_once_more(scene, client_id, lambda: client.set(panel.gui_reset, True))
    refused_once_more(scene, client_id, lambda: client.drag_goal([0.03, 0.0, -0.26]))
    refused_once_more(scene, client_id, lambda: client.set(start, True))
    for name in ("save_point", "delete_point", "go_to"):  # what a later Go to reaches
        handle = panel.handle(client_id, name)
        refused_once_more(scene, client_id, lambda h=handle: client.set(h, True))
    assert unmoved(before, robot(app_client)), (before, robot(app_client))
    assert ok_json(app_client.get("/api/runs")) == []
    assert ok_json(app_client.get("/api/lease"))["holder"] == "browser"


@pytest.mark.slow
def test_the_scene_e_stop_is_open_to_anyone(scene, raw, app_client):
    client, _ = raw
    client.set(scene.panel.gui_estop, True)
    wait_for(lambda: robot(app_client)["mode"] == "estop", "the e-stop from the scene")


@pytest.mark.slow
def test_the_token_unlocks_but_taking_control_from_a_holder_is_explicit(scene, raw, app_client):
    client, client_id = raw
    client.set(scene.access.handle(client_id, "token"), "not-the-token")
    client.set(scene.access.handle(client_id, "unlock"), True)
    wait_for(lambda: scene.access.message(client_id) == "wrong token", "the wrong token refused")
    refused_once_more(scene, client_id, lambda: client.set(scene.panel.gui_torque, "off"))
    client.set(scene.access.handle(client_id, "token"), TOKEN)
    client.set(scene.access.handle(client_id, "unlock"), True)
    wait_for(lambda: scene.access.message(client_id) == "", "unlocked by the token")
    assert scene.access.handle(client_id, "token").value == ""  # not left on screen
    # unlocked, but the browser holds the lease: no command until it takes control
    before = robot(app_client)
    jog = scene.panel.handle(client_id, "jog")
    refused_once_more(scene, client_id, lambda: client.set(jog, "+Z"))
    assert "held by 'browser'" in scene.access.message(client_id)
    assert unmoved(before, robot(app_client)), (before, robot(app_client))
    client.set(scene.access.handle(client_id, "take"), True)
    wait_for(lambda: scene.access.holds(client_id), "the scene client to take control")
    client.set(jog, "-Z")
    wait_for(lambda: robot(app_client)["goal_m"][2] < GOAL[2] - 1e-3, "the scene's jog down")
    # now the browser's old lease is refused until it takes control back
    refused = app_client.post("/api/torque", json={"enabled": False})
    assert refused.status_code == 409 and "scene client" in refused.json()["detail"]


def test_a_second_scene_client_cannot_command_while_another_holds_control(scene, app_client):
    access = scene.access
    first, second = access.connect(9001), access.connect(9002)
    for client_id in (9001, 9002):
        assert access.unlock(client_id, TOKEN)
    assert access.take(9001, take_over=True)
    before = robot(app_client)
    # the torque buttons' own callback, as viser calls it for a click from client 9002
    callback = scene.panel.gui_torque._impl.update_cb[0]
    scene.panel.gui_torque.value = "off"
    callback(viser.GuiEvent(None, 9002, scene.panel.gui_torque))
    assert access.refused(9002) == 1 and "held by 'scene client 9001'" in second.message
    assert unmoved(before, robot(app_client)), (before, robot(app_client))
    access.disconnect(9001)  # a closed tab gives control back
    assert not ok_json(app_client.get("/api/lease"))["held"]
    access.disconnect(9002)
    assert first.lease_id is not None


def operator_of(scene, client: RawClient, client_id: int) -> None:
    """Unlock ``client`` with the token and give it control, as the operator does."""
    client.set(scene.access.handle(client_id, "token"), TOKEN)
    client.set(scene.access.handle(client_id, "unlock"), True)
    wait_for(lambda: scene.access.unlocked(client_id), "unlocked by the token")
    client.set(scene.access.handle(client_id, "take"), True)
    wait_for(lambda: scene.access.holds(client_id), "the operator to take control")


def goal_z(app_client) -> float:
    return robot(app_client)["goal_m"][2]


@pytest.mark.slow
def test_a_locked_client_cannot_change_what_the_operators_click_does(scene, raw, app_client):
    """Issue 28 point 1: the jog Step and Speed (and the sinusoid's fields) were shared by
    every scene client, so a locked one set Step to 50 mm and the operator's next click
    moved 50 mm. Each client's fields are its own now."""
    operator, operator_id = raw
    operator_of(scene, operator, operator_id)
    before = set(scene.server.get_clients())
    attacker = RawClient(scene.server.get_port())
    try:
        attacker_id = next(
            iter(wait_for(lambda: set(scene.server.get_clients()) - before, "the attacker"))
        )
        wait_for(lambda: built(scene, attacker_id), "the attacker's folders")
        panel = scene.panel
        for name, value in (("jog_step", 50.0), ("jog_speed", 500.0)):
            attacker.set(panel.handle(operator_id, name), value)  # the operator's fields
            attacker.set(panel.handle(attacker_id, name), value)  # and its own
        attacker.set(scene.tests.handle(operator_id, "amplitude"), (90.0, 90.0, 90.0))
        # the attacker's messages are handled in order: once its own field holds 50 mm,
        # the ones before it were handled too
        wait_for(lambda: panel.handle(attacker_id, "jog_step").value == 50.0, "handled")
        refused_once_more(
            scene, attacker_id, lambda: attacker.set(panel.handle(attacker_id, "jog"), "-Z")
        )
    finally:
        attacker.close()
    assert panel.handle(operator_id, "jog_step").value == pytest.approx(5.0)
    assert panel.handle(operator_id, "jog_speed").value == pytest.approx(50.0)
    assert scene.tests.handle(operator_id, "amplitude").value == pytest.approx((50.0, 50.0, 80.0))
    z = goal_z(app_client)
    operator.set(panel.handle(operator_id, "jog"), "-Z")
    wait_for(lambda: goal_z(app_client) < z - 1e-3, "the operator's jog")
    assert goal_z(app_client) == pytest.approx(z - 0.005, abs=1e-6), "one 5 mm step"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("field", "value", "reason"),
    [("jog_step", 1e6, "jog step"), ("jog_speed", 1e6, "jog speed"), ("jog_step", 0.0, "jog step")],
)
def test_the_server_checks_a_jog_field_whoever_sends_it(
    scene, raw, app_client, field, value, reason
):
    """viser stores any number a client sends, whatever the field's min and max: a 1e6 mm
    step moved the tool 165 mm to the boundary. The server refuses it and nothing moves."""
    operator, operator_id = raw
    operator_of(scene, operator, operator_id)
    panel = scene.panel
    operator.set(panel.handle(operator_id, field), value)
    wait_for(lambda: panel.handle(operator_id, field).value == value, "the field written")
    before = robot(app_client)
    panel.message = ""
    operator.set(panel.handle(operator_id, "jog"), "+X")
    wait_for(lambda: reason in panel.message, "the jog refused", seen=lambda: panel.message)
    assert "refused" in panel.message
    assert unmoved(before, robot(app_client)), (before, robot(app_client))
