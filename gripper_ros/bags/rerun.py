"""Closed-loop what-if: a recorded grasp re-run without ROS, with changed gains or controllers.

``bag_replay BAG --resimulate --closed-loop [--config FILE] [--set SECTION.KEY=VALUE ...]
[--position-controller K] [--force-controller K] [--approach-force-margin M]`` (or
:func:`whatif`) takes from a grasp bag (format 2, its custom_data) the request, the object
placed (compliance, hold and lift, a scheduled fault), the controller kinds and the
configuration in effect, applies the changes asked for, and grasps again in closed loop with
:func:`gripper_ros.core.runtime.headless.simulate_grasp`: the plant, supervisor and stage code the
node graph runs, wired as the graph wires them in fast mode, tick for tick. Unlike the open-loop
``--resimulate`` the plant answers the new commands, so a new gain's effect on position, force,
contact peak and settling is seen. Both the recording and the re-run are analysed by
:func:`gripper_ros.bags.analyze.analyze_series`, from the same series type
(:class:`gripper_ros.core.series.GraspSeries`: the bag's messages, the re-run's kept alike).

Without a change the re-run equals the recording: every field of every tick, reference and
command (grasp and stage ids and the world revision counted on from the recording's first).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields, replace
import functools
import math
import os
from pathlib import Path
from typing import Any, Sequence

from gripper_ros.bags.analyze import analyze_series, GraspMetrics
from gripper_ros.bags.reader import Bag, BagError, open_bag
from gripper_ros.bags.resimulate import build_stages, load_resim_config
from gripper_ros.bags.series import bag_namespace, load_grasp_series
from gripper_ros.core.config import (ConfigError, dotted_section, flatten, GripperConfig,
                                     parse_config)
from gripper_ros.core.physics.plant import check_fault, GraspObject, Lift
from gripper_ros.core.runtime.headless import HeadlessGrasp, map_cases, simulate_grasp
from gripper_ros.core.series import GraspSeries
from gripper_ros.core.supervision.requests import GraspRequest, RequestError, validate_request
from gripper_ros.text import one_line
from gripper_ros.wire import (Controller, DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                              DEFAULT_POSITION_CONTROLLER, DEFAULT_STATE_RATE_HZ, FaultKind,
                              ForceControllerKind, Outcome, Phase, PositionControllerKind,
                              TimeMode)
import numpy as np
import yaml

REQUEST_FIELDS = tuple(f.name for f in fields(GraspRequest))
"""What a bag's ``request`` may hold (the Grasp request's fields, in order)."""
OBJECT_FIELDS = {
    'width_m': 'object_width_m', 'stiffness_n_per_m': 'stiffness_n_per_m',
    'damping_n_s_per_m': 'damping_n_s_per_m', 'mass_kg': 'object_mass_kg',
    'static_friction': 'static_friction', 'kinetic_friction': 'kinetic_friction',
    'pad_length_m': 'pad_length_m'}
"""A bag's ``object`` fields (SetObject names) -> simulate_grasp's keyword."""
FRICTION_FIELDS = ('static_friction', 'kinetic_friction')
"""The object's pad friction: 0 frictionless; the configured one with ``default_friction``, and
in a bag recorded before that field, where 0 meant it."""
LIFT_FIELDS = ('lift_acceleration_mps2', 'lift_delay_s', 'lift_duration_s', 'lift_profile',
               'lift_frequency_hz', 'lift_off_s')
"""A bag's lift fields, Lift's arguments in order (a bag without the last two: a step)."""
FAULT_FIELDS = ('fault', 'fault_at_s', 'fault_time_constant_s')


class RerunError(BagError):
    """A bag, option or configuration a closed-loop re-run cannot use (one line)."""


# --- what the bag recorded ---------------------------------------------------------------------

@dataclass
class GraspRecord:
    """What a closed-loop re-run takes from a grasp bag."""

    path: Path
    series: GraspSeries
    request: dict
    obj: dict
    controllers: dict
    config: GripperConfig               # the configuration in effect while it was recorded
    time_mode: str
    grasp_start_ns: int                 # the grasp's first tick (its first POSITION decision)
    hold_s: float                       # realtime: recorded time after the answer (fast: 0)
    grasp: dict = field(default_factory=dict)   # simulate_grasp's request and object keywords
    state_rate_hz: float = DEFAULT_STATE_RATE_HZ    # of the plant's sim/object_state
    after_fault: bool = False           # the graph was in FAULT before: its idle tick unpowered

    @property
    def truncated(self) -> bool:
        return self.series.truncated


def _mapping(custom: dict, key: str, path, why: str) -> dict:
    value = custom.get(key)
    if not isinstance(value, dict):
        raise RerunError(f'{path}: no recorded {why} (custom_data "{key}"); a '
                         f'closed-loop re-run needs the request, the object and the '
                         f'configuration')
    return value


def load_record(bag: Bag | str | os.PathLike) -> GraspRecord:
    """Read what a re-run takes from ``bag``; RerunError (one line) when it cannot be re-run."""
    bag = open_bag(bag)
    custom = bag.custom_data_parsed()
    info = custom.get('gripper_ros')
    try:
        fmt, ns = bag_namespace(bag)
    except BagError:
        if not isinstance(info, dict):
            raise RerunError(f'{bag.path}: not a gripper_ros grasp bag (no gripper_ros '
                             f'custom_data and no <namespace>/loop/tick topic)') from None
        raise
    if fmt == 1:
        raise RerunError(f'{bag.path}: a bag of format 1 (recorded before the lockstep protocol) '
                         f'holds neither the request nor the object placed; only the open-loop '
                         f'--resimulate can use it')
    if isinstance(custom.get('not_rerun'), str):
        raise RerunError(f'{bag.path}: not re-run in closed loop: {custom["not_rerun"]}')
    request = _mapping(custom, 'request', bag.path, 'request')
    obj = _mapping(custom, 'object', bag.path, 'object')
    data = _mapping(custom, 'config', bag.path, 'configuration')
    controllers = custom.get('controllers') if isinstance(custom.get('controllers'), dict) else {}
    try:
        config = parse_config(copy.deepcopy(data), f'{bag.path} (recorded config)')
    except ConfigError as exc:
        raise RerunError(one_line(exc)) from None
    for name, value in request.items():
        if name not in REQUEST_FIELDS:
            raise RerunError(f'{bag.path}: recorded request field "{name}" is not re-run')
        _number(value, f'{bag.path}: recorded request "{name}"')
    for name in ('width_m', 'mass_kg'):
        if name not in request:
            raise RerunError(f'{bag.path}: the recorded request has no "{name}"')
    known = set(OBJECT_FIELDS) | set(LIFT_FIELDS) | set(FAULT_FIELDS) | \
        {'open_fingers', 'announce_lift', 'default_friction'}
    for name, value in obj.items():
        if name not in known:
            raise RerunError(f'{bag.path}: recorded object field "{name}" is not re-run')
        _number(value, f'{bag.path}: recorded object "{name}"')
    if obj.get('open_fingers', 1.0) != 1.0:
        raise RerunError(f'{bag.path}: the object was placed without opening the fingers; a '
                         f're-run starts from fully open')
    grasp = _grasp_keywords(bag.path, request, obj)
    series = load_grasp_series(bag, ns)
    st = series.decisions
    starts = np.flatnonzero((st['phase'] == Phase.POSITION) &
                            (st['outcome'] == Outcome.UNKNOWN))
    if starts.size == 0:
        raise RerunError(f'{bag.path}: no grasp starts in the bag (no POSITION decision)')
    start_ns = int(series.references['stamp_ns'][starts[0]])
    same = series.references['grasp_id'] == series.references['grasp_id'][starts[0]]
    answered = np.flatnonzero(same & (series.references['outcome'] != Outcome.UNKNOWN))
    fast = TimeMode.FAST.parameter
    time_mode = str(info.get('time_mode', fast)) if isinstance(info, dict) else fast
    hold_s = 0.0
    if time_mode != fast and answered.size and series.ticks['stamp_ns'].size:
        hold_s = (int(series.ticks['stamp_ns'][-1]) -
                  int(series.references['stamp_ns'][answered[0]])) * 1e-9
    rate = info.get('state_rate_hz', DEFAULT_STATE_RATE_HZ) if isinstance(info, dict) else \
        DEFAULT_STATE_RATE_HZ
    rate = _number(rate, f'{bag.path}: recorded state_rate_hz')
    if rate <= 0.0:
        raise RerunError(f'{bag.path}: recorded state_rate_hz must be > 0, got {rate!r}')
    first = np.flatnonzero(series.ticks['stamp_ns'] == start_ns)
    after_fault = bool(first.size) and \
        int(series.ticks['applied_source'][first[0]]) == Controller.NONE
    return GraspRecord(bag.path, series, dict(request), dict(obj), dict(controllers), config,
                       time_mode, start_ns, hold_s, grasp, rate, after_fault)


def _grasp_keywords(path, request: dict, obj: dict) -> dict:
    """Give simulate_grasp's keywords for the recorded request and object.

    They are read as sim/set_object reads them: a lift only with a duration, a fault checked as
    the plant checks it.
    """
    out = {name: float(request.get(name, 0.0)) for name in REQUEST_FIELDS}
    for name, keyword in OBJECT_FIELDS.items():
        if name in obj:
            out[keyword] = float(obj[name])
    # the configured friction: asked for (default_friction), or a bag from before that field,
    # whose 0 meant it
    for name in FRICTION_FIELDS:
        given = float(obj.get(name, 0.0))
        asked = float(obj['default_friction']) if 'default_friction' in obj else given == 0.0
        out[name] = None if asked else given
    try:
        if float(obj.get('lift_duration_s', 0.0)) > 0.0:
            values = [float(obj.get(name, 0.0)) for name in LIFT_FIELDS]
            if values[3] != int(values[3]):
                raise ValueError(f'lift_profile must be a LiftProfile code, got {values[3]!r}')
            values[3] = int(values[3])
            out['lift'] = Lift(*values)
            out['announce'] = bool(obj.get('announce_lift', False))
        kind = int(obj.get('fault', 0))
        if kind != obj.get('fault', 0):
            raise ValueError(f'fault must be a FaultKind code, got {obj["fault"]!r}')
        if kind != FaultKind.NONE:
            at_s, tau = (float(obj.get(name, 0.0)) for name in FAULT_FIELDS[1:])
            check_fault(kind, at_s, tau, GraspObject(
                0.0, float(obj.get('stiffness_n_per_m', 0.0))).rigid)
            out['fault'] = (FaultKind(kind), at_s, tau)
    except ValueError as exc:
        raise RerunError(f'{path}: the recorded object cannot be placed again: '
                         f'{one_line(exc)}') from None
    return out


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value):
        raise RerunError(f'{what} must be a finite number, got {value!r}')
    return float(value)


# --- the changes -------------------------------------------------------------------------------

def parse_assignment(text: str, option: str = '--set') -> tuple[str, Any]:
    """``SECTION.KEY=VALUE`` -> (dotted key, value read as YAML); ConfigError when malformed."""
    key, sep, value = text.partition('=')
    key = key.strip()
    if not sep or not key or not value.strip() or '.' not in key:
        raise ConfigError(f'bad {option} {text!r} (expected SECTION.KEY=VALUE)')
    return key, _value(value.strip())


def parse_sweep(text: str) -> tuple[str, list]:
    """``SECTION.KEY=V1,V2,...`` -> (dotted key, values); ConfigError when malformed."""
    key, _ = parse_assignment(text, '--sweep')
    values = [v.strip() for v in text.partition('=')[2].split(',')]
    if not values or any(not v for v in values):
        raise ConfigError(f'bad --sweep {text!r} (expected SECTION.KEY=V1,V2,...)')
    return key, [_value(v) for v in values]


def _value(text: str):
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    if isinstance(value, str):
        try:
            return float(value)             # YAML 1.1 reads 1e5 as a string
        except ValueError:
            pass
    return value


def apply_settings(data: dict, settings: Sequence[tuple[str, Any]], source: str) -> dict:
    """Copy the config mapping ``data`` with each dotted key set to its value.

    A key must be one the mapping holds (as a node declares only the keys of its config file
    as parameters); ConfigError names an unknown key and what its section holds.
    """
    out = copy.deepcopy(data)
    for key, value in settings:
        section, leaf = dotted_section(out, key, source)
        if isinstance(section[leaf], dict):
            raise ConfigError(f'"{key}" is a section of {source}, not a value (it has: '
                              f'{", ".join(sorted(section[leaf]))})')
        section[leaf] = value
    return out


@dataclass
class Changes:
    """What to change for a re-run (None or empty: as recorded)."""

    config_path: str | None = None
    settings: list[tuple[str, Any]] = field(default_factory=list)
    position_controller: str | None = None
    force_controller: str | None = None
    approach_force_margin: float | None = None


@dataclass
class RerunSetup:
    """The configuration and controllers of one re-run, and how they differ from the record."""

    config: GripperConfig
    position_controller: str
    force_controller: str
    approach_force_margin: float
    changes: list[str]                  # one line per difference from the recording


def resolve(record: GraspRecord, changes: Changes | None = None) -> RerunSetup:
    """Build the re-run's configuration and controllers; ConfigError (one line) if unusable."""
    changes = changes or Changes()
    base = record.config
    if changes.config_path:
        base = load_resim_config(changes.config_path)
    data = apply_settings(base.data, changes.settings, base.source) if changes.settings \
        else base.data
    source = base.source + (' with ' + ', '.join(f'{k}={v}' for k, v in changes.settings)
                            if changes.settings else '')
    try:
        config = parse_config(copy.deepcopy(data), source)
    except ConfigError as exc:
        raise ConfigError(one_line(exc)) from None
    rec = record.controllers
    position = changes.position_controller or rec.get('position_controller') or \
        DEFAULT_POSITION_CONTROLLER.value
    force = changes.force_controller or rec.get('force_controller') or \
        DEFAULT_FORCE_CONTROLLER.value
    margin = changes.approach_force_margin
    if margin is None:
        margin = rec.get('approach_force_margin', DEFAULT_APPROACH_FORCE_MARGIN)
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or \
            not (math.isfinite(margin) and margin >= 0.0):
        raise ConfigError(f'approach_force_margin must be finite and >= 0, got {margin!r}')
    position_stage, force_stage = build_stages(config, position, force, float(margin))
    for key, value in changes.settings:
        _check_read(base, key, value, position_stage.kind.value, force_stage.kind.value,
                    float(margin))
    _request(record, config)            # the re-run's supervisor must accept the request
    out = RerunSetup(config, position_stage.kind.value, force_stage.kind.value,
                     float(force_stage.approach_margin), [])
    before, after = flatten(record.config.data), flatten(config.data)
    for key in sorted(set(before) | set(after)):
        if before.get(key, '(none)') != after.get(key, '(none)'):
            out.changes.append(f'{key} {before.get(key, "(none)")} -> {after.get(key, "(none)")}')
    recorded = (rec.get('position_controller') or DEFAULT_POSITION_CONTROLLER.value,
                rec.get('force_controller') or DEFAULT_FORCE_CONTROLLER.value,
                float(rec.get('approach_force_margin', DEFAULT_APPROACH_FORCE_MARGIN)))
    for name, was, now in zip(('position_controller', 'force_controller',
                               'approach_force_margin'), recorded,
                              (out.position_controller, out.force_controller,
                               out.approach_force_margin)):
        if was != now:
            out.changes.append(f'{name} {was:g} -> {now:g}' if isinstance(now, float)
                               else f'{name} {was} -> {now}')
    return out


