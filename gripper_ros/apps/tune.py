"""tune: search config gains with Optuna for fast, gentle grasps over an envelope of objects.

    ros2 run gripper_ros tune --param KEY=LO:HI[:log] [--param ...]
                              --envelope quick|tablev|holdout|FILE.yaml --trials N
                              [--objective median|cost] [--peak-weight S] [--multi]
                              [--storage URL] [--study NAME] [--seed N]
                              [--jobs N | --scheduler tcp://HOST:8786]
                              [--holdout quick|tablev|holdout|none|FILE.yaml] [--hold-s S]
                              [--config FILE] [--top K] [--quiet] --output DIR

Each trial sets the ``--param`` keys (any numeric key of config/gripper.yaml, dotted) to values
Optuna picks in their ranges, grasps every object of the envelope headless (the graph's logic,
bit-identical) through the batch engine, holds on ``--hold-s`` and scores the trial:

- objective ``median`` (default): the median time from request to a steady HOLDING;
  ``cost``: that median plus ``--peak-weight`` seconds per unit of the worst peak / F_sp;
  ``--multi``: both the median time and the worst peak / F_sp, for the Pareto front;
- hard constraints, never traded: the peak contact force at most ``--max-peak-ratio`` (1.10)
  x F_sp, every object held (none lost, refused or timed out), and the force over the continued
  hold within the supervisor's settle band. A trial that breaks one is kept in the study (the
  sampler learns from it) and never reported as best.

The study lives in ``--storage`` (default: the SQLite file ``DIR/study.db``; any SQLAlchemy
URL, e.g. PostgreSQL for many machines, or ``journal:FILE`` for Optuna's journal file), so a
stopped run resumes: ``--trials`` is the study's total of finished trials, and several ``tune``
processes may work on one study. The first trial of a new study is the shipped setting.

Writes ``DIR/params.yaml`` (ROS parameters: ``--ros-args --params-file``), ``DIR/config.yaml``
(the whole config with the best values: ``--config``), ``DIR/trials.txt`` (the table it prints),
``DIR/history.png`` and ``DIR/pareto.png``; and checks the best setting beside the shipped one on
a held-out envelope (default: ``holdout``, objects inside the envelope that ``quick`` leaves out).
Bad input: one line on stderr, exit 2; no feasible trial: exit 1.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
import functools
import math
from pathlib import Path
import statistics
import sys
import warnings

from gripper_ros.apps.common import load_config_or_report, negative_option, with_values
from gripper_ros.core.config import bounds_of
from gripper_ros.core.runtime.engine import add_engine_arguments

PROG = 'tune'
ENVELOPES = ('quick', 'tablev', 'holdout')
"""Named envelopes: contact_sweep's quick grid, the paper's Table V objects (rigid), and the
envelope's inside held out of quick."""
DEFAULT_MAX_PEAK_RATIO = 1.10
"""The spike constraint: peak contact force / F_sp (the contact sweep's limit)."""
DEFAULT_STUDY = 'tune'
DEFAULT_TOP = 10
OBJECT_FIELDS = {'width_m': True, 'mass_kg': True, 'stiffness_n_per_m': False,
                 'damping_n_s_per_m': False, 'width_tolerance_m': False,
                 'object_width_m': False}
"""Fields of an object in an envelope YAML file, and whether each is required."""


CONSTRAINT_NAMES = ('peak_over_limit', 'not_held', 'unsettled')
"""The hard constraints, each met at <= 0 (:meth:`Evaluation.constraints`)."""


def _named_constraints() -> bool:
    from optuna.trial import Trial
    return hasattr(Trial, 'set_constraint')


NAMED_CONSTRAINTS = _named_constraints()
"""Optuna 5: a trial sets its constraints itself (the samplers' function is deprecated)."""


class TuneError(ValueError):
    """Bad input to tune: one line naming what is wrong."""


@dataclass(frozen=True)
class Param:
    """One searched key: its range, scale and type (that of the shipped value)."""

    key: str
    low: float
    high: float
    log: bool
    integer: bool


