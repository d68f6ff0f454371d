"""The twin's Present Current noise (SimBusConfig.current_noise_a): what a real servo's
current reads carry, for the force estimate's figures beyond the twin's determinism."""

from __future__ import annotations

import numpy as np
import pytest

from hardware.dynamixel.control_table import AMPERE_PER_CURRENT_UNIT
from hardware.sim.sim_bus import SimBus, SimBusConfig


def _reads(noise_a: float, n: int = 400) -> np.ndarray:
    bus = SimBus(SimBusConfig(realtime=False, torque_on_at_start=True, current_noise_a=noise_a))
    bus.connect()
    try:
        bus.advance(0.5)  # settled, holding home
        return np.array([bus.read_state().current_a for _ in range(n)])
    finally:
        bus.disconnect()


def test_without_noise_a_still_arm_reads_the_same_current_each_time() -> None:
    reads = _reads(0.0, 50)
    assert np.ptp(reads, axis=0).max() == 0.0


def test_the_noise_has_the_configured_spread_in_whole_register_units() -> None:
    noise = 5 * AMPERE_PER_CURRENT_UNIT
    reads = _reads(noise)
    units = reads / AMPERE_PER_CURRENT_UNIT
    np.testing.assert_allclose(units, np.round(units), atol=1e-9)  # the register's quanta
    # rounding adds a quantum^2 / 12 to the variance
    expected = np.sqrt(noise**2 + AMPERE_PER_CURRENT_UNIT**2 / 12)
    assert reads.std(axis=0) == pytest.approx(np.full(3, expected), rel=0.15)


@pytest.mark.parametrize("noise", [-0.001, 2.0, float("nan")])
def test_a_bad_noise_is_refused_naming_the_field(noise: float) -> None:
    with pytest.raises(ValueError, match="current_noise_a"):
        SimBusConfig(current_noise_a=noise)
