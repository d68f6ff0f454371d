"""Run logs written as the run goes: MCAP (JSON-schema messages) and CSV.

Every control tick of a run becomes one row/message, written by a background thread so
the control thread only appends to a queue. MCAP is written unchunked and flushed often:
a run cut short by an abort, a fault or a crash still leaves a file that the ``mcap``
reader (and Foxglove, PlotJuggler) reads up to the last flushed message.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any, TextIO

from mcap.writer import CompressionType, Writer

TOPIC = "/deltadash/tick"
COLUMNS = [
    "t_s",
    "phase",
    "mode",
    "goal_x_m",
    "goal_y_m",
    "goal_z_m",
    "commanded_q1_rad",
    "commanded_q2_rad",
    "commanded_q3_rad",
    "measured_q1_rad",
    "measured_q2_rad",
    "measured_q3_rad",
    "measured_x_m",
    "measured_y_m",
    "measured_z_m",
    "external_x_m",
    "external_y_m",
    "external_z_m",
    "lateness_ms",
    "faults",
    "world_goal_x_m",
    "world_goal_y_m",
    "world_goal_z_m",
    "world_measured_x_m",
    "world_measured_y_m",
    "world_measured_z_m",
    "outside",
    "pose_age_ms",
    "gap_ms",
    "overrun",
    "sim_time_s",
    "stale",
    "feedback_age_ms",
]

SCHEMA = {
    "title": "deltadash.Tick",
    "description": "One control tick of a run: SI units, base frame",
    "type": "object",
    "properties": {name: {"type": ["number", "string", "boolean", "null"]} for name in COLUMNS},
}


class RunLog:
    """The MCAP and CSV files of one run; ``write(row)`` per tick, ``close()`` at the end."""

    FLUSH_EVERY_S = 0.25

    def __init__(self, folder: Path, metadata: dict[str, str]) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.mcap_path, self.csv_path = folder / "log.mcap", folder / "log.csv"
        self._mcap_file = open(self.mcap_path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._mcap_file, use_chunking=False, compression=CompressionType.NONE)
        self._writer.start(profile="", library="deltadash")
        self._writer.add_metadata("run", metadata)
        schema = self._writer.register_schema(
            "deltadash.Tick", "jsonschema", json.dumps(SCHEMA).encode()
        )
        self._channel = self._writer.register_channel(TOPIC, "json", schema)
        self._csv_file: TextIO = open(self.csv_path, "w", newline="")  # noqa: SIM115
        self._csv = csv.writer(self._csv_file)
        self._csv.writerow(COLUMNS)
        self._sequence = 0
        self._last_flush = time.monotonic()

    def write(self, row: dict[str, Any]) -> None:
        """One tick; keys are COLUMNS (None for unknown values)."""
        stamp = int(row["t_s"] * 1e9)
        self._writer.add_message(
            self._channel, stamp, json.dumps(row).encode(), stamp, self._sequence
        )
        self._sequence += 1
        self._csv.writerow(["" if row[c] is None else row[c] for c in COLUMNS])
        if time.monotonic() - self._last_flush > self.FLUSH_EVERY_S:
            self._flush()

    def _flush(self) -> None:
        self._mcap_file.flush()
        self._csv_file.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the MCAP summary and close both files."""
        self._writer.finish()
        self._mcap_file.close()
        self._csv_file.close()


def read_messages(path: Path) -> list[dict[str, Any]]:
    """Every tick message in an MCAP log, also from a file cut short by a crash.

    A finished file has a summary and any MCAP reader opens it; an unfinished one is read
    record by record up to the last complete message.
    """
    from mcap.exceptions import EndOfFile
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    messages: list[dict[str, Any]] = []
    with open(path, "rb") as file:
        try:
            for record in StreamReader(file).records:
                if isinstance(record, Message):
                    messages.append(json.loads(record.data))
        except EndOfFile:
            pass  # truncated: everything before the cut is kept
    return messages
