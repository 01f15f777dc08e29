"""config/gripper.yaml: the shipped file is the paper's Tables I and II.

Bad files are refused with a ConfigError that names the offending key, and nothing is
half-loaded.
"""
import copy
import dataclasses
import enum
import math
from pathlib import Path
import re

from gripper_ros.core.config import (ADDED_LATER, ConfigError, ForceLaw, load_config,
                                     parse_config, PidGains, read_as_notes,
                                     SHIPPED as SHIPPED_VALUE)
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / 'config' / 'gripper.yaml'


@pytest.fixture(scope='module')
def shipped_data():
    return yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))


def write(tmp_path, data, name='bad.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def set_key(data, dotted, value):
    d = copy.deepcopy(data)
    *parents, leaf = dotted.split('.')
    node = d
    for p in parents:
        node = node[p]
    if value is DELETE:
        del node[leaf]
    else:
        node[leaf] = value
    return d


DELETE = object()


# ------------------------------------------------------------------ the shipped file
def test_shipped_table_one_gives_the_force_the_readme_quotes():
    """Table I's one home is the shipped file: eq. 13 at stall and 24 V gives the force quoted.

    F = k_t V / (eta p N R_a) (N2/N1 = 1 / gear ratio); docs/USING.md refuses a grasp beyond it.
    """
    p = load_config(SHIPPED).plant
    stall_n = p.torque_constant_n_m_per_a * p.voltage_limit_v / (
        p.efficiency * p.pitch_m * p.gear_ratio * p.resistance_ohm)
    quoted = re.search(r'beyond what 24 V can hold \((\d+\.\d+) N\)',
                       ' '.join((REPO / 'docs' / 'USING.md').read_text(encoding='utf-8').split()))
    assert f'{stall_n:.2f}' == quoted.group(1)
    assert p.max_force_n == pytest.approx(stall_n, rel=1e-12)


def test_shipped_file_is_table_two():
    cfg = load_config(SHIPPED)
    pos, frc = cfg.position, cfg.force
    assert pos.sample_time_s == 0.01
    assert pos.pd == PidGains(kc=968.0, kd=364.0)
    assert pos.pid == PidGains(kc=653.0, ki=148.0, kd=640.0)
    assert pos.mpc_pd == PidGains(kc=968.0, kd=364.0)
    assert (pos.mpc_pd_dmc.horizon, pos.mpc_pd_dmc.control_horizon,
            pos.mpc_pd_dmc.move_suppression) == (700, 10, 1.001)
    assert isinstance(pos.mpc_pd_dmc.horizon, int)
    assert frc.paper_sample_time_s == 0.0001
    assert frc.pi_paper == PidGains(kc=1.0291, ki=18183.0)
    assert (frc.mpc_pi_paper_dmc.horizon, frc.mpc_pi_paper_dmc.control_horizon,
            frc.mpc_pi_paper_dmc.move_suppression) == (100, 10, 1.005)
    assert 0.0 <= frc.closed_loop_pole < 1.0


def test_shipped_force_law_and_pad_friction(tmp_path, shipped_data):
    cfg = load_config(SHIPPED)
    assert (cfg.supervisor.force_law, cfg.supervisor.grip_safety_factor) == \
        (ForceLaw.FRICTION, 1.5)
    assert 0.0 < cfg.contact.kinetic_friction <= cfg.contact.static_friction
    paper = load_config(write(tmp_path, set_key(shipped_data, 'supervisor.force_law', 'paper')))
    assert paper.supervisor.force_law is ForceLaw.PAPER


def test_derived_plant_constants():
    p = load_config(SHIPPED).plant
    assert p.force_lever_m == pytest.approx(0.2 * 0.0075 * 4.4, rel=1e-15)
    assert p.travel_per_rad_m == pytest.approx(0.0075 / (2 * math.pi), rel=1e-15)
    assert p.stall_force_per_volt_n == pytest.approx(1.391, abs=5e-4)
    assert p.max_force_n == pytest.approx(33.39, abs=0.01)


def test_default_path_loads_the_shipped_file(monkeypatch):
    monkeypatch.delenv('GRIPPER_ROS_CONFIG', raising=False)
    assert dataclasses.replace(load_config(), source='') == \
        dataclasses.replace(load_config(SHIPPED), source='')


def test_environment_variable_selects_the_file(monkeypatch, tmp_path, shipped_data):
    path = write(tmp_path, set_key(shipped_data, 'plant.resistance_ohm', 3.0), 'env.yaml')
    monkeypatch.setenv('GRIPPER_ROS_CONFIG', str(path))
    cfg = load_config()
    assert cfg.plant.resistance_ohm == 3.0 and cfg.source == str(path)


# ------------------------------------------------------------------ bad files
@pytest.mark.parametrize('key, value, words', [
    ('plant.resistance_ohm', DELETE, 'missing'),
    ('plant.inductance_h', 'abc', 'number'),
    ('plant.inductance_h', '0.2', 'number'),                # a string, even if numeric
    ('plant.pitch_m', True, 'number'),
    ('plant.pitch_m', None, 'number'),
    ('plant.pitch_m', [0.0075], 'number'),
    ('plant.efficiency', float('nan'), 'finite'),
    ('plant.gear_ratio', float('inf'), 'finite'),
    ('plant.inertia_kg_m2', -0.0043, '> 0'),
    ('plant.resistance_ohm', 0.0, '> 0'),
    ('contact.stiffness_n_per_m', -1.0, '>= 0'),
    ('force_sensor.activation_force_n', -0.2, '> 0'),
    ('position_control.pd.kc', -968.0, '>= 0'),
    ('position_control.pid.ki', 'fast', 'number'),
    ('position_control.mpc_pd.horizon', 700.5, 'whole'),
    ('position_control.mpc_pd.control_horizon', 0, '> 0'),
    ('position_control.sample_time_s', DELETE, 'missing'),
    ('force_control.pi_paper.kc', DELETE, 'missing'),
    ('force_control.mpc_pi.move_suppression', float('nan'), 'finite'),
    ('force_control.closed_loop_pole', 1.0, '[0, 1)'),
    ('supervisor.timeout_s', -20.0, '> 0'),
    ('supervisor.force_law', 'magic', "one of 'friction', 'paper'"),
    ('supervisor.force_law', 1.0, "one of 'friction', 'paper'"),
    ('supervisor.force_law', None, 'one of'),
    ('supervisor.grip_safety_factor', 0.9, '[1, 10] (a grip that knowingly'),
    ('supervisor.grip_safety_factor', float('nan'), 'finite'),
    ('contact.static_friction', -0.5, '> 0'),
    ('contact.kinetic_friction', 0.6, '<= "contact.static_friction"'),
    ('contact.pad_length_m', 0.0, '> 0'),
])
def test_bad_value_raises_config_error_naming_the_key(tmp_path, shipped_data, key, value, words):
    path = write(tmp_path, set_key(shipped_data, key, value))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert key in message and words in message
    assert '\n' not in message


@pytest.mark.parametrize('section', ['plant', 'contact', 'force_sensor', 'position_control',
                                     'force_control', 'supervisor'])
def test_missing_section_is_named(tmp_path, shipped_data, section):
    path = write(tmp_path, set_key(shipped_data, section, DELETE))
    with pytest.raises(ConfigError, match=section):
        load_config(path)


def test_yaml_nan_literal_is_refused(tmp_path):
    text = SHIPPED.read_text(encoding='utf-8').replace(
        'resistance_ohm: 2.32', 'resistance_ohm: .nan')
    assert '.nan' in text
    path = tmp_path / 'nan.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError, match=r'plant\.resistance_ohm.*finite'):
        load_config(path)


@pytest.mark.parametrize('text', [
    'plant: [1, 2\n',                                    # unclosed flow sequence
    'plant:\n  inertia_kg_m2: 0.0043\n   gear_ratio: 4.4\n  : x\n',   # bad indentation
    'plant: !!python/object:os.system {}\n',            # tag safe_load refuses
    'plant: {a: 1}\n\t- b\n',                            # tab indentation
])
def test_unknown_yaml_syntax_raises_config_error_naming_the_file(tmp_path, text):
    path = tmp_path / 'broken.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(path) in str(info.value) and 'not valid YAML' in str(info.value)


@pytest.mark.parametrize('text', ['', '- 1\n- 2\n', '42\n'])
def test_top_level_not_a_mapping(tmp_path, text):
    path = tmp_path / 'flat.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError, match='mapping'):
        load_config(path)


def test_missing_file_raises_config_error_naming_it(tmp_path):
    missing = tmp_path / 'nope.yaml'
    with pytest.raises(ConfigError, match='nope.yaml'):
        load_config(missing)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


# ------------------------------------------------------------------ nothing partially applied
def test_failed_load_applies_nothing(tmp_path, shipped_data):
    good = load_config(SHIPPED)
    snapshot = copy.deepcopy(good)
    # the bad value sits in the LAST section read: earlier sections must not leak out anywhere
    bad = set_key(shipped_data, 'supervisor.timeout_s', 'never')
    bad['plant']['resistance_ohm'] = 99.0
    with pytest.raises(ConfigError, match='supervisor.timeout_s'):
        load_config(write(tmp_path, bad))
    assert good == snapshot
    assert load_config(SHIPPED) == snapshot
    with pytest.raises(dataclasses.FrozenInstanceError):
        good.plant.resistance_ohm = 99.0


def test_parse_config_does_not_mutate_its_input(shipped_data):
    data = copy.deepcopy(shipped_data)
    parse_config(data)
    assert data == shipped_data
    bad = set_key(shipped_data, 'plant.gear_ratio', -1.0)
    before = copy.deepcopy(bad)
    with pytest.raises(ConfigError):
        parse_config(bad)
    assert bad == before


def test_optional_gains_default_to_zero(tmp_path, shipped_data):
    data = set_key(shipped_data, 'position_control.pd.kd', DELETE)
    assert load_config(write(tmp_path, data)).position.pd == PidGains(kc=968.0, ki=0.0, kd=0.0)


def test_a_servo_lead_of_zero_is_read_as_no_lead(tmp_path, shipped_data):
    """The file says ``0 = none`` for supervisor.servo_lead_s: the reader takes 0."""
    data = set_key(shipped_data, 'supervisor.servo_lead_s', 0.0)
    assert load_config(write(tmp_path, data)).supervisor.servo_lead_s == 0.0
    with pytest.raises(ConfigError, match='servo_lead_s'):
        load_config(write(tmp_path, set_key(shipped_data, 'supervisor.servo_lead_s', -0.1)))


# ------------------------------------------------------------------ every key of the shipped file
def _leaves(data, prefix=''):
    """Dotted paths of every numeric leaf of the YAML mapping."""
    for key, value in data.items():
        path = f'{prefix}{key}'
        if isinstance(value, dict):
            yield from _leaves(value, path + '.')
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            yield path


SHIPPED_KEYS = list(_leaves(yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))))