_STAGE_SECTIONS = {'position_control': ('position', PositionControllerKind),
                   'force_control': ('force', ForceControllerKind)}
"""The config sections the stage controllers read: which stage, and its kinds."""


def _stage_bytes(config: GripperConfig, stage: str, kind: str, margin: float):
    """Return what a stage built from ``config`` holds (its records' bytes), or why it fails."""
    try:
        built = build_stages(config, **{f'{stage}_controller': kind,
                                        'approach_force_margin': margin})
    except ConfigError as exc:
        return str(exc)
    return tuple(np.asarray(a).tobytes() for a in built[stage == 'force'].kernel)


def _check_read(base: GripperConfig, key: str, value, position: str, force: str,
                margin: float) -> None:
    """Refuse (ConfigError) a ``--set`` of a stage key the re-run's controller does not read.

    A controller reads a key when setting it changes the controller built from the config;
    the refusal names the controllers that do read it. A key no stage reads (the paper's
    gains, a key of another section) passes: the plant or the supervisor may read it.
    """
    section = key.split('.', 1)[0]
    if section not in _STAGE_SECTIONS:
        return
    stage, kinds = _STAGE_SECTIONS[section]
    try:
        changed = parse_config(apply_settings(base.data, [(key, value)], base.source))
    except ConfigError:
        return                              # the whole change is checked (and refused) above
    chosen = position if stage == 'position' else force
    readers = [k.value for k in kinds
               if _stage_bytes(base, stage, k.value, margin)
               != _stage_bytes(changed, stage, k.value, margin)]
    if readers and chosen not in readers:
        raise ConfigError(f'{key} is not read by the {stage} controller of this re-run '
                          f'({chosen}); {" and ".join(readers)} '
                          f'{"reads" if len(readers) == 1 else "read"} it: add '
                          f'--{stage}-controller {readers[0]}')


