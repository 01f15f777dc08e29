"""Closed-loop what-if (``bag_replay BAG --resimulate --closed-loop``) on recorded grasps.

The grasps are recorded through the node graph over DDS.
- Without a change the re-run equals the recording: every field of every tick, reference,
  command and object state, and so every figure (rigid, stiff, a lift that loses the object,
  a sensor dropout that ends in FAULT, and a grasp recorded right after that FAULT).
- The paper's PI force controller on a stiff object: the re-run shows the contact spike and the
  bounce (OBJECT_LOST) the recording with the default stage did not have, exactly as a headless
  grasp with that controller from the start.
- A changed PD position gain moves the position settling time as the linear PD + plant model
  predicts: the position stage ends when the finger enters the 2 % band, the first time the
  model's unsaturated step response reaches 98 %; on a 10 mm step the PD barely saturates and
  the two agree to a tick.
- Bad input (a serve bag without its placement, a key the controller does not read, an unknown
  key, an out-of-range value, a bag of another package, a bag of format 1): one line on stderr,
  exit 2.
"""
from __future__ import annotations

import copy
import functools
import json
from pathlib import Path

from gripper_ros.bags import replay as bag_replay
from gripper_ros.bags import rerun
from gripper_ros.core.config import ConfigError, load_config, parse_config
from gripper_ros.core.control.factories import position_step_response
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.recording import recorded_grasp, ServeRecorder
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import FaultKind, Outcome
from helpers import assert_rerun_equals_recording, run_main
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
import yaml

