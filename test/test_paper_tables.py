"""Tables III and IV: our simulations against the paper's published numbers.

And against closed-form answers (continuous-time PI loop, discrete characteristic polynomial).
"""
import math
from pathlib import Path

from gripper_ros.apps import paper_tables
from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import force_pi_gains, make_force_controller
from gripper_ros.studies.metrics import step_metrics, StepMetrics
from gripper_ros.studies.paper import PAPER_TABLE_III, PAPER_TABLE_IV
from gripper_ros.studies.step_runs import force_step
from gripper_ros.wire import ForceControllerKind
import numpy as np
import pytest
from scipy.signal import step as lti_step

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
P = CONFIG.plant
TAU_E = P.inductance_h / P.resistance_ohm
K_F = P.stall_force_per_volt_n                       # eq. 13 DC gain, 1.391 N/V


@pytest.fixture(scope='module')
def table_rows():
    return paper_tables.position_rows(CONFIG), paper_tables.force_rows(CONFIG)


@pytest.fixture
def rows(table_rows):
    return table_rows[0] + table_rows[1]


def force_run(gains, dt, substeps):
    ctl = make_force_controller(CONFIG, ForceControllerKind.PI, gains, dt)
    return force_step(CONFIG, ctl, dt, 1.0, 0.004, substeps)


def paper_table(title):
    """One table of the paper, as printed (test/data): {controller: StepMetrics}."""
    lines = (REPO / 'test' / 'data' / 'paper_tables_iii_iv.txt').read_text(
        encoding='utf-8').splitlines()
    start = lines.index(title)
    rows = {}
    for line in lines[start + 1:]:
        if line.startswith('TABLE '):
            break
        if '\t' in line:
            label, *cells = line.split('\t')
            rows[label] = cells
    columns = rows.pop('Controller')
    figures = [[float(c) for c in rows[label]] for label in
               ('RMS Error', 'Overshoot', 'Settling Time (s)')]
    assert not set(rows) - {'RMS Error', 'Overshoot', 'Settling Time (s)'}
    return {name: StepMetrics(*(figure[i] for figure in figures))
            for i, name in enumerate(columns)}


@pytest.mark.parametrize('title, published', [
    ('TABLE III', PAPER_TABLE_III), ('TABLE IV', PAPER_TABLE_IV)])
def test_the_paper_column_is_the_papers_table(title, published):
    """Every cell of the paper column, controller by controller, as the paper prints it."""
    assert published == paper_table(title)


# ------------------------------------------------------------------ Table III
def test_pd_row_within_one_percent_of_the_paper(rows):
    (pd,) = [r for r in rows if r.table == 'III' and r.controller == 'PD']
    assert pd.ours.rms_error == pytest.approx(0.0242, rel=0.01)
    assert pd.ours.overshoot_pct == pytest.approx(7.2985, rel=0.01)
    assert pd.ours.settling_time_s == pytest.approx(4.6404, rel=0.01)


def test_every_command_within_the_24_volt_limit(rows):
    assert len(rows) >= 9
    for r in rows:
        assert 0.0 < r.max_abs_voltage_v <= P.voltage_limit_v + 1e-12, r.controller


# ------------------------------------------------------------------ Table IV
def discrete_pi_closed_loop_poles(gains, dt):
    """PI (backward rectangle) on the ZOH of eq. 13; state (F[k], I[k-1]), derived here."""
    a = math.exp(-dt / TAU_E)
    b = K_F * (1 - a)
    s = gains.kc + gains.ki * dt
    return np.linalg.eigvals(np.array([[a - b * s, b], [-gains.ki * dt, 1.0]]))


def test_paper_force_pi_is_unstable_as_a_discrete_pi_at_0_1_ms():
    gains = CONFIG.force.pi_paper
    dt = CONFIG.force.paper_sample_time_s
    assert max(abs(discrete_pi_closed_loop_poles(gains, dt))) > 1.4      # -1.447
    run = force_run(gains, dt, 10)
    m = run.metrics()
    assert m.settling_time_s == math.inf
    assert m.overshoot_pct > 100.0
    # the error grows: the sampled force swings ever wider over the first millisecond
    sampled = run.output[::10][:11]
    assert np.max(np.abs(sampled[6:] - 1.0)) > 3 * np.max(np.abs(sampled[:4] - 1.0))
    assert run.max_abs_command_v <= P.voltage_limit_v


