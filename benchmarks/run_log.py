"""Write cost per tick of a run's logs (the writer thread's work, not the control thread's).

Usage: python benchmarks/run_log.py [--ticks 20000] [--rate 200] [--flush 0.25] [--repeat 3]

Each layout writes the same realistic rows (every logs.COLUMNS value set) to an MCAP and a
CSV file, committing every ``rate * flush`` ticks as a run at ``rate`` Hz flushing every
``flush`` s would:

- ``committed + trailer`` (app/runs/logs.RunLog, the layout in use): unchunked, whole
  commits, each ending the file with DataEnd + Footer + magic (a complete file after each);
- ``unchunked, buffered`` (the layout before): unchunked, a buffered file flushed at the
  same cadence, no trailer (a cut file the mcap readers do not open);
- ``chunk per flush``: a chunk of uncompressed messages cut at each flush (``Writer.flush``),
  the "small chunks" alternative (still no footer until the end).

Prints, per layout, the mean write cost per tick (commits included; the best of
``repeat`` passes, the layouts taking turns), the p50 / p99 / max of a commit over all
passes, and the bytes per tick on disk. Costs are the writing thread's CPU time (user and
system, ``time.thread_time``): on a loaded machine wall time mostly measures the others.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent  # benchmarks/kinematics.py would shadow the package
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from mcap.writer import CompressionType, Writer  # noqa: E402

from app.runs.logs import COLUMNS, SCHEMA, TOPIC, RunLog  # noqa: E402


def _rows(n: int) -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for k in range(n):
        row = {c: float(rng.normal()) for c in COLUMNS}
        row.update({"t_s": k * 0.005, "phase": "timed", "mode": "test", "faults": ""})
        row.update({"outside": False, "pose_age_ms": None})
        rows.append(row)
    return rows


class _Buffered:
    """The layout before: unchunked MCAP and CSV through buffered files."""

    def __init__(self, folder: Path, chunked: bool) -> None:
        self.mcap = open(folder / "log.mcap", "wb")  # noqa: SIM115
        self.writer = Writer(
            self.mcap,
            use_chunking=chunked,
            chunk_size=1 << 30,  # chunks are cut at flush only
            compression=CompressionType.NONE,
        )
        self.chunked = chunked
        self.writer.start(profile="", library="bench")
        schema = self.writer.register_schema("t", "jsonschema", json.dumps(SCHEMA).encode())
        self.channel = self.writer.register_channel(TOPIC, "json", schema)
        self.csv_file = open(folder / "log.csv", "w", newline="")  # noqa: SIM115
        self.csv = csv.writer(self.csv_file)
        self.sequence = 0

    def write(self, row: dict) -> None:
        stamp = 1_800_000_000_000_000_000 + round(row["t_s"] * 1e9)
        self.writer.add_message(self.channel, stamp, json.dumps(row).encode(), stamp, self.sequence)
        self.sequence += 1
        self.csv.writerow(["" if row[c] is None else row[c] for c in COLUMNS])

    def flush(self) -> None:
        if self.chunked:
            self.writer.flush()
        self.mcap.flush()
        self.csv_file.flush()

    def close(self) -> None:
        self.writer.finish()
        self.mcap.close()
        self.csv_file.close()


class _Committed:
    def __init__(self, folder: Path) -> None:
        self.log = RunLog(folder, {"run_id": "bench"})
        self.log.FLUSH_EVERY_S = math.inf  # commits at the benchmark's cadence
        self.log.start_ns = 1_800_000_000_000_000_000

    def write(self, row: dict) -> None:
        self.log.write(row)

    def flush(self) -> None:
        self.log._flush()

    def close(self) -> None:
        self.log.close()


def _measure(make, rows: list[dict], every: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        log = make(folder)
        commits = []
        began = time.thread_time()
        for k, row in enumerate(rows, 1):
            log.write(row)
            if k % every == 0:
                t = time.thread_time()
                log.flush()
                commits.append(time.thread_time() - t)
        total = time.thread_time() - began
        log.close()
        size = sum(p.stat().st_size for p in folder.rglob("log.*"))
    return {
        "per_tick_us": total / len(rows) * 1e6,
        "commits_us": np.array(commits) * 1e6,
        "bytes_per_tick": size / len(rows),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--ticks", type=int, default=20000)
    parser.add_argument("--rate", type=float, default=200.0)
    parser.add_argument("--flush", type=float, default=0.25)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    every = max(1, round(args.rate * args.flush))
    rows = _rows(args.ticks)
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.2f}, Python {platform.python_version()}; "
        f"{args.ticks} ticks, a commit every {every} ticks"
    )
    layouts = {
        "committed + trailer (in use)": lambda f: _Committed(f / "run"),
        "unchunked, buffered (before)": lambda f: _Buffered(f, chunked=False),
        "chunk per flush": lambda f: _Buffered(f, chunked=True),
    }
    results: dict[str, list[dict]] = {name: [] for name in layouts}
    for make in layouts.values():
        _measure(make, rows[: every * 4], every)  # warm up
    for _ in range(args.repeat):
        for name, make in layouts.items():
            results[name].append(_measure(make, rows, every))
    for name, passes in results.items():
        per_tick = min(r["per_tick_us"] for r in passes)
        commits = np.concatenate([r["commits_us"] for r in passes])
        p50, p99, worst = np.percentile(commits, 50), np.percentile(commits, 99), commits.max()
        print(
            f"  {name:30} {per_tick:6.1f} us/tick   commit p50 {p50:6.0f} "
            f"p99 {p99:6.0f} max {worst:6.0f} us   {passes[0]['bytes_per_tick']:5.0f} B/tick"
        )


if __name__ == "__main__":
    main()