@dataclass
class Evaluation:
    """An envelope grasped with one setting: the figures a trial is scored on."""

    grasps: int
    not_held: int                  # lost, refused, timed out, no object: anything not HOLDING
    unsettled: int                 # held, but the continued hold left the settle band
    worst_peak_ratio: float
    median_time_s: float           # over all grasps; one not held counts as the timeout
    mean_time_s: float

    def constraints(self, max_peak_ratio: float) -> list[float]:
        """Optuna's constraint values: each <= 0 when met."""
        return [self.worst_peak_ratio - max_peak_ratio, float(self.not_held),
                float(self.unsettled)]

    def feasible(self, max_peak_ratio: float) -> bool:
        return all(c <= 0.0 for c in self.constraints(max_peak_ratio))


# --- input -------------------------------------------------------------------------------------

def parse_param(text: str, data: dict) -> Param:
    """``KEY=LO:HI[:log]`` against the config mapping ``data``; TuneError naming the problem."""
    key, sep, span = text.partition('=')
    key = key.strip()
    parts = span.split(':')
    if not sep or not key or len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] != 'log'):
        raise TuneError(f'bad --param {text!r} (expected SECTION.KEY=LO:HI or KEY=LO:HI:log)')
    node = data
    for part in key.split('.'):
        if not isinstance(node, dict) or part not in node:
            raise TuneError(f'--param {key}: no such key in the config')
        node = node[part]
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise TuneError(f'--param {key}: not a numeric key (it holds {node!r})')
    bounds = bounds_of(key)
    try:
        low, high = float(parts[0]), float(parts[1])
    except ValueError:
        raise TuneError(f'--param {key}: LO and HI must be numbers, got {span!r}') from None
    log = len(parts) == 3
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise TuneError(f'--param {key}: LO and HI must be finite with LO < HI, got {span!r}')
    if log and low <= 0.0:
        raise TuneError(f'--param {key}: a log range needs LO > 0, got {low!r}')
    if bounds is not None and not bounds[0] <= low < high <= bounds[1]:
        raise TuneError(f"--param {key}: LO:HI must lie within the key's bounds "
                        f'[{bounds[0]:g}, {bounds[1]:g}], got {span!r}')
    integer = isinstance(node, int)
    if integer and (low != int(low) or high != int(high)):
        raise TuneError(f'--param {key}: an integer key needs integer LO and HI, got {span!r}')
    return Param(key, low, high, log, integer)


def load_envelope(name: str, config) -> list:
    """Return the envelope's cases (:class:`SweepCase`); TuneError for a bad name or file."""
    from gripper_ros.studies import sweep_runs
    if name == 'quick':
        return sweep_runs.quick_cases(config)[0]
    if name == 'holdout':
        return sweep_runs.holdout_cases(config)[0]
    if name == 'tablev':
        from gripper_ros.studies.paper import PAPER_OBJECTS
        return [sweep_runs.SweepCase('rigid', 0.0, 0.0, 0.0, w, w, 0.0, m)
                for w, m in PAPER_OBJECTS]
    return _envelope_file(name, config)


