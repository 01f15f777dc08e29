"""The arm's motion as the load: step, pick-and-place and shake profiles against their definitions.

A pick-and-place goes up, across and down with trapezoidal velocities: its acceleration
integrates to no velocity and no displacement (the object is put down at the height it was
picked from); a shake is ``A sin(2 pi f t)`` held over each 0.1 ms piece at its midpoint value.
"""
import math
from pathlib import Path

from gripper_ros.core.config import load_config
from gripper_ros.core.physics.hold import HoldModel, HoldState, Lift, parse_profile, SHAKE_SAMPLE_S
from gripper_ros.wire import LiftProfile
import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
G = CONFIG.plant.gravity_mps2
C = CONFIG.contact


def played(lift, force_n=1e3, mass_kg=1.0):
    """Run ``lift`` on a firmly held object; return [(t_s, dt_s, a)] of its constant pieces."""
    hold = HoldModel(mass_kg, C.static_friction, C.kinetic_friction, C.pad_length_m, G, lift)
    hold.begin(0, mass_kg)
    t_ns, pieces = 0, []
    while True:
        hold.fire_events(t_ns)
        nxt = hold.next_event_ns
        if nxt is None:
            return hold, pieces
        assert hold.advance(force_n, (nxt - t_ns) * 1e-9) is None
        assert hold.state in (HoldState.RESTING, HoldState.STUCK)   # never slides
        pieces.append((t_ns * 1e-9, (nxt - t_ns) * 1e-9, hold.acceleration_mps2))
        t_ns = nxt


def test_step_is_one_constant_acceleration_then_weight_alone():
    hold, pieces = played(Lift(2.0, 0.2, 1.0))
    assert pieces == [(0.0, 0.2, 0.0), (0.2, 1.0, 2.0)]
    assert hold.acceleration_mps2 == 0.0 and hold.load_n == G


def test_pick_and_place_goes_up_across_and_down_and_ends_where_it_began():
    a, d = 3.0, 1.2
    hold, pieces = played(Lift(a, 0.0, d, LiftProfile.PICK_AND_PLACE))
    ramp = d / 12
    assert [p[2] for p in pieces] == [a, 0.0, -a, 0.0, -a, 0.0, a]
    assert [p[1] for p in pieces] == pytest.approx([ramp, 2 * ramp, ramp, 4 * ramp, ramp,
                                                    2 * ramp, ramp], rel=1e-12)
    v = x = top = 0.0
    for _, dt, acc in pieces:                     # exact: a is constant on each piece
        x += v * dt + 0.5 * acc * dt * dt
        v += acc * dt
        top = max(top, x)
    assert v == pytest.approx(0.0, abs=1e-12) and x == pytest.approx(0.0, abs=1e-12)
    assert top == pytest.approx(a * ramp * 3 * ramp, rel=1e-12)   # rises v_max x 3 ramps
    assert hold.acceleration_mps2 == 0.0


def test_shake_is_the_sinusoid_at_each_piece_midpoint():
    a, hz, d = 3.0, 2.0, 1.0
    _, pieces = played(Lift(a, 0.0, d, LiftProfile.SHAKE, hz))
    assert len(pieces) == round(d / SHAKE_SAMPLE_S)
    for t, dt, acc in pieces:
        assert dt == pytest.approx(SHAKE_SAMPLE_S, rel=1e-9)
        assert acc == pytest.approx(a * math.sin(2 * math.pi * hz * (t + 0.5 * dt)),
                                    abs=1e-12)
    # two whole periods: the arm comes back with no net velocity
    assert sum(dt * acc for _, dt, acc in pieces) == pytest.approx(0.0, abs=1e-9)
    assert max(acc for *_, acc in pieces) == pytest.approx(a, rel=1e-6)