def continuous_pi_step(gains):
    """F/E = K/(tau s + 1) with C = kc + ki/s, closed loop, on a 0.1 us grid."""
    num = np.polymul([K_F], [gains.kc, gains.ki])
    den = np.polyadd(np.polymul([TAU_E, 1.0], [1.0, 0.0]), num)
    t = np.arange(0.0, 0.004, 1e-7)
    _, y = lti_step((num, den), T=t)
    return t, y


def test_paper_force_pi_near_continuous_settles_like_the_continuous_loop():
    gains = CONFIG.force.pi_paper
    assert max(abs(discrete_pi_closed_loop_poles(gains, 1e-6))) < 1.0
    run = force_run(gains, 1e-6, 1)
    ours = run.metrics()
    t, y = continuous_pi_step(gains)
    cont = step_metrics(t, y, 1.0)
    assert ours.settling_time_s == pytest.approx(cont.settling_time_s, abs=5e-6)
    assert ours.overshoot_pct == pytest.approx(cont.overshoot_pct, abs=0.1)
    assert ours.rms_error == pytest.approx(cont.rms_error, rel=0.01)
    # the paper reports 0.3557 ms; the continuous model of eq. 13 gives 0.325 ms
    assert ours.settling_time_s == pytest.approx(0.3557e-3, rel=0.12)
    assert ours.rms_error == pytest.approx(0.0888, rel=0.05)


def test_our_force_pi_at_0_1_ms_settles_fast_without_overshoot():
    gains = force_pi_gains(CONFIG)
    dt = CONFIG.force.sample_time_s
    pole = CONFIG.force.closed_loop_pole
    np.testing.assert_allclose(discrete_pi_closed_loop_poles(gains, dt), [pole, pole], atol=1e-6)
    run = force_run(gains, dt, 10)
    m = run.metrics()
    assert 0.3e-3 <= m.settling_time_s <= 0.45e-3
    assert m.overshoot_pct < 3.0
    assert run.output[-1] == pytest.approx(1.0, abs=1e-9)           # integral action
    assert run.command_v[-1] == pytest.approx(1.0 / K_F, rel=1e-9)  # stall: V = F / 1.391
    assert run.max_abs_command_v <= P.voltage_limit_v


# ------------------------------------------------------------------ console script
def test_main_prints_both_tables(capsys, monkeypatch, table_rows):
    # the rows are the ones computed (and checked) above; main's job is to load and print them
    pos, frc = table_rows
    monkeypatch.setattr(paper_tables, 'position_rows', lambda config: pos)
    monkeypatch.setattr(paper_tables, 'force_rows', lambda config: frc)
    assert paper_tables.main([]) == 0
    out, err = capsys.readouterr()
    assert err == ''
    assert 'Table III' in out and 'Table IV' in out
    pd_line = next(line for line in out.splitlines() if line.split()[:1] == ['PD'])
    fields = pd_line.split()
    assert fields[1:3] == ['0.0242', '0.02424'] and fields[3] == '7.298'
    for name in ('PID', 'MPC-PD', 'PI paper gains', 'MPC-PI'):
        assert any(line.startswith(name) for line in out.splitlines()), name


def test_main_missing_config_exits_2_with_one_line(capsys, tmp_path):
    missing = tmp_path / 'absent.yaml'
    assert paper_tables.main(['--config', str(missing)]) == 2
    out, err = capsys.readouterr()
    assert out == ''
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith('paper_tables: ')
    assert str(missing) in lines[0]


def test_main_bad_config_exits_2_naming_the_key(capsys, tmp_path):
    text = (REPO / 'config' / 'gripper.yaml').read_text(encoding='utf-8').replace(
        'inductance_h: 0.238e-3', 'inductance_h: -1')
    path = tmp_path / 'bad.yaml'
    path.write_text(text, encoding='utf-8')
    assert paper_tables.main(['--config', str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == '' and len(err.splitlines()) == 1 and 'plant.inductance_h' in err