def _request(record: GraspRecord, config: GripperConfig) -> None:
    """Refuse (ConfigError) a configuration whose supervisor refuses the recorded request."""
    r = record.request
    request = GraspRequest(*(float(r.get(name, 0.0)) for name in REQUEST_FIELDS))
    try:
        validate_request(request, config.plant, config.supervisor, config.load_grip)
    except RequestError as exc:
        raise ConfigError(f"{config.source}: the re-run's supervisor refuses the recorded "
                          f'request: {one_line(exc)}') from None


RECORDING_TOLERANCE = 1e-6
"""How near a closed-loop re-run must come to a bag whose bits it cannot give: a bag recorded by
an earlier core, whose linear algebra took the CPU's BLAS kernels. Each float field within this
fraction of its series' full scale; stamps, phases, states and codes exact. A 1-ulp change in a
model's coefficient grows in the force loop to 4e-6 of a field's value near its zero crossings,
and to at most 3.4e-8 of its full scale (docs/ARCHITECTURE.md, "Same results on every CPU")."""


# --- the re-run --------------------------------------------------------------------------------

@dataclass
class Rerun:
    """One closed-loop re-run: its setup, the headless grasp, its series and figures.

    ``difference`` is '' when the re-run equals the recording bit for bit, else where it first
    differs; None when changes were applied (nothing to hold it to). ``agreement`` is the same
    judgement within :data:`RECORDING_TOLERANCE` (only computed when the bits differ).
    """

    setup: RerunSetup
    headless: HeadlessGrasp
    series: GraspSeries
    metrics: GraspMetrics
    difference: str | None = None
    agreement: str | None = None
    value: Any = None                   # the swept value (a sweep's row)


