"""The pads' shear and displacement sensing: resolution, noise, bandwidth and latency.

Each property against its definition: readings are multiples of the resolution, the noise's
standard deviation is the one configured, a step comes through exactly ``latency / dt`` samples
late and then rises as the first-order low-pass ``1 - exp(-2 pi f t)``.
"""
import math
from pathlib import Path

from gripper_ros.core.config import ChannelSpec, load_config
from gripper_ros.core.physics.pad_sensor import PadChannel
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
DT_S = 1e-4


def test_config_defaults_are_the_named_sensor_class():
    s = CONFIG.pad_sensor
    assert s.shear.resolution == 1.0 / 320.0            # ATI Nano17 class, shear axes
    assert s.shear.bandwidth_hz > 0.0 and s.shear.latency_s > 0.0
    assert s.displacement.resolution > 0.0


def test_readings_are_multiples_of_the_resolution_and_round_to_nearest():
    q = 1.0 / 320.0
    ch = PadChannel(ChannelSpec(q, 0.0, 0.0, 0.0), DT_S)
    values = np.array([0.0, 0.4 * q, 0.6 * q, 7.49 * q, 7.51 * q, -2.6 * q])
    assert list(ch.run(values)) == [0.0, 0.0, q, 7 * q, 8 * q, -3 * q]


def test_noise_has_the_configured_standard_deviation_and_no_bias():
    sigma = 0.01
    ch = PadChannel(ChannelSpec(0.0, sigma, 0.0, 0.0), DT_S, seed=7)
    out = ch.run(np.full(200_000, 3.0)) - 3.0
    assert abs(out.mean()) < 5 * sigma / math.sqrt(out.size)
    assert out.std() == pytest.approx(sigma, rel=0.01)
    again = PadChannel(ChannelSpec(0.0, sigma, 0.0, 0.0), DT_S, seed=7).run(np.full(10, 3.0))
    assert np.array_equal(again, out[:10] + 3.0)                 # bit-identical run to run


def test_a_step_arrives_after_the_latency_then_rises_as_the_low_pass():
    latency_s, hz = 0.0012, 500.0
    delay = round(latency_s / DT_S)
    ch = PadChannel(ChannelSpec(0.0, 0.0, hz, latency_s), DT_S)
    values = np.r_[np.zeros(5), np.ones(100)]
    out = ch.run(values)
    assert np.all(out[:5 + delay] == 0.0)                        # nothing before the latency
    n = np.arange(1, 100 - delay + 1)
    assert out[5 + delay:] == pytest.approx(1.0 - np.exp(-2 * math.pi * hz * DT_S * n),
                                            rel=1e-12)


@pytest.mark.parametrize('field', ['resolution', 'noise', 'bandwidth_hz', 'latency_s'])
@pytest.mark.parametrize('bad', [math.nan, math.inf, -1.0])
def test_a_bad_setting_is_refused_naming_it(field, bad):
    kwargs = {'resolution': 0.0, 'noise': 0.0, 'bandwidth_hz': 0.0, 'latency_s': 0.0}
    kwargs[field] = bad
    with pytest.raises(ValueError, match=field):
        ChannelSpec(**kwargs)
