"""What the console apps share: the configuration loaded as a command line expects."""
from __future__ import annotations

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
