"""tune on a small budget: a study that resumes, a result a node loads, constraints kept hard.

The envelope is two rigid objects (5 mm and 140 mm, 0.1 kg) and the searched key the contact
stage's impact_force_fraction over 0.3-0.95: a larger fraction meets the object faster and,
above about 0.75 on the 5 mm object, harder than 1.10 x F_sp. So the trial with the smallest
median time breaks the spike constraint, and tune must report the best trial that keeps it.
"""
from __future__ import annotations

import signal

from gripper_ros.apps import tune
from gripper_ros.core.config import load_config
from gripper_ros.wire import NODE_FORCE_CONTROLLER
import matplotlib.image
import numpy as np
import optuna
import pytest
from rcl_interfaces.srv import GetParameters
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from test_node_executables import _start, _wait_until_running, Case
import yaml

KEY = 'force_control.contact_aware.impact_force_fraction'
ENVELOPE = [{'width_m': 0.005, 'mass_kg': 0.1}, {'width_m': 0.14, 'mass_kg': 0.1}]
FEASIBLE, BROKE, LIMIT = (0.122, 0.467, 0.706), (1.0, 0.498, 0.055), (1.0, 0.0, 0.0)
"""The plots' colours: feasible trials (matplotlib's C0), broken ones (C1), the peak limit."""
SHIPPED = load_config().data['force_control']['contact_aware']['impact_force_fraction']


def _args(out, trials: int, *extra) -> list[str]:
    return ['--param', f'{KEY}=0.3:0.95', '--envelope', str(out / 'objects.yaml'),
            '--trials', str(trials), '--jobs', '1', '--hold-s', '0.2', '--holdout', 'tablev',
            '--quiet', '--output', str(out), *extra]


@pytest.fixture(scope='module')
def study_dir(tmp_path_factory):
    """Run 3 trials, stop, then resume the same study to 8 trials."""
    out = tmp_path_factory.mktemp('tune')
    (out / 'objects.yaml').write_text(yaml.safe_dump(ENVELOPE), encoding='utf-8')
    assert tune.main(_args(out, 3)) == 0
    first = _trials(out)
    assert tune.main(_args(out, 8)) == 0
    return out, first


def _trials(out) -> list:
    study = optuna.load_study(study_name=tune.DEFAULT_STUDY,
                              storage=f'sqlite:///{out / "study.db"}')
    return [(t.number, t.params, t.values, t.user_attrs) for t in study.trials]


def test_the_study_resumes_from_its_sqlite_file(study_dir):
    out, first = study_dir
    trials = _trials(out)
    assert len(first) == 3 and len(trials) == 8
    assert trials[:3] == first                         # the first run's trials are kept
    assert trials[0][1] == {KEY: SHIPPED}              # a new study starts from the shipped one
    assert len({t[1][KEY] for t in trials}) == 8       # the resumed sampler did not repeat them


def test_a_constraint_violation_is_never_reported_as_best(study_dir):
    out, _ = study_dir
    trials = _trials(out)
    broke = [t for t in trials if t[3]['worst_peak_ratio'] > tune.DEFAULT_MAX_PEAK_RATIO]
    kept = [t for t in trials if t[3]['worst_peak_ratio'] <= tune.DEFAULT_MAX_PEAK_RATIO]
    best = min(kept, key=lambda t: t[2][0])
    assert broke and min(t[2][0] for t in broke) < best[2][0]   # a faster trial that spikes
    params = yaml.safe_load((out / 'params.yaml').read_text(encoding='utf-8'))
    assert params == {'/**': {'ros__parameters': {KEY: best[1][KEY]}}}
    config = load_config(out / 'config.yaml')                    # loads as --config
    assert config.force.contact_aware.impact_force_fraction == best[1][KEY]
    report = (out / 'trials.txt').read_text(encoding='utf-8')
    assert f'{len(broke)} broke a constraint' in report and 'held-out check' in report
    for name, colours in (('history.png', (FEASIBLE, BROKE)),
                          ('pareto.png', (FEASIBLE, BROKE, LIMIT))):
        image = matplotlib.image.imread(out / name)[:, :, :3]
        assert image.shape[:2] == (450, 700), name          # 7 x 4.5 in at 100 dpi
        for colour in colours:                              # the markers and the limit line
            assert np.any(np.all(np.abs(image - colour) < 0.02, axis=-1)), (name, colour)


