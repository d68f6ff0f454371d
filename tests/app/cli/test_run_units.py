"""Issue 32 item 7: `deltadash run sinusoid` speaks mm, degrees and Hz as ik, fk, gcode and
the page do (--si: metres and radians), and sends SI; metres typed where mm are expected
are refused, not run as a 50 micrometre sinusoid."""

from __future__ import annotations

import json
import math

import pytest

from app.cli import build_parser, main
from app.cli import run as run_cli
from app.runs.trajectories import SinusoidParams


def params(*options: str) -> SinusoidParams:
    return run_cli._params(build_parser().parse_args(["run", "sinusoid", *options]))


def test_lengths_are_mm_and_angles_degrees_by_default():
    got = params("--amplitude", "20", "20", "30", "--phase", "0", "90", "-45")
    assert got.amplitude_m == pytest.approx((0.020, 0.020, 0.030), abs=1e-15)
    assert got.phase_rad == pytest.approx((0.0, math.pi / 2, -math.pi / 4), abs=1e-15)
    got = params("--offset", "10", "0", "-240", "--frequency", "0,5", "1", "2", "--duration", "3")
    assert got.offset_m == pytest.approx((0.010, 0.0, -0.240), abs=1e-15)
    assert got.frequency_hz == (0.5, 1.0, 2.0)  # Hz either way
    assert got.duration_s == 3.0


def test_si_keeps_metres_and_radians():
    got = params("--si", "--amplitude", "0.02", "0.02", "0.03", "--phase", "0", "1.5", "0")
    assert got.amplitude_m == (0.02, 0.02, 0.03)
    assert got.phase_rad == (0.0, 1.5, 0.0)
    got = params("--si", "--offset", "0", "0", "-0,24", "--phi-amplitude", "0,5")
    assert got.offset_m == (0.0, 0.0, -0.24)
    assert got.phi_amplitude_rad == 0.5


def test_the_wrist_amplitude_is_degrees():
    got = params("--phi-amplitude", "30", "--phi-frequency", "0,5")
    assert got.phi_amplitude_rad == pytest.approx(math.pi / 6, abs=1e-15)
    assert got.phi_frequency_hz == 0.5


def test_options_not_given_are_the_thesis_defaults_in_both_unit_systems():
    assert params() == SinusoidParams() == params("--si")


def test_a_decimal_comma_is_a_decimal_point():
    got = params("--amplitude", "12,5", "0", "0,6", "--offset", "0", "0", "-240,5")
    assert got.amplitude_m == pytest.approx((0.0125, 0.0, 0.0006), abs=1e-15)
    assert got.offset_m == pytest.approx((0.0, 0.0, -0.2405), abs=1e-15)


@pytest.mark.parametrize(
    ("option", "values", "hint"),
    [
        ("--amplitude", ["0.05", "0.05", "0.08"], "give --amplitude 50 50 80, or add --si"),
        ("--offset", ["0", "0", "-0.24"], "give --offset 0 0 -240, or add --si"),
        ("--amplitude", ["0,02", "0", "0"], "give --amplitude 20 0 0, or add --si"),
    ],
)
def test_metres_where_mm_are_expected_are_refused(option, values, hint):
    with pytest.raises(ValueError, match="looks like metres") as refused:
        params(option, *values)
    assert hint in str(refused.value)
    params(option, *values, "--si")  # the same numbers as metres: taken


def test_one_small_length_beside_a_real_one_is_taken():
    got = params("--amplitude", "20", "0", "0,3")  # 0.3 mm on z: small, not metres
    assert got.amplitude_m == pytest.approx((0.020, 0.0, 0.0003), abs=1e-15)


def fake_server(monkeypatch) -> list[tuple[str, str, dict | None]]:
    calls: list[tuple[str, str, dict | None]] = []

    def fake_http(url, method="GET", body=None, headers=None):
        calls.append((method, url, body))
        if url.endswith("/api/lease") and method == "POST":
            return {"lease_id": "id", "holder": "deltadash run", "timeout_s": 30.0}
        if url.endswith("/api/tests/sinusoid"):
            return {"run_id": "r1"}
        if url.endswith("/api/runs/r1"):
            return {"run_id": "r1", "state": "done", "reason": None}
        return {"accepted": True}

    monkeypatch.setattr(run_cli, "_http", fake_http)
    return calls


def test_what_is_sent_to_the_server_is_si(monkeypatch, capsys):
    calls = fake_server(monkeypatch)
    argv = ["run", "sinusoid", "--url", "http://robot", "--json", "--amplitude", "20", "20", "30"]
    argv += ["--phase", "0", "90", "0", "--offset", "0", "0", "-240,5", "--phi-amplitude", "30"]
    assert main(argv) == 0
    (body,) = [b for m, u, b in calls if u == "http://robot/api/tests/sinusoid"]
    assert body["amplitude_m"] == pytest.approx([0.020, 0.020, 0.030], abs=1e-15)
    assert body["phase_rad"] == pytest.approx([0.0, math.pi / 2, 0.0], abs=1e-15)
    assert body["offset_m"] == pytest.approx([0.0, 0.0, -0.2405], abs=1e-15)
    assert body["phi_amplitude_rad"] == pytest.approx(math.pi / 6, abs=1e-15)
    assert json.loads(capsys.readouterr().out)["state"] == "done"


def test_a_refused_value_sends_nothing_and_exits_2(monkeypatch, capsys):
    calls = fake_server(monkeypatch)
    argv = ["run", "sinusoid", "--url", "http://robot", "--amplitude", "0.05", "0.05", "0.08"]
    assert main(argv) == 2
    assert calls == []  # not even the lease was taken
    err = capsys.readouterr().err
    assert "error: --amplitude 0.05 0.05 0.08:" in err and "--si" in err


def test_the_help_names_each_unit(capsys):
    with pytest.raises(SystemExit):
        main(["run", "sinusoid", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--amplitude X Y Z per axis [mm; m with --si] (default 50 50 80 mm)" in out
    assert "--phase X Y Z per axis [deg; rad with --si] (default 0 0 0 deg)" in out
    assert "--offset X Y Z per axis [mm; m with --si] (default 0 0 -240 mm)" in out
    assert "--frequency X Y Z per axis [Hz] (default 1 1 2 Hz)" in out
    assert "amplitude [deg; rad with --si]" in out