def _as_recorded(series: GraspSeries, record: GraspRecord, first_ns: int, start_ns: int,
                 label: str, config: GripperConfig) -> GraspSeries:
    """Return a re-run's series from tick ``first_ns`` on, numbered as the recording is.

    Its object and configuration (``custom_data``) are the recording's object and the
    re-run's ``config``, so figures that read them (the lift-off's end) see this re-run.

    The object's ground truth from the grasp's start ``start_ns`` on (the plant published
    the idle tick's when the object was placed, before the recording began); the grasp id,
    stage id and revision go on from the recording's at the grasp's start.
    """
    rec = record.series.references
    first = np.flatnonzero(rec['stamp_ns'] == record.grasp_start_ns)[0]
    ticks, refs, cmds, statuses = (rows[rows['stamp_ns'] >= first_ns] for rows in (
        series.ticks, series.references, series.commands, series.statuses))
    ours = refs[refs['stamp_ns'] == start_ns]
    if ours.size:
        shift = {name: int(rec[name][first]) - int(ours[0][name])
                 for name in ('grasp_id', 'stage_id', 'revision')}
        ticks = _shifted(ticks, {'revision': shift['revision']})
        refs = _shifted(refs, shift)
        cmds = _shifted(cmds, shift)
        statuses = _shifted(statuses, {name: shift[name] for name in ('grasp_id', 'stage_id')})
    stamps = ticks['stamp_ns']
    return replace(series, ticks=ticks, references=refs, commands=cmds, statuses=statuses,
                   objects=series.objects[series.objects['stamp_ns'] >= start_ns],
                   tick_states=None, path=Path(label), namespace=record.series.namespace,
                   custom_data={'object': dict(record.obj), 'config': config.data},
                   start_ns=int(stamps[0]) if stamps.size else first_ns,
                   end_ns=int(stamps[-1]) if stamps.size else first_ns)


