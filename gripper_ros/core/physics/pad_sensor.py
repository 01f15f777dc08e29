"""The pads' load sensing: shear force and object displacement per pad, read as a sensor would.

Each pad sits on a 3-axis load cell that reads its tangential (shear) force, and measures how far
the object has moved on its surface. One channel turns the true value into the reading, each
force-loop sample ``dt_s``, in the order a real chain does it:

1. latency: the reading is the value of ``round(latency_s / dt_s)`` samples ago;
2. bandwidth: a first-order low-pass at ``bandwidth_hz``, discretised exactly
   (``y += (1 - exp(-2 pi f dt)) (u - y)``);
3. noise: white Gaussian of standard deviation ``noise``, from the channel's own generator
   (splitmix64 and Box-Muller, seeded per channel: runs are bit-identical);
4. resolution: rounded to a multiple of ``resolution`` (0: none).

The defaults (``pad_sensor`` in config/gripper.yaml) are of the class of a miniature six-axis
strain-gauge force/torque sensor under each pad (ATI Nano17 class: 1/320 N resolution in its
shear axes on the 12 N range, a 7 kHz output).
"""
from __future__ import annotations

import math

from gripper_ros.core.config import ChannelSpec
from gripper_ros.core.records import copy_fields, face_kernel, FLOATS
import numba
import numpy as np

MAX_LATENCY_SAMPLES = 4096     # ring buffer length: 0.41 s at the force loop's 0.1 ms

CHANNEL_DTYPE = np.dtype([
    ('resolution', np.float64),
    ('noise', np.float64),                 # standard deviation
    ('alpha', np.float64),                 # low-pass step share, 1 = no filter
    ('delay', np.int64),                   # latency in samples
    ('head', np.int64),                    # ring buffer write index
    ('filtered', np.float64),
    ('primed', np.uint8),                  # the filter has its first value
    ('rng', np.uint64),                    # splitmix64 state
    ('spare', np.float64),                 # Box-Muller's second normal
    ('has_spare', np.uint8),
    ('reading', np.float64),
], align=True)
"""One sensor channel's settings and state."""


def make_channel(spec: ChannelSpec, dt_s: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Return a channel's (record, delay buffer) for samples every ``dt_s``; ValueError if bad."""
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f'pad sensor dt_s must be > 0, got {dt_s!r}')
    delay = round(spec.latency_s / dt_s)
    if delay >= MAX_LATENCY_SAMPLES:
        raise ValueError(f'pad sensor latency_s must be below {MAX_LATENCY_SAMPLES * dt_s:g} s '
                         f'at {dt_s:g} s a sample, got {spec.latency_s!r}')
    rec = np.zeros(1, CHANNEL_DTYPE)
    r = rec[0]
    copy_fields(r, spec, ('resolution', 'noise'))
    r['alpha'] = 1.0 if spec.bandwidth_hz == 0.0 else \
        -math.expm1(-2.0 * math.pi * spec.bandwidth_hz * dt_s)
    r['delay'] = delay
    r['rng'] = np.uint64(seed)
    return rec, np.zeros(MAX_LATENCY_SAMPLES)


@numba.njit(cache=True)
def _splitmix64(c):
    c.rng = c.rng + np.uint64(0x9E3779B97F4A7C15)
    z = c.rng
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True)
def _uniform(c):
    """Return a uniform number in (0, 1], 53 bits."""
    return ((_splitmix64(c) >> np.uint64(11)) + np.uint64(1)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def _normal(c):
    if c.has_spare:
        c.has_spare = 0
        return c.spare
    u1 = _uniform(c)
    u2 = _uniform(c)
    r = math.sqrt(-2.0 * math.log(u1))
    c.spare = r * math.sin(2.0 * math.pi * u2)
    c.has_spare = 1
    return r * math.cos(2.0 * math.pi * u2)


@numba.njit(cache=True)
def channel_step(c, buf, value):
    """Take one sample of the true ``value``; return (and keep) the reading."""
    n = buf.shape[0]
    if not c.primed:                        # before the first sample the value was the same
        for i in range(n):
            buf[i] = value
        c.filtered = value
        c.primed = 1
    buf[c.head] = value
    delayed = buf[(c.head - c.delay) % n]
    c.head = (c.head + 1) % n
    c.filtered += c.alpha * (delayed - c.filtered)
    out = c.filtered
    if c.noise > 0.0:
        out += c.noise * _normal(c)
    if c.resolution > 0.0:
        out = c.resolution * math.floor(out / c.resolution + 0.5)
    c.reading = out
    return out


@face_kernel(CHANNEL_DTYPE, FLOATS, FLOATS)
@numba.njit(cache=True)
def _channel_run(rec, buf, values):
    out = np.empty(values.shape[0])
    for i in range(values.shape[0]):
        out[i] = channel_step(rec[0], buf, values[i])
    return out


class PadChannel:
    """One sensor channel (Python face over the compiled kernel)."""

    def __init__(self, spec: ChannelSpec, dt_s: float, seed: int = 1):
        self.spec = spec
        self.record, self.buffer = make_channel(spec, dt_s, seed)

    def run(self, values) -> np.ndarray:
        """Sample each of ``values`` in turn, one ``dt_s`` apart; return the readings."""
        return _channel_run(self.record, self.buffer, np.asarray(values, dtype=np.float64))
