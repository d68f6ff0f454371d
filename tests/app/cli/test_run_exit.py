"""A headless `deltadash run sinusoid` exits non-zero when it could not make the robot safe
at exit (torque off failed), and 0 when it could."""

from __future__ import annotations

import contextlib
import re

import pytest

from app.cli import main
from app.server import backends
from hardware.errors import CommError
from tests.support.fake_bus import FakeBus


class NoTorqueOff(FakeBus):
    """An ideal servo whose torque-off write is never answered."""

    def torque(self, enabled: bool) -> None:
        if not enabled:
            raise CommError((1, 2, 3), "write torque", "no status packet (fake)")
        super().torque(enabled)


def headless_on(monkeypatch, tmp_path, bus: FakeBus) -> None:
    @contextlib.contextmanager
    def opened(settings, emulator_in_process=False):
        yield backends.Backend(bus, "emulated", "fake bus")

    monkeypatch.setattr(backends, "open_backend", opened)
    monkeypatch.setenv("DELTADASH_RUNS__FOLDER", str(tmp_path))


@pytest.mark.slow  # a short run on the control thread
@pytest.mark.parametrize(("bus", "code"), [(NoTorqueOff(), 3), (FakeBus(), 0)])
def test_headless_run_exits_non_zero_when_torque_off_at_exit_fails(
    monkeypatch, tmp_path, capsys, bus, code
):
    headless_on(monkeypatch, tmp_path, bus)
    assert main(["run", "sinusoid", "--duration", "0.3"]) == code
    out, err = capsys.readouterr()
    assert ": done" in out and "test: sinusoid per axis" in out  # the run itself ended well
    assert ("torque off at exit failed" in err) == (code == 3), err
    assert ("torque", True) in bus.calls
    assert re.search(r"run \S+: \d+% \(", err), err  # its progress, as lines (not a TTY)
