"""The telemetry message carries the tip's contact force estimate (issue 33), as GET
/api/status has it: the plots' "tip force" set draws it."""

from __future__ import annotations

import numpy as np
import pytest

from app.control.state import ContactReading, Snapshot
from app.server.api import serialize
from app.server.api.responses import TelemetryMessage


def test_the_contact_estimate_is_in_the_telemetry_as_in_the_status():
    reading = ContactReading(
        force_n=np.array([0.5, 0.0, -2.0]), std_n=np.array([0.1, 0.1, 0.2]), valid=True, reason=None
    )
    message = serialize.telemetry(Snapshot(contact=reading))
    assert message["contact"] == {
        "force_n": [0.5, 0.0, -2.0],
        "std_n": [0.1, 0.1, 0.2],
        "magnitude_n": pytest.approx(np.hypot(0.5, 2.0)),
        "valid": True,
        "reason": None,
    }
    assert message["contact"] == serialize.contact(Snapshot(contact=reading))
    TelemetryMessage.model_validate(message)  # the schema /openapi.json gives


def test_no_estimate_is_null_with_its_reason():
    message = serialize.telemetry(Snapshot(contact=ContactReading(reason="leg 2: not read")))
    contact = message["contact"]
    assert contact["force_n"] == [None, None, None] and contact["magnitude_n"] is None
    assert contact["valid"] is False and contact["reason"] == "leg 2: not read"
    TelemetryMessage.model_validate(message)
