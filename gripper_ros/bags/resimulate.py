"""Open-loop re-simulation of a grasp bag, its commands compared with the recorded ones.

The recorded measurements go through the controllers of a configuration, tick by tick exactly
as the controller nodes answer them.

``bag_replay BAG --resimulate [CONFIG.yaml]`` (or :func:`resimulate_bag`):

1. every stage reference of the bag (``<ns>/loop/position_reference`` and
   ``<ns>/loop/force_reference``, each with its tick's measurement), in recorded order, goes to
   the stage it names (:class:`gripper_ros.core.runtime.lockstep.StageSide`, the code the nodes
   run);
2. each answer is compared with the recorded ``<ns>/loop/motor_command`` of the same
   (source, stage, stamp).

Bags recorded before the lockstep protocol carry a status per tick and the measurements on
their own topics; their references are rebuilt from those (a new stage whenever the active
controller or the grasp changed, as those controllers restarted), and a tick whose measurement
is not in the bag (the first of a grasp) uses the supervisor's copy in the status (counted as
``measurements_from_status``).

OPEN LOOP: the plant is not re-run. The measurements are the recorded ones whatever the
re-simulated controller commands, and the supervisor's decisions (switch tick, contact, seed
voltage, end of the grasp) are the recorded ones too. With the configuration (and controller
kinds) the bag was recorded with the commands are bit-identical; with changed gains the
differences show what the new controller would have commanded *at the first ticks where it
differs*; after that the recorded measurements no longer belong to the re-simulated commands.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import json
import math
import os
from pathlib import Path
import struct
from typing import Any

from gripper_ros.bags.reader import Bag, BagError, open_bag
from gripper_ros.bags.series import (bag_namespace, LEGACY_MOTOR_COMMAND, LEGACY_MOTOR_STATE,
                                     LEGACY_NAMESPACE, LEGACY_TOPICS)
from gripper_ros.core.config import ConfigError, default_config_path, GripperConfig, parse_config
from gripper_ros.core.control.stages import (ForceStageController, PositionStageController,
                                             Reference, SOURCE_FORCE, SOURCE_POSITION)
from gripper_ros.core.runtime.lockstep import StageSide
from gripper_ros.text import one_line
from gripper_ros.wire import (COMMAND_LAYOUT, DEFAULT_APPROACH_FORCE_MARGIN,
                              DEFAULT_FORCE_CONTROLLER, DEFAULT_POSITION_CONTROLLER,
                              ForceControllerKind, PositionControllerKind, qualified,
                              REFERENCE_LAYOUT, stamp_ns, TOPIC_FORCE_REFERENCE,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_POSITION_REFERENCE, TOPIC_STATUS)
import yaml

OPEN_LOOP_NOTE = ('open loop: the recorded measurements and supervisor decisions are replayed; '
                  'the plant is NOT re-run, so they do not respond to changed commands')
STAGE_NAMES = {SOURCE_POSITION: 'position', SOURCE_FORCE: 'force'}


class NothingToResimulateError(BagError):
    """A bag in which no controller was ever named active."""


def _bits(value: float) -> int:
    return struct.unpack('<q', struct.pack('<d', float(value)))[0]


@dataclass
class StageComparison:
    """Re-simulated vs recorded commands of one controller (one stage) over the whole bag."""

    stage: str
    source: int
    recorded: int = 0               # recorded commands of this source
    resimulated: int = 0            # ticks the re-simulated controller answered
    compared: int = 0               # ticks present in both
    only_recorded: int = 0          # recorded commands with no re-simulated answer
    only_resimulated: int = 0       # re-simulated answers with no recorded command
    differing: int = 0              # compared ticks whose voltage differs (bitwise)
    max_abs_dv_v: float = 0.0       # max |V_resim - V_recorded| over compared ticks
    rms_dv_v: float = 0.0           # RMS of V_resim - V_recorded over compared ticks
    max_abs_d_inner: float = 0.0    # same for the inner setpoint (DMC output / setpoint)
    first_diff_tick: int | None = None      # index among this stage's compared ticks
    first_diff_t_s: float | None = None     # simulated time (header stamp) of that tick
    first_diff_recorded_v: float | None = None
    first_diff_resimulated_v: float | None = None
    hold_s_recorded: float | None = None    # hold_s of the recorded commands (first one)
    hold_s_config: float | None = None      # sample time of the re-simulated controller
    nonfinite_measurements: int = 0         # ticks answered with 0 V (non-finite measurement)

    @property
    def identical(self) -> bool:
        return (self.differing == 0 and self.only_recorded == 0 and self.only_resimulated == 0)


@dataclass
class ResimulationReport:
    bag: str
    config: str
    position_controller: str
    force_controller: str
    approach_force_margin: float
    grasp_ids: list[int]
    status_ticks: int
    measurements_from_status: int
    truncated: bool
    stages: dict[str, StageComparison] = field(default_factory=dict)
    note: str = OPEN_LOOP_NOTE
    ticks: list[dict] = field(default_factory=list, repr=False)   # per tick, with keep_ticks

    @property
    def identical(self) -> bool:
        """Every command bit-identical and no tick only on one side."""
        return all(s.identical for s in self.stages.values())

    def to_dict(self, with_ticks: bool = False) -> dict[str, Any]:
        out = {k: v for k, v in asdict(self).items() if k not in ('stages', 'ticks')}
        out['identical'] = self.identical
        out['stages'] = {name: {**asdict(s), 'identical': s.identical}
                         for name, s in self.stages.items()}
        if with_ticks:
            out['ticks'] = self.ticks
        return out


def _json_value(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    if isinstance(value, dict):
        return {k: _json_value(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_value(v) for v in value]
    return value


def to_json(report: ResimulationReport, with_ticks: bool = False) -> str:
    return json.dumps(_json_value(report.to_dict(with_ticks)), indent=2)


def load_resim_config(config_path: str | os.PathLike | None) -> GripperConfig:
    """Read the configuration to re-simulate with (None or '' = the installed default).

    It is read like :func:`gripper_ros.core.config.load_config`; ConfigError with a one-line
    message.
    """
    path = Path(config_path) if config_path else default_config_path()
    try:
        text = path.read_text(encoding='utf-8')
    except IsADirectoryError:
        raise ConfigError(f'cannot read config file {path}: is a directory') from None
    except OSError as exc:
        raise ConfigError(f'cannot read config file {path}: {exc.strerror or exc}') from None
    except UnicodeDecodeError:
        raise ConfigError(f'config file {path} is not UTF-8 text') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        problem = getattr(exc, 'problem', None) or str(exc)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark is not None else ''
        raise ConfigError(f'config file {path} is not valid YAML: '
                          f'{one_line(problem)}{where}') from None
    try:
        return parse_config(data, str(path))
    except ConfigError as exc:
        raise ConfigError(one_line(exc)) from None


def build_stages(config: GripperConfig,
                 position_controller: PositionControllerKind | str = DEFAULT_POSITION_CONTROLLER,
                 force_controller: ForceControllerKind | str = DEFAULT_FORCE_CONTROLLER,
                 approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN):
    """Build the two stage controllers exactly as the nodes build them.

    ConfigError when the configuration cannot give a controller (e.g. a force pole faster than
    the loop allows).
    """
    try:
        return (PositionStageController(config, position_controller),
                ForceStageController(config, force_controller, approach_force_margin))
    except ConfigError:
        raise
    except (ValueError, ArithmeticError, ImportError) as exc:
        raise ConfigError(f'{config.source}: cannot build the controllers: '
                          f'{one_line(exc)}') from None


def resimulate_bag(bag: Bag | str | os.PathLike, config: GripperConfig | str | os.PathLike | None,
                   position_controller: PositionControllerKind | str = DEFAULT_POSITION_CONTROLLER,
                   force_controller: ForceControllerKind | str = DEFAULT_FORCE_CONTROLLER,
                   approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN,
                   keep_ticks: bool = False) -> ResimulationReport:
    """Re-simulate every controller tick of ``bag`` with ``config``; compare with the recording.

    ``config`` is a GripperConfig, a YAML path, or None for the installed default.
    Raises BagError (one line) for an unusable bag and ConfigError (one line) for an unusable
    configuration. A truncated bag is re-simulated up to the damage (``report.truncated``).
    With ``keep_ticks`` the report holds one row per compared tick (for plots and debugging).
    """
    if not isinstance(config, GripperConfig):
        config = load_resim_config(config)
    position, force = build_stages(config, position_controller, force_controller,
                                   approach_force_margin)
    bag = open_bag(bag)
    fmt, ns = bag_namespace(bag)
    refs, recorded, recorded_order, from_status, status_ticks = (
        _lockstep_ticks(bag, ns) if fmt == 2 else _legacy_ticks(bag))
    stages = {SOURCE_POSITION: position, SOURCE_FORCE: force}
    sides = {src: StageSide(stage) for src, stage in stages.items()}
    answers: dict[tuple[int, int, int], Any] = {}
    nonfinite = {SOURCE_POSITION: 0, SOURCE_FORCE: 0}
    grasp_ids: list[int] = []
    for ref in refs:
        side = sides.get(int(ref.controller))
        if side is None:
            continue
        cmd = side.answer(ref)
        if cmd is None:
            continue
        if int(ref.grasp_id) not in grasp_ids:
            grasp_ids.append(int(ref.grasp_id))
        if not cmd.finite:
            nonfinite[int(ref.controller)] += 1
        answers[(int(ref.controller), int(ref.stage_id), int(ref.stamp_ns))] = cmd
    if not answers:
        raise NothingToResimulateError(f'{bag.path}: no supervisor decision names a controller '
                                       f'(no grasp tick to re-simulate)')

    report = ResimulationReport(
        bag=str(bag.path), config=str(config.source),
        position_controller=position.kind.value, force_controller=force.kind.value,
        approach_force_margin=force.approach_margin, grasp_ids=grasp_ids,
        status_ticks=status_ticks, measurements_from_status=from_status,
        truncated=bag.truncated)
    # A truncated bag may end with a tick whose status and measurement were written but whose
    # command was cut off: answers past the last recorded command are beyond the damage.
    last_recorded = (max(k[1:] for k in recorded) if bag.truncated and recorded
                     else (math.inf, math.inf))
    for src, stage in stages.items():
        cmp = StageComparison(stage=STAGE_NAMES[src], source=src,
                              hold_s_config=stage.sample_time_s)
        cmp.recorded = len(recorded_order[src])
        cmp.resimulated = sum(1 for k in answers if k[0] == src)
        cmp.nonfinite_measurements = nonfinite[src]
        sq_sum = 0.0
        for key in recorded_order[src]:
            rec = recorded[key]
            if cmp.hold_s_recorded is None:
                cmp.hold_s_recorded = float(rec.hold_s)
            sim = answers.get(key)
            if sim is None:
                cmp.only_recorded += 1
                continue
            index = cmp.compared
            cmp.compared += 1
            rec_v, sim_v = float(rec.voltage_v), float(sim.voltage_v)
            dv = sim_v - rec_v
            same = _bits(rec_v) == _bits(sim_v)
            if not same:
                cmp.differing += 1
                if cmp.first_diff_tick is None:
                    cmp.first_diff_tick = index
                    cmp.first_diff_t_s = key[2] * 1e-9
                    cmp.first_diff_recorded_v = rec_v
                    cmp.first_diff_resimulated_v = sim_v
                if math.isfinite(dv):
                    sq_sum += dv * dv
                    cmp.max_abs_dv_v = max(cmp.max_abs_dv_v, abs(dv))
                else:                                        # NaN/inf on one side only
                    cmp.max_abs_dv_v = math.inf
                    sq_sum = math.inf
            d_inner = float(sim.inner_setpoint) - float(rec.inner_setpoint)
            if d_inner != 0.0:
                cmp.max_abs_d_inner = max(cmp.max_abs_d_inner,
                                          abs(d_inner) if math.isfinite(d_inner) else math.inf)
            if keep_ticks:
                report.ticks.append({'stage': cmp.stage, 'stage_id': key[1], 't_s': key[2] * 1e-9,
                                     'recorded_v': rec_v, 'resimulated_v': sim_v,
                                     'recorded_inner': float(rec.inner_setpoint),
                                     'resimulated_inner': float(sim.inner_setpoint)})
        cmp.only_resimulated = sum(1 for k in answers if k[0] == src and k not in recorded
                                   and k[1:] <= last_recorded)
        cmp.rms_dv_v = math.sqrt(sq_sum / cmp.compared) if cmp.compared else 0.0
        report.stages[cmp.stage] = cmp
    return report


def _lockstep_ticks(bag: Bag, ns: str):
    """Return the references and recorded commands of a lockstep bag (repeated ticks once)."""
    ref_topics = {qualified(ns, TOPIC_POSITION_REFERENCE), qualified(ns, TOPIC_FORCE_REFERENCE)}
    cmd_topic = qualified(ns, TOPIC_MOTOR_COMMAND)
    bag.require_topics([cmd_topic])
    refs, seen = [], set()
    recorded: dict[tuple[int, int, int], Any] = {}
    order: dict[int, list] = {SOURCE_POSITION: [], SOURCE_FORCE: []}
    for raw in bag.messages:
        if raw.topic in ref_topics:
            values = REFERENCE_LAYOUT.unpack(raw.data) or tuple(   # older types: 0 limits
                getattr(bag.decode(raw), n, 0.0) for n in REFERENCE_LAYOUT.fields)
            ref = Reference._make(values)
            key = (ref.stage_id, ref.stamp_ns)
            if key not in seen:
                seen.add(key)
                refs.append(ref)
        elif raw.topic == cmd_topic:
            values = COMMAND_LAYOUT.unpack(raw.data) or tuple(
                getattr(bag.decode(raw), n) for n in COMMAND_LAYOUT.fields)
            c = dict(zip(COMMAND_LAYOUT.fields, values))
            cmd = _RecordedCommand(c['source'], c['stage_id'], c['stamp_ns'], c['voltage_v'],
                                   c['hold_s'], c['inner_setpoint'])
            key = (int(cmd.source), int(cmd.stage_id), int(cmd.stamp_ns))
            if key not in recorded and cmd.source in order:
                order[cmd.source].append(key)
                recorded[key] = cmd
    if not refs:
        raise NothingToResimulateError(f'{bag.path}: no stage reference in the bag')
    refs.sort(key=lambda r: (r.stamp_ns, r.stage_id))        # tick order, whatever DDS did
    for source in order:
        order[source].sort(key=lambda key: (key[2], key[1]))
    return refs, recorded, order, 0, len(refs)


@dataclass(frozen=True)
class _RecordedCommand:
    source: int
    stage_id: int
    stamp_ns: int
    voltage_v: float
    hold_s: float
    inner_setpoint: float


def _legacy_ticks(bag: Bag):
    """Return references rebuilt from a bag of the earlier protocol, and its recorded commands."""
    topic = {name: qualified(LEGACY_NAMESPACE, name) for name in LEGACY_TOPICS
             if name != LEGACY_MOTOR_STATE}          # the re-simulation needs no motor_state
    bag.require_topics(list(topic.values()))
    joint_at: dict[int, tuple[float, float]] = {}
    force_at: dict[int, float] = {}
    statuses, commands = [], []
    for raw in bag.messages:
        if raw.topic == topic[TOPIC_JOINT_STATES]:
            m = bag.decode(raw)
            joint_at[stamp_ns(m.header.stamp)] = (
                m.position[0] if len(m.position) else math.nan,
                m.velocity[0] if len(m.velocity) else 0.0)
        elif raw.topic == topic[TOPIC_FORCE_SENSOR]:
            m = bag.decode(raw)
            force_at[stamp_ns(m.header.stamp)] = m.force_n
        elif raw.topic == topic[TOPIC_STATUS]:
            statuses.append(bag.decode(raw))
        elif raw.topic == topic[LEGACY_MOTOR_COMMAND]:
            commands.append(bag.decode(raw))
    refs, stage_of, from_status = [], {}, 0
    stage, current = 0, None
    for s in statuses:
        stamp, active = stamp_ns(s.header.stamp), int(s.active_controller)
        if (int(s.grasp_id), active) != current:
            current = (int(s.grasp_id), active)
            stage += 1
        if active not in (SOURCE_POSITION, SOURCE_FORCE):
            continue
        stage_of[(active, int(s.grasp_id), stamp)] = stage
        position, velocity = joint_at.get(stamp, (s.position_m, 0.0))
        force_n = force_at.get(stamp, s.force_n)
        if stamp not in (joint_at if active == SOURCE_POSITION else force_at):
            from_status += 1                    # the first tick: published before recording
        refs.append(Reference(stamp, int(s.grasp_id), stage, 0, int(s.phase), int(s.outcome),
                              active, s.outcome == 0, bool(s.contact), s.position_setpoint_m,
                              getattr(s, 'approach_setpoint_m', s.position_setpoint_m),
                              s.force_setpoint_n, position, velocity, force_n, s.seed_voltage_v))
    recorded: dict[tuple[int, int, int], Any] = {}
    order: dict[int, list] = {SOURCE_POSITION: [], SOURCE_FORCE: []}
    for m in commands:
        stamp = stamp_ns(m.header.stamp)
        stage_id = stage_of.get((int(m.source), int(m.grasp_id), stamp), -1)
        cmd = _RecordedCommand(int(m.source), stage_id, stamp, float(m.voltage_v),
                               float(m.hold_s), float(m.inner_setpoint))
        key = (cmd.source, cmd.stage_id, cmd.stamp_ns)
        if key not in recorded and cmd.source in order:
            order[cmd.source].append(key)
            recorded[key] = cmd
    return refs, recorded, order, from_status, len(statuses)


# --- text output ------------------------------------------------------------------------------

def _g(value, fmt: str = '.6g') -> str:
    if value is None:
        return '-'
    if isinstance(value, float) and math.isnan(value):
        return 'nan'
    return format(value, fmt)


def to_table(report: ResimulationReport) -> str:
    """Terminal report: header, one row per stage, verdict, open-loop note."""
    lines = [
        f'bag:         {report.bag}' + ('  (TRUNCATED: re-simulated up to the damage)'
                                        if report.truncated else ''),
        f'config:      {report.config}',
        f'controllers: position {report.position_controller}, force {report.force_controller}, '
        f'approach_force_margin {report.approach_force_margin:g}',
        f'grasp ids:   {", ".join(str(g) for g in report.grasp_ids)}   status ticks: '
        f'{report.status_ticks}   first-tick measurements from status: '
        f'{report.measurements_from_status}',
        '',
    ]
    header = ['stage', 'recorded', 'resim', 'compared', 'differing', 'max|dV| (V)',
              'RMS dV (V)', 'max|d inner|', 'first differing tick']
    rows = []
    for s in report.stages.values():
        first = ('-' if s.first_diff_tick is None else
                 f'#{s.first_diff_tick} t={s.first_diff_t_s:.4f} s: '
                 f'{s.first_diff_recorded_v:.6g} -> {s.first_diff_resimulated_v:.6g} V '
                 f'(dV {s.first_diff_resimulated_v - s.first_diff_recorded_v:+.3g})')
        rows.append([s.stage, str(s.recorded), str(s.resimulated), str(s.compared),
                     str(s.differing), _g(s.max_abs_dv_v), _g(s.rms_dv_v),
                     _g(s.max_abs_d_inner), first])
    widths = [max(len(r[c]) for r in [header] + rows) for c in range(len(header))]
    lines.append('  '.join(h.ljust(w) for h, w in zip(header, widths)).rstrip())
    lines.append('  '.join('-' * w for w in widths))
    lines.extend('  '.join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)
    lines.append('')
    for s in report.stages.values():
        extra = []
        if s.only_recorded or s.only_resimulated:
            extra.append(f'{s.only_recorded} recorded tick(s) not answered, '
                         f'{s.only_resimulated} answered tick(s) not recorded')
        if (s.hold_s_recorded is not None and s.hold_s_config is not None
                and s.hold_s_recorded != s.hold_s_config):
            extra.append(f'hold_s {s.hold_s_recorded:g} s recorded vs {s.hold_s_config:g} s in '
                         f'the config (ticks stay the recorded ones)')
        if s.nonfinite_measurements:
            extra.append(f'{s.nonfinite_measurements} non-finite measurement(s): 0 V held')
        for text in extra:
            lines.append(f'{s.stage}: {text}')
    verdict = ('IDENTICAL: every command is bit-identical to the recording' if report.identical
               else 'DIFFERENT: the re-simulated commands differ from the recording')
    lines.append(f'result: {verdict}')
    lines.append(f'note: {report.note}')
    return '\n'.join(lines)
