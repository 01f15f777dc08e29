"""Bag tools against synthetic grasp bags with known answers (no rclpy needed, except replay).

The synthetic bags are written with rosbags' Writer (rosbag2 version 9, MCAP), in both formats
the tools read: the lockstep loop (``/gripper/loop/tick``, stage references, motor commands,
plus the supervisor's status) and, with the interface definitions of that time
(``test/data/legacy_msgs``), the earlier one message per topic per tick. Both hold the same
grasp: a first-order position step (settling at tau*ln(50)), an underdamped second-order force
step (overshoot exp(-pi*zeta/sqrt(1-zeta^2))), a voltage saturated for exactly 50 ms.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
import shutil
import subprocess
import sys

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', '78')

from gripper_ros.bags import analyze as bag_analyze  # noqa: E402
from gripper_ros.bags import info as bag_info  # noqa: E402
from gripper_ros.bags import replay as bag_replay  # noqa: E402
from gripper_ros.bags.reader import (  # noqa: E402
    BagNotFoundError,
    EmptyBagError,
    EXIT_CLOSED_PIPE,
    EXIT_ERROR,
    EXIT_TRUNCATED,
    MissingTopicsError,
    NotABagError,
    read_bag,
)
from gripper_ros.bags.series import LEGACY_TOPICS, load_grasp_series  # noqa: E402
from gripper_ros.wire import (COMMAND_LAYOUT, LOOP_TOPICS, Outcome, Phase,  # noqa: E402
                              qualified, REFERENCE_LAYOUT, TICK_LAYOUT, TOPIC_CLOCK,
                              TOPIC_FORCE_REFERENCE, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_POSITION_REFERENCE, TOPIC_STATUS, TOPIC_TICK)
from helpers import copy_mcap  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import get_types_from_msg, get_typestore, Stores  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
MSG_DIR = REPO / 'gripper_interfaces' / 'msg'
LEGACY_MSG_DIR = Path(__file__).resolve().parent / 'data' / 'legacy_msgs'

# known answers
DT_NS = 1_000_000                 # 1 ms ticks
T0_NS = 1_000_000_000             # grasp starts at simulated 1.0 s
N_TICKS = 2001                    # 1.0 s .. 3.0 s
K_CONTACT, K_SWITCH, K_HOLD = 550, 600, 1500
TAU_S = 0.1                       # position stage: y = sp (1 - exp(-t/tau))
POS_SP_M = 0.03
ZETA, WN = 0.5, 20.0              # force stage: second order
FORCE_SP_N = 5.0
V_LIMIT_TICKS = 50                # |V| = 24 V on ticks 1..50 -> 50 ms at the limit
GRASP_ID = 7

NS = 'gripper'
TICK, STATUS, JOINTS = (qualified(NS, t) for t in (TOPIC_TICK, TOPIC_STATUS, TOPIC_JOINT_STATES))
POS_REF, FORCE_REF, COMMAND = (qualified(NS, t) for t in (
    TOPIC_POSITION_REFERENCE, TOPIC_FORCE_REFERENCE, TOPIC_MOTOR_COMMAND))
LOCKSTEP_TOPICS = {**{qualified(NS, t): ty for t, ty in LOOP_TOPICS.items()},
                   STATUS: 'gripper_interfaces/msg/SupervisorStatus',
                   JOINTS: 'sensor_msgs/msg/JointState'}
"""The topics of the synthetic lockstep bag (every tick on each but the unused reference)."""
OLD = {name: qualified(NS, name) for name in LEGACY_TOPICS}
OLD_TOPICS = {TOPIC_CLOCK: 'rosgraph_msgs/msg/Clock',
              **{OLD[name]: ty for name, ty in LEGACY_TOPICS.items()}}


def _typestore(msg_dir: Path = MSG_DIR):
    store = get_typestore(Stores.ROS2_JAZZY)
    for path in sorted(msg_dir.glob('*.msg')):
        store.register(get_types_from_msg(path.read_text(), f'gripper_interfaces/msg/{path.stem}'))
    return store


def _make(cls, **values):
    """Make a rosbags message with unset numeric/bool/str fields zeroed (interfaces evolve)."""
    import dataclasses
    zero = {'float': 0.0, 'int': 0, 'bool': False, 'str': ''}
    for f in dataclasses.fields(cls):
        if f.name not in values and f.name != '__msgtype__':
            values[f.name] = zero.get(f.type if isinstance(f.type, str) else f.type.__name__, 0)
    return cls(**values)


def _force(tau_s: float) -> float:
    wd = WN * math.sqrt(1 - ZETA ** 2)
    return FORCE_SP_N * (1 - math.exp(-ZETA * WN * tau_s) * (
        math.cos(wd * tau_s) + ZETA / math.sqrt(1 - ZETA ** 2) * math.sin(wd * tau_s)))


def _voltage(k: int) -> float:
    if k == 0:
        return 0.0
    if k <= V_LIMIT_TICKS:
        return 24.0
    if k < K_SWITCH:
        return 24.0 * math.exp(-(k - V_LIMIT_TICKS) * 1e-3 / 0.05)
    return 2.0


def _tick(k: int, n_ticks: int) -> dict:
    """Return the known grasp at tick ``k``."""
    y_switch = POS_SP_M * (1 - math.exp(-(K_SWITCH - 1) * 1e-3 / TAU_S))
    pos = POS_SP_M * (1 - math.exp(-k * 1e-3 / TAU_S)) if k < K_SWITCH else y_switch
    force = 0.0 if k < K_CONTACT else (1e-3 if k < K_SWITCH else _force((k - K_SWITCH) * 1e-3))
    last = k == n_ticks - 1
    phase = 1 if k < K_SWITCH else (2 if k < K_HOLD else 3)
    return {'t_ns': T0_NS + k * DT_NS, 'pos': pos, 'force': force, 'phase': phase,
            'source': 1 if phase == 1 else 2, 'stage': 1 if phase == 1 else 2,
            'outcome': 1 if last else 0, 'switch': 0 if k < K_SWITCH else 2}


def write_grasp_bag(path: Path, topics=None, n_ticks: int = N_TICKS, custom_data=True,
                    move: bool = False) -> Path:
    """Write a lockstep-format grasp bag with analytically known figures (module docstring).

    ``move``: the same ticks as one move (phase MOVING, answered MOVED), no grasp.
    """
    store = _typestore()
    T = store.types
    topics = dict(LOCKSTEP_TOPICS) if topics is None else {t: LOCKSTEP_TOPICS.get(
        t, 'rosgraph_msgs/msg/Clock') for t in topics}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {t: writer.add_connection(t, ty, typestore=store) for t, ty in topics.items()}
        if custom_data:
            writer.set_custom_data('gripper_ros', json.dumps({'format': 2, 'namespace': NS}))
            writer.set_custom_data('grasp_request', json.dumps(
                {'width_m': 0.05, 'mass_kg': 0.2, 'friction_coefficient': 0.4}))
        for k in range(n_ticks):
            g = _tick(k, n_ticks)
            if move:
                g.update(phase=int(Phase.MOVING), source=1, stage=1, switch=0,
                         outcome=int(Outcome.MOVED) if g['outcome'] else 0)
            t_ns = g['t_ns']
            stamp = T['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            hdr = T['std_msgs/msg/Header'](stamp=stamp, frame_id='')
            running = g['outcome'] == 0
            raw = {
                TICK: TICK_LAYOUT.pack(t_ns, g['pos'], 0.0, g['force'], g['force'],
                                       0.2 + 0.4 * g['force'], _voltage(k), 0.1 * _voltage(k),
                                       0.0, g['source'] if k else 0, 0, 0.0, 0.0, 0.0, 0.0),
                POS_REF if g['source'] == 1 else FORCE_REF: REFERENCE_LAYOUT.pack(
                    t_ns, GRASP_ID, g['stage'], 0, g['phase'], g['outcome'], g['source'],
                    running, k >= K_CONTACT, POS_SP_M, POS_SP_M, FORCE_SP_N, g['pos'], 0.0,
                    g['force'], 0.0, 0.0, 0.0, 0.0, 0.0),
                COMMAND: COMMAND_LAYOUT.pack(t_ns, GRASP_ID, g['stage'], 0, g['source'],
                                             g['phase'], g['outcome'], running, True,
                                             _voltage(k + 1), 1e-3, 0.0),
            }
            msgs = {
                TOPIC_CLOCK: T['rosgraph_msgs/msg/Clock'](clock=stamp),
                JOINTS: T['sensor_msgs/msg/JointState'](
                    header=hdr, name=['finger_joint'], position=np.array([g['pos']]),
                    velocity=np.array([0.0]), effort=np.array([g['force']])),
                STATUS: _make(T['gripper_interfaces/msg/SupervisorStatus'],
                              header=hdr, phase=g['phase'], active_controller=g['source'],
                              switch_criterion=g['switch'], grasp_id=GRASP_ID,
                              stage_id=g['stage'], outcome=g['outcome'], running=running,
                              position_setpoint_m=POS_SP_M, approach_setpoint_m=POS_SP_M,
                              force_setpoint_n=FORCE_SP_N, mass_kg=0.2, position_m=g['pos'],
                              force_n=g['force'], contact=k >= K_CONTACT),
            }
            for topic in topics:
                if topic in raw:
                    writer.write(conns[topic], t_ns, raw[topic])
                elif topic in msgs:
                    writer.write(conns[topic], t_ns, store.serialize_cdr(msgs[topic],
                                                                         topics[topic]))
    return path


def write_legacy_grasp_bag(path: Path, n_ticks: int = N_TICKS) -> Path:
    """Write the same grasp in the earlier format, with the interface definitions of that time."""
    store = _typestore(LEGACY_MSG_DIR)
    T = store.types
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {t: writer.add_connection(t, ty, typestore=store) for t, ty in OLD_TOPICS.items()}
        writer.set_custom_data('grasp_request', json.dumps({'width_m': 0.05, 'mass_kg': 0.2}))
        for k in range(n_ticks):
            g = _tick(k, n_ticks)
            t_ns = g['t_ns']
            stamp = T['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            hdr = T['std_msgs/msg/Header'](stamp=stamp, frame_id='')
            msgs = {
                TOPIC_CLOCK: T['rosgraph_msgs/msg/Clock'](clock=stamp),
                OLD['joint_states']: T['sensor_msgs/msg/JointState'](
                    header=hdr, name=['finger_joint'], position=np.array([g['pos']]),
                    velocity=np.array([0.0]), effort=np.array([g['force']])),
                OLD['force_sensor']: _make(
                    T['gripper_interfaces/msg/ForceSensor'],
                    header=hdr, force_n=g['force'], voltage_v=0.2 + 0.4 * g['force'],
                    peak_force_n=g['force']),
                OLD['motor_state']: _make(
                    T['gripper_interfaces/msg/MotorState'],
                    header=hdr, voltage_v=_voltage(k), current_a=0.1 * _voltage(k),
                    speed_rad_s=0.0),
                OLD['supervisor/status']: _make(
                    T['gripper_interfaces/msg/SupervisorStatus'],
                    header=hdr, phase=4 if g['outcome'] else g['phase'],
                    active_controller=g['source'], switch_criterion=g['switch'],
                    grasp_id=GRASP_ID, outcome=g['outcome'], position_setpoint_m=POS_SP_M,
                    force_setpoint_n=FORCE_SP_N, position_m=g['pos'], force_n=g['force'],
                    contact=k >= K_CONTACT, seed_voltage_v=0.0),
                OLD['motor_command']: _make(
                    T['gripper_interfaces/msg/MotorCommand'],
                    header=hdr, source=g['source'], grasp_id=GRASP_ID,
                    voltage_v=_voltage(k + 1), hold_s=1e-3, inner_setpoint=0.0),
            }
            for topic, msg in msgs.items():
                writer.write(conns[topic], t_ns, store.serialize_cdr(msg, OLD_TOPICS[topic]))
    return path


@pytest.fixture(scope='module')
def legacy_bag(tmp_path_factory) -> Path:
    return write_legacy_grasp_bag(tmp_path_factory.mktemp('legacy') / 'grasp')


@pytest.fixture(scope='module')
def grasp_bag(tmp_path_factory) -> Path:
    return write_grasp_bag(tmp_path_factory.mktemp('bags') / 'grasp')


def rechunk(src: Path, dst: Path, chunk_size: int = 16 * 1024) -> Path:
    """Copy a bag's .mcap with small chunks, as a recorder flushing often would write it.

    (rosbags writes 1 MiB chunks, so a small bag is one chunk: cut anywhere, nothing survives.)
    """
    dst.mkdir(parents=True)
    copy_mcap(next(src.glob('*.mcap')), dst / f'{dst.name}_0.mcap', chunk_size=chunk_size)
    return dst


@pytest.fixture(scope='module')
def truncated_bag(tmp_path_factory, grasp_bag) -> Path:
    """Return the grasp bag re-chunked, its .mcap cut in the middle (no summary or footer).

    The cut bag has no metadata.yaml either.
    """
    base = tmp_path_factory.mktemp('cut')
    whole = rechunk(grasp_bag, base / 'whole')
    out = base / 'cut'
    out.mkdir()
    data = next(whole.glob('*.mcap')).read_bytes()
    (out / 'cut_0.mcap').write_bytes(data[:len(data) // 2])
    return out


# --- bag_io -----------------------------------------------------------------------------------

def test_read_bag_counts_and_metadata(grasp_bag):
    bag = read_bag(grasp_bag)
    assert not bag.truncated
    counts = bag.counts()
    assert counts[POS_REF] + counts[FORCE_REF] == N_TICKS
    assert {t: counts[t] for t in (TICK, COMMAND, STATUS, JOINTS)} == dict.fromkeys(
        (TICK, COMMAND, STATUS, JOINTS), N_TICKS)
    assert bag.metadata['version'] == 9
    assert bag.custom_data_parsed()['grasp_request']['width_m'] == 0.05
    assert bag.start_ns == T0_NS and bag.end_ns == T0_NS + (N_TICKS - 1) * DT_NS
    assert bag.topics[TICK].rate_hz == pytest.approx(1000.0)


def test_bag_is_self_describing(grasp_bag):
    """Custom types decode from the schemas inside the bag (no interface package needed)."""
    bag = read_bag(grasp_bag)
    assert 'gripper_interfaces/msg/SupervisorStatus' in bag.schemas
    status = [bag.decode(m) for m in bag.messages if m.topic == STATUS]
    assert status[-1].outcome == 1 and status[-1].grasp_id == GRASP_ID
    tick = [bag.decode(m) for m in bag.messages if m.topic == TICK][-1]
    assert tick.stamp_ns == T0_NS + (N_TICKS - 1) * DT_NS


@pytest.mark.parametrize('which', ['lockstep', 'legacy'])
def test_grasp_series(grasp_bag, legacy_bag, which):
    s = load_grasp_series(grasp_bag if which == 'lockstep' else legacy_bag)
    assert s.bag_format == (2 if which == 'lockstep' else 1) and s.namespace == NS
    assert s.t_s[0] == pytest.approx(1.0) and len(s.t_s) == N_TICKS
    assert s.ticks['position_m'][-1] == pytest.approx(POS_SP_M * (1 - math.exp(-0.599 / TAU_S)))
    assert s.ticks['sensor_voltage_v'][0] == pytest.approx(0.2)
    assert s.decisions['phase'][K_SWITCH] == 2 and s.commands['source'][0] == 1
    assert s.ticks['motor_voltage_v'][1] == 24.0
    assert s.duration_s == pytest.approx(2.0)


def test_truncated_recovers_complete_messages(grasp_bag, truncated_bag):
    full = read_bag(grasp_bag)
    cut = read_bag(truncated_bag)
    assert cut.truncated and 0 < cut.message_count < full.message_count
    # every recovered message is byte-identical to the original at the same position
    assert [m.data for m in cut.messages] == [m.data for m in full.messages[:cut.message_count]]
    assert cut.custom_data == {} or 'grasp_request' in cut.custom_data


@pytest.mark.parametrize('make, error', [
    (lambda d: d / 'nope', BagNotFoundError),
    (lambda d: (d / 'notabag').mkdir() or (d / 'notabag' / 'x.txt').write_text('x')
     and d / 'notabag', NotABagError),
])
def test_bad_paths(tmp_path, make, error):
    with pytest.raises(error) as exc_info:
        read_bag(make(tmp_path))
    assert '\n' not in str(exc_info.value)


# --- bag_analyze: the known answers -----------------------------------------------------------

@pytest.mark.parametrize('which', ['lockstep', 'legacy'])
def test_analysis_known_answers(grasp_bag, legacy_bag, which):
    """The same figures come from either format.

    Bags recorded before the lockstep protocol still analyse the same.
    """
    m = bag_analyze.analyze_series(load_grasp_series(grasp_bag if which == 'lockstep'
                                                     else legacy_bag))
    dt = 1e-3
    assert m.grasp_id == GRASP_ID and m.outcome == 'HOLDING'
    assert m.time_to_contact_s == pytest.approx(K_CONTACT * dt, abs=1e-9)
    assert m.switch_time_s == pytest.approx(K_SWITCH * dt, abs=1e-9)
    assert m.switch_criterion == 'SENSOR_VOLTAGE'
    # position: first order, 2 % settling at tau ln 50 (first sample inside the band)
    assert m.position_overshoot_pct == 0.0
    assert TAU_S * math.log(50) <= m.position_settling_s <= TAU_S * math.log(50) + dt + 1e-9
    t_stage = K_SWITCH * dt
    rms_analytic = POS_SP_M * math.sqrt(TAU_S / (2 * t_stage)
                                        * (1 - math.exp(-2 * t_stage / TAU_S)))
    assert m.position_rms_m == pytest.approx(rms_analytic, rel=0.02)
    # force: second order overshoot and envelope bound on settling
    os_pct = 100 * math.exp(-math.pi * ZETA / math.sqrt(1 - ZETA ** 2))
    assert m.force_overshoot_pct == pytest.approx(os_pct, abs=0.01)
    t_env = -math.log(0.02 * math.sqrt(1 - ZETA ** 2)) / (ZETA * WN)
    half_period = math.pi / (WN * math.sqrt(1 - ZETA ** 2))
    assert t_env - half_period <= m.force_settling_s <= t_env + dt
    assert m.peak_contact_force_n == pytest.approx(FORCE_SP_N * (1 + os_pct / 100), rel=1e-4)
    assert m.peak_force_ratio == pytest.approx(1 + os_pct / 100, rel=1e-4)
    # voltage saturated on exactly 50 ticks of 1 ms
    assert m.max_abs_voltage_v == 24.0
    assert m.time_at_voltage_limit_s == pytest.approx(V_LIMIT_TICKS * dt, abs=1e-9)
    assert m.final_position_error_m == pytest.approx(POS_SP_M * math.exp(-0.599 / TAU_S))
    assert abs(m.final_force_error_n) < 1e-3


def test_time_at_the_limit_is_measured_against_the_limit_the_bag_recorded(grasp_bag):
    """The limit comes from the bag's recorded config, else the installed config's 24 V.

    The bag's command sits at 24 V for V_LIMIT_TICKS ticks and never above: a bag recorded
    with a higher limit never reached it, one with exactly 24 V spent those ticks there.
    """
    series = load_grasp_series(grasp_bag)
    assert 'config' not in series.custom_data          # the synthetic bag records none
    installed = bag_analyze.analyze_series(series)
    assert installed.time_at_voltage_limit_s == pytest.approx(V_LIMIT_TICKS * 1e-3, abs=1e-9)

    def recorded_with(limit_v):
        data = {**series.custom_data, 'config': {'plant': {'voltage_limit_v': limit_v}}}
        return bag_analyze.analyze_series(dataclasses.replace(series, custom_data=data))

    assert recorded_with(30.0).time_at_voltage_limit_s == 0.0
    assert recorded_with(24.0).time_at_voltage_limit_s == pytest.approx(V_LIMIT_TICKS * 1e-3,
                                                                        abs=1e-9)


def test_analyze_cli_table_json_csv_plot(grasp_bag, tmp_path, capsys):
    assert bag_analyze.main([str(grasp_bag), str(grasp_bag)]) == 0
    out = capsys.readouterr().out
    assert 'switch_criterion' in out and 'SENSOR_VOLTAGE' in out
    assert bag_analyze.main([str(grasp_bag), '--json']) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]['time_at_voltage_limit_s'] == pytest.approx(0.05, abs=1e-9)
    assert bag_analyze.main([str(grasp_bag), '--csv']) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith('bag,grasp_id')
    png = tmp_path / 'fig.png'
    assert bag_analyze.main([str(grasp_bag), str(grasp_bag), '--plot', str(png), '--json']) == 0
    assert png.stat().st_size > 10_000


def test_analyze_says_what_a_bag_without_a_grasp_holds(grasp_bag, tmp_path, capsys):
    """A move's bag: exit 0, one line naming the move, its outcome, time and ranges; no figure."""
    move = write_grasp_bag(tmp_path / 'move', move=True)
    png = tmp_path / 'move.png'
    assert bag_analyze.main([str(move), '--plot', str(png)]) == 0
    out = capsys.readouterr().out.splitlines()
    duration_s = (N_TICKS - 1) * DT_NS * 1e-9
    assert out[0] == (f'move: no grasp: 1 move (ids {GRASP_ID}-{GRASP_ID}: MOVED 1), '
                      f'{duration_s:.3f} s, finger 0.0000-{_tick(N_TICKS - 1, N_TICKS)["pos"]:.4f}'
                      f' m, motor {min(_voltage(k) for k in range(1, N_TICKS + 1)):.2f} to '
                      '24.00 V')
    assert out[1:] == ['no figure: no grasp in this bag'] and not png.exists()
    assert bag_analyze.main([str(grasp_bag), str(move), '--plot', str(png)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-2].startswith('move: no grasp') and out[-1] == f'figure: {png}'
    assert png.stat().st_size > 10_000


# --- bag_info ---------------------------------------------------------------------------------

def test_info_cli(grasp_bag, capsys):
    assert bag_info.main([str(grasp_bag)]) == 0
    out = capsys.readouterr().out
    for text in ('Files:', 'Bag size:', 'Storage id:', 'mcap', 'Duration:', '2.000000000s',
                 'Messages:', str(5 * N_TICKS), 'Topic: /gripper/joint_states',
                 'Type: sensor_msgs/msg/JointState', f'Count: {N_TICKS}',
                 'Serialization Format: cdr', 'Rate: 1000.0 Hz', 'width_m=0.05',
                 'outcome HOLDING', 'switch SENSOR_VOLTAGE', 'force 5 N'):
        assert text in out, text


# --- every CLI: bad input -> one line on stderr, non-zero exit ---------------------------------

def _empty_bag(tmp_path: Path) -> Path:
    store = _typestore()
    path = tmp_path / 'empty'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection(TOPIC_CLOCK, 'rosgraph_msgs/msg/Clock', typestore=store)
    return path


def _clock_only_bag(tmp_path: Path) -> Path:
    return write_grasp_bag(tmp_path / 'clock_only', topics=[TOPIC_CLOCK], n_ticks=20,
                           custom_data=False)


def _not_a_bag(tmp_path: Path) -> Path:
    path = tmp_path / 'plain'
    path.mkdir()
    (path / 'notes.txt').write_text('hello')
    return path


def _garbage_mcap(tmp_path: Path) -> Path:
    path = tmp_path / 'garbage.mcap'
    path.write_bytes(b'this is not an mcap file at all')
    return path


BAD_INPUTS = {
    'missing': lambda d: d / 'does_not_exist',
    'not_a_bag': _not_a_bag,
    'empty': _empty_bag,
    'garbage': _garbage_mcap,
}

CLIS = {
    'bag_info': (bag_info.main, []),
    'bag_analyze': (bag_analyze.main, []),
    'bag_replay': (bag_replay.main, ['--quiet']),
}


def _run_cli(main, argv, capsys):
    with pytest.raises(SystemExit) as exc_info:
        main(argv)
    captured = capsys.readouterr()
    return exc_info.value.code, captured


@pytest.mark.parametrize('cli', sorted(CLIS))
@pytest.mark.parametrize('bad', sorted(BAD_INPUTS))
def test_cli_bad_input_one_line(cli, bad, tmp_path, capsys):
    main, extra = CLIS[cli]
    code, captured = _run_cli(main, [str(BAD_INPUTS[bad](tmp_path))] + extra, capsys)
    assert code == EXIT_ERROR
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'{cli}: error: '), captured.err
    assert 'Traceback' not in captured.err