def _envelope_file(path: str, config) -> list:
    import yaml
    from gripper_ros.studies.sweep_runs import SweepCase
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except OSError as exc:
        raise TuneError(f'cannot read envelope {path} ({exc.strerror or exc}); named '
                        f'envelopes: {", ".join(ENVELOPES)}') from None
    except yaml.YAMLError as exc:
        raise TuneError(f'envelope {path} is not valid YAML: '
                        f'{str(exc).splitlines()[0]}') from None
    if isinstance(data, dict):
        data = data.get('objects')
    if not isinstance(data, list) or not data:
        raise TuneError(f'envelope {path}: expected a list of objects (or objects: [...])')
    cases = []
    for i, obj in enumerate(data):
        where = f'envelope {path}: object {i}'
        if not isinstance(obj, dict):
            raise TuneError(f'{where}: expected a mapping of {", ".join(OBJECT_FIELDS)}')
        unknown = sorted(set(obj) - set(OBJECT_FIELDS))
        if unknown:
            raise TuneError(f'{where}: unknown field {unknown[0]} (fields: '
                            f'{", ".join(OBJECT_FIELDS)})')
        values = {}
        for field_name, required in OBJECT_FIELDS.items():
            if field_name not in obj:
                if required:
                    raise TuneError(f'{where}: {field_name} is required')
                continue
            v = obj[field_name]
            if isinstance(v, str):
                try:
                    v = float(v)               # YAML 1.1 reads 1e5 as a string
                except ValueError:
                    pass
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0.0:
                raise TuneError(f'{where}: {field_name} must be a finite number >= 0, got {v!r}')
            values[field_name] = float(v)
        for field_name in ('width_m', 'mass_kg'):
            if values[field_name] <= 0.0:
                raise TuneError(f'{where}: {field_name} must be > 0')
        k = values.get('stiffness_n_per_m', 0.0)
        c = values.get('damping_n_s_per_m', 0.0)
        zeta = c / (2.0 * math.sqrt(k * config.plant.reflected_mass_kg)) if k > 0.0 else 0.0
        cases.append(SweepCase('file' if k else 'rigid', k, zeta, c, values['width_m'],
                               values.get('object_width_m', values['width_m']),
                               values.get('width_tolerance_m', 0.0), values['mass_kg']))
    return cases


# --- evaluation --------------------------------------------------------------------------------

def evaluate(config, cases: list, hold_s: float, *, jobs: int | None = None,
             scheduler=None, progress=None) -> Evaluation:
    """Grasp every case with ``config`` through the engine and score the envelope."""
    from gripper_ros.studies.sweep_runs import case_keywords, grasp_summary
    from gripper_ros.core.runtime.headless import simulate_grasps
    results = simulate_grasps(config, [case_keywords(c, None, hold_s) for c in cases], jobs,
                              summarize=grasp_summary, scheduler=scheduler, progress=progress)
    band = config.supervisor.force_settle_band_fraction
    timeout_s = config.supervisor.timeout_s
    times, peaks, not_held, unsettled = [], [0.0], 0, 0
    for res in results:
        if res is None:
            not_held += 1
            times.append(timeout_s)
            continue
        outcome, f_sp, peak, t_hold, lo, hi, _ = res
        peaks.append(peak / f_sp)
        if outcome != 'HOLDING':
            not_held += 1
            times.append(timeout_s)
            continue
        times.append(t_hold)
        if hold_s > 0.0 and not (1.0 - band <= lo <= hi <= 1.0 + band):
            unsettled += 1
    return Evaluation(len(cases), not_held, unsettled, max(peaks), statistics.median(times),
                      statistics.fmean(times))


def _objective(params: list[Param], base, cases, hold_s: float, engine: dict, how: dict,
               trial):
    import optuna
    values = {}
    for p in params:
        if p.integer:
            values[p.key] = trial.suggest_int(p.key, int(p.low), int(p.high), log=p.log)
        else:
            values[p.key] = trial.suggest_float(p.key, p.low, p.high, log=p.log)
    from gripper_ros.core.config import ConfigError
    try:
        config = with_values(base, values)
    except ConfigError as exc:
        message = str(exc).splitlines()[0]
        trial.set_user_attr('error', message)
        raise optuna.TrialPruned(message) from None
    ev = evaluate(config, cases, hold_s, **engine)
    for name, value in vars(ev).items():
        trial.set_user_attr(name, value)
    constraints = ev.constraints(how['max_peak_ratio'])
    trial.set_user_attr('constraints', constraints)
    if NAMED_CONSTRAINTS:
        for name, value in zip(CONSTRAINT_NAMES, constraints):
            trial.set_constraint(name, value)
    if how['multi']:
        return ev.median_time_s, ev.worst_peak_ratio
    if how['objective'] == 'cost':
        return ev.median_time_s + how['peak_weight_s'] * ev.worst_peak_ratio
    return ev.median_time_s


