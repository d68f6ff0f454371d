"""The program library (app/programs/library.py) and its routes: every program sent to
check, dry-run or run kept by its text, listed the most recent first, reopened by id;
bad names and ids refused naming the field and the reason, no path leaves its folder."""

from __future__ import annotations

import hashlib
import json

import pytest

from app.programs.library import (
    MAX_NAME,
    LibraryError,
    ProgramLibrary,
    program_id,
)
from tests.support.wait import ok_json

START = [0.0, 0.0, -0.22]
SHORT = "G21 G90\nG1 F1200 X5 Y0 Z-220\nM2\n"


# ---- the module, on a folder of its own ----


def test_a_text_sent_again_is_one_entry_with_its_last_name_and_count(tmp_path):
    library = ProgramLibrary(tmp_path)
    first = library.add(SHORT, "a.ngc", "check", None, now=100.0)
    again = library.add(SHORT, "b.ngc", "run", (0.0, 0.0, -0.28), now=200.0)
    assert first is not None and again is not None
    assert first.id == again.id == hashlib.sha256(SHORT.encode()).hexdigest()[:16]
    (entry,) = library.entries()
    assert (entry.name, entry.action, entry.sends, entry.sent_at) == ("b.ngc", "run", 2, 200.0)
    assert entry.work_offset_m == [0.0, 0.0, -0.28]
    assert (entry.bytes, entry.lines, entry.first) == (len(SHORT), 3, "G21 G90")
    assert library.get(entry.id) == (entry, SHORT)


def test_the_list_is_most_recent_first_and_capped(tmp_path):
    library = ProgramLibrary(tmp_path, max_entries=3)
    for k in range(5):
        library.add(f"G4 P{k}\n", f"p{k}", "check", now=float(k))
    assert [e.name for e in library.entries()] == ["p4", "p3", "p2"]
    assert len(list(tmp_path.glob("*.ngc"))) == 3  # the oldest two removed, text and all
    with pytest.raises(KeyError):
        library.get(program_id("G4 P0\n"))


def test_a_text_over_the_cap_is_not_kept(tmp_path):
    library = ProgramLibrary(tmp_path, max_bytes=10)
    assert library.add("G4 P1\n" * 3, "long", "check") is None
    assert library.entries() == []


@pytest.mark.parametrize(
    ("name", "reason"),
    [
        ("", "empty"),
        ("   ", "empty"),
        ("x" * (MAX_NAME + 1), f"over the {MAX_NAME} allowed"),
        ("a\nb", "control character"),
        ("../../etc/passwd", "a name is a label, not a path"),
        ("..\\boot.ini", "a name is a label, not a path"),
    ],
)
def test_a_bad_name_is_refused_naming_the_field(tmp_path, name, reason):
    with pytest.raises(LibraryError) as refused:
        ProgramLibrary(tmp_path).add(SHORT, name, "check")
    assert refused.value.field == "name" and reason in refused.value.reason
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ident", ["../secret", "0123456789ABCDEF", "0123", "%2e%2e", ""])
def test_an_id_not_of_the_library_form_is_refused_before_any_path(tmp_path, ident):
    (tmp_path / "secret").write_text("not a program")
    with pytest.raises(LibraryError) as refused:
        ProgramLibrary(tmp_path / "programs").get(ident)
    assert refused.value.field == "id"


def test_a_foreign_file_in_the_folder_is_not_listed(tmp_path):
    library = ProgramLibrary(tmp_path)
    library.add(SHORT, "a.ngc", "check")
    (tmp_path / "notes.json").write_text("{}")
    (tmp_path / "0123456789abcdef.json").write_text("not json")
    assert [e.name for e in library.entries()] == ["a.ngc"]


# ---- the routes, in-process ----


