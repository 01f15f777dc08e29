"""What the console apps share: the config loaded, options checked, a graph run and closed."""
from __future__ import annotations

import copy
import math
import sys

from gripper_ros.core.config import ConfigError, GripperConfig, load_config


def load_config_or_report(prog: str, path: str | None) -> GripperConfig | None:
    """Load the config file ``path`` (None: the installed one).

    A bad file is one line on stderr, ``prog: why``, and None: the app then exits 2.
    """
    try:
        return load_config(path)
    except ConfigError as exc:
        print(f'{prog}: {exc}', file=sys.stderr)
        return None


def negative_option(args, names) -> str | None:
    """Return the error of the first option in ``names`` not finite and >= 0; None if all are.

    ``names`` are argparse destinations (``lift_delay``); the error names the option
    (``--lift-delay``) and the value given. An option not given (None) passes.
    """
    for name in names:
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value >= 0.0):
            return f'--{name.replace("_", "-")} must be finite and >= 0, got {value!r}'
    return None


FRICTION_OPTIONS = '--static-friction and --kinetic-friction'


def friction_option(args) -> str | None:
    """Return the error of an object's friction given by halves; None if both or neither are.

    Neither: the configured friction (``SetObject.default_friction``); 0 is frictionless.
    """
    if (args.static_friction is None) != (args.kinetic_friction is None):
        return (f'{FRICTION_OPTIONS} go together (neither: the configured friction; '
                f'0: frictionless)')
    return None


def set_object_fields(args) -> dict:
    """Return the SetObject fields of an app's object and lift options.

    ``args`` holds ``object_mass``, ``static_friction``, ``kinetic_friction`` (both None: the
    configured friction), ``profile`` (parsed, or None), ``lift_off`` and ``unannounced``;
    ``lift``, ``lift_delay`` and ``lift_duration`` where the app has them (else ``profile``'s
    acceleration and the lift runs' timing). Only the object's fields that were given; no lift
    fields without a lift.
    """
    from gripper_ros.studies.lift_runs import LIFT_DELAY_S, LIFT_DURATION_S
    out = {'mass_kg': args.object_mass} if args.object_mass else {}
    if args.static_friction is None and args.kinetic_friction is None:
        out['default_friction'] = True
    else:
        out.update(static_friction=args.static_friction or 0.0,
                   kinetic_friction=args.kinetic_friction or 0.0)
    lift = getattr(args, 'lift', 0.0) or (args.profile[1] if args.profile is not None else 0.0)
    if not lift:
        return out
    out.update({'lift_acceleration_mps2': lift,
                'lift_delay_s': getattr(args, 'lift_delay', LIFT_DELAY_S),
                'lift_duration_s': getattr(args, 'lift_duration', LIFT_DURATION_S)})
    if args.lift_off:
        out['lift_off_s'] = args.lift_off
    if args.profile is not None:
        out.update({'lift_profile': int(args.profile[0]), 'lift_frequency_hz': args.profile[2]})
    out['announce_lift'] = not args.unannounced
    return out


def with_values(config, values: dict):
    """Return ``config`` with each dotted key set; ConfigError (one line) if the reader refuses."""
    from gripper_ros.bags.rerun import apply_settings
    from gripper_ros.core.config import parse_config
    data = apply_settings(config.data, sorted(values.items()), config.source)
    source = config.source + ' with ' + ', '.join(f'{k}={v!r}' for k, v in sorted(values.items()))
    return parse_config(copy.deepcopy(data), source)


def run_graph(prog: str, make_graph, work, signals, closed: str, errors=()) -> int:
    """Return the exit code of ``work(graph)`` on the graph that ``make_graph()`` starts.

    A start-up, graph or recording error (or one of ``errors``) is one line, ``prog: why``, and
    exit 2; Ctrl-C or SIGTERM, raised as KeyboardInterrupt by ``signals``, says that the
    ``closed`` bags were closed, exit 130. The graph and ``signals`` are closed in every case.
    """
    from gripper_ros.bags.recorder import BagRecorderError, RecordingError
    from gripper_ros.nodes.graph import GraphError
    from gripper_ros.nodes.process import close_app_graph
    from gripper_ros.nodes.startup import StartupError
    graph = None
    try:
        graph = make_graph()
        return work(graph)
    except (ConfigError, StartupError, GraphError, BagRecorderError, RecordingError,
            RuntimeError, *errors) as exc:
        print(f'{prog}: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'{prog}: interrupted; {closed} closed', file=sys.stderr)
        return 130
    finally:
        close_app_graph(graph, signals)
