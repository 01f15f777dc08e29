"""gripper_graph: the gripper's whole node graph in one process, as ``ros2 launch`` starts it.

    ros2 run gripper_ros gripper_graph --ros-args -r __ns:=/left -p time_mode:=fast

The nodes of the launch file (plant_simulator, position_controller, force_controller,
supervisor, grasp_action_server, move_action_server, description_publisher) plus
excitation_server and the graph's own service client, under one executor, the loop topics
handed over in the process. Its settings are the launch file's parameters, given the ROS way
(``-p NAME:=VALUE`` or a ``--params-file`` for ``/**``, which also reaches every node of the
process): ``config_file``, ``time_mode``, ``real_time_factor``, ``publish_clock``,
``use_sim_time``, ``prefix``, ``foxglove``, ``foxglove_port``, ``foxglove_address``; the
namespace is ``-r __ns:=/NAME`` (default ``/gripper``). Ctrl-C or SIGTERM stops it, exit 0; a
bad setting, a parameter no node of it declares or a taken namespace is one line, exit 2.
"""
from __future__ import annotations

import sys
import time

from gripper_ros.wire import DEFAULT_NAMESPACE, TimeMode

NAME = 'gripper_graph'
CLIENT_NODE = 'gripper_graph_client'
SETTINGS = (('config_file', '', 'config YAML (default: the installed one)'),
            ('time_mode', TimeMode.REALTIME.parameter, 'realtime | fast'),
            ('real_time_factor', 1.0, 'realtime: simulated seconds per wall second'),
            ('publish_clock', True, 'publish /clock'),
            ('use_sim_time', False, 'follow the /clock of a world simulator (publish none)'),
            ('prefix', '', "the xacro's prefix: the joint's and the URDF's names; "
             'default: from the namespace (wire.namespace_prefix)'),
            ('foxglove', False, 'serve the graph live to Foxglove (its WebSocket protocol)'),
            ('foxglove_port', 8765, "the live view's port (0: any free port)"),
            ('foxglove_address', '127.0.0.1', 'where the live view listens (0.0.0.0: every '
             'interface)'))
"""The launch arguments this process takes as parameters: name, default, description."""
POLL_S = 0.1
"""How often the main thread looks for a stop signal or a graph that stopped spinning."""


def read_settings(context=None) -> dict:
    """Return :data:`SETTINGS` as the command line gives them (``-p``, ``--params-file``).

    With them ``namespace``: the graph's, :data:`DEFAULT_NAMESPACE` as ``-r __ns:=`` remaps it.
    The start-up probe node reads them (``ros2 node list`` does not show it afterwards). The
    ``prefix`` not given comes from the namespace, as each node's own (``declare_prefix``).
    """
    from gripper_ros.nodes.names import probe_node, retire_probe
    from gripper_ros.wire import namespace_prefix
    probe = probe_node(DEFAULT_NAMESPACE, context)
    try:
        namespace = probe.get_namespace().strip('/')
        defaults = {'prefix': namespace_prefix(namespace)}
        settings = {name: (probe.get_parameter(name) if probe.has_parameter(name) else
                           probe.declare_parameter(name, defaults.get(name, default))).value
                    for name, default, _ in SETTINGS}          # rclpy declares use_sim_time
        return {**settings, 'namespace': namespace}
    finally:
        retire_probe(probe)          # destroyed once the graph's nodes live


def usage() -> str:
    """Return what ``gripper_graph --help`` prints."""
    lines = [f'usage: {NAME} [--ros-args -r __ns:=/NAMESPACE -p NAME:=VALUE '
             '--params-file FILE ...]', '', __doc__.strip(), '', 'Parameters:']
    lines += [f'  {name} (default {default!r}): {text}' for name, default, text in SETTINGS]
    return '\n'.join(lines)


def main(args: list[str] | None = None) -> int:
    """Serve the graph until Ctrl-C or SIGTERM; exit codes as every node executable's."""
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.exceptions import InvalidNamespaceException, ParameterException
    from gripper_ros.core.config import ConfigError
    from gripper_ros.nodes.graph import GraphError, GraphOptions, GripperGraph
    from gripper_ros.nodes.live_view import LiveViewError, serve_live
    from gripper_ros.nodes.process import (BoundedCleanUp, CLEAN_UP_LIMIT_S,
                                           exit_without_a_last_collection, GIL_HELD_MARGIN_S,
                                           init_without_signal_handlers, StopSignals,
                                           user_arguments)
    from gripper_ros.nodes.startup import EXIT_BAD_START, StartupError
    from gripper_ros.text import one_line
    from gripper_ros.wire import qualified

    argv = sys.argv if args is None else args
    exit_without_a_last_collection()
    user_args = user_arguments(NAME, argv)
    if user_args is None:
        return EXIT_BAD_START
    if {'-h', '--help'} & set(user_args):
        print(usage())
        return 0
    if user_args:
        print(f'{NAME}: unknown arguments {user_args}: settings are ROS parameters '
              '(--ros-args -p NAME:=VALUE)', file=sys.stderr)
        return EXIT_BAD_START
    graph = None
    exit_code = 0
    with StopSignals(hard_bound_s=CLEAN_UP_LIMIT_S + GIL_HELD_MARGIN_S) as signals:
        if not init_without_signal_handlers(NAME, argv):
            return EXIT_BAD_START
        try:
            settings = read_settings()
            graph = GripperGraph(GraphOptions(
                config_file=settings['config_file'], namespace=settings['namespace'],
                time_mode=settings['time_mode'],
                real_time_factor=float(settings['real_time_factor']),
                publish_clock=bool(settings['publish_clock']), prefix=settings['prefix'],
                use_sim_time=bool(settings['use_sim_time']), client_name=CLIENT_NODE,
                process_parameters=tuple(name for name, _, _ in SETTINGS)))
            if settings['foxglove']:
                serve_live(NAME, graph, settings['foxglove_address'], settings['foxglove_port'])
            names = ', '.join(qualified(graph.namespace, n) for n in graph.served_names())
            print(f'{NAME}: serving {names} ({graph.time_text}); Ctrl-C to stop', flush=True)
            while not signals.received and graph.spinning:
                time.sleep(POLL_S)
        except (ConfigError, ParameterException, StartupError, RCLError, GraphError,
                InvalidNamespaceException, ValueError, LiveViewError) as exc:
            print(f'{NAME}: {one_line(exc)}', file=sys.stderr)
            exit_code = EXIT_BAD_START
        except KeyboardInterrupt:
            pass
        finally:
            with BoundedCleanUp(NAME, exit_code):
                if graph is not None:
                    graph.close()
                rclpy.try_shutdown()
    return exit_code


if __name__ == '__main__':
    sys.exit(main())
