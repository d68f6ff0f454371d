"""Run logs written as the run goes: MCAP (JSON-schema messages) and CSV, and, given the
settings, the same ticks as a ROS 2 bag (``log.ros2.mcap``, app/runs/ros2_log.py).

Every control tick of a run becomes one row/message, written by a background thread so
the control thread only appends to a queue. Both files grow by whole commits, every
``FLUSH_EVERY_S``: what was written since the last one goes to the file in one write.

A crash must leave an MCAP file that the standard readers open, and they need a footer:
``mcap``'s seeking reader starts from the Footer at the end of the file and its
non-seeking reader reads up to one (a file cut without one raises, losing every message
when read in log-time order). So the MCAP is written unchunked (each message is a record
of its own, readable as soon as it is in the file; no chunk waits in memory) and every
commit ends the file with a closing trailer, DataEnd + Footer (no summary) + magic, that
the next commit replaces. After each commit the file is a complete, unindexed MCAP file;
``close()`` ends it with the summary instead. A process killed between commits leaves a
file every reader opens, up to the last commit; one killed inside a commit (or a machine
that loses its power) can leave a file cut anywhere, of which ``read_messages`` reads the
whole messages and ``finish_cut_log`` makes a complete file.

Log times (MCAP ``log_time`` and ``publish_time``) are UTC wall-clock nanoseconds: the
wall clock at the run's first tick (``start_ns``) plus the loop's monotonic run time
``t_s`` of the tick, so they never go backwards if the system clock is stepped mid-run.
The ROS 2 bag's messages carry the same times, and it grows by the same commits.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

from app.runs.ros2_log import FILE as ROS2_FILE
from app.runs.ros2_log import Ros2Log

if TYPE_CHECKING:
    from app.config import Settings
    from app.control.state import Snapshot

try:
    import fcntl
except ImportError:  # not POSIX: no lock, a restart cannot tell a live writer
    fcntl = None  # type: ignore[assignment]

log = logging.getLogger(__name__)

TOPIC = "/deltadash/tick"
MEDIA_TYPE = "application/vnd.mcap"  # IANA-registered media type of MCAP files
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
    "line",  # a G-code program's line in execution (app/programs); None for other runs
    # the wrist (a [wrist] section), empty without one: its goal, last command and reading
    "phi_goal_rad",
    "phi_commanded_rad",
    "phi_measured_rad",
    # hold-in-world with a wrist: the tool's world heading kept, and measured
    "world_heading_goal_rad",
    "world_heading_measured_rad",
    "heading_limited",
    # a program standing (Pause, M0 / M1, a single step's stop) or braking to: why, in
    # words (app/link/paths.py Playback); empty while it runs. Standing, one row a second
    # is kept (app/runs/recorder.py)
    "paused",
    # the tip's contact force estimate (app/control/contact.py): the force the tip applies,
    # base frame [N], empty when not known; contact_valid: the estimate could be made
    "contact_force_x_n",
    "contact_force_y_n",
    "contact_force_z_n",
    "contact_valid",
]

SCHEMA = {
    "title": "deltadash.Tick",
    "description": "One control tick of a run: SI units, base frame",
    "type": "object",
    "properties": {name: {"type": ["number", "string", "boolean", "null"]} for name in COLUMNS},
}


def _trailer() -> bytes:
    """DataEnd (no CRC), a Footer without summary, magic: what closes an unindexed file."""
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


TRAILER = _trailer()


class _CommittedFile:
    """A binary file that grows by whole commits.

    ``write`` keeps the bytes in memory; ``commit(tail)`` puts them in the file in one
    write, followed by ``tail``, which the next commit drops before it writes (so the file
    is always a prefix of the stream written so far, plus the last tail). ``tell`` is the
    position in that stream, as the MCAP writer needs for its summary offsets.
    """

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb", buffering=0)  # noqa: SIM115 - closed in close()
        self._pending = bytearray()
        self._end = 0  # bytes of the stream in the file
        self._tail = 0  # bytes of the last tail after them

    def fileno(self) -> int:
        return self._file.fileno()

    def write(self, data: bytes) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._end + len(self._pending)

    def flush(self) -> None:
        """The writer's flush: nothing; bytes reach the file at ``commit``."""

    def commit(self, tail: bytes = b"") -> None:
        # The new bytes overwrite the last tail in place (no truncate first): a kill at any
        # moment leaves either the old complete file or the new one, never a bare prefix.
        data = memoryview(bytes(self._pending) + tail)
        self._file.seek(self._end)
        while data:
            data = data[self._file.write(data) :]
        if len(self._pending) + len(tail) < self._tail:
            self._file.truncate(self._end + len(self._pending) + len(tail))
        self._end += len(self._pending)
        self._tail = len(tail)
        self._pending.clear()

    def close(self) -> None:
        self._file.close()