CONFIG = load_config()
LEGACY_MSG_DIR = Path(__file__).resolve().parent / 'data' / 'legacy_msgs'
STIFF = {'stiffness_n_per_m': 1e5, 'damping_n_s_per_m': 50.0}


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Grasps recorded through the node graph (fast mode), one bag each."""
    out = tmp_path_factory.mktemp('whatif')
    runs = {}
    with GripperGraph.in_own_context() as graph:
        runs['rigid'] = recorded_grasp(graph, out / 'rigid', 0.05, 1.69)
        runs['stiff'] = recorded_grasp(graph, out / 'stiff', 0.05, 1.0, **STIFF)
        runs['lift'] = recorded_grasp(graph, out / 'lift', 0.05, 1.0, lift_acceleration_mps2=8.0,
                                      lift_delay_s=0.1, lift_duration_s=0.3,
                                      default_friction=True)
        runs['dropout'] = recorded_grasp(graph, out / 'dropout', 0.05, 1.0,
                                         fault=int(FaultKind.SENSOR_DROPOUT), fault_at_s=2.92)
        runs['after_fault'] = recorded_grasp(graph, out / 'after_fault', 0.11, 0.5)
        # serve mode: a bag per request made by others; the first grasp follows its placement,
        # the second (after a release) grasps the object placed before the first
        serve = ServeRecorder(graph, out / 'serve')
        graph.set_object(0.11)
        graph.wait_still()
        assert graph.grasp(0.11, 0.5).success
        assert wait_until(lambda: len(serve.bags) == 1 and not serve.recording, 10.0)
        assert graph.release().success
        graph.wait_still()
        assert graph.grasp(0.11, 0.5).success
        assert wait_until(lambda: len(serve.bags) == 2 and not serve.recording, 10.0)
        runs['serve'], runs['serve_unplaced'] = serve.bags
    with GripperGraph.in_own_context(GraphOptions(position_controller='pd')) as graph:
        runs['pd'] = recorded_grasp(graph, out / 'pd', 0.14, 1.0)
    assert runs['dropout'].response.outcome == Outcome.FAULT, runs['dropout'].response.message
    assert runs['lift'].final_outcome == Outcome.OBJECT_LOST, runs['lift'].final_message
    for name in ('rigid', 'stiff', 'after_fault', 'pd'):
        assert runs[name].response.outcome == Outcome.HOLDING, runs[name].response.message
    return {name: (r if isinstance(r, Path) else Path(r.bag_dir)) for name, r in runs.items()}


_cli = functools.partial(run_main, bag_replay.main)      # (argv, capsys)


def _one_line_exit_2(argv, capsys) -> str:
    code, out = _cli(argv, capsys)
    assert code == 2, (code, out)
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('bag_replay: error: '), out.err
    assert out.out == ''
    return lines[0]


# --- no change: the recording, series for series ------------------------------------------------

@pytest.mark.parametrize('name', ['rigid', 'stiff', 'lift', 'dropout', 'after_fault'])
def test_rerun_without_changes_reproduces_the_recorded_series(bags, name):
    w = rerun.whatif(bags[name])
    r = w.reruns[0]
    assert r.setup.changes == []
    assert_rerun_equals_recording(w)
    assert r.metrics.outcome == w.recorded.outcome


def test_a_difference_is_found_and_named(bags):
    """The equality check can fail: a one-ULP change of one recorded force is reported."""
    w = rerun.whatif(bags['rigid'])
    rec = copy.deepcopy(w.record.series)
    k = int(np.flatnonzero(rec.ticks['force_n'] > 0)[0])
    rec.ticks['force_n'][k] = np.nextafter(rec.ticks['force_n'][k], np.inf)
    text = rerun.series_difference(rec, w.reruns[0].series, w.record.grasp_start_ns)
    assert rerun.series_difference(w.record.series, w.reruns[0].series,
                                   w.record.grasp_start_ns) == ''
    assert text.startswith('tick force_n differs first at') and f'(tick {k})' in text


def test_cli_table_and_json_without_changes(bags, capsys):
    code, out = _cli([str(bags['rigid']), '--resimulate', '--closed-loop'], capsys)
    assert code == 0, out.err
    assert 'changes:      none' in out.out
    assert 'series:       identical to the recording' in out.out
    for metric in ('outcome', 'time_to_contact_s', 'switch_time_s', 'position_settling_s',
                   'position_overshoot_pct', 'force_settling_s', 'peak_force_ratio',
                   'position_rms_m', 'force_rms_n', 'time_at_voltage_limit_s'):
        assert any(line.split()[:1] == [metric] for line in out.out.splitlines()), metric
    code, out = _cli([str(bags['rigid']), '--resimulate', '--closed-loop', '--json'], capsys)
    assert code == 0
    data = json.loads(out.out)
    assert data['series_identical'] is True and data['changes'] == []
    assert data['recorded'] == data['rerun']
    assert data['recorded']['outcome'] == 'HOLDING'


# --- the paper's PI on a stiff object ------------------------------------------------------------

def test_paper_pi_on_a_stiff_object_shows_the_spike_the_recording_did_not(bags, capsys, tmp_path):
    w = rerun.whatif(bags['stiff'], rerun.Changes(force_controller='pi'))
    r = w.reruns[0]
    assert r.setup.changes == ['force_controller contact_aware -> pi']
    assert w.recorded.outcome == 'HOLDING' and w.recorded.peak_force_ratio <= 1.01
    # the PI on the stiff object meets it at 1.7-6.1x F_sp and bounces off
    assert r.metrics.peak_force_ratio >= 1.7
    assert r.metrics.outcome == 'OBJECT_LOST'
    # ... exactly what a headless grasp with the PI from the start gives
    h = simulate_grasp(CONFIG, 0.05, 1.0, force_controller='pi', **STIFF,
                       start_ns=w.record.grasp_start_ns - round(0.01 * 1e9))
    assert np.array_equal(h.series.ticks['force_n'][1:], r.series.ticks['force_n'])
    stamps = h.series.ticks['stamp_ns']
    in_grasp = (stamps >= h.start_ns) & (stamps <= h.answer_ns)
    assert r.metrics.peak_contact_force_n == np.max(h.series.ticks['force_n'][in_grasp])
    assert r.metrics.outcome == h.answer.name
    png = tmp_path / 'whatif.png'
    code, out = _cli([str(bags['stiff']), '--resimulate', '--closed-loop', '--force-controller',
                      'pi', '--json', '--plot', str(png)], capsys)
    assert code == 0, out.err
    data = json.loads(out.out)
    assert data['recorded']['outcome'] == 'HOLDING' and data['rerun']['outcome'] == 'OBJECT_LOST'
    assert data['rerun']['peak_force_ratio'] == r.metrics.peak_force_ratio
    assert data['difference']['peak_force_ratio'] == pytest.approx(
        r.metrics.peak_force_ratio - w.recorded.peak_force_ratio)
    assert data['series_identical'] is None          # a change: nothing to hold it to
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


# --- a position gain and the linear model --------------------------------------------------------

def _model_band_entry_s(kc: float) -> float:
    """First time the unsaturated PD + plant step response (control/factories.py) reaches 98 %."""
    data = copy.deepcopy(CONFIG.data)
    data['position_control']['pd']['kc'] = kc
    config = parse_config(data)
    response = np.asarray(position_step_response(config, config.position.pd, 1000))
    return (np.flatnonzero(response >= 0.98)[0] + 1) * config.position.sample_time_s


def test_position_gain_moves_settling_as_the_linear_model_predicts(bags, capsys):
    recorded_kc = CONFIG.position.pd.kc
    values = [800.0, 1500.0]
    w = rerun.whatif(bags['pd'], sweep=('position_control.pd.kc', values))
    dt = CONFIG.position.sample_time_s
    base = w.recorded.position_settling_s
    assert abs(base - _model_band_entry_s(recorded_kc)) <= dt + 1e-9
    for kc, r in zip(values, w.reruns):
        assert r.setup.changes == [f'position_control.pd.kc {recorded_kc} -> {kc}']
        assert r.metrics.outcome == 'HOLDING'
        settle = r.metrics.position_settling_s
        predicted = _model_band_entry_s(kc) - _model_band_entry_s(recorded_kc)
        assert abs(predicted) > 5 * dt                   # the model sees a clear change ...
        assert np.sign(settle - base) == np.sign(predicted)     # ... and the re-run follows it
        assert abs(settle - _model_band_entry_s(kc)) <= dt + 1e-9
    # the sweep table: the recording, then one row per value; the recorded value = recording
    code, out = _cli([str(bags['pd']), '--resimulate', '--closed-loop', '--sweep',
                      f'position_control.pd.kc={recorded_kc},1500'], capsys)
    assert code == 0, out.err
    rows = out.out.splitlines()[-3:]
    assert rows[0].startswith(f'recorded ({recorded_kc})')
    assert rows[1].startswith(f'{recorded_kc} (= recording)')
    assert rows[2].startswith('1500')
    code, out = _cli([str(bags['pd']), '--resimulate', '--closed-loop', '--json', '--sweep',
                      'position_control.pd.kc=800,1500'], capsys)
    data = json.loads(out.out)
    assert [row['value'] for row in data['rerun']] == [800, 1500]
    assert data['rerun'][1]['position_settling_s'] == w.reruns[1].metrics.position_settling_s


def test_set_and_config_file_change_the_same_key(bags, tmp_path, capsys):
    """--set on the recorded config, and a config file with that value, give one re-run."""
    a = rerun.whatif(bags['pd'], rerun.Changes(settings=[('position_control.pd.kc', 1500)]))
    data = copy.deepcopy(a.record.config.data)
    data['position_control']['pd']['kc'] = 1500.0
    path = tmp_path / 'changed.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    b = rerun.whatif(bags['pd'], rerun.Changes(config_path=str(path)))
    assert np.array_equal(a.reruns[0].series.ticks['position_m'],
                          b.reruns[0].series.ticks['position_m'])
    assert b.reruns[0].setup.changes == ['position_control.pd.kc 968.0 -> 1500.0']


# --- bad input: one line, exit 2 ----------------------------------------------------------------

def _foreign_bag(path: Path) -> Path:
    store = get_typestore(Stores.ROS2_JAZZY)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=store)
        msg = store.types['std_msgs/msg/String'](data='hello')
        writer.write(conn, 1, store.serialize_cdr(msg, 'std_msgs/msg/String'))
    return path


def _format_1_bag(path: Path) -> Path:
    store = get_typestore(Stores.ROS2_JAZZY)
    for msg in sorted(LEGACY_MSG_DIR.glob('*.msg')):
        store.register(get_types_from_msg(msg.read_text(), f'gripper_interfaces/msg/{msg.stem}'))
    T = store.types
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        joint = writer.add_connection('/gripper/joint_states', 'sensor_msgs/msg/JointState',
                                      typestore=store)
        writer.add_connection('/gripper/supervisor/status',
                              'gripper_interfaces/msg/SupervisorStatus', typestore=store)
        stamp = T['builtin_interfaces/msg/Time'](sec=0, nanosec=0)
        msg = T['sensor_msgs/msg/JointState'](
            header=T['std_msgs/msg/Header'](stamp=stamp, frame_id=''), name=['finger_joint'],
            position=np.array([0.0]), velocity=np.array([0.0]), effort=np.array([0.0]))
        writer.write(joint, 1, store.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))
    return path


def test_a_serve_bag_carries_its_request_and_object_and_reruns_as_recorded(bags):
    """grasp_demo --serve's bag of a grasp made just after its placement re-runs as recorded."""
    w = rerun.whatif(bags['serve'])
    assert w.record.request['width_m'] == 0.11 and w.record.request['mass_kg'] == 0.5
    assert w.record.obj['width_m'] == 0.11
    assert_rerun_equals_recording(w)


