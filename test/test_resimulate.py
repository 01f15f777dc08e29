"""Open-loop re-simulation (``bag_replay BAG --resimulate CONFIG.yaml``) on a real recorded grasp.

One grasp (paper object 1: 50 mm, 1.69 kg) is recorded through the node graph over DDS; its
recorded measurements are then fed through the controllers of a configuration:
- the configuration it was recorded with gives bit-identical commands in both stages;
- a changed force pole changes the force stage only; changed PD gains the position stage only;
- bad bags, configs and options give one-line errors (exit 1 bag/options, 2 config, 3 truncated).
"""
from __future__ import annotations

import copy
import functools
import json
import math
from pathlib import Path

from gripper_ros.bags import replay as bag_replay
from gripper_ros.bags.reader import EXIT_ERROR, EXIT_TRUNCATED, MissingTopicsError, read_bag
from gripper_ros.bags.resimulate import OPEN_LOOP_NOTE, resimulate_bag
from gripper_ros.core.config import ConfigError, default_config_path, load_config, parse_config
from gripper_ros.core.control.stages import (ForceStageController, LockstepAnswerer,
                                             PositionStageController, Reference)
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.nodes.recording import recorded_grasp
from helpers import run_main
import pytest
import yaml

CONFIG = load_config()
RECORDED_GRASP_ID: list[int] = []
"""The id the recorded grasp got (the namespace's ids go on from earlier runs)."""
CONFIG_DATA = yaml.safe_load(Path(default_config_path()).read_text(encoding='utf-8'))


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """(bag dir, graph node stage classes) of one recorded grasp of paper object 1."""
    out = tmp_path_factory.mktemp('resim')
    with GripperGraph.in_own_context() as graph:
        run = recorded_grasp(graph, out / 'grasp', 0.05, 1.69)
        stages = (type(graph.position.stage), type(graph.force.stage))
    assert run.response.success, run.response.message
    assert run.response.grasp_id >= 1          # ids go on across graphs of one namespace
    RECORDED_GRASP_ID.append(run.response.grasp_id)
    return Path(run.bag_dir), stages


def _config_with(tmp_path: Path, name: str, edit) -> Path:
    data = copy.deepcopy(CONFIG_DATA)
    edit(data)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding='utf-8')
    return path


_run_cli = functools.partial(run_main, bag_replay.main)      # (argv, capsys)


# --- the nodes and re-simulation share one implementation ---------------------------------------

def test_nodes_run_the_shared_stage_controllers(recorded):
    _, (position_cls, force_cls) = recorded
    assert position_cls is PositionStageController
    assert force_cls is ForceStageController


# --- unchanged configuration: bit-identical ------------------------------------------------------

def test_recorded_config_reproduces_every_command_bitwise(recorded):
    bag_dir, _ = recorded
    report = resimulate_bag(bag_dir, None)              # the installed default config
    assert report.identical
    assert report.grasp_ids == RECORDED_GRASP_ID
    assert report.measurements_from_status == 0         # each reference carries its tick's
    counts = read_bag(bag_dir).counts()
    total = 0
    for name in ('position', 'force'):
        s = report.stages[name]
        assert s.recorded > 0
        assert s.compared == s.recorded == s.resimulated
        assert s.differing == 0 and s.only_recorded == 0 and s.only_resimulated == 0
        assert s.max_abs_dv_v == 0.0 and s.rms_dv_v == 0.0 and s.max_abs_d_inner == 0.0
        assert s.first_diff_tick is None
        total += s.compared
    assert total == counts['/gripper/loop/motor_command']


def test_cli_table_and_json_for_the_recorded_config(recorded, capsys):
    bag_dir, _ = recorded
    code, out = _run_cli([str(bag_dir), '--resimulate', str(default_config_path())], capsys)
    assert code == 0, out.err
    assert 'IDENTICAL' in out.out and 'NOT re-run' in out.out
    assert out.err == ''
    code, out = _run_cli([str(bag_dir), '--resimulate', '--json'], capsys)
    assert code == 0, out.err
    data = json.loads(out.out)
    assert data['identical'] is True and data['note'] == OPEN_LOOP_NOTE
    assert data['stages']['force']['max_abs_dv_v'] == 0.0
    assert data['stages']['position']['max_abs_dv_v'] == 0.0