class RunLog:
    """The MCAP and CSV files of one run; ``write(row, snap)`` per tick, ``close()`` at the
    end.

    ``on_flush(messages)`` is called (in the writer's thread) after each commit with the
    number of ticks then in the files. ``start_ns``: UTC wall clock [ns] at ``t_s`` = 0,
    set by the recorder at the run's first tick (else taken at the first write).
    ``settings``: with ``[ros2] run_log`` on, the ticks' snapshots are also written as ROS 2
    messages to ``log.ros2.mcap`` (``ros2_path``; None without).

    While it is open the MCAP file holds an exclusive ``flock``: another process can tell
    a live run from one whose writer has died (``is_being_written``).
    """

    FLUSH_EVERY_S = 0.25

    def __init__(
        self,
        folder: Path,
        metadata: dict[str, str],
        on_flush: Callable[[int], None] | None = None,
        settings: Settings | None = None,
    ) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.mcap_path, self.csv_path = folder / "log.mcap", folder / "log.csv"
        self.start_ns: int | None = None
        self._on_flush = on_flush
        self._mcap_file = _CommittedFile(self.mcap_path)
        if fcntl is not None:
            fcntl.flock(self._mcap_file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        self._writer = Writer(
            self._mcap_file,  # type: ignore[arg-type]
            use_chunking=False,
            compression=CompressionType.NONE,
        )
        self._writer.start(profile="", library="deltadash")
        self._writer.add_metadata("run", metadata)
        schema = self._writer.register_schema(
            "deltadash.Tick", "jsonschema", json.dumps(SCHEMA).encode()
        )
        self._channel = self._writer.register_channel(TOPIC, "json", schema)
        self.ros2_path: Path | None = None
        self._ros2_file: _CommittedFile | None = None
        self._ros2: Ros2Log | None = None
        self._ros2_errors = 0
        if settings is not None and settings.ros2.run_log:
            self.ros2_path = folder / ROS2_FILE
            self._ros2_file = _CommittedFile(self.ros2_path)
            self._ros2 = Ros2Log(self._ros2_file, settings, metadata)  # type: ignore[arg-type]
        self._csv_file = _CommittedFile(self.csv_path)
        self._csv_text = io.StringIO()
        self._csv = csv.writer(self._csv_text)
        self._csv.writerow(COLUMNS)
        self._sequence = 0
        self._commit(TRAILER)
        self._last_flush = time.monotonic()

    def write(self, row: dict[str, Any], snap: Snapshot | None = None) -> None:
        """One tick; keys are COLUMNS (None for unknown values). ``snap``: the tick's
        snapshot, for the ROS 2 bag (none there without it)."""
        offset_ns = round(row["t_s"] * 1e9)
        if self.start_ns is None:
            self.start_ns = time.time_ns() - offset_ns
        stamp = self.start_ns + offset_ns
        self._writer.add_message(
            self._channel, stamp, json.dumps(row).encode(), stamp, self._sequence
        )
        self._sequence += 1
        if self._ros2 is not None and snap is not None:
            self._write_ros2(snap, stamp)
        self._csv.writerow(["" if row.get(c) is None else row[c] for c in COLUMNS])
        if time.monotonic() - self._last_flush > self.FLUSH_EVERY_S:
            self._flush()

    def _write_ros2(self, snap: Snapshot, stamp_ns: int) -> None:
        assert self._ros2 is not None
        try:
            self._ros2.write(snap, stamp_ns)
        except Exception:  # the ROS 2 copy must not cost the run its own log
            self._ros2_errors += 1
            if self._ros2_errors == 1:
                log.exception("run log: a tick could not be written as ROS 2 messages")

    def _commit(self, mcap_tail: bytes) -> None:
        self._mcap_file.commit(mcap_tail)
        if self._ros2_file is not None:
            self._ros2_file.commit(mcap_tail)
        self._csv_file.write(self._csv_text.getvalue().encode())
        self._csv_text.seek(0)
        self._csv_text.truncate()
        self._csv_file.commit()

    def _flush(self) -> None:
        self._commit(TRAILER)
        self._last_flush = time.monotonic()
        if self._on_flush is not None:
            self._on_flush(self._sequence)

    def close(self) -> None:
        """Write the MCAP summaries in place of the trailers and close the files."""
        self._writer.finish()
        if self._ros2 is not None:
            self._ros2.finish()
        self._commit(b"")
        self._mcap_file.close()  # and the lock with it
        self._csv_file.close()
        if self._ros2_file is not None:
            self._ros2_file.close()


def is_being_written(path: Path) -> bool:
    """Whether a live process holds ``path`` open as a RunLog (its lock is taken)."""
    if fcntl is None or not path.exists():
        return False
    with open(path, "rb") as file:
        try:
            fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(file.fileno(), fcntl.LOCK_UN)
    return False


def _whole_records(data: bytes) -> int:
    """Length of the longest prefix of an MCAP stream made of whole records (magic, then
    <opcode u8><length u64><body> each), up to its Footer: where a cut file can be read to.
    The mcap reader is not told of a cut inside a record (a short read of a message's
    data returns the bytes there are), so it is only given whole records."""
    magic = len(MCAP0_MAGIC)
    if len(data) < magic:
        return 0
    position = magic
    while position + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, position)
        end = position + 9 + length
        if end > len(data):
            break
        position = end
        if opcode == Opcode.FOOTER:
            break
    return position


