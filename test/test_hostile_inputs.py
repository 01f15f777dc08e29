"""Hostile input without a running graph: config files, namespaces, claims and bag_replay.

Each case is one a user met, where a lax check would accept it and break something later, or
end in a traceback. Known answer: a refusal in one line that names the field, and no change.
"""
from __future__ import annotations

from pathlib import Path
import shutil
import subprocess
import sys

from gripper_ros.bags import replay as bag_replay
from gripper_ros.bags.reader import EXIT_ERROR, NotABagError, read_bag
from gripper_ros.core.config import (bounds_text, ConfigError, default_config_path, load_config,
                                     MAX_HORIZON, parse_config)
from gripper_ros.nodes.names import claim_folder
from gripper_ros.wire import check_namespace, MAX_NAMESPACE_LENGTH
from helpers import run_main
import pytest
import yaml

SHIPPED = default_config_path()
BAG = Path(__file__).resolve().parent / 'data' / 'python_core_bags' / 'rigid_w50mm_m1.69kg'


def _shipped() -> dict:
    return yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))


def _with(dotted: str, value) -> dict:
    data = _shipped()
    *parents, leaf = dotted.split('.')
    section = data
    for p in parents:
        section = section[p]
    section[leaf] = value
    return data


# ---------------------------------------------------------------- items 3 and 4: values
@pytest.mark.parametrize('dotted, value, words', [
    ('position_control.mpc_pd.control_horizon', 1000, 'must be <= "position_control.mpc_pd.'
                                                      'horizon" (700)'),
    ('force_control.mpc_pi.control_horizon', 101, 'must be <= "force_control.mpc_pi.horizon"'),
    ('position_control.mpc_pd.horizon', 10_000_000, f'in [1, {MAX_HORIZON}]'),
    ('force_control.sample_time_s', 1e-8, '"force_control.sample_time_s" must be in [5e-05'),
    ('position_control.mpc_pd.kc', 1e308, '"position_control.mpc_pd.kc" must be in [0, 1e+06]'),
    ('supervisor.timeout_s', 1e12, '"supervisor.timeout_s" must be in'),
])
def test_values_the_controllers_cannot_take_are_refused_naming_the_key(dotted, value, words):
    with pytest.raises(ConfigError) as err:
        parse_config(_with(dotted, value))
    assert words in str(err.value)


def test_the_shipped_values_lie_within_their_bounds_and_the_file_lists_them():
    load_config(SHIPPED)
    assert SHIPPED.read_text(encoding='utf-8').endswith('\n' + bounds_text())


# ---------------------------------------------------------------- item 11: config files
def test_a_typo_in_a_key_is_refused_naming_the_closest_known_one():
    data = _shipped()
    data['plant']['gear_ratoi'] = data['plant'].pop('gear_ratio')
    with pytest.raises(ConfigError, match='unknown key "plant.gear_ratoi"; did you mean '
                                          '"plant.gear_ratio"'):
        parse_config(data)


def test_an_unknown_section_is_refused():
    with pytest.raises(ConfigError, match='unknown key "supervsior"; did you mean "supervisor"'):
        parse_config({**_shipped(), 'supervsior': {}})


def test_a_float_yaml_reads_as_text_gets_the_yaml_hint(tmp_path):
    path = tmp_path / 'c.yaml'
    path.write_text(SHIPPED.read_text(encoding='utf-8').replace(
        'inductance_h: 0.238e-3', 'inductance_h: 2e-4'), encoding='utf-8')
    with pytest.raises(ConfigError, match=r'"plant.inductance_h" must be a number, got the text '
                                          r"'2e-4'.*write 1.0e-3"):
        load_config(path)


def test_a_binary_file_is_refused_in_one_line(tmp_path):
    path = tmp_path / 'c.yaml'
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ConfigError, match='is not UTF-8 text'):
        load_config(path)


def test_a_deeply_nested_file_is_refused_in_one_line(tmp_path):
    path = tmp_path / 'c.yaml'
    path.write_text('[' * 100_000 + ']' * 100_000, encoding='utf-8')
    with pytest.raises(ConfigError, match='nested too deeply'):
        load_config(path)


# ---------------------------------------------------------------- item 12: namespaces
@pytest.mark.parametrize('namespace', ['ü', 'ａｂ', 'left/rüght', 'a' * 200, 'a' * 300,
                                       'a' * (MAX_NAMESPACE_LENGTH + 1)])
def test_namespaces_rcl_would_refuse_are_refused_in_one_line(namespace):
    with pytest.raises(ValueError) as err:
        check_namespace(namespace)
    assert '\n' not in str(err.value)


def test_a_namespace_of_the_longest_length_passes():
    assert check_namespace('/' + 'a' * MAX_NAMESPACE_LENGTH) == 'a' * MAX_NAMESPACE_LENGTH


