"""``deltadash calibrate --from-csv``: the offline fit of joint/measurement pairs, its
output, and the joint offsets written into a config's zero offsets."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.calibration.fit import plan
from app.calibration.pairs import write_pairs
from app.cli import main
from app.config import load_settings
from app.server.backends import _calibrations
from hardware.encoder import RAD_PER_TICK
from kinematics import THESIS_DELTA, PerLegRotaryDelta
from kinematics.identification import MeasurementFrame

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
OFFSETS = np.radians([2.0, -3.0, 1.5])
FRAME = MeasurementFrame((0.1, 0.0, -0.5), (0.0, 0.0, 1.5))


def _pairs(path, offsets=OFFSETS, noise_m=3e-4) -> None:
    chosen = plan(NOMINAL, 30)
    q = chosen.joints
    true = NOMINAL.with_values(joint_offsets_rad=tuple(offsets))
    y = FRAME.from_base(true.fk(q).points)
    y += np.random.default_rng(3).normal(0.0, noise_m, y.shape)
    write_pairs(path, q, y, len(chosen.holdout_joints))


def test_offline_fit_prints_the_offsets_and_figures(tmp_path, capsys) -> None:
    _pairs(tmp_path / "pairs.csv")
    code = main(["calibrate", "--from-csv", str(tmp_path / "pairs.csv"), "--json"])
    body = json.loads(capsys.readouterr().out)
    assert code == 0 and body["state"] == "done"
    error_deg = np.degrees(np.subtract(body["parameters"]["joint_offsets_rad"], OFFSETS))
    assert np.all(np.abs(error_deg) < 0.1), error_deg
    # single samples with 0.3 mm of noise per axis: the noise alone is 0.52 mm in 3D
    assert body["holdout_rmse_before_m"] > 2e-3 > 6e-4 > body["holdout_rmse_m"]
    assert body["unobservable"] == [] and body["condition_number"] < 20


def test_human_output_is_in_mm_and_degrees(tmp_path, capsys) -> None:
    _pairs(tmp_path / "pairs.csv")
    assert main(["calibrate", "--from-csv", str(tmp_path / "pairs.csv")]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("joint offsets: "))
    shown = [float(v) for v in line.removeprefix("joint offsets: ").removesuffix(" deg").split(",")]
    np.testing.assert_allclose(shown, np.degrees(OFFSETS), atol=0.1)
    assert "RMSE after (held out): 0." in out and "mm" in out


def test_write_moves_the_zero_offsets_by_the_fitted_angles(tmp_path, capsys) -> None:
    _pairs(tmp_path / "pairs.csv")
    config = tmp_path / "robot.toml"
    config.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    before = _calibrations(load_settings(config))
    code = main(
        ["calibrate", "--from-csv", str(tmp_path / "pairs.csv"), "--write", str(config), "--json"]
    )
    assert code == 0
    found = json.loads(capsys.readouterr().out)["parameters"]["joint_offsets_rad"]
    settings = load_settings(config)
    assert settings.server.http_port == 8123
    for old, new, offset in zip(before, _calibrations(settings), found, strict=True):
        # the same raw position now reads the angle plus the offset, to a tick
        assert math.isclose(new.to_rad(2000), old.to_rad(2000) + offset, abs_tol=RAD_PER_TICK)


@pytest.mark.slow
def test_geometry_is_written_as_the_robot_legs_and_read_back(tmp_path, capsys) -> None:
    """A geometry fit's --write: the legs go to [robot.legs] and the offsets to the zero
    offsets; the config read back builds the fitted robot (the true one, from exact pairs)."""
    true = NOMINAL.with_values(
        joint_offsets_rad=tuple(OFFSETS),
        L=(0.1560, 0.1555, 0.1558),
        l=(0.2440, 0.2425, 0.2430),
        R=(0.0844, 0.0850, 0.0841),
    )
    chosen = plan(NOMINAL, 40, "geometry")
    write_pairs(
        tmp_path / "pairs.csv",
        chosen.joints,
        FRAME.from_base(true.fk(chosen.joints).points),
        len(chosen.holdout_joints),
    )
    config = tmp_path / "robot.toml"
    config.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    before = _calibrations(load_settings(config))
    args = ["calibrate", "--from-csv", str(tmp_path / "pairs.csv"), "--parameters", "geometry"]
    assert main([*args, "--write", str(config)]) == 0
    assert "[robot.legs] written" in capsys.readouterr().err
    settings = load_settings(config)
    assert settings.server.http_port == 8123
    robot = settings.robot.build()
    assert isinstance(robot, PerLegRotaryDelta) and robot.joint_offsets_rad == (0.0, 0.0, 0.0)
    for name in ("L", "l", "R", "r"):
        np.testing.assert_allclose(getattr(robot, name), getattr(true, name), atol=1e-6)
    for old, new, offset in zip(before, _calibrations(settings), OFFSETS, strict=True):
        assert math.isclose(new.to_rad(2000), old.to_rad(2000) + offset, abs_tol=RAD_PER_TICK)


def test_a_bad_csv_exits_2_naming_line_and_column(tmp_path, capsys) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("q0_rad,q1_rad,q2_rad,x_m,y_m,z_m\n0,0,0,1,2,x\n")
    assert main(["calibrate", "--from-csv", str(path)]) == 2
    assert "line 2: z_m = 'x'" in capsys.readouterr().err