@pytest.mark.parametrize('cli, argv', [
    ('bag_analyze', []),
    ('bag_replay', ['--topics', JOINTS, '--quiet']),
])
def test_cli_missing_topics(cli, argv, tmp_path, capsys):
    main, _ = CLIS[cli]
    code, captured = _run_cli(main, [str(_clock_only_bag(tmp_path))] + argv, capsys)
    assert code == EXIT_ERROR
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and ('not a grasp bag' in lines[0] or 'not in bag' in lines[0])


def test_info_on_bag_without_grasp_topics_is_fine(tmp_path, capsys):
    assert bag_info.main([str(_clock_only_bag(tmp_path))]) == 0
    assert 'Topic: /clock' in capsys.readouterr().out


@pytest.mark.parametrize('argv', [
    ['--rate', '0'], ['--rate', 'nan'], ['--start-offset', '-1'], ['--remap', 'nocolon'],
    ['--remap', '/nope:=/x'], ['--start-offset', '1000'], ['--wait-for-all-acked', '-1'],
    ['--wait-for-all-acked', '100000000000'],
])
def test_replay_bad_options(grasp_bag, argv, capsys):
    code, captured = _run_cli(bag_replay.main, [str(grasp_bag), '--quiet'] + argv, capsys)
    assert code == EXIT_ERROR
    assert len(captured.err.strip().splitlines()) == 1


