"""Test isolation: DDS traffic stays on this machine and on a domain of this run's own.

scripts/test.sh picks a free domain id per run; these defaults only apply when pytest is run
directly.
"""
import os

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(40 + os.getpid() % 50))