# --- changed gains: only the changed stage differs -----------------------------------------------

def test_changed_force_gain_changes_the_force_stage_only(recorded, tmp_path, capsys):
    bag_dir, _ = recorded
    path = _config_with(tmp_path, 'kp.yaml', lambda d: d['force_control']['contact_aware']
                        .__setitem__('force_gain_v_per_n', 0.6))
    code, out = _run_cli([str(bag_dir), '--resimulate', str(path), '--json'], capsys)
    assert code == 0, out.err                            # it ran: exit 0 even though it differs
    data = json.loads(out.out)
    assert data['identical'] is False
    pos, frc = data['stages']['position'], data['stages']['force']
    assert pos['identical'] and pos['max_abs_dv_v'] == 0.0 and pos['differing'] == 0
    assert frc['differing'] > 0 and frc['max_abs_dv_v'] > 0.0 and frc['rms_dv_v'] > 0.0
    # the force gain acts from contact on: the approach ticks before it are identical
    assert frc['first_diff_tick'] > 0
    assert frc['compared'] == frc['recorded']
    code, out = _run_cli([str(bag_dir), '--resimulate', str(path)], capsys)
    assert code == 0 and 'DIFFERENT' in out.out and 'NOT re-run' in out.out


def test_changed_pd_gain_changes_the_position_stage_only(recorded):
    bag_dir, _ = recorded
    data = copy.deepcopy(CONFIG_DATA)
    data['position_control']['mpc_pd']['kc'] = 500.0
    report = resimulate_bag(bag_dir, parse_config(data, 'kc500'), keep_ticks=True)
    pos, frc = report.stages['position'], report.stages['force']
    assert frc.identical and frc.max_abs_dv_v == 0.0
    assert pos.differing > 0 and pos.max_abs_dv_v > 0.0
    assert len(report.ticks) == pos.compared + frc.compared
    dv = [abs(t['resimulated_v'] - t['recorded_v']) for t in report.ticks
          if t['stage'] == 'position']
    assert max(dv) == pos.max_abs_dv_v


def test_other_force_controller_kind_differs(recorded):
    bag_dir, _ = recorded
    report = resimulate_bag(bag_dir, CONFIG, force_controller='mpc_pi')
    assert report.stages['position'].identical
    assert not report.stages['force'].identical


# --- the lockstep bookkeeping the nodes use ------------------------------------------------------

def _ref(stamp, stage_id=1, grasp_id=1, position_m=1.5, position_setpoint_m=0.1):
    return Reference(stamp, grasp_id, stage_id, 0, 1, 0, 1, True, False, position_setpoint_m,
                     0.1, 1.0, position_m, 0.0, 0.0, 0.0)


def test_lockstep_answerer_dedupes_restarts_on_a_new_stage_and_holds_on_nan():
    stage = PositionStageController(CONFIG)
    a = LockstepAnswerer(stage)
    first = a.answer(_ref(10))
    assert first.finite and a.active_stage == 1
    assert a.answer(_ref(10)) is None                    # same (stage, stamp): answered once
    assert a.answer(_ref(20, position_m=2.0)).finite and a.active_stage == 1
    a.answer(_ref(30, stage_id=3))                       # a new stage: restarted
    assert a.active_stage == 3
    held = a.answer(_ref(40, stage_id=3, position_m=math.nan))
    assert held.voltage_v == 0.0 and not held.finite and 'measurement' in held.reason
    bad = a.answer(_ref(50, stage_id=3, position_setpoint_m=math.inf))
    assert not bad.finite and 'position_setpoint_m=inf' in bad.reason
    assert a.active_stage == 3                           # neither touched the law


# --- bad input -----------------------------------------------------------------------------------

def _one_line_error(out, code, expected_code):
    assert code == expected_code, out.err
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('bag_replay: error: '), out.err
    assert 'Traceback' not in out.err
    return lines[0]