def test_replay_resimulate_with_a_missing_config_is_a_clear_error(grasp_bag, tmp_path, capsys):
    code, captured = _run_cli(bag_replay.main, [str(grasp_bag), '--resimulate',
                                                str(tmp_path / 'c.yaml')], capsys)
    assert code == 2 and 'cannot read config file' in captured.err
    assert len(captured.err.strip().splitlines()) == 1


@pytest.mark.parametrize('cli', ['bag_info', 'bag_analyze'])
def test_cli_truncated(cli, truncated_bag, grasp_bag, capsys):
    """A bag cut in the middle: the tools work on the complete messages, say so, exit 3."""
    main, extra = CLIS[cli]
    recovered = read_bag(truncated_bag).message_count
    code, captured = _run_cli(main, [str(truncated_bag)] + extra, capsys)
    assert code == EXIT_TRUNCATED
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and f'truncated: {recovered} complete messages recovered' in lines[0]
    assert captured.out.strip()


def test_garbage_in_mcap_folder(tmp_path):
    folder = tmp_path / 'bag'
    folder.mkdir()
    shutil.copy(_garbage_mcap(tmp_path), folder / 'bag_0.mcap')
    with pytest.raises(Exception) as exc_info:
        read_bag(folder)
    assert 'not an MCAP file' in str(exc_info.value)


def test_empty_bag_error_type(tmp_path):
    with pytest.raises(EmptyBagError):
        read_bag(_empty_bag(tmp_path))
    assert read_bag(_empty_bag(tmp_path / 'x'), allow_empty=True).message_count == 0


def test_missing_topics_error(tmp_path):
    with pytest.raises(MissingTopicsError, match='not a grasp bag: no <namespace>/loop/tick'):
        load_grasp_series(_clock_only_bag(tmp_path))


@pytest.mark.parametrize('module, extra', [('analyze', ['--json']), ('info', [])])
def test_output_into_a_pipe_closed_early_ends_quietly(grasp_bag, module, extra):
    """``bag_analyze BAG --json | head -1``: the reader stops early; no traceback, exit 141."""
    proc = subprocess.Popen([sys.executable, '-m', f'gripper_ros.bags.{module}', str(grasp_bag),
                             *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                       # the reader is gone before the first line
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_CLOSED_PIPE, err.decode()
    assert err == b''
