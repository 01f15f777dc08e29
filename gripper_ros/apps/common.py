"""What the console apps share: the configuration loaded as a command line expects."""
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
    (``--lift-delay``) and the value given.
    """
    for name in names:
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0.0):
            return f'--{name.replace("_", "-")} must be finite and >= 0, got {value!r}'
    return None


def with_values(config, values: dict):
    """Return ``config`` with each dotted key set; ConfigError (one line) if the reader refuses."""
    from gripper_ros.bags.rerun import apply_settings
    from gripper_ros.core.config import parse_config
    data = apply_settings(config.data, sorted(values.items()), config.source)
    source = config.source + ' with ' + ', '.join(f'{k}={v!r}' for k, v in sorted(values.items()))
    return parse_config(copy.deepcopy(data), source)
