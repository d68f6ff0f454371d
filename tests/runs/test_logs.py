"""Run logs: every commit leaves a complete MCAP file; a file cut anywhere reads as a
prefix of its messages and is finished into a complete one; log times are UTC."""

from __future__ import annotations

import io
import json
import random
import struct
import time
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader, make_reader

from app.runs.logs import (
    COLUMNS,
    RunLog,
    finish_cut_log,
    is_being_written,
    read_csv_rows,
    read_messages,
)

MESSAGE = 0x05  # MCAP opcode of a Message record


def _row(k: int) -> dict:
    row = dict.fromkeys(COLUMNS)
    row.update(
        {"t_s": k * 0.005, "phase": "timed", "mode": "test", "goal_x_m": 0.001 * k, "faults": ""}
    )
    row["measured_z_m"] = -0.24 + 1e-6 * k
    return row


def _standard_reads(data: bytes) -> tuple[list, list]:
    """The messages the mcap package's seeking and non-seeking readers give."""
    seeking = list(make_reader(io.BytesIO(data)).iter_messages())
    streaming = list(NonSeekingReader(io.BytesIO(data)).iter_messages())
    return seeking, streaming


def _message_ends(data: bytes) -> list[int]:
    """Byte offsets where each Message record of an MCAP stream ends, walking the
    records by their opcode and length (spec: <opcode u8><length u64><body>)."""
    ends, position = [], 8  # after the magic
    while position + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, position)
        position += 9 + length
        if opcode == MESSAGE:
            ends.append(position)
        if opcode == 0x0F:  # DataEnd: what follows is the closing trailer
            break
    return ends


@pytest.fixture
def committed(tmp_path: Path) -> tuple[list[bytes], list[int], RunLog]:
    """A log written in 6 commits; the file's bytes after each and the rows it held."""
    log = RunLog(tmp_path / "run", {"run_id": "x"})
    log.start_ns = 1_800_000_000 * 10**9  # 2027-01-15T08:00:00Z
    snapshots, counts = [(log.mcap_path.read_bytes())], [0]
    for k in range(300):
        log.write(_row(k))
        if k % 50 == 49:
            log._flush()
            snapshots.append(log.mcap_path.read_bytes())
            counts.append(k + 1)
    return snapshots, counts, log


def test_every_commit_leaves_a_file_the_standard_readers_read_whole(committed):
    snapshots, counts, log = committed
    for data, count in zip(snapshots, counts, strict=True):
        seeking, streaming = _standard_reads(data)
        for read in (seeking, streaming):
            assert [json.loads(m.data) for _, _, m in read] == [_row(k) for k in range(count)]
            assert [m.sequence for _, _, m in read] == list(range(count))
    log.close()


def test_log_times_are_utc_wall_clock_nanoseconds(committed):
    snapshots, _, log = committed
    log.close()
    with open(log.mcap_path, "rb") as file:
        messages = [m for _, _, m in make_reader(file).iter_messages()]
    for k, message in enumerate(messages):
        assert message.log_time == message.publish_time == log.start_ns + round(k * 0.005e9)
        assert json.loads(message.data)["t_s"] == k * 0.005  # run time kept in the message
    # without a start from the recorder, the first write takes the wall clock
    other = RunLog(log.mcap_path.parent.parent / "other", {})
    before = time.time_ns()
    other.write(_row(0))
    other.close()
    with open(other.mcap_path, "rb") as file:
        stamp = next(iter(make_reader(file).iter_messages()))[2].log_time
    assert before <= stamp <= time.time_ns()


def test_a_finished_log_has_a_summary(committed):
    _, _, log = committed
    log.close()
    with open(log.mcap_path, "rb") as file:
        summary = make_reader(file).get_summary()
    assert summary is not None and summary.statistics.message_count == 300
    assert summary.statistics.message_end_time - summary.statistics.message_start_time == round(
        299 * 0.005e9
    )
    seeking, streaming = _standard_reads(log.mcap_path.read_bytes())
    assert len(seeking) == len(streaming) == 300
    assert len(read_messages(log.mcap_path)) == 300


@pytest.mark.slow
def test_a_log_cut_anywhere_reads_as_a_prefix_and_is_finished_whole(committed, tmp_path):
    snapshots, _, log = committed
    data = snapshots[-1]
    ends = _message_ends(data)
    assert len(ends) == 300
    rows = [_row(k) for k in range(300)]
    generator = random.Random(16)
    cuts = sorted(
        {*range(0, 600), *(e + d for e in ends[:5] + ends[-5:] for d in (-1, 0, 1))}
        | {generator.randrange(len(data) + 1) for _ in range(40)}
        | {len(data) - d for d in range(0, 60)}  # inside the closing trailer
    )
    for cut in cuts:
        path = tmp_path / "cut" / f"{cut}.mcap"
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(data[:cut])
        whole = sum(1 for end in ends if end <= cut)
        assert read_messages(path) == rows[:whole], cut
        if cut % 7 and cut not in ends:  # finishing is slower: a sample of the cuts
            continue
        kept = path.with_suffix(".cut.mcap")
        assert finish_cut_log(path, kept) == whole
        assert kept.read_bytes() == data[:cut]  # the file as the crash left it
        seeking, streaming = _standard_reads(path.read_bytes())
        for read in (seeking, streaming):
            assert [json.loads(m.data) for _, _, m in read] == rows[:whole], cut
        with open(path, "rb") as file:
            assert make_reader(file).get_summary().statistics.message_count == whole
        assert finish_cut_log(path, kept) == whole  # repeating it changes nothing
    log.close()


def test_the_csv_log_grows_by_whole_rows(committed):
    _, counts, log = committed
    text = log.csv_path.read_text()
    assert text.endswith("\n") and text.count("\n") == 1 + counts[-1]  # committed rows only
    assert read_csv_rows(log.csv_path) == [_row(k) for k in range(counts[-1])]
    log.csv_path.write_text(text + "1.5,timed,te")  # a crash inside a commit
    assert len(read_csv_rows(log.csv_path)) == counts[-1]
    log.close()


def test_an_open_log_is_locked_until_closed(committed):
    _, _, log = committed
    assert is_being_written(log.mcap_path)
    log.close()
    assert not is_being_written(log.mcap_path)