# ---------------------------------------------------------------- item 8: claims
def test_claim_folders_of_different_namespaces_differ():
    folders = {ns: claim_folder(7, ns) for ns in ('a/b', 'a_b', 'a', '', 'a/b/c', 'a_b_c')}
    assert len(set(folders.values())) == len(folders)
    assert all(len(part) < 256 for part in claim_folder(7, 'a' * MAX_NAMESPACE_LENGTH).parts)


# ---------------------------------------------------------------- item 13: bag_replay
@pytest.mark.parametrize('argv, words', [
    (['--start-offset', '1e300'], '--start-offset must be <='),
    (['-r', '1e-300'], '--rate must be in'),
    (['-r', '1e300'], '--rate must be in'),
    (['--delay', '1e300'], '--delay must be <='),
    (['--remap', '/gripper/loop/tick:=bad//name'], "'bad//name' is not a topic name"),
])
def test_bag_replay_refuses_absurd_options_in_one_line(argv, words, capsys):
    code, captured = run_main(bag_replay.main, [str(BAG), '--quiet', *argv], capsys)
    assert code == EXIT_ERROR
    assert words in captured.err and len(captured.err.strip().splitlines()) == 1, captured.err


def test_a_bag_whose_metadata_points_outside_its_folder_is_refused(tmp_path, capsys):
    bag = tmp_path / 'bag'
    shutil.copytree(BAG, bag)
    outside = tmp_path / 'secret.mcap'
    mcap = next(bag.glob('*.mcap'))
    shutil.copy(mcap, outside)
    meta = bag / 'metadata.yaml'
    meta.write_text(meta.read_text(encoding='utf-8').replace(
        f'- {mcap.name}', '- ../secret.mcap'), encoding='utf-8')
    with pytest.raises(NotABagError, match='outside the bag folder'):
        read_bag(bag)
    code, captured = run_main(bag_replay.main, [str(bag), '--quiet'], capsys)
    assert code == EXIT_ERROR and 'outside the bag folder' in captured.err


# ---------------------------------------------------------------- item 10: grasp_demo --output
@pytest.mark.parametrize('make, words', [
    (lambda tmp: tmp / 'a_file', 'not a folder'),
    (lambda tmp: tmp / 'a_file' / 'sub', 'cannot make the folder'),
    (lambda tmp: Path('/proc/x'), 'cannot make the folder'),
])
def test_grasp_demo_refuses_an_output_it_cannot_write_in_one_line(tmp_path, make, words,
                                                                  capsys):
    from gripper_ros.apps import grasp_demo
    (tmp_path / 'a_file').write_text('x', encoding='utf-8')
    output = make(tmp_path)
    code, captured = run_main(grasp_demo.main, ['--width', '0.05', '--mass', '1.0', '--output',
                                                str(output), '--no-plot'], capsys)
    assert code == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('grasp_demo: --output') and words in lines[0], \
        captured.err


@pytest.mark.parametrize('content', [None, b'\x00\xff garbage: ['])
def test_grasp_demo_refuses_a_bad_params_file_in_one_line(tmp_path, content, capsys):
    from gripper_ros.apps import grasp_demo
    path = tmp_path / 'params.yaml'
    if content is not None:
        path.write_bytes(content)
    code, captured = run_main(grasp_demo.main, ['--no-record', '--no-plot', '--ros-args',
                                                '--params-file', str(path)], capsys)
    assert code == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('grasp_demo: bad --ros-args'), captured.err


@pytest.mark.parametrize('record', [True, False], ids=['recorded', 'no_record'])
def test_grasp_demo_says_refused_for_a_width_in_mm(tmp_path, record):
    """Say REFUSED in grasp_demo's table for --width 50 (mm for m).

    The reason is below it, and the demo ends 1 without a traceback, its bag of no grasp left
    out of the analysis.
    """
    argv = ['--width', '50', '--mass', '1', '--no-plot']
    argv += ['--output', str(tmp_path)] if record else ['--no-record']
    result = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', *argv],
                            capture_output=True, text=True, timeout=120,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 1, result.stdout + result.stderr
    assert 'Traceback' not in result.stderr, result.stderr
    row = next(line for line in result.stdout.splitlines() if line.startswith('  50.000'))
    assert row.split()[2] == 'REFUSED', row
    assert 'refused: width_m must be in (0, 0.15) m' in result.stdout


def test_grasp_demo_without_bags_says_which_columns_need_them():
    """--no-record leaves the bag's columns blank and says so, naming them, instead of a figure."""
    result = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--no-record',
                             '--width', '0.05', '--mass', '1.69', '--namespace', 'no_record'],
                            capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    header = next(line for line in lines if line.split()[:2] == ['width', 'm'])
    row = next(line for line in lines if line.split()[:3] == ['0.050', '1.690', 'HOLDING'])
    assert row[header.index('contact s'):header.index('switch s')].strip() == ''
    assert lines[-1] == ('--no-record: contact s, criterion, peak N, peak/F_sp and max|V| come '
                         'from the bags, as does the figure: left out')
    assert not any(line.startswith(('bag:', 'figure:')) for line in lines)
