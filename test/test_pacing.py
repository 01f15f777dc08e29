"""The plant's pacing without ROS: when a tick of simulated time may be published, each mode.

Known answers on a wall clock the test sets: realtime at factor f waits (t - t0) / f of wall
time for a tick at t and never lets one out early, restarts after a stall longer than
MAX_LAG_S instead of rushing; fast publishes while time is needed and idles otherwise; following
/clock publishes exactly the ticks the world's time has reached, starts at the world's first
time and counts as held once the world's time stood still for WORLD_STILL_S; a pause holds and
a sim/step advances now in every mode, ending after its n ticks or at its time.
"""
import math

from gripper_ros.core.runtime.pacing import (ClockPacing, FastPacing, HELD, IDLE, make_pacing,
                                             MAX_LAG_S, MAX_STEP_S, MAX_STEP_TICKS, NOW, QUANTUM_S,
                                             RealtimePacing, step_problem, WORLD_STILL_S,
                                             WorldTime)
from gripper_ros.wire import TimeMode
import pytest

MS = 1_000_000


class WallClock:
    """A wall clock that moves only when the test says."""

    def __init__(self, start_s: float = 100.0):
        self.now_s = start_s
        self.slept_s = None                         # the last wait slept in place

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, wait_s: float) -> None:
        """Sleep ``wait_s`` as the wall clock does: woken a little late (1 us)."""
        self.slept_s = wait_s
        self.now_s += wait_s + 1e-6


def never() -> bool:
    raise AssertionError('only fast mode asks whether time is needed')


@pytest.mark.parametrize('factor', [1.0, 0.5, 2.0])
def test_realtime_waits_for_the_wall_clock_at_its_factor(factor):
    wall = WallClock()
    pacing = RealtimePacing(0, factor, wall)
    assert pacing.gate(0, 10 * MS, never) == pytest.approx(0.010 / factor)
    wall.now_s += 0.002
    assert pacing.gate(0, 10 * MS, never) == pytest.approx(0.010 / factor - 0.002)
    wall.now_s += 0.010 / factor                    # the wall clock is past the tick's time
    assert pacing.gate(0, 10 * MS, never) == NOW
    assert pacing.target_factor == factor


def test_realtime_catches_up_a_short_lag_and_restarts_after_a_stall():
    wall = WallClock()
    pacing = RealtimePacing(0, 1.0, wall)
    wall.now_s += 0.080                             # 80 ms late: caught up tick by tick
    for k in range(1, 9):
        assert pacing.gate((k - 1) * 10 * MS, k * 10 * MS, never) == NOW
    assert pacing.gate(80 * MS, 90 * MS, never) == pytest.approx(0.010)
    wall.now_s += 0.090 + MAX_LAG_S + 0.5           # a stall: no burst, pacing from now
    assert pacing.gate(80 * MS, 90 * MS, never) == pytest.approx(0.010)


def test_realtime_sleeps_a_wait_of_up_to_a_quantum_in_place():
    wall = WallClock()
    pacing = RealtimePacing(0, 1.0, wall, wall.sleep)
    assert pacing.gate(0, 10 * MS, never) == pytest.approx(0.010)    # the node's timer
    wall.now_s += 0.0099
    assert pacing.gate(0, 10 * MS, never) == NOW    # 0.1 ms: slept here, then published
    assert wall.slept_s == pytest.approx(0.0001)


def test_realtime_publishes_short_ticks_in_bursts_a_quantum_apart():
    wall = WallClock()
    pacing = RealtimePacing(0, 1.0, wall, wall.sleep)
    tick_ns = 100_000                               # the force stage's 0.1 ms
    assert pacing.gate(0, tick_ns, never) == NOW    # after a quantum's sleep, not 0.1 ms
    assert wall.slept_s == pytest.approx(QUANTUM_S)
    burst = round(QUANTUM_S * 1e9) // tick_ns       # every tick due by now goes out
    wall.slept_s = None
    for k in range(2, burst + 1):
        assert pacing.gate((k - 1) * tick_ns, k * tick_ns, never) == NOW
    assert wall.slept_s is None
    # the next is a tick ahead of the wall clock: the wake after it is a quantum on
    assert pacing.gate(burst * tick_ns, (burst + 1) * tick_ns, never) == NOW
    assert wall.slept_s == pytest.approx(QUANTUM_S - 1e-6)