def test_a_serve_bag_of_a_grasp_without_its_placement_says_why_it_is_not_rerun(bags, capsys):
    line = _one_line_exit_2([str(bags['serve_unplaced']), '--resimulate', '--closed-loop'],
                            capsys)
    assert 'not re-run in closed loop' in line and 'placed before an earlier request' in line


def test_a_bag_of_another_package_is_refused(tmp_path, capsys):
    line = _one_line_exit_2([str(_foreign_bag(tmp_path / 'chatter')), '--resimulate',
                             '--closed-loop'], capsys)
    assert 'not a gripper_ros grasp bag' in line


def test_a_bag_of_format_1_is_refused(tmp_path, capsys):
    line = _one_line_exit_2([str(_format_1_bag(tmp_path / 'old')), '--resimulate',
                             '--closed-loop'], capsys)
    assert 'format 1' in line and 'open-loop' in line


def test_an_unknown_key_is_refused(bags, capsys):
    line = _one_line_exit_2([str(bags['rigid']), '--resimulate', '--closed-loop', '--set',
                             'position_control.mpc_pd.kx=900'], capsys)
    assert 'unknown config key "position_control.mpc_pd.kx"' in line and ' kc,' in line
    line = _one_line_exit_2([str(bags['rigid']), '--resimulate', '--closed-loop', '--sweep',
                             'position_contrl.pd.kc=1,2'], capsys)
    assert 'unknown config key "position_contrl.pd.kc"' in line