def test_the_shipped_file_has_numeric_keys():
    assert len(SHIPPED_KEYS) > 40 and 'plant.resistance_ohm' in SHIPPED_KEYS


@pytest.mark.parametrize('value, words', [
    ('abc', 'number'), ('1.0', 'number'), (None, 'number'), (True, 'number'), ([1.0], 'number'),
    ({'a': 1}, 'number'), (float('nan'), 'finite'), (float('inf'), 'finite'),
    (float('-inf'), 'finite'), (-1.0, '>= 0')],
    ids=['string', 'numeric_string', 'null', 'bool', 'list', 'mapping', 'nan', '+inf', '-inf',
         'negative'])
def test_every_key_of_the_shipped_file_refuses_a_bad_value_naming_it(shipped_data, value, words):
    """Wrong type, non-finite or negative, in ANY key: a ConfigError that names that key.

    A key the loader ignored would load silently and fail here.
    """
    unchecked = []
    for key in SHIPPED_KEYS:
        try:
            parse_config(set_key(shipped_data, key, value), 'shipped')
        except ConfigError as exc:
            message = str(exc)
            assert key in message, (key, message)
            if words == '>= 0':     # positive keys say '> 0', non-negative ones '>= 0'
                assert '> 0' in message or '>= 0' in message or '[0, 1)' in message, message
            else:
                assert words in message, (key, message)
            continue
        unchecked.append(key)
    assert not unchecked, f'accepted {value!r} in {unchecked}'


