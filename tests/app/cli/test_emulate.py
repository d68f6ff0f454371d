"""``deltadash emulate``: argument parsing, and a standalone emulator a client can reach."""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import threading

import dynamixel_sdk as sdk
import pytest

from app.cli import emulate as emulator_cli
from tests.support.servo_emulator import BAUD, PatientPort


def test_parse_ids() -> None:
    assert emulator_cli.parse_ids("1,2,3") == [1, 2, 3]
    for bad in ("", "1,1", "1,x", "300"):
        with pytest.raises(argparse.ArgumentTypeError):
            emulator_cli.parse_ids(bad)


def test_add_parser_registers_emulate() -> None:
    parser = argparse.ArgumentParser(prog="deltadash")
    emulator_cli.add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["emulate", "--ids", "4,5"])
    assert args.command == "emulate" and args.ids == [4, 5] and args.handler is emulator_cli.run


def test_run_prints_a_port_the_sdk_can_ping() -> None:
    args = emulator_cli.configure(argparse.ArgumentParser()).parse_args(
        ["--ids", "7,8", "--return-delay-us", "0"]
    )
    stop = threading.Event()
    out = io.StringIO()
    thread = threading.Thread(target=emulator_cli.run, args=(args, stop, out))
    thread.start()
    try:
        for _ in range(200):
            if out.getvalue().endswith("\n"):
                break
            stop.wait(0.01)
        path = out.getvalue().strip()
        port = PatientPort(path)
        assert port.openPort() and port.setBaudRate(BAUD)
        try:
            ph = sdk.PacketHandler(2.0)
            assert ph.ping(port, 8)[:2] == (1030, sdk.COMM_SUCCESS)
            assert ph.read1ByteTxRx(port, 7, 9) == (0, sdk.COMM_SUCCESS, 0)
        finally:
            port.closePort()
    finally:
        stop.set()
        thread.join(timeout=5)
    assert not thread.is_alive()


@pytest.mark.slow
def test_module_entry_point_runs_and_stops_on_sigterm() -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "hardware.emulator", "--ids", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        path = process.stdout.readline().strip()
        assert path.startswith("/dev/")
        process.terminate()
        assert process.wait(timeout=10) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