def _records(path: Path) -> list[Any]:
    """The data section's records of an MCAP file, up to its DataEnd or, in a file cut
    short, the last whole record."""
    data = path.read_bytes()
    whole = _whole_records(data)
    records: list[Any] = []
    if whole == 0:
        return records  # cut inside the magic: nothing was written yet
    try:
        for record in StreamReader(io.BytesIO(data[:whole])).records:
            if isinstance(record, DataEnd):
                break
            records.append(record)
    except EndOfFile:
        pass  # cut: every whole record before the cut is kept
    return records


def read_messages(path: Path) -> list[dict[str, Any]]:
    """Every tick message in an MCAP log, also from a file cut short by a crash.

    A finished or committed file has a footer and any MCAP reader opens it; one cut
    anywhere else is read record by record up to the last complete message.
    """
    return [json.loads(r.data) for r in _records(path) if isinstance(r, Message)]


def read_csv_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a CSV log as ``RunLog.write`` got them (numbers as floats, empty as
    None); a last line cut short by a crash is left out."""
    text = path.read_text()
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # the cut line
    reader = csv.DictReader(io.StringIO(text))
    texts = {"phase", "mode", "faults"}

    def value(name: str, cell: str) -> Any:
        if name in texts:
            return cell
        if name == "paused":  # a text, or empty while the program runs (None)
            return cell or None
        if cell == "":
            return None
        if cell in ("True", "False"):
            return cell == "True"
        return float(cell)

    return [{k: value(k, v) for k, v in row.items() if k is not None} for row in reader]


def finish_cut_log(path: Path, original: Path) -> int:
    """Make the MCAP log of a run that never ended a complete file with a summary
    (message count, time range, channels: what Foxglove reads first), keeping the file as
    the crash left it at ``original``. Every whole message up to the cut is kept, with its
    times and sequence. Returns the number of messages in the new file.

    Safe to repeat: if ``original`` exists it is the source (a restart that stopped
    between the two renames finishes the job).
    """
    if not original.exists():
        if not path.exists():
            return 0
        path.replace(original)
    records = _records(original)
    header = next((r for r in records if isinstance(r, Header)), None)
    temporary = path.with_name(path.name + ".tmp")
    count = 0
    with open(temporary, "wb") as file:
        writer = Writer(file, use_chunking=False, compression=CompressionType.NONE)
        writer.start(
            profile=header.profile if header else "",
            library=header.library if header else "deltadash",
        )
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for record in records:
            if isinstance(record, Metadata):
                writer.add_metadata(record.name, record.metadata)
            elif isinstance(record, Schema):
                schemas[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel):
                channels[record.id] = writer.register_channel(
                    record.topic,
                    record.message_encoding,
                    schemas.get(record.schema_id, 0),
                    record.metadata,
                )
            elif isinstance(record, Message) and record.channel_id in channels:
                writer.add_message(
                    channels[record.channel_id],
                    record.log_time,
                    record.data,
                    record.publish_time,
                    record.sequence,
                )
                count += 1
        writer.finish()
    temporary.replace(path)
    return count
