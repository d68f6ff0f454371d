"""The tip's contact force in a run's log (issue 33): contact_force_{x,y,z}_n [N] and
contact_valid per tick, as the loop's ContactReading had them, in log.mcap and log.csv
alike; an estimate not made is logged empty (not as a number) with contact_valid false;
the replay series carries the force columns (GET /api/runs/{id}/series)."""

from __future__ import annotations

import csv

import numpy as np

from app.control.state import ContactReading, Snapshot
from app.runs.logs import COLUMNS, RunLog, read_messages
from app.runs.recorder import row_of
from app.runs.series import series

FORCES = [(0.1, -0.2, -2.5), (0.0, 0.25, -3.125)]  # [N], exact in binary and in text


def _snap(k: int, contact: ContactReading) -> Snapshot:
    return Snapshot(time_s=0.005 * k, tick=k, mode="touch", contact=contact)


def _snaps() -> list[Snapshot]:
    valid = [
        ContactReading(force_n=np.array(f), std_n=np.full(3, 0.1), valid=True, reason=None)
        for f in FORCES
    ]
    lost = ContactReading(reason="leg 2: current not read")  # force NaN, not valid
    return [_snap(k, c) for k, c in enumerate([*valid, lost])]


def test_the_columns_follow_the_others() -> None:
    names = ["contact_force_x_n", "contact_force_y_n", "contact_force_z_n", "contact_valid"]
    assert COLUMNS[-4:] == names and len(set(COLUMNS)) == len(COLUMNS)


def test_the_contact_force_is_logged_per_tick(tmp_path) -> None:
    log = RunLog(tmp_path / "run", {"run_id": "x"})
    rows = [row_of(s, s.time_s) for s in _snaps()]
    for row, snap in zip(rows, _snaps(), strict=True):
        assert set(row) == set(COLUMNS)
        log.write(row, snap)
    log.close()
    logged = read_messages(log.mcap_path)
    with open(log.csv_path, newline="") as file:
        table = list(csv.DictReader(file))
    for k, force in enumerate(FORCES):
        for axis, value in zip("xyz", force, strict=True):
            assert logged[k][f"contact_force_{axis}_n"] == value
            assert float(table[k][f"contact_force_{axis}_n"]) == value
        assert logged[k]["contact_valid"] is True and table[k]["contact_valid"] == "True"
    # the estimate lost: nothing logged as a force, and said not valid
    assert [logged[2][f"contact_force_{a}_n"] for a in "xyz"] == [None, None, None]
    assert [table[2][f"contact_force_{a}_n"] for a in "xyz"] == ["", "", ""]
    assert logged[2]["contact_valid"] is False and table[2]["contact_valid"] == "False"


def test_the_replay_series_has_the_force() -> None:
    rows = [row_of(s, s.time_s) for s in _snaps()]
    signals = series(rows)["signals"]
    assert signals["contact_force_z_n"] == [-2.5, -3.125, None]
    assert signals["contact_force_x_n"] == [0.1, 0.0, None]