def _shifted(rows: np.ndarray, shift: dict[str, int]) -> np.ndarray:
    """Return ``rows`` with the named integer fields moved by their shift (no wrap-around)."""
    out = rows.copy()
    for name, by in shift.items():
        out[name] = rows[name].astype(np.int64) + by
    return out


def run(record: GraspRecord, setup: RerunSetup, label: str = 're-run') -> Rerun:
    """Grasp again, headless, with ``setup``.

    One position tick before the recorded grasp's first tick the fingers are fully open at
    rest, as when the graph placed the object.
    """
    state_period_ns = round(1e9 / record.state_rate_hz)
    # the tick before the grasp: the position stage's hold, or 0 V for a state period (FAULT)
    idle_ns = state_period_ns if record.after_fault else \
        round(record.config.position.sample_time_s * 1e9)
    try:
        h = simulate_grasp(setup.config, start_ns=record.grasp_start_ns - idle_ns,
                           idle_unpowered_s=idle_ns * 1e-9 if record.after_fault else 0.0,
                           hold_s=record.hold_s, position_controller=setup.position_controller,
                           force_controller=setup.force_controller,
                           approach_force_margin=setup.approach_force_margin,
                           trace_state_period_ns=state_period_ns,
                           **record.grasp)
    except RequestError as exc:
        raise ConfigError(f"{setup.config.source}: the re-run's supervisor refuses the "
                          f'recorded request: {one_line(exc)}') from None
    except ValueError as exc:
        raise RerunError(f'{record.path}: the recorded object cannot be placed again: '
                         f'{one_line(exc)}') from None
    recorded_ticks = record.series.ticks['stamp_ns']
    first_ns = max(int(recorded_ticks[0]), int(h.series.ticks['stamp_ns'][0])) \
        if recorded_ticks.size else h.start_ns
    series = _as_recorded(h.series, record, first_ns, h.start_ns, label, setup.config)
    metrics = analyze_series(series, setup.config.plant.voltage_limit_v)
    metrics.bag = label
    out = Rerun(setup, h, series, metrics)
    if not setup.changes and not record.truncated:
        out.difference = series_difference(record.series, series, first_ns, h.start_ns)
        out.agreement = out.difference and series_difference(
            record.series, series, first_ns, h.start_ns, tolerance=RECORDING_TOLERANCE)
    return out


