"""The bodies of refused requests: the programs routes' validation errors in the programs'
own error shape; JSON that cannot be read (invalid UTF-8, a BOM, duplicate keys, a number
past Python's int limit, nesting too deep) a 422 naming the field or "body" and the reason.
"""

from __future__ import annotations

import json

import pytest

PROGRAM_ROUTES = ("/api/programs/check", "/api/programs/dry-run", "/api/programs/run")
JSON = {"content-type": "application/json"}
DIGITS = "7" * 5000  # past sys.get_int_max_str_digits() (4300): int() raises ValueError


def post_raw(client, path, raw: bytes):
    return client.post(path, content=raw, headers=JSON)


@pytest.mark.slow
@pytest.mark.parametrize("path", PROGRAM_ROUTES)
@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"gcode": 5}, "gcode"),
        ({}, "gcode"),
        ({"gcode": "M2", "start_m": [0.0, "x", -0.2]}, "start_m.1"),
        ({"gcode": "M2", "speed": 1}, "speed"),
    ],
)
def test_validation_errors_on_program_routes_have_the_programs_error_shape(
    fresh, path, body, field
):
    response = fresh.post(path, json=body)
    assert response.status_code == 422, response.text
    answer = response.json()
    assert set(answer) == {"detail", "line", "word", "violations"}
    assert answer["line"] is None and answer["word"] is None  # no program was read
    fields = [v["field"] for v in answer["violations"]]
    assert field in fields
    for violation in answer["violations"]:
        assert set(violation) == {"field", "reason"} and violation["reason"]
        assert f"{violation['field']}: {violation['reason']}" in answer["detail"]


@pytest.mark.parametrize(
    ("path", "raw", "field", "words"),
    [
        ("/api/programs/check", b'{"gcode": "M2\xff"}', "body", "UTF-8"),
        ("/api/goal", b'{"position_m": [0, 0, -0.2], "phi_rad": 0\xc3}', "body", "UTF-8"),
        ("/api/goal", b'{"position_m": [%s, 0, -0.2]}' % DIGITS.encode(), "position_m.0", "digits"),
        (
            "/api/programs/check",
            b'{"gcode": "M2", "start_m": -%s}' % DIGITS.encode(),
            "start_m",
            "digits",
        ),
        ("/api/goal", b"[" * 100_000 + b"]" * 100_000, "body", "nested"),
        (
            "/api/programs/check",
            b'{"gcode": ' + b"[" * 50_000 + b"]" * 50_000 + b"}",
            "body",
            "nested",
        ),
    ],
)
def test_json_that_cannot_be_read_is_a_422_naming_field_and_reason(fresh, path, raw, field, words):
    before = fresh.get("/api/status").json()["goal"] if path == "/api/goal" else None
    response = post_raw(fresh, path, raw)
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert detail.startswith(f"{field}: ") and words in detail
    if before is not None:
        assert fresh.get("/api/status").json()["goal"] == before


@pytest.mark.parametrize(
    ("path", "raw", "field"),
    [
        ("/api/programs/check", b'{"gcode": "G1 X1", "gcode": "M2"}', "gcode"),
        ("/api/goal", b'{"position_m": [0, 0, -0.2], "position_m": [0, 0, -0.21]}', "position_m"),
        (
            "/api/tuning/run",
            b'{"target": {"bandwidth_hz": 5, "bandwidth_hz": 8}}',
            "target.bandwidth_hz",
        ),
    ],
)
def test_a_duplicated_key_is_a_422_naming_it(fresh, path, raw, field):
    response = post_raw(fresh, path, raw)
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert detail.startswith(f"{field}: ") and "duplicate" in detail


@pytest.mark.parametrize("path", ["/api/programs/check", "/api/goal"])
def test_a_utf8_bom_is_a_422_saying_so(fresh, path):
    body = {"gcode": "M2"} if "programs" in path else {"position_m": [0, 0, -0.2]}
    response = post_raw(fresh, path, b"\xef\xbb\xbf" + json.dumps(body).encode())
    assert response.status_code == 422, response.text
    assert response.json()["detail"].startswith("body: ") and "BOM" in response.json()["detail"]


def test_unreadable_json_on_a_program_route_has_the_programs_error_shape(fresh):
    raw = b'{"gcode": "M2", "gcode": "M2"}'
    answer = post_raw(fresh, "/api/programs/check", raw).json()
    assert answer["line"] is None and answer["word"] is None
    assert [v["field"] for v in answer["violations"]] == ["gcode"]
