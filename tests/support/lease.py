"""Test clients take the control lease like any other client (app/control/authority.py)."""

from __future__ import annotations

from typing import Any


def take_lease(
    client: Any, name: str = "tests", token: str | None = None, sticky: bool = True
) -> dict[str, str]:
    """Take control (over anyone) for a TestClient; returns the headers a command needs
    (``X-Lease``, and ``Authorization`` when ``token`` is given). ``sticky``: also set them
    as the client's default headers, so every later request of that client sends them."""
    auth = {"Authorization": f"Bearer {token}"} if token else {}
    response = client.post("/api/lease", json={"client": name, "take_over": True}, headers=auth)
    assert response.status_code == 200, response.text
    headers = {**auth, "X-Lease": response.json()["lease_id"]}
    if sticky:
        client.headers.update(headers)
    return headers