def _bits(values: np.ndarray) -> np.ndarray:
    values = np.ascontiguousarray(values)
    return values.view(np.int64) if values.dtype == np.float64 else values


def _first_apart(a: np.ndarray, b: np.ndarray, tolerance: float) -> np.ndarray:
    """Return where ``a`` and ``b`` differ: in their bits, or beyond ``tolerance`` of full scale.

    With ``tolerance`` 0, or for integers, any bit counts; otherwise a float may stand within
    ``tolerance`` times the recorded series' largest magnitude (NaN only equals NaN).
    """
    if tolerance == 0.0 or a.dtype != np.float64:
        return np.flatnonzero(_bits(a) != _bits(b))
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    finite = np.abs(a[~nan_a])
    scale = float(finite.max()) if finite.size else 0.0
    with np.errstate(invalid='ignore'):
        apart = ~(np.abs(a - b) <= tolerance * scale)
    return np.flatnonzero(np.where(nan_a | nan_b, nan_a != nan_b, apart))


FLAGS = ('running', 'contact', 'finite')
"""The loop messages' fields that are yes or no (a byte on the wire)."""


def _widened(column: np.ndarray, name: str) -> np.ndarray:
    """Return a message field's column as numbers are compared and shown: int64, or bool."""
    if column.dtype.kind in 'ui' and column.dtype != np.int64:
        return column.astype(bool if name in FLAGS else np.int64)
    return column