def _constraints(frozen) -> list[float]:
    return frozen.user_attrs.get('constraints', [math.inf])


def open_study(storage: str, name: str, multi: bool, seed: int):
    """Open (or create) the study; the sampler knows the hard constraints."""
    import optuna
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings('ignore', category=optuna.exceptions.ExperimentalWarning)
    if storage.startswith('journal:'):
        from optuna.storages import JournalStorage
        try:
            from optuna.storages.journal import JournalFileBackend
        except ImportError:                     # Optuna 3.x (Ubuntu 24.04's python3-optuna)
            from optuna.storages import JournalFileStorage as JournalFileBackend
        storage = JournalStorage(JournalFileBackend(storage[len('journal:'):]))
    return optuna.create_study(storage=storage, study_name=name, sampler=make_sampler(multi, seed),
                               directions=['minimize'] * (2 if multi else 1), load_if_exists=True)


def make_sampler(multi: bool, seed: int):
    """Return NSGA-II (two objectives) or TPE (one), both told the hard constraints.

    Optuna 5 reads the constraints each trial sets; Optuna 3 and 4 (Ubuntu 24.04's) take a
    function of the finished trial.
    """
    import optuna
    told = {} if NAMED_CONSTRAINTS else {'constraints_func': _constraints}
    if multi:
        return optuna.samplers.NSGAIISampler(seed=seed, **told)
    return optuna.samplers.TPESampler(seed=seed, **told)


def finished(study) -> list:
    """Return the study's complete trials, in order."""
    from optuna.trial import TrialState
    return [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]


def feasible(trials: list) -> list:
    return [t for t in trials if all(c <= 0.0 for c in _constraints(t))]


def best_trials(study, multi: bool) -> list:
    """Return the feasible trials to report, best first: by value, or the Pareto front.

    An infeasible trial is never among them, whatever its value.
    """
    ok = feasible(finished(study))
    if not multi:
        return sorted(ok, key=lambda t: (t.values[0], t.number))
    front = [t for t in ok if not any(
        all(a <= b for a, b in zip(o.values, t.values)) and o.values != t.values for o in ok)]
    return sorted(front, key=lambda t: (t.values[0], t.number))


# --- output ------------------------------------------------------------------------------------

def params_yaml(values: dict) -> str:
    """Return the values as a ROS params file for every node (``--ros-args --params-file``)."""
    import yaml
    body = {k: (int(v) if isinstance(v, int) and not isinstance(v, bool) else float(v))
            for k, v in sorted(values.items())}
    return yaml.safe_dump({'/**': {'ros__parameters': body}}, sort_keys=False)


def config_yaml(config, values: dict, note: str) -> str:
    """Return the whole config with the values set (``--config FILE``), with a note on top."""
    import yaml
    from gripper_ros.bags.rerun import apply_settings
    data = apply_settings(config.data, sorted(values.items()), config.source)
    return ''.join(f'# {line}\n' for line in note.splitlines()) + \
        yaml.safe_dump(data, sort_keys=False)


def format_table(trials: list, params: list[Param], multi: bool, max_peak_ratio: float,
                 total: int, infeasible: int, pruned: int) -> str:
    """Return the best trials as a table (the Pareto front with ``multi``)."""
    head = f'{"trial":>5s} ' + ' '.join(f'{f"p{i + 1}":>10s}' for i in range(len(params))) + \
        f' {"median s":>9s} {"mean s":>8s} {"peak/F_sp":>9s} {"not held":>8s} {"unsettled":>9s}'
    title = 'Pareto front (median time to hold vs worst peak), feasible trials' if multi else \
        'best feasible trials'
    lines = [f'tune: {total} trials finished, {infeasible} broke a constraint (peak > '
             f'{max_peak_ratio:g} x F_sp, an object not held, or a hold out of the settle '
             f'band), {pruned} refused by the config reader; {title}:',
             *(f'  p{i + 1} = {p.key}' for i, p in enumerate(params)), head]
    for t in trials:
        a = t.user_attrs
        values = ' '.join(f'{t.params[p.key]:10.5g}' for p in params)
        lines.append(f'{t.number:5d} {values} {a["median_time_s"]:9.3f} {a["mean_time_s"]:8.3f} '
                     f'{a["worst_peak_ratio"]:9.4f} {a["not_held"]:8d} {a["unsettled"]:9d}')
    if not trials:
        lines.append('  (none)')
    return '\n'.join(lines)