def test_fast_publishes_only_while_time_is_needed():
    pacing = FastPacing(0, 1.0, WallClock())
    assert pacing.gate(0, 10 * MS, lambda: True) == NOW
    assert pacing.gate(0, 10 * MS, lambda: False) == IDLE
    assert not pacing.runs_unasked and pacing.target_factor == 0.0


def test_following_clock_publishes_what_the_world_has_reached():
    wall = WallClock()
    pacing = ClockPacing(0, 1.0, wall)
    assert pacing.gate(0, 10 * MS, never) is HELD and pacing.held and not pacing.started
    assert pacing.take_world_time(5_004 * MS) is WorldTime.START
    assert pacing.started and not pacing.held
    assert pacing.gate(5_000 * MS, 5_010 * MS, never) is HELD      # the world is at 5.004 s
    assert pacing.take_world_time(5_010 * MS) is WorldTime.ON
    assert pacing.gate(5_000 * MS, 5_010 * MS, never) == NOW       # reached, to the ns
    assert pacing.gate(5_010 * MS, 5_010 * MS + 100_000, never) is HELD
    assert pacing.behind_s(5_000 * MS) == pytest.approx(0.010)


def test_following_clock_is_held_while_the_world_stands_still():
    wall = WallClock()
    pacing = ClockPacing(0, 1.0, wall)
    pacing.take_world_time(1_000 * MS)
    wall.now_s += WORLD_STILL_S * 0.9
    assert not pacing.held
    wall.now_s += WORLD_STILL_S * 0.2               # still for longer than WORLD_STILL_S
    assert pacing.held
    pacing.take_world_time(1_001 * MS)              # it moves on
    assert not pacing.held


def test_following_clock_waits_for_a_world_that_went_back_to_pass_it_again():
    pacing = ClockPacing(0, 1.0, WallClock())
    pacing.take_world_time(2_000 * MS)
    assert pacing.take_world_time(0) is WorldTime.BACK
    assert pacing.gate(2_000 * MS, 2_010 * MS, never) is HELD
    pacing.take_world_time(2_010 * MS)
    assert pacing.gate(2_000 * MS, 2_010 * MS, never) == NOW


def test_following_clock_refuses_pause_and_step():
    pacing = make_pacing(TimeMode.SIM_TIME, 0)
    assert isinstance(pacing, ClockPacing)
    assert 'use_sim_time' in pacing.pause_refusal()
    assert make_pacing(TimeMode.REALTIME, 0).pause_refusal() == ''


@pytest.mark.parametrize('mode', list(TimeMode))
def test_a_pause_holds_and_a_step_advances_now_in_every_mode(mode):
    pacing = make_pacing(mode, 0, 1.0, WallClock())
    pacing.paused = True
    assert pacing.gate(0, 10 * MS, lambda: True) is HELD
    pacing.start_step(3, 0.0, 0)
    assert pacing.gate(0, 10 * MS, lambda: False) == NOW
    assert [pacing.spend(k * 10 * MS) for k in (1, 2, 3)] == [False, False, True]
    pacing.end_step(30 * MS)
    pacing.start_step(0, 0.025, 30 * MS)            # until t = 55 ms
    assert [pacing.spend(t * MS) for t in (40, 50, 60)] == [False, False, True]


def test_the_achieved_factor_is_simulated_over_wall_time():
    wall = WallClock()
    pacing = RealtimePacing(0, 1.0, wall)
    wall.now_s += 2.0
    factor, elapsed_s, advanced = pacing.achieved(1_000 * MS)
    assert (factor, elapsed_s, advanced) == (pytest.approx(0.5), pytest.approx(2.0), True)
    assert pacing.last_factor == pytest.approx(0.5)
    wall.now_s += 1.0
    assert pacing.achieved(1_000 * MS)[2] is False


@pytest.mark.parametrize('ticks, duration_s, words', [
    (0, 0.0, 'exactly one'), (3, 0.5, 'exactly one'), (0, math.nan, 'finite'),
    (0, -1.0, '>= 0'), (0, MAX_STEP_S + 1.0, f'<= {MAX_STEP_S:g}'),
    (MAX_STEP_TICKS + 1, 0.0, f'<= {MAX_STEP_TICKS}')])
def test_a_bad_step_is_named(ticks, duration_s, words):
    assert words in step_problem(ticks, duration_s)


def test_a_good_step_is_taken():
    assert step_problem(5, 0.0) == step_problem(0, 1.5) == ''
