"""The package's executables (``ros2 run gripper_ros NAME``): one table, read by setup.py.

Each starts once more with the condition-wait fix preloaded (:mod:`gripper_ros.native`) before
it imports anything heavy, then runs its module's ``main``.
"""
from __future__ import annotations

import importlib

from gripper_ros.native import preload_into_this_process

EXECUTABLES = {
    'plant_simulator': 'gripper_ros.nodes.plant_simulator_node:main',
    'position_controller': 'gripper_ros.nodes.position_controller_node:main',
    'force_controller': 'gripper_ros.nodes.force_controller_node:main',
    'supervisor': 'gripper_ros.nodes.supervisor_node:main',
    'grasp_demo': 'gripper_ros.apps.grasp_demo:main',
    'grasp_client': 'gripper_ros.apps.grasp_client:main',
    'grasp_action_server': 'gripper_ros.nodes.grasp_action_node:main',
    'move_action_server': 'gripper_ros.nodes.move_action_node:main',
    'trajectory_action_server': 'gripper_ros.nodes.trajectory_action_node:main',
    'excitation_server': 'gripper_ros.nodes.excitation_node:main',
    'description_publisher': 'gripper_ros.nodes.description_node:main',
    'gripper_graph': 'gripper_ros.nodes.graph_process:main',
    'gripper_urdf': 'gripper_ros.apps.gripper_urdf:main',
    'paper_tables': 'gripper_ros.apps.paper_tables:main',
    'position_limit': 'gripper_ros.apps.position_limit:main',
    'bag_info': 'gripper_ros.bags.info:main',
    'bag_replay': 'gripper_ros.bags.replay:main',
    'bag_analyze': 'gripper_ros.bags.analyze:main',
    'bag_identify': 'gripper_ros.bags.identify:main',
    'excite': 'gripper_ros.apps.excite:main',
    'bench_graph': 'gripper_ros.bench.graph:main',
    'contact_sweep': 'gripper_ros.apps.contact_sweep:main',
    'bench_soak': 'gripper_ros.bench.soak:main',
    'bench_controllers': 'gripper_ros.bench.controllers:main',
    'lift_table': 'gripper_ros.apps.lift_table:main',
    'grip_study': 'gripper_ros.apps.grip_study:main',
    'bench_realtime': 'gripper_ros.bench.realtime:main',
    'bench_headless': 'gripper_ros.bench.headless:main',
    'bench_launch_stop': 'gripper_ros.bench.launch_stop:main',
    'bench_trees': 'gripper_ros.bench.trees:main',
    'tune': 'gripper_ros.apps.tune:main',
}
"""Each executable's name and the ``module:function`` that is its main."""


def run(name: str):
    """Run executable ``name``: with the fix preloaded, its main's return value."""
    preload_into_this_process()
    module, function = EXECUTABLES[name].split(':')
    return getattr(importlib.import_module(module), function)()


def __getattr__(name: str):
    """``gripper_ros.executables.NAME``: the entry point setup.py installs as NAME."""
    if name not in EXECUTABLES:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return lambda: run(name)