def format_check(name: str, shipped: Evaluation, tuned: Evaluation, max_peak_ratio: float) -> str:
    """Return the held-out check: the shipped and the tuned setting side by side."""
    lines = [f'held-out check on {name!r} ({shipped.grasps} objects not used in tuning):',
             f'{"setting":>8s} {"median s":>9s} {"mean s":>8s} {"peak/F_sp":>9s} '
             f'{"not held":>8s} {"unsettled":>9s} {"feasible":>8s}']
    for label, ev in (('shipped', shipped), ('tuned', tuned)):
        lines.append(f'{label:>8s} {ev.median_time_s:9.3f} {ev.mean_time_s:8.3f} '
                     f'{ev.worst_peak_ratio:9.4f} {ev.not_held:8d} {ev.unsettled:9d} '
                     f'{"yes" if ev.feasible(max_peak_ratio) else "NO":>8s}')
    gain_s = shipped.median_time_s - tuned.median_time_s
    lines.append(f'median time to a steady hold: tuned {gain_s:+.3f} s faster than shipped '
                 f'({100.0 * gain_s / shipped.median_time_s:+.1f} %); mean '
                 f'{shipped.mean_time_s - tuned.mean_time_s:+.3f} s')
    return '\n'.join(lines)


def plot(study, multi: bool, max_peak_ratio: float, out: Path) -> list[Path]:
    """Write the optimisation history and the time-vs-peak (Pareto) plot; return their paths."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    trials = finished(study)
    ok = {t.number for t in feasible(trials)}
    history, pareto = out / 'history.png', out / 'pareto.png'
    fig, ax = _trials_against(plt, trials, ok, lambda t: t.number)
    best, xs, ys = math.inf, [], []
    for t in trials:
        if t.number in ok:
            best = min(best, t.user_attrs['median_time_s'])
        if math.isfinite(best):
            xs.append(t.number)
            ys.append(best)
    ax.step(xs, ys, where='post', color='k', label='best feasible so far')
    ax.set_xlabel('trial')
    _save(plt, fig, ax, f'{study.study_name}: optimisation history', history)
    fig, ax = _trials_against(plt, trials, ok, lambda t: t.user_attrs['worst_peak_ratio'])
    front = best_trials(study, True) if multi else _front_2d(feasible(trials))
    front = sorted(front, key=lambda t: t.user_attrs['worst_peak_ratio'])
    ax.plot([t.user_attrs['worst_peak_ratio'] for t in front],
            [t.user_attrs['median_time_s'] for t in front], 'k-', label='Pareto front')
    ax.axvline(max_peak_ratio, color='r', ls='--', label=f'{max_peak_ratio:g} x F_sp')
    ax.set_xscale('log')                    # a spike is hundreds of times F_sp
    ax.set_xlabel('worst peak contact force / F_sp')
    _save(plt, fig, ax, f'{study.study_name}: time against peak', pareto)
    return [history, pareto]


def _trials_against(plt, trials, ok, x_of):
    """Return a figure of each trial's median time against ``x_of(trial)``, feasible or not."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for good, style, label in ((True, 'o', 'feasible'), (False, 'x', 'broke a constraint')):
        sel = [t for t in trials if (t.number in ok) == good]
        ax.plot([x_of(t) for t in sel], [t.user_attrs['median_time_s'] for t in sel], style,
                label=label, ms=5)
    return fig, ax


