"""The package passes ament_flake8, as ``colcon test`` runs it on a ROS 2 Python package.

flake8 with ament_flake8's own configuration: line length 99, google import order, pep257
docstrings through flake8-docstrings (with ament_pep257's ignore list), builtins,
comprehensions and quotes. The configuration is the installed ament_flake8's, wherever that is
(the venv's wheels or a system ROS), so the project is held to the one every ROS 2 package
is held to.
"""

import importlib.metadata
import json
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]

# The plugins ament_flake8's configuration names (requirements.txt installs them); without one,
# flake8 silently checks less.
PLUGINS = ('flake8-builtins', 'flake8-comprehensions', 'flake8-docstrings',
           'flake8-import-order', 'flake8-quotes')


def _python_scripts():
    """Return the helper scripts in ``scripts/`` that are Python, by suffix or shebang."""
    found = []
    for path in sorted((ROOT / 'scripts').iterdir()):
        if not path.is_file():
            continue
        with open(path, 'rb') as f:
            first_line = f.readline()
        if path.suffix == '.py' or (first_line.startswith(b'#!') and b'python' in first_line):
            found.append(path.relative_to(ROOT).as_posix())
    return found


def _linted():
    """Return the paths test_flake8 lints: the package, its tests, launch files and scripts."""
    return ['gripper_ros', 'test', 'launch', 'setup.py', *_python_scripts()]


def _flake8(argv):
    """Run ament_flake8 from the repository root on ``argv``; return (rc, violations)."""
    pytest.importorskip('flake8', reason='flake8 is not installed (bash scripts/setup.sh)')
    pytest.importorskip('ament_flake8.main', reason='ament_flake8 is not installed (ROS 2 '
                        'ament_lint)')
    missing = []
    for name in PLUGINS:
        try:
            importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            missing.append(name)
    assert not missing, f'flake8 plugins missing (bash scripts/setup.sh installs them): {missing}'
    # In an interpreter of its own: flake8 forks a pool of checkers, and a fork of this test
    # process (its executors' and clusters' threads holding locks) can hang. ament_flake8 walks
    # the working directory for AMENT_IGNORE; relative paths in the report.
    done = subprocess.run(
        [sys.executable, '-c', 'import json, sys\n'
         'from ament_flake8.main import main_with_errors\n'
         'rc, errors = main_with_errors(argv=sys.argv[1:])\n'
         'print(json.dumps([rc, errors]))', *argv],
        cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    rc, errors = json.loads(done.stdout.strip().splitlines()[-1])
    return rc, errors


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    """Every Python file of the project passes flake8."""
    rc, errors = _flake8(_linted())
    assert rc == 0, f'{len(errors)} flake8 violations:\n' + '\n'.join(errors)
