"""Console script: the gripper's URDF, written from a config file.

    ros2 run gripper_ros gripper_urdf [--config FILE] [--prefix P] [-o FILE] [--macro FILE]

Prints the URDF that ``description_publisher`` publishes on ``robot_description`` (the links,
``finger_joint`` and its limits from the config); ``-o urdf/gripper.urdf`` rewrites the plain
URDF the package ships for robot_state_publisher, ``--macro urdf/gripper.macro.xacro`` the
xacro macro (the same links and joints with a ``prefix`` and a ``parent`` link).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

from gripper_ros.apps.common import load_config_or_report
from gripper_ros.core.description import urdf_text, xacro_macro_text
from gripper_ros.wire import NAME_CHARACTERS

PROG = 'gripper_urdf'


def main(argv=None) -> int:
    """Write the URDF of ``--config`` to stdout or ``-o``; 2 on a bad config or path."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('--config', help='config YAML (default: the installed gripper.yaml)')
    parser.add_argument('-o', '--output', help='write here instead of stdout')
    parser.add_argument('--macro', help='also write the xacro macro here')
    parser.add_argument('--prefix', default='', help='put before every link and joint name')
    args = parser.parse_args(argv)
    config = load_config_or_report(PROG, args.config)
    if config is None:
        return 2
    if not set(args.prefix) <= NAME_CHARACTERS:
        print(f'{PROG}: --prefix may hold only ASCII letters, digits and _, got '
              f'{args.prefix!r}', file=sys.stderr)
        return 2
    if not args.output:
        sys.stdout.write(urdf_text(config, args.prefix))
    writes = [(args.output, lambda c: urdf_text(c, args.prefix)), (args.macro, xacro_macro_text)]
    for path, text in writes:
        if not path:
            continue
        try:
            Path(path).write_text(text(config), encoding='utf-8')
        except OSError as exc:
            print(f'{PROG}: cannot write {path}: {exc.strerror}', file=sys.stderr)
            return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
