"""Trajectories streamed to the position servo, headless: within 1 mm where 24 V allows.

Each trajectory is a closed form (``studies/servo_runs.py``) that needs at most 80 % of the
voltage limit at any instant (its feed-forward's peak, ``k_v v + k_a a``: the bound, asserted
first). It is streamed as ros2_control's JointStateTopicSystem sends a controller's commands on
``joint_commands`` (``joint_state_topic_hardware_interface.cpp``: at each 100 Hz update, unless
the joint is within ``trigger_joint_command_threshold``, 1e-5, of it; stamped with the update's
instant), through the graph's own loop, and the finger is held to the trajectory at every tick:
within 1 mm, positions alone (velocity and acceleration estimated from the stream), with
velocities, with accelerations (a FollowJointTrajectory server's samples), on time or with a
share of the setpoints late as on a busy machine.

A ramp from rest (what joint_trajectory_controller makes of one position-only point) needs an
infinite voltage at its start: the finger then lags no more than 1.1 mm beyond the least lag
24 V allows from rest within the speed limit, and runs on past its end less than the least
stopping distance from the speed limit.
"""
from __future__ import annotations


from gripper_ros.core.config import load_config
from gripper_ros.studies.servo_runs import (farthest_m, GIVEN, needed_peak_v, Ramp, Sine,
                                            Spline, stopping_m, track, Trapezoid)
from gripper_ros.wire import Outcome
import numpy as np
import pytest

CONFIG = load_config()
P = CONFIG.plant
LIMIT_V = 0.8 * P.voltage_limit_v
TOLERANCE_M = 1e-3
TRAJECTORIES = {
    'trapezoid closing': Trapezoid(0.01, 0.14, 0.036, 0.015),
    'trapezoid opening': Trapezoid(0.14, 0.01, 0.036, 0.015),
    'sine': Sine(0.075, 0.06, 9.0),
    'spline': Spline(((0.0, 0.02), (4.0, 0.08), (6.0, 0.07), (10.0, 0.135), (14.0, 0.02))),
}


@pytest.mark.parametrize('name', sorted(TRAJECTORIES))
@pytest.mark.parametrize('given', GIVEN)
def test_a_stream_within_80_percent_of_the_voltage_is_tracked_within_1_mm(name, given):
    trajectory = TRAJECTORIES[name]
    needed = needed_peak_v(CONFIG, trajectory)
    assert 0.7 * P.voltage_limit_v < needed <= LIMIT_V, needed
    run = track(CONFIG, trajectory, given=given)
    print(f'{trajectory.name} ({given}): needs {needed:.2f} V of {P.voltage_limit_v:g} V; '
          f'worst error {run.worst_error_m * 1e3:.3f} mm')
    assert run.worst_error_m <= TOLERANCE_M
    assert run.outcome is Outcome.MOVED                         # ended at rest at the goal


@pytest.mark.parametrize('name', sorted(TRAJECTORIES))
def test_late_setpoints_with_their_stamps_are_tracked_within_1_mm(name):
    """A fifth of the setpoints up to 50 ms late, the rest queued behind them (seeded)."""
    trajectory = TRAJECTORIES[name]
    for seed in (1, 2):
        run = track(CONFIG, trajectory, late_share=0.2, late_updates=5, seed=seed)
        print(f'{trajectory.name}, late (seed {seed}): worst {run.worst_error_m * 1e3:.3f} mm')
        assert run.worst_error_m <= TOLERANCE_M


@pytest.mark.parametrize('name', sorted(TRAJECTORIES))
def test_unstamped_setpoints_on_time_are_tracked_within_1_mm(name):
    """Without stamps each setpoint is taken at the tick it comes."""
    run = track(CONFIG, TRAJECTORIES[name], stamped=False)
    assert run.worst_error_m <= TOLERANCE_M


def test_an_infeasible_ramp_lags_by_about_the_least_24_v_allows():
    ramp = Ramp(0.0, 0.04, 2.0)
    limit_mps = CONFIG.supervisor.move_default_speed_mps
    run = track(CONFIG, ramp, settle_s=3.0)
    on = (run.t_s >= 0.3) & (run.t_s <= ramp.ramp_s)
    least = np.array([0.04 * t - farthest_m(P, t, limit_mps) for t in run.t_s[on]])
    lag = run.error_m[on]
    overshoot = np.max(run.position_m) - ramp.at(ramp.ramp_s)[0]
    print(f'ramp 0.04 m/s from rest: worst lag {np.max(lag) * 1e3:.2f} mm (least '
          f'{np.max(least) * 1e3:.2f}), {lag[-1] * 1e3:.2f} at its end (least '
          f'{least[-1] * 1e3:.2f}); runs on {overshoot * 1e3:.2f} mm (stopping from 0.04 m/s '
          f'takes {stopping_m(P, 0.04) * 1e3:.2f})')
    assert np.all(run.error_m[run.t_s <= ramp.ramp_s] >= -1e-3)      # never ahead of it
    assert np.all(lag <= least + 1.1e-3)
    assert overshoot <= stopping_m(P, limit_mps)
    assert run.outcome is Outcome.MOVED and run.moves == 1