SECTIONS = {'position_control': 'position', 'force_control': 'force'}
"""File sections whose attribute of GripperConfig has another name (the rest: the same)."""


def _carried(config, dotted):
    """Return what ``config`` carries for the file's key ``dotted`` (an enum as its value)."""
    section, *parts = dotted.split('.')
    obj = getattr(config, SECTIONS.get(section, section))
    for i, part in enumerate(parts):
        if not hasattr(obj, part) or (i + 1 < len(parts)
                                      and not hasattr(getattr(obj, part), parts[i + 1])):
            part += '_dmc'                  # mpc_pd: {kc, kd} gains, {horizon, ...} the DMC's
        obj = getattr(obj, part)
    return obj.value if isinstance(obj, enum.Enum) else obj


def _value_at(data, dotted):
    for part in dotted.split('.'):
        data = data[part]
    return data


def _every_leaf(data, prefix=''):
    for key, value in data.items():
        if isinstance(value, dict):
            yield from _every_leaf(value, f'{prefix}{key}.')
        else:
            yield f'{prefix}{key}'


def test_every_key_of_the_shipped_file_is_what_the_loaded_config_carries(shipped_data):
    config = load_config(SHIPPED)
    keys = list(_every_leaf(shipped_data))
    assert 'supervisor.force_law' in keys and len(keys) == len(SHIPPED_KEYS) + 1
    for key in keys:
        value = _value_at(shipped_data, key)
        assert _carried(config, key) == value, (key, _carried(config, key), value)


