"""``bag_info``: what ``ros2 bag info`` prints (no rosbag2 here), plus rate, size and the grasp.

Works on damaged bags too: a truncated file is reported with the number of complete messages
recovered instead of failing.
"""
from __future__ import annotations

import argparse
import datetime as dt
import sys
from typing import Any, Sequence

from gripper_ros.bags.reader import (Bag, BagError, EXIT_ERROR, EXIT_TRUNCATED,
                                     quiet_on_closed_pipe, read_bag)
from gripper_ros.wire import Controller, enum_name, Outcome, Phase, SwitchCriterion, TOPIC_STATUS

PROG = 'bag_info'
_LABEL_WIDTH = 19


def format_size(size_bytes: int) -> str:
    """Human size the way ros2 bag info prints it (B, KiB, MiB, GiB)."""
    size = float(size_bytes)
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if size < 1024.0 or unit == 'GiB':
            return f'{size:.0f} {unit}' if unit == 'B' else f'{size:.1f} {unit}'
        size /= 1024.0
    return f'{size_bytes} B'


def format_time(t_ns: int) -> str:
    """Format as 'Jan  1 1970 00:00:01.500000000 (1.500000000)': date plus seconds from 0."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    stamp = dt.datetime.fromtimestamp(sec, tz=dt.timezone.utc)
    return f'{stamp:%b %e %Y %H:%M:%S}.{nsec:09d} ({sec}.{nsec:09d})'


def _line(label: str, value: str) -> str:
    head = f'{label}:' if label else ''
    return f'{head:<{_LABEL_WIDTH - 1}} {value}'


def _format_value(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, dict):
        return '  '.join(f'{k}={_format_value(v)}' for k, v in value.items())
    return str(value)


def _last_status(bag: Bag):
    """Last SupervisorStatus in the bag (the grasp's final decision), or None."""
    last = None
    for raw in bag.messages:
        if raw.topic.endswith('/' + TOPIC_STATUS):
            last = raw
    if last is None:
        return None
    try:
        return bag.decode(last)
    except BagError:
        return None


def grasp_lines(bag: Bag) -> list[str]:
    """Grasp request/outcome from custom_data and the last supervisor status."""
    lines = []
    for key, value in bag.custom_data_parsed().items():
        if key == 'config' and isinstance(value, dict):
            value = f'{len(value)} sections ({", ".join(value)}), as the graph used them'
        lines.append(_line(f'{key}', _format_value(value)))
    status = _last_status(bag)
    if status is not None:
        lines.append(_line('Setpoints', f'position {status.position_setpoint_m:.6g} m, '
                                        f'force {status.force_setpoint_n:.6g} N'))
        lines.append(_line('Last status', (
            f'grasp {status.grasp_id}, phase {enum_name(Phase, status.phase)}, '
            f'active {enum_name(Controller, status.active_controller)}, '
            f'switch {enum_name(SwitchCriterion, status.switch_criterion)}, '
            f'outcome {enum_name(Outcome, status.outcome)}, '
            f'position {status.position_m:.6g} m, force {status.force_n:.6g} N')))
    return lines


def format_info(bag: Bag) -> str:
    """Return the whole report as text."""
    lines = [
        _line('Files', ', '.join(str(f.name) for f in bag.files)),
        _line('Bag size', format_size(bag.size_bytes)),
        _line('Storage id', bag.storage_identifier),
        _line('ROS Distro', bag.ros_distro or 'unknown'),
        _line('Duration', f'{bag.duration_ns * 1e-9:.9f}s'),
        _line('Start', format_time(bag.start_ns)),
        _line('End', format_time(bag.end_ns)),
        _line('Messages', str(bag.message_count)),
    ]
    if bag.truncated:
        lines.append(_line('Truncated', f'truncated: {bag.message_count} complete messages '
                                        f'recovered ({bag.damage})'))
    topics = sorted(bag.topics.values(), key=lambda t: t.name)
    name_w = max((len(t.name) for t in topics), default=0)
    type_w = max((len(t.msgtype) for t in topics), default=0)
    for i, info in enumerate(topics):
        text = (f'Topic: {info.name:<{name_w}} | Type: {info.msgtype:<{type_w}} | '
                f'Count: {info.count} | Serialization Format: {info.serialization_format} | '
                f'Rate: {info.rate_hz:.1f} Hz | Size: {format_size(info.size_bytes)}')
        lines.append(_line('Topic information' if i == 0 else '', text))
    if not topics:
        lines.append(_line('Topic information', ''))
    lines.extend(grasp_lines(bag))
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description='Print what a rosbag2 MCAP bag holds '
                                     '(like ros2 bag info) plus the grasp request and outcome.')
    parser.add_argument('bags', metavar='BAG', nargs='+', help='bag folder or .mcap file')
    return parser


@quiet_on_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    """Exit 0; 1 on bad input (one line on stderr); 3 when a bag was truncated (info printed)."""
    args = build_parser().parse_args(argv)
    bags = []
    for path in args.bags:
        try:
            bag = read_bag(path)
            bags.append((bag, format_info(bag)))
        except BagError as exc:
            print(f'{PROG}: error: {exc}', file=sys.stderr)
            sys.exit(EXIT_ERROR)
    print('\n\n'.join(text for _, text in bags))
    damaged = [bag for bag, _ in bags if bag.truncated]
    for bag in damaged:
        print(f'{PROG}: warning: {bag.truncation_note()}', file=sys.stderr)
    if damaged:
        sys.exit(EXIT_TRUNCATED)
    return 0


if __name__ == '__main__':
    sys.exit(main())
