"""excite: run the identification experiment on its own gripper graph and record it as a bag.

    ros2 run gripper_ros excite --seconds 20 --amplitude-v 12 --seed 1
    ros2 run gripper_ros excite --config hidden.yaml --output bags

The gripper goes through a seeded sequence of moves inside its travel at pseudo-random speeds,
the driving voltage capped at ``--amplitude-v``, and (unless ``--no-hold``) every few requests
it grasps a rigid stop, for the force model and the electrical time constant
(:mod:`gripper_ros.identify.excitation`). It all goes through the ``move`` and ``grasp``
services, so ``stop`` ends it at once. The bag is written under
``--output`` and its path printed as ``bag: PATH``; ``bag_identify PATH`` fits the plant to it.
"""
from __future__ import annotations

import argparse
import copy
from datetime import datetime
import os
from pathlib import Path
import sys
import time

EXCITATION_FORMAT = 2       # custom_data 'excitation' layout (2: the holds are grasps)


def build_parser() -> argparse.ArgumentParser:
    from gripper_ros.identify.excitation import ExcitationSpec, MAX_SECONDS, MIN_SECONDS
    from gripper_ros.wire import DEFAULT_NAMESPACE
    d = ExcitationSpec()
    p = argparse.ArgumentParser(prog='excite', description=__doc__.splitlines()[0])
    p.add_argument('--config', default='', help='YAML parameter file (default: installed)')
    p.add_argument('--output', default='bags', help='folder for the bag (default %(default)s)')
    p.add_argument('--seconds', type=float, default=d.seconds,
                   help=f'simulated duration, in [{MIN_SECONDS:g}, {MAX_SECONDS:g}] '
                        '(default %(default)g)')
    p.add_argument('--amplitude-v', type=float, default=d.amplitude_v,
                   help="most voltage that drives the finger, up to the plant's limit "
                        '(default %(default)g)')
    p.add_argument('--seed', type=int, default=d.seed,
                   help='seed of the pseudo-random sequence (default %(default)d)')
    p.add_argument('--position-noise-m', type=float, default=None,
                   help='sensor_noise.position_noise_m of the simulated plant (default: the '
                        "config's)")
    p.add_argument('--force-noise-n', type=float, default=None,
                   help='sensor_noise.force_noise_n of the simulated plant (default: the '
                        "config's)")
    p.add_argument('--noise-seed', type=int, default=None,
                   help="sensor_noise.seed of the simulated plant (default: the config's)")
    p.add_argument('--no-hold', action='store_true',
                   help='free motion only: no grasp of the rigid stop (no force model, no '
                        'electrical time constant)')
    p.add_argument('--namespace', default=DEFAULT_NAMESPACE,
                   help='ROS namespace of this gripper (default %(default)s)')
    return p