def test_the_file_is_the_one_home_of_the_values():
    """No dataclass repeats a value of the file; only a law's missing gain (ki, kd) is 0."""
    import gripper_ros.core.config as config_module
    defaults = {(cls.__name__, f.name) for cls in vars(config_module).values()
                if dataclasses.is_dataclass(cls) and isinstance(cls, type)
                for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}
    assert defaults == {('PidGains', 'ki'), ('PidGains', 'kd')}


def test_every_required_key_of_the_shipped_file_is_named_when_missing(shipped_data):
    """A key left out is refused naming it, or means what ADDED_LATER says (an old file)."""
    optional = set()
    for key in SHIPPED_KEYS:
        try:
            config = parse_config(set_key(shipped_data, key, DELETE), 'shipped')
        except ConfigError as exc:
            assert key in str(exc) and 'missing' in str(exc), (key, str(exc))
            continue
        optional.add(key)
        meaning = ADDED_LATER.get(key, ADDED_LATER.get(key.split('.')[0], 'required'))
        if key.rsplit('.', 1)[1] in ('ki', 'kd'):
            meaning = 0.0
        assert meaning != 'required', f'{key} may be left out but ADDED_LATER has no meaning'
        expected = _value_at(shipped_data, key) if meaning is SHIPPED_VALUE else meaning
        assert _carried(config, key) == expected, key
    sections = {k for k in ADDED_LATER if '.' not in k}
    assert optional == {k for k in SHIPPED_KEYS if k in ADDED_LATER or k.split('.')[0] in
                        sections or k.rsplit('.', 1)[1] in ('ki', 'kd')}


def test_a_file_that_predates_the_pads_and_the_chain_has_them_off(shipped_data):
    data = copy.deepcopy(shipped_data)
    for key in ('pad_tangential_stiffness_n_per_m', 'finger_stiffness_n_per_m'):
        del data['contact'][key]
    del data['supervisor']['position_switch_speed_mps']
    del data['sensor_noise']
    config = parse_config(data, 'old')
    assert config.contact.pad_tangential_stiffness_n_per_m == 0.0 == \
        config.contact.finger_stiffness_n_per_m
    assert config.supervisor.position_switch_speed_mps == 0.0
    assert not config.sensor_noise.enabled
    assert load_config(SHIPPED).contact.pad_tangential_stiffness_n_per_m == 6.0e4


def test_a_default_move_speed_above_the_free_speed_is_read_as_the_free_speed(
        tmp_path, shipped_data):
    """A plant slower than the default move speed loads; the note says what the file means."""
    data = set_key(shipped_data, 'plant.damping_n_m_s_per_rad', 0.0038 * 3.0)
    config = load_config(write(tmp_path, data))
    p = config.plant
    free = p.torque_constant_n_m_per_a * p.pitch_m / (2.0 * math.pi) / (
        p.damping_n_m_s_per_rad * p.resistance_ohm
        + p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad) * p.voltage_limit_v
    assert free < 0.05 == config.data['supervisor']['move_default_speed_mps']
    assert config.supervisor.move_default_speed_mps == pytest.approx(free, rel=1e-12)
    [note] = read_as_notes(config)
    assert 'move_default_speed_mps 0.05' in note and f'{free:.6g}' in note
    assert read_as_notes(load_config(SHIPPED)) == []
    assert load_config(SHIPPED).supervisor.move_default_speed_mps == 0.05