def _save(plt, fig, ax, title: str, path: Path) -> None:
    """Title, label and legend a plot of median times, write it to ``path`` and close it."""
    ax.set_ylabel('median time to a steady hold (s)')
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _front_2d(trials: list) -> list:
    pts = [(t.user_attrs['median_time_s'], t.user_attrs['worst_peak_ratio'], t) for t in trials]
    return [t for a, b, t in pts if not any(c <= a and d <= b and (c, d) != (a, b)
                                            for c, d, _ in pts)]


# --- command -----------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument('--param', action='append', required=True, metavar='KEY=LO:HI[:log]',
                        help='a numeric config key and its range (repeatable), e.g. '
                             'force_control.contact_aware.impact_force_fraction=0.2:0.9')
    parser.add_argument('--envelope', default='quick', metavar='quick|tablev|holdout|FILE.yaml',
                        help='objects tuned over (default quick: contact_sweep --quick); a file '
                             'lists objects with width_m, mass_kg, stiffness_n_per_m, '
                             'damping_n_s_per_m, width_tolerance_m, object_width_m')
    parser.add_argument('--trials', type=int, required=True,
                        help="the study's total of finished trials (a resumed study runs the "
                             'rest)')
    parser.add_argument('--objective', choices=['median', 'cost'], default='median',
                        help='median time to a steady hold (default), or that plus '
                             '--peak-weight x worst peak / F_sp')
    parser.add_argument('--peak-weight', type=float, default=1.0, metavar='S',
                        help='seconds of cost per unit of peak / F_sp (--objective cost)')
    parser.add_argument('--multi', action='store_true',
                        help='two objectives, median time and worst peak: the Pareto front')
    parser.add_argument('--max-peak-ratio', type=float, default=DEFAULT_MAX_PEAK_RATIO,
                        help='the spike constraint, peak / F_sp (default %(default)s)')
    parser.add_argument('--storage', help='Optuna storage: an SQLAlchemy URL or journal:FILE '
                                          '(default: sqlite:///DIR/study.db)')
    parser.add_argument('--study', default=DEFAULT_STUDY, help='study name (default %(default)s)')
    parser.add_argument('--seed', type=int, default=0, help="the sampler's seed (default 0)")
    add_engine_arguments(parser)
    parser.add_argument('--holdout', default='holdout',
                        metavar='quick|tablev|holdout|none|FILE.yaml',
                        help='envelope of the held-out check (default holdout: the envelope '
                             'inside, left out of quick)')
    parser.add_argument('--hold-s', type=float, default=1.0,
                        help='continued hold after HOLDING, checked against the settle band '
                             '(default %(default)s s)')
    parser.add_argument('--config', help='YAML config file to start from (default: installed)')
    parser.add_argument('--top', type=int, default=DEFAULT_TOP, help='rows of the table')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--output', required=True, metavar='DIR', help='where to write results')
    return parser


def _check_args(args) -> None:
    if args.trials < 1 or args.top < 1:
        raise TuneError('--trials and --top must be >= 1')
    from gripper_ros.core.runtime.engine import options_problem
    problem = options_problem(args.jobs, args.scheduler) or \
        negative_option(args, ('hold_s', 'peak_weight', 'max_peak_ratio'))
    if problem:
        raise TuneError(problem)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    base = load_config_or_report(PROG, args.config)
    if base is None:
        return 2
    try:
        _check_args(args)
        params = [parse_param(text, base.data) for text in args.param]
        if len({p.key for p in params}) != len(params):
            raise TuneError('--param: a key is given twice')
        cases = load_envelope(args.envelope, base)
        holdout = None if args.holdout == 'none' else load_envelope(args.holdout, base)
        out = Path(args.output)
        out.mkdir(parents=True, exist_ok=True)
    except (TuneError, OSError) as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return 2
    return _run(args, base, params, cases, holdout, out)