def _fail(message: str) -> int:
    print(f'excite: {message}', file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.utilities import remove_ros_args

    args = build_parser().parse_args(remove_ros_args(sys.argv if argv is None else
                                                     ['excite', *argv])[1:])
    from gripper_ros.apps.common import run_graph
    from gripper_ros.core.config import ConfigError, load_config, parse_config
    from gripper_ros.identify.excitation import check_spec, ExcitationSpec
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.wire import check_namespace, TimeMode

    spec = ExcitationSpec(args.seconds, args.amplitude_v, args.seed, not args.no_hold)
    noise = {f'sensor_noise.{key}': value for key, value in (   # as declared: doubles, int seed
        ('position_noise_m', args.position_noise_m), ('force_noise_n', args.force_noise_n),
        ('seed', args.noise_seed)) if value is not None}
    try:
        namespace = check_namespace(args.namespace)
        config = load_config(args.config or None)
        check_spec(spec, config.plant)
        if noise:
            if 'sensor_noise' not in config.data:
                raise ConfigError(f'{config.source} has no sensor_noise section to set')
            data = copy.deepcopy(config.data)
            for dotted, value in noise.items():
                data['sensor_noise'][dotted.split('.')[1]] = value
            parse_config(data, 'the noise options')      # the reader's checks, named
    except (ValueError, ConfigError) as exc:
        return _fail(str(exc))
    from gripper_ros.nodes.process import raise_keyboard_interrupt, StopSignals
    from rclpy.signals import SignalHandlerOptions
    # Ctrl-C and SIGTERM end the experiment here (KeyboardInterrupt), not inside rclpy: the
    # graph stops and the bag is closed first, and a second signal cannot cut that short (as
    # grasp_demo does).
    rclpy.init(args=None if argv is None else [], signal_handler_options=SignalHandlerOptions.NO)
    signals = StopSignals(on_first=raise_keyboard_interrupt)
    signals.__enter__()

    def excite(graph) -> int:
        bag_dir, outcome = recorded_excitation(graph, Path(args.output), spec)
        print(f'excite: {outcome}', flush=True)
        print(f'bag: {bag_dir}', flush=True)
        return 0
    return run_graph('excite', lambda: GripperGraph(GraphOptions(
        config_file=args.config, namespace=namespace, time_mode=TimeMode.FAST.parameter,
        plant_parameters=noise)), excite, signals, 'bag', errors=(ValueError,))


def run_excitation(graph, spec) -> str:
    """Send the experiment's requests until ``spec.seconds`` of simulated time have passed.

    Returns how it ended; a request that ends STOPPED, REFUSED or FAULT (a ``stop``, a
    refusal, a fault) ends the experiment at once.
    """
    from gripper_ros.core.supervision.requests import GraspRequest
    from gripper_ros.identify.excitation import ExcitationRun
    from gripper_ros.wire import Outcome
    run = ExcitationRun(spec, graph.plant.config, graph.sim_time_ns)
    while (request := run.next_request(graph.sim_time_ns)) is not None:
        if isinstance(request, GraspRequest):
            answer = graph.grasp(request.width_m, request.mass_kg, timeout_s=request.timeout_s)
        else:
            answer = graph.move(request.width_m, request.speed_mps, request.max_effort_n,
                                timeout_s=request.timeout_s)
        if not run.answered(Outcome(answer.outcome).name, answer.message):
            break
    return run.summary(graph.sim_time_ns)


def recorded_excitation(graph, output: Path, spec) -> tuple[Path, str]:
    """Place the rigid stop, record every topic of the graph and run the experiment."""
    from gripper_ros.bags.recorder import BagRecorder, RecordingError, unique_bag_dir
    from gripper_ros.identify.excitation import STOP_WIDTH_M
    from gripper_ros.nodes.recording import bag_metadata, drain_published, graph_tap
    width = STOP_WIDTH_M if spec.hold else 0.0
    placed = graph.set_object(width)
    if not placed.success:
        raise RecordingError(f'set_object: {placed.message}')
    graph.wait_still()
    stamp = datetime.now().strftime('%Y%m%d_%H%M%S')
    bag_dir = unique_bag_dir(output, f'excite_{stamp}_{spec.seconds:g}s_{spec.amplitude_v:g}V_'
                                     f'seed{spec.seed}')
    custom = bag_metadata(graph, {}, {'width_m': width, 'stiffness_n_per_m': 0.0,
                                      'damping_n_s_per_m': 0.0})
    custom['excitation'] = {'format': EXCITATION_FORMAT, 'seconds': spec.seconds,
                            'amplitude_v': spec.amplitude_v, 'seed': spec.seed,
                            'hold': spec.hold}
    tap = graph_tap(graph)
    recorder = BagRecorder(graph.client_node, bag_dir, tap.topics, overwrite=True,
                           subscribe=False, time_source=lambda: graph.sim_time_ns,
                           custom_data=custom)
    before = graph.published_counts()
    received_before = dict(tap.received)
    tap.start(recorder, 'now')
    t0 = time.perf_counter()
    try:
        outcome = run_excitation(graph, spec)
        graph.wait_still()
    finally:
        drain_published(graph, tap, recorder, before, received_before)
        tap.sink = None
        if not recorder.closed:
            recorder.close()
    if tap.error:
        raise RecordingError(tap.error)
    return bag_dir, f'{outcome} (wall {time.perf_counter() - t0:.1f} s)'
