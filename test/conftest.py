"""Test isolation: DDS traffic stays on this machine and on a domain of this run's own.

scripts/test.sh picks free domain ids per run, one for each pytest-xdist worker
(``GRIPPER_ROS_WORKER_DOMAINS``); worker ``gwK`` takes the K-th. Run directly, pytest falls back
to a PID-derived id.
"""
import os

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
_worker = os.environ.get('PYTEST_XDIST_WORKER', '')
_domains = os.environ.get('GRIPPER_ROS_WORKER_DOMAINS', '').split()
if _worker.startswith('gw') and _worker[2:].isdigit() and int(_worker[2:]) < len(_domains):
    os.environ['ROS_DOMAIN_ID'] = _domains[int(_worker[2:])]
os.environ.setdefault('ROS_DOMAIN_ID', str(40 + os.getpid() % 50))