def test_shake_starts_a_slip_only_beyond_the_static_limit_and_ends_it_below_the_kinetic():
    m, a, hz, mu_s, mu_k = 1.0, 3.0, 2.0, 0.5, 0.45
    a_static = 1.5                                      # the grip holds up to this
    f = m * (G + a_static) / (2 * mu_s)
    a_kinetic = 2 * mu_k * f / m - G                    # sliding stops only below this
    hold = HoldModel(m, mu_s, mu_k, 1.0, G,
                     Lift(a, 0.0, 1.0, LiftProfile.SHAKE, hz))
    hold.begin(0, m)
    t_ns, starts, stops = 0, [], []
    while hold.next_event_ns is not None:
        hold.fire_events(t_ns)
        before = hold.state
        nxt = hold.next_event_ns if hold.next_event_ns is not None else t_ns
        hold.advance(f, (nxt - t_ns) * 1e-9)
        if before is HoldState.STUCK and hold.state is HoldState.SLIDING:
            starts.append(hold.acceleration_mps2)
        if before is HoldState.SLIDING and hold.state is HoldState.STUCK:
            stops.append(hold.acceleration_mps2)
        t_ns = nxt
    assert len(starts) == len(stops) == 2              # once a period
    assert all(a_static < acc < a_static + 0.01 for acc in starts)
    assert all(acc < a_kinetic for acc in stops)
    assert hold.state is HoldState.STUCK and hold.slip_m > 0.0


@pytest.mark.parametrize('kwargs, field', [
    ({'profile': 7}, 'profile'),
    ({'profile': LiftProfile.SHAKE}, 'frequency_hz'),
    ({'profile': LiftProfile.SHAKE, 'frequency_hz': 1e3}, 'frequency_hz'),
    ({'frequency_hz': math.nan}, 'frequency_hz'),
])
def test_a_bad_profile_is_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Lift(3.0, 0.0, 1.0, **kwargs)


@pytest.mark.parametrize('text, expected', [
    ('step:2', (LiftProfile.STEP, 2.0, 0.0)),
    ('pick-and-place:3', (LiftProfile.PICK_AND_PLACE, 3.0, 0.0)),
    ('shake:3,2', (LiftProfile.SHAKE, 3.0, 2.0)),
])
def test_command_line_profiles_read_as_the_lift_fields(text, expected):
    assert parse_profile(text) == expected


@pytest.mark.parametrize('text, says', [
    ('wave:3', 'profile must be'), ('shake:3', 'A,HZ'), ('step:x', 'numbers expected'),
    ('step:-1', 'acceleration_mps2'), ('shake:3,0', 'frequency_hz'), ('step:nan', 'finite'),
])
def test_a_bad_command_line_profile_is_one_line_naming_it(text, says):
    with pytest.raises(ValueError, match=says):
        parse_profile(text)


def test_a_shake_recorded_by_grasp_demo_reruns_bit_for_bit(tmp_path):
    """grasp_demo --profile records the profile with the object; a re-run plays the same shake."""
    import subprocess
    import sys

    from gripper_ros.bags import rerun
    from helpers import assert_rerun_equals_recording
    out = tmp_path / 'bags'
    demo = subprocess.run(
        [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--width', '0.05', '--mass',
         '0.6', '--profile', 'shake:3,2', '--lift-duration', '0.5', '--object-mass', '0.6',
         '--static-friction', '0.3', '--kinetic-friction', '0.24', '--force-law', 'paper',
         '--output', str(out), '--no-plot'],
        capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert demo.returncode == 1, demo.stdout + demo.stderr      # eq. 23 at mu_s 0.3: lost
    assert 'OBJECT_LOST' in demo.stdout
    (bag,) = [p for p in out.iterdir() if p.is_dir()]
    w = rerun.whatif(bag)
    assert w.record.obj['lift_profile'] == LiftProfile.SHAKE
    assert w.record.obj['lift_frequency_hz'] == 2.0
    assert_rerun_equals_recording(w)
    assert w.reruns[0].metrics.final_outcome == 'OBJECT_LOST'