def test_a_checked_program_is_in_the_library_and_reopens_as_sent(client):
    text = "G21 G90\n(library round trip)\nG1 F1200 X4 Y0 Z-220\nM2\n"
    body = {"gcode": text, "start_m": START, "name": "round trip.ngc"}
    body["work_offset_m"] = [0.0, 0.0, 0.0]
    ok_json(client.post("/api/programs/check", json=body))
    listed = ok_json(client.get("/api/programs/library"))
    assert listed["max_entries"] > 0 and listed["max_bytes"] > 0
    entry = listed["programs"][0]  # the most recent
    assert entry["id"] == program_id(text)
    assert (entry["name"], entry["action"], entry["bytes"], entry["lines"]) == (
        "round trip.ngc",
        "check",
        len(text.encode()),
        4,
    )
    assert entry["work_offset_m"] == [0.0, 0.0, 0.0]
    opened = ok_json(client.get(f"/api/programs/library/{entry['id']}"))
    assert opened["gcode"] == text and opened["name"] == "round trip.ngc"


def test_an_unnamed_program_is_kept_as_unnamed_and_counts_its_sends(client):
    text = "G4 P0.05\n(unnamed, twice)\n"
    for _ in range(2):
        ok_json(client.post("/api/programs/check", json={"gcode": text, "start_m": START}))
    listed = ok_json(client.get("/api/programs/library"))["programs"]
    entry = next(e for e in listed if e["id"] == program_id(text))
    assert (entry["name"], entry["sends"], entry["work_offset_m"]) == ("unnamed", 2, None)


@pytest.mark.parametrize(
    ("name", "field", "reason"),
    [
        ("x" * (MAX_NAME + 1), "name", "at most 120 characters"),
        ("../../etc/passwd", "name", "a name is a label, not a path"),
        ("tab\there", "name", "control character"),
        (" ", "name", "empty"),
    ],
)
def test_a_bad_name_is_a_422_naming_the_field_and_nothing_is_checked(client, name, field, reason):
    text = f"G4 P0.01\n(refused name {len(name)})\n"
    response = client.post("/api/programs/check", json={"gcode": text, "name": name})
    assert response.status_code == 422, response.text
    body = response.json()
    assert body["detail"].startswith(f"{field}: ")
    assert [v["field"] for v in body["violations"]] == [field]
    assert reason in body["violations"][0]["reason"]
    listed = ok_json(client.get("/api/programs/library"))["programs"]
    assert program_id(text) not in {e["id"] for e in listed}


@pytest.mark.parametrize(
    ("path", "status"),
    [
        ("/api/programs/library/%2e%2e", 422),  # not an id: refused, not read
        ("/api/programs/library/..%5C..%5Crun.json", 422),
        ("/api/programs/library/0123456789ABCDEF", 422),
        ("/api/programs/library/" + "a" * 5000, 422),
        ("/api/programs/library/0123456789abcdef", 404),  # an id, not kept
    ],
)
def test_a_bad_or_unknown_id_is_refused_with_its_field(client, path, status):
    response = client.get(path)
    assert response.status_code == status, response.text
    assert response.json()["detail"].startswith("id: ")


def test_a_path_for_an_id_matches_no_route_and_reads_nothing(client):
    # an encoded '/' is a path separator to the router: no library route, nothing read
    response = client.get("/api/programs/library/..%2F..%2Fconfig.toml")
    assert response.status_code == 404, response.text
    assert set(response.json()) == {"detail"} and "gcode" not in response.text


def test_a_body_that_is_not_utf8_is_a_422_naming_the_body(client):
    raw = b'{"gcode": "G4 P0.1 (Stra\xdfe)", "name": "latin1.ngc"}'
    response = client.post(
        "/api/programs/check", content=raw, headers={"Content-Type": "application/json"}
    )
    assert response.status_code == 422, response.text
    assert response.json()["violations"][0]["field"]


def test_the_defaults_are_the_configs(client):
    body = ok_json(client.get("/api/programs/defaults"))
    assert body["work_offset_m"] == [0.0, 0.0, 0.0] and body["start_m"] == [0.0, 0.0, -0.24]
    assert body["dry_run_max_s"] == 60.0 and body["loop_rate_hz"] > 0


def test_a_kept_entry_file_is_plain_json(client, tmp_path):
    library = ProgramLibrary(tmp_path)
    entry = library.add(SHORT, "plain.ngc", "dry-run")
    assert entry is not None
    assert json.loads((tmp_path / f"{entry.id}.json").read_text())["action"] == "dry-run"