def test_the_params_file_loads_into_a_real_node(study_dir):
    out, _ = study_dir
    case = Case(NODE_FORCE_CONTROLLER, 'tune_params',
                ['--params-file', str(out / 'params.yaml')], stop=signal.SIGINT)
    _start(case)
    try:
        _wait_until_running([case])
        assert case.answered, case.proc.stderr.read()[-2000:]
        value = _get_parameter(f'/{case.namespace}/{case.node}', KEY)
    finally:
        case.proc.send_signal(signal.SIGINT)
        case.proc.communicate(timeout=60)
    tuned = yaml.safe_load((out / 'params.yaml').read_text(encoding='utf-8'))
    assert value == tuned['/**']['ros__parameters'][KEY] != SHIPPED


def _get_parameter(node: str, name: str) -> float:
    context = Context()
    rclpy.init(context=context)
    try:
        probe = rclpy.create_node('tune_probe', context=context, start_parameter_services=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(probe)
        client = probe.create_client(GetParameters, f'{node}/get_parameters')
        assert client.wait_for_service(timeout_sec=30.0)
        future = client.call_async(GetParameters.Request(names=[name]))
        executor.spin_until_future_complete(future, timeout_sec=30.0)
        return future.result().values[0].double_value
    finally:
        rclpy.try_shutdown(context=context)


def test_multi_objective_mode_reports_a_feasible_pareto_front(tmp_path, capsys):
    (tmp_path / 'objects.yaml').write_text(yaml.safe_dump(ENVELOPE), encoding='utf-8')
    assert tune.main(_args(tmp_path, 4, '--multi', '--holdout', 'none')) == 0
    out = capsys.readouterr().out
    assert 'Pareto front' in out
    study = optuna.load_study(study_name=tune.DEFAULT_STUDY,
                              storage=f'sqlite:///{tmp_path / "study.db"}')
    front = tune.best_trials(study, multi=True)
    assert front and all(t.user_attrs['worst_peak_ratio'] <= 1.10 for t in front)
    for t in front:                                    # nobody feasible dominates a front trial
        assert not any(o.values[0] <= t.values[0] and o.values[1] <= t.values[1]
                       and o.values != t.values for o in tune.feasible(tune.finished(study)))


@pytest.mark.parametrize('param, words', [
    ('force_control.contact_aware.nonsense=0:1', 'no such key'),
    (f'{KEY}=0.9:0.3', 'LO < HI'),
    (f'{KEY}=nan:1', 'LO < HI'),
    (f'{KEY}=0:1:log', 'LO > 0'),
    ('supervisor.force_law=0:1', 'not a numeric key'),
    ('position_control.mpc_pd.horizon=10.5:20', 'integer'),
    (f'{KEY}', 'expected SECTION.KEY=LO:HI'),
    ('position_control.pd.kc=1:1e300', "within the key's bounds [0, 1e+06], got '1:1e300'"),
    ('force_control.contact_aware.contact_force_n=0:1', 'bounds [1e-09, 10]'),
])
def test_a_bad_param_is_refused_in_one_line_and_nothing_is_written(
        tmp_path, capsys, param, words):
    out = tmp_path / 'out'
    assert tune.main(['--param', param, '--trials', '1', '--output', str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('tune: ') and words in err[0], err
    assert not out.exists()


@pytest.mark.parametrize('objects, words', [
    ([{'width_m': 0.05}], 'mass_kg is required'),
    ([{'width_m': 0.05, 'mass_kg': float('nan')}], 'mass_kg must be a finite number'),
    ([{'width_m': -0.05, 'mass_kg': 1.0}], 'width_m must be a finite number >= 0'),
    ([{'width_m': 0.05, 'mass_kg': 1.0, 'colour': 'red'}], 'unknown field colour'),
    ({'not': 'a list'}, 'expected a list of objects'),
])
def test_a_bad_envelope_file_is_refused_naming_the_field(tmp_path, capsys, objects, words):
    path = tmp_path / 'objects.yaml'
    path.write_text(yaml.safe_dump(objects), encoding='utf-8')
    assert tune.main(['--param', f'{KEY}=0.3:0.6', '--envelope', str(path), '--trials', '1',
                      '--output', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