def test_a_key_the_recorded_controller_does_not_read_is_refused_naming_readers(bags, capsys):
    """The rigid bag ran mpc_pd: pd's gain changes nothing there, so the re-run says so."""
    line = _one_line_exit_2([str(bags['rigid']), '--resimulate', '--closed-loop', '--set',
                             'position_control.pd.kc=1500'], capsys)
    assert line == ('bag_replay: error: position_control.pd.kc is not read by the position '
                    'controller of this re-run (mpc_pd); pd reads it: add '
                    '--position-controller pd')
    line = _one_line_exit_2([str(bags['stiff']), '--resimulate', '--closed-loop', '--sweep',
                             'force_control.mpc_pi.move_suppression=1.01,1.02'], capsys)
    assert '(contact_aware); mpc_pi reads it: add --force-controller mpc_pi' in line
    w = rerun.whatif(bags['rigid'], rerun.Changes(settings=[('position_control.pd.kc', 1500.0)],
                                                  position_controller='pd'))
    assert w.reruns[0].setup.changes == ['position_control.pd.kc 968.0 -> 1500.0',
                                         'position_controller mpc_pd -> pd']


@pytest.mark.parametrize('assignment', ['position_control.mpc_pd.kc=-5',
                                        'force_control.closed_loop_pole=1.5',
                                        'supervisor.force_law=paper2',
                                        'position_control.mpc_pd.horizon=7.5',
                                        'contact.kinetic_friction=0.9'])
def test_an_out_of_range_value_gets_the_config_readers_error(bags, capsys, assignment):
    key, value = assignment.split('=')
    data = copy.deepcopy(CONFIG.data)
    node = data
    *sections, leaf = key.split('.')
    for part in sections:
        node = node[part]
    node[leaf] = rerun.parse_assignment(assignment)[1]
    with pytest.raises(ConfigError) as reader:
        parse_config(data)
    line = _one_line_exit_2([str(bags['rigid']), '--resimulate', '--closed-loop', '--set',
                             assignment], capsys)
    assert line == f'bag_replay: error: {reader.value}'
    line = _one_line_exit_2([str(bags['rigid']), '--resimulate', '--closed-loop', '--sweep',
                             assignment], capsys)
    assert line == f'bag_replay: error: {reader.value}'


def test_malformed_options_are_refused(bags, capsys):
    base = [str(bags['rigid']), '--resimulate', '--closed-loop']
    assert 'expected SECTION.KEY=VALUE' in _one_line_exit_2(base + ['--set', 'kc900'], capsys)
    assert 'V1,V2' in _one_line_exit_2(base + ['--sweep', 'position_control.pd.kc=1,,2'], capsys)
    assert 'is a section' in _one_line_exit_2(base + ['--set', 'position_control.pd=1'], capsys)
    assert '.png' in _one_line_exit_2(base + ['--plot', 'figure.jpg'], capsys)
    assert 'approach-force-margin' in _one_line_exit_2(
        base + ['--approach-force-margin', 'nan'], capsys)
    # 3 x 1.69 kg x g / (2 x 0.5) = 49.7 N: more than the motor gives at 24 V
    line = _one_line_exit_2(base + ['--set', 'supervisor.grip_safety_factor=3'], capsys)
    assert 'refuses the recorded request' in line