def series_difference(recorded: GraspSeries, rerun: GraspSeries, first_ns: int,
                      objects_from_ns: int | None = None, tolerance: float = 0.0) -> str:
    """Say where the re-run first differs from the recording ('' when nowhere).

    Every field of every tick, reference and command of the recording from tick ``first_ns``
    on, and of every object state from ``objects_from_ns`` (default the same), is compared with
    the re-run's, but fields the bag's own message types lack: bit for bit, or with
    ``tolerance`` > 0 each float within that fraction of its series' full scale (stamps,
    phases, states and codes stay exact). The answer is one line.
    """
    within = f' (beyond {tolerance:g} of full scale)' if tolerance else ''
    for kind, rec, new in (('tick', recorded.ticks, rerun.ticks),
                           ('reference', recorded.references, rerun.references),
                           ('command', recorded.commands, rerun.commands),
                           ('object state', recorded.objects, rerun.objects)):
        from_ns = objects_from_ns if kind == 'object state' and objects_from_ns is not None \
            else first_ns
        keep = rec['stamp_ns'] >= from_ns
        count = int(np.count_nonzero(keep))
        if count != new['stamp_ns'].size:
            return (f'{count} {kind}s recorded from t = {from_ns * 1e-9:.4f} s, '
                    f'{new["stamp_ns"].size} re-run')
        for name in rec.dtype.names:
            column = _widened(rec[name], name)
            if f'{kind}.{name}' in recorded.absent:
                continue                    # the bag's (older) message type has no such field
            a = np.ascontiguousarray(column[keep])
            b = np.ascontiguousarray(_widened(new[name], name))
            differ = _first_apart(a, b, tolerance)
            if differ.size:
                i = differ[0]
                return (f'{kind} {name} differs first at t = '
                        f'{rec["stamp_ns"][keep][i] * 1e-9:.4f} s ({kind} {i}){within}: '
                        f'{column[keep][i]!r} recorded, {new[name][i]!r} re-run')
    return ''


@dataclass
class WhatIf:
    """A recording and its re-runs (one, or one per value of a sweep)."""

    record: GraspRecord
    recorded: GraspMetrics
    reruns: list[Rerun]
    sweep_key: str | None = None

    @property
    def recorded_value(self):
        """The swept key's value in the recorded configuration."""
        if self.sweep_key is None:
            return None
        return flatten(self.record.config.data).get(self.sweep_key)


def _run_value(record: GraspRecord, item: tuple) -> Rerun:
    """One re-run of a sweep (module level: it runs in worker processes)."""
    value, setup, label = item
    r = run(record, setup, label)
    r.value = value
    return r


def whatif(bag: Bag | str | os.PathLike, changes: Changes | None = None,
           sweep: tuple[str, Sequence] | None = None, jobs: int | None = None, *,
           scheduler: str | None = None, progress=None) -> WhatIf:
    """Re-run a recorded grasp with ``changes``, once or once per value of ``sweep``.

    ``sweep`` = (dotted key, values) is applied on top of the changes; its re-runs go to
    ``jobs`` local processes (None: one per core) or the Dask cluster at ``scheduler`` by the
    batch engine (:func:`gripper_ros.core.runtime.engine.map_cases`, with its ``progress``). Every
    setup is checked before the first re-run: RerunError (the bag) or ConfigError (an option,
    key or value), one line.
    """
    record = load_record(bag)
    recorded = analyze_series(record.series, record.config.plant.voltage_limit_v)
    changes = changes or Changes()
    if sweep is None:
        setups = [(None, resolve(record, changes))]
    else:
        key, values = sweep
        setups = []
        for value in values:
            one = copy.copy(changes)
            one.settings = list(changes.settings) + [(key, value)]
            setups.append((value, resolve(record, one)))
    items = [(value, setup, 're-run' if sweep is None else f're-run {sweep[0]}={value}')
             for value, setup in setups]
    reruns = map_cases(functools.partial(_run_value, record), items,
                       1 if sweep is None else jobs,
                       scheduler=None if sweep is None else scheduler, progress=progress)
    return WhatIf(record, recorded, reruns, None if sweep is None else sweep[0])


def series_nrmse(recorded: GraspSeries, rerun: GraspSeries) -> dict[str, float]:
    """NRMSE of the re-run's position and force against the recording's, tick by tick.

    Over the ticks both have at the same instant; RMS difference over the recording's range.
    """
    from gripper_ros.identify.fit import nrmse
    a, b = recorded.ticks, rerun.ticks
    if not a.size or not b.size:
        return {}
    _, ia, ib = np.intersect1d(a['stamp_ns'], b['stamp_ns'], return_indices=True)
    out = {}
    for name in ('position_m', 'force_n'):
        rec = np.asarray(a[name], dtype=float)
        span = float(np.nanmax(rec) - np.nanmin(rec)) if rec.size else 0.0
        out[name] = nrmse(np.asarray(b[name], dtype=float)[ib], rec[ia], span)
    return out