@pytest.mark.parametrize('key, value, words', [
    ('plant.resistance_ohm', -2.32, '> 0'),            # negative resistance
    ('plant.voltage_limit_v', -24.0, '> 0'),
    ('force_control.closed_loop_pole', -0.1, '>= 0'),
    ('force_control.closed_loop_pole', 1.5, '[0, 1)'),   # out of range: an unstable loop
    ('position_control.mpc_pd_braking_voltage_v', 30.0, 'plant.voltage_limit_v'),
    ('position_control.mpc_pd.horizon', '700', 'number'),
    ('force_control.mpc_pi.control_horizon', 2.5, 'whole'),
    ('supervisor.move_stall_force_fraction', 1.2, '(0, 1]'),   # a force never reached
    ('supervisor.move_default_speed_mps', 0.0004, 'move_rest_speed_mps'),   # "at rest"
    ('position_control.speed_limit_pole', 0.995, 'open-loop pole'),  # never reaches the limit
])
def test_more_bad_values_are_refused_naming_the_key(tmp_path, shipped_data, key, value, words):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, set_key(shipped_data, key, value)))
    assert key in str(info.value) and words in str(info.value)


# ------------------------------------------------------------------ the schema
def _fields_under(cls):
    """Yield ``(class, field)`` of every field of ``cls`` and of the dataclasses it holds."""
    import typing
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        yield cls, f
        if dataclasses.is_dataclass(hints[f.name]):
            yield from _fields_under(hints[f.name])


def _incomplete(schema, shipped):
    """Return what the declarations of ``schema`` lack: '' when each key is whole."""
    from gripper_ros.core.config import NONNEGATIVE, POSITIVE, unit_of, UNITS
    lacks = []
    for dotted, spec in schema.items():
        if not spec.doc or '\n' in spec.description:
            lacks.append(f'{dotted}: no one-line meaning')
        if spec.choices is not None:
            if spec.bounds is not None or not spec.choices(_value_at(shipped, dotted)):
                lacks.append(f'{dotted}: a choice with bounds, or the shipped value not one')
            continue
        if spec.bounds is None or not spec.bounds[0] < spec.bounds[1]:
            lacks.append(f'{dotted}: no bounds')
        elif dotted in set(_every_leaf(shipped)) and not spec.holds(_value_at(shipped, dotted)):
            lacks.append(f'{dotted}: the shipped value lies outside its bounds')
        if spec.rule not in (POSITIVE, NONNEGATIVE):
            lacks.append(f'{dotted}: no rule')
        if spec.unit != unit_of(dotted.rsplit('.', 1)[1]) or \
                spec.unit not in ('', *UNITS.values()):
            lacks.append(f'{dotted}: a unit other than its name says')
    return '; '.join(lacks)


def test_every_key_is_declared_with_a_meaning_bounds_a_rule_and_a_unit(shipped_data):
    """Each field of the config's dataclasses is declared as a key (or a part) once, completely.

    A field added without its meaning or bounds fails here: it would be read unchecked and
    offered to ROS without a range or a description.
    """
    from gripper_ros.core.config import BOUNDS, GripperConfig, SCHEMA
    declared = [(cls, f) for cls, f in _fields_under(GripperConfig)
                if f.name not in ('source', 'data')]
    assert all('key' in f.metadata or 'part' in f.metadata for _, f in declared), \
        [f'{cls.__name__}.{f.name}' for cls, f in declared if not f.metadata]
    assert set(SCHEMA) >= set(_every_leaf(shipped_data))
    assert _incomplete(SCHEMA, shipped_data) == ''
    assert BOUNDS == {k: spec.bounds for k, spec in SCHEMA.items() if spec.choices is None}
    assert SCHEMA['supervisor.hold_watch_s'].unit == 's' and \
        SCHEMA['plant.torque_constant_n_m_per_a'].unit == 'N m/A'


def test_a_key_declared_without_bounds_or_a_meaning_is_caught(shipped_data):
    """The completeness check has teeth: each missing part of a declaration is named."""
    from gripper_ros.core.config import key, SCHEMA
    hold = 'supervisor.hold_watch_s'
    for bad, words in ((key('a watch'), 'no bounds'), (key('', bounds=(0.0, 1.0)), 'meaning'),
                       (key('a watch', bounds=(0.0, 1e-3)), 'outside its bounds'),
                       (key('a watch', bounds=(0.0, 1.0), unit='ms'), 'unit')):
        spec = bad.metadata['key']
        spec = spec if spec.unit is not None else spec._replace(unit='s')
        assert words in _incomplete({**SCHEMA, hold: spec}, shipped_data)


def test_the_supervisor_kernel_reads_the_numbers_its_dataclass_declares():
    from gripper_ros.core.config import numbers_of, SupervisorParams
    from gripper_ros.core.supervision.machine import PARAMS_DTYPE
    assert set(PARAMS_DTYPE.names) == set(numbers_of(SupervisorParams))
    assert 'force_law' not in PARAMS_DTYPE.names and 'hold_watch_s' in PARAMS_DTYPE.names