def _run(args, base, params, cases, holdout, out: Path) -> int:
    from optuna.study import MaxTrialsCallback
    from optuna.trial import TrialState
    from gripper_ros.core.runtime.engine import EngineError
    from gripper_ros.progress import progress_bar
    storage = args.storage or f'sqlite:///{(out / "study.db").resolve()}'
    engine = {'jobs': args.jobs, 'scheduler': args.scheduler}
    how = {'multi': args.multi, 'objective': args.objective, 'peak_weight_s': args.peak_weight,
           'max_peak_ratio': args.max_peak_ratio}
    try:
        study = open_study(storage, args.study, args.multi, args.seed)
    except Exception as exc:        # noqa: B902 - storage errors come from several libraries
        print(f'{PROG}: cannot open study {args.study!r} in {storage}: '
              f'{str(exc).splitlines()[0]}', file=sys.stderr)
        return 2
    done = len([t for t in study.get_trials(deepcopy=False)
                if t.state in (TrialState.COMPLETE, TrialState.PRUNED)])
    if done == 0 and not study.get_trials(deepcopy=False):
        shipped = {}
        for p in params:
            node = base.data
            for part in p.key.split('.'):
                node = node[part]
            shipped[p.key] = node
        if all(p.low <= shipped[p.key] <= p.high for p in params):
            study.enqueue_trial(shipped)
    # a resumed study's sampler starts from a seed of its own: not the trials already run
    study.sampler = make_sampler(args.multi, args.seed + done)
    left = max(0, args.trials - done)
    objective = functools.partial(_objective, params, base, cases, args.hold_s, engine, how)
    try:
        with progress_bar(left, PROG, 'trial', quiet=args.quiet) as bar:
            study.optimize(objective, n_trials=left, callbacks=[
                MaxTrialsCallback(args.trials, states=(TrialState.COMPLETE, TrialState.PRUNED)),
                lambda *_: bar.update(1)])
    except EngineError as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted; the finished trials are kept in {storage}: the same command '
              'resumes the study', file=sys.stderr)
        return 130
    trials = finished(study)
    pruned = len(study.get_trials(deepcopy=False, states=(TrialState.PRUNED,)))
    best = best_trials(study, args.multi)
    table = format_table(best[:args.top] if not args.multi else best, params, args.multi,
                         args.max_peak_ratio, len(trials), len(trials) - len(feasible(trials)),
                         pruned)
    print(table)
    figures = plot(study, args.multi, args.max_peak_ratio, out) if trials else []
    report = [table]
    if not best:
        for figure in figures:
            print(f'figure: {figure}')
        print(f'{PROG}: no trial met the constraints: nothing written but the table and plots',
              file=sys.stderr)
        (out / 'trials.txt').write_text(table + '\n', encoding='utf-8')
        return 1
    chosen = best[0]
    values = dict(chosen.params)
    note = (f'tune: study {args.study!r}, trial {chosen.number}, envelope {args.envelope!r}: '
            f'median time to a steady hold {chosen.user_attrs["median_time_s"]:.3f} s, '
            f'worst peak {chosen.user_attrs["worst_peak_ratio"]:.4f} x F_sp\n'
            + '\n'.join(f'{k}: {v!r}' for k, v in sorted(values.items())))
    (out / 'params.yaml').write_text(params_yaml(values), encoding='utf-8')
    (out / 'config.yaml').write_text(config_yaml(base, values, note), encoding='utf-8')
    print(f'best: trial {chosen.number}: '
          + ', '.join(f'{k}={v:.6g}' for k, v in sorted(values.items())))
    if holdout is not None:
        try:
            shipped_ev = evaluate(base, holdout, args.hold_s, **engine)
            tuned_ev = evaluate(with_values(base, values), holdout, args.hold_s, **engine)
        except EngineError as exc:
            print(f'{PROG}: {exc}', file=sys.stderr)
            return 2
        check = format_check(args.holdout, shipped_ev, tuned_ev, args.max_peak_ratio)
        print()
        print(check)
        report += ['', check]
    (out / 'trials.txt').write_text('\n'.join(report) + '\n', encoding='utf-8')
    for figure in figures:
        print(f'figure: {figure}')
    print(f'wrote {out / "params.yaml"}, {out / "config.yaml"}, {out / "trials.txt"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