@pytest.mark.parametrize('make, code, words', [
    (lambda t: t / 'missing.yaml', 2, 'cannot read config file'),
    (lambda t: t, 2, 'is a directory'),
    (lambda t: _write(t / 'bad.yaml', 'plant: [1, 2\n  x: {'), 2, 'not valid YAML'),
    (lambda t: _write(t / 'empty.yaml', ''), 2, 'top level must be a mapping'),
    (lambda t: _config_with(t, 'unstable.yaml',
                            lambda d: d['force_control'].__setitem__('closed_loop_pole', 1.5)),
     2, 'closed_loop_pole'),
    (lambda t: _config_with(t, 'negative.yaml',
                            lambda d: d['position_control']['mpc_pd'].__setitem__('kc', -1.0)),
     2, 'position_control.mpc_pd.kc'),
])
def test_bad_config_is_one_line_exit_2(recorded, tmp_path, capsys, make, code, words):
    bag_dir, _ = recorded
    cfg = make(tmp_path)
    got, out = _run_cli([str(bag_dir), '--resimulate', str(cfg)], capsys)
    assert words in _one_line_error(out, got, code)


def test_bad_bag_is_one_line_exit_1(tmp_path, capsys):
    got, out = _run_cli([str(tmp_path / 'nope'), '--resimulate'], capsys)
    assert 'no such file' in _one_line_error(out, got, EXIT_ERROR)
    (tmp_path / 'notabag').mkdir()
    got, out = _run_cli([str(tmp_path / 'notabag'), '--resimulate'], capsys)
    assert 'not a rosbag2 bag' in _one_line_error(out, got, EXIT_ERROR)


def test_bag_without_commands_is_refused(recorded, tmp_path):
    """A bag missing a topic the comparison needs: MissingTopicsError naming it."""
    bag_dir, _ = recorded
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    out = tmp_path / 'no_commands'
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag_dir) as reader, \
            Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for c in reader.connections:
            if c.topic != '/gripper/loop/motor_command':
                conns[c.id] = writer.add_connection(c.topic, c.msgtype, typestore=store,
                                                    msgdef=c.msgdef.data, rihs01=c.digest)
        for c, t, data in reader.messages():
            if c.id in conns:
                writer.write(conns[c.id], t, data)
    with pytest.raises(MissingTopicsError) as exc_info:
        resimulate_bag(out, CONFIG)
    assert '/gripper/loop/motor_command' in str(exc_info.value)
    assert '\n' not in str(exc_info.value)


@pytest.mark.parametrize('argv, words', [
    (['--resimulate', '--approach-force-margin', 'nan'], 'approach-force-margin'),
    (['--resimulate', '--approach-force-margin', '-1'], 'approach-force-margin'),
    (['--json'], '--json only applies to --resimulate'),
])
def test_bad_options_are_one_line_exit_1(recorded, capsys, argv, words):
    bag_dir, _ = recorded
    got, out = _run_cli([str(bag_dir)] + argv, capsys)
    assert words in _one_line_error(out, got, EXIT_ERROR)


def test_truncated_bag_is_resimulated_up_to_the_damage_exit_3(recorded, tmp_path, capsys):
    bag_dir, _ = recorded
    cut = tmp_path / 'cut'
    cut.mkdir()
    mcap = next(Path(bag_dir).glob('*.mcap'))
    data = mcap.read_bytes()
    (cut / mcap.name).write_bytes(data[:len(data) // 2])   # no footer, no metadata.yaml
    recovered = read_bag(cut).message_count
    got, out = _run_cli([str(cut), '--resimulate'], capsys)
    assert got == EXIT_TRUNCATED
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and f'truncated: {recovered} complete messages recovered' in lines[0]
    assert 'TRUNCATED' in out.out
    # what was recovered still matches the recording bit for bit
    report = resimulate_bag(cut, CONFIG)
    assert report.truncated and report.identical
    assert 0 < sum(s.compared for s in report.stages.values())


def test_resimulate_hook_in_bag_replay_returns_the_report(recorded):
    bag_dir, _ = recorded
    report = bag_replay.resimulate(read_bag(bag_dir), str(default_config_path()))
    assert report.identical
    with pytest.raises(ConfigError):
        bag_replay.resimulate(read_bag(bag_dir), '/nonexistent/gripper.yaml')
