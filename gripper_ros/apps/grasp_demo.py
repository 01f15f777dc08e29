"""grasp_demo: the whole gripper graph in one process, one executor; grasps and records bags.

    ros2 run gripper_ros grasp_demo                       # the paper's three objects (Table V)
    ros2 run gripper_ros grasp_demo --width 0.05 --mass 1.69
    ros2 run gripper_ros grasp_demo --serve               # keep the graph up for grasp_client

Each grasp is recorded as a rosbag2 MCAP bag under ``--output`` (default ``bags/``), a summary
line per object is printed, and a figure like the paper's Fig. 8 is written as PNG.
DDS discovery is limited to localhost unless ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is set.
"""
from __future__ import annotations

import argparse
from datetime import datetime
import math
import os
from pathlib import Path
import sys
import time


def build_parser() -> argparse.ArgumentParser:
    from gripper_ros.core.config import ForceLaw
    from gripper_ros.nodes.live_view import DEFAULT_ADDRESS, DEFAULT_PORT
    from gripper_ros.nodes.process import ExecutorKind
    from gripper_ros.studies.lift_runs import LIFT_DELAY_S, LIFT_DURATION_S
    from gripper_ros.wire import (DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                                  DEFAULT_NAMESPACE, DEFAULT_POSITION_CONTROLLER,
                                  ForceControllerKind, PositionControllerKind, TIME_MODE_CHOICES)
    p = argparse.ArgumentParser(prog='grasp_demo', description=__doc__.splitlines()[0])
    p.add_argument('--width', type=float, help='object width (m); with --mass grasps one object')
    p.add_argument('--mass', type=float,
                   help='object mass (kg); 0 = unknown: the grip tracks the load the pads '
                        'measure (load_grip), OVERLOADED when 24 V cannot hold it')
    p.add_argument('--friction', type=float, default=0.0, help='mu_s (0 = configured default)')
    p.add_argument('--stiffness', type=float, default=0.0,
                   help="object contact stiffness N/m (0 = rigid, the paper's model)")
    p.add_argument('--damping', type=float, default=0.0, help='object contact damping N s/m')
    p.add_argument('--width-tolerance', type=float, default=0.0,
                   help='the object may be this much wider or narrower, m (0 = default)')
    p.add_argument('--object-width', type=float, default=None,
                   help="the simulated object's real width, m (default: the requested --width)")
    p.add_argument('--lift', type=float, default=0.0, metavar='A',
                   help='after HOLDING the arm lifts the object at A m/s^2 upward (the request '
                        'carries a = A for the force law); 0 = no lift')
    p.add_argument('--profile', default=None, metavar='NAME:A[,HZ]',
                   help="the arm's motion after HOLDING, along the pads: step:A (= --lift A), "
                        'pick-and-place:A (up, across, down; +-A m/s^2 trapezoids over the '
                        'duration) or shake:A,HZ (A sin(2 pi HZ t)); the request carries a = A')
    p.add_argument('--unannounced', action='store_true',
                   help='the arm moves without notice; by default it announces its motion '
                        'ahead on arm/planned_acceleration (the load-tracking grip of --mass 0 '
                        'then rises with the load it brings)')
    p.add_argument('--lift-off', type=float, default=0.0, metavar='S',
                   help='the arm hands the weight from the support to the pads over S seconds '
                        '(a hand takes 0.1-0.2 s; 0 = contact.lift_off_s, 0 as shipped)')
    p.add_argument('--object-mass', type=float, default=0.0, metavar='KG',
                   help="the simulated object's real mass, not told to the controller "
                        '(0 = the requested --mass)')
    p.add_argument('--static-friction', type=float, default=None, metavar='MU',
                   help="the simulated object's real mu_s on the pads, not told to the "
                        'controller (0 = frictionless; with --kinetic-friction, neither = the '
                        'configured friction)')
    p.add_argument('--kinetic-friction', type=float, default=None, metavar='MU',
                   help='its real mu_k (<= mu_s; 0 = it slides without friction)')
    p.add_argument('--lift-delay', type=float, default=LIFT_DELAY_S,
                   help='seconds from HOLDING to the lift (default %(default)g)')
    p.add_argument('--lift-duration', type=float, default=LIFT_DURATION_S,
                   help='seconds the lift accelerates (default %(default)g)')
    p.add_argument('--force-law', choices=[law.value for law in ForceLaw], default=None,
                   help='grip force: friction, F_sp = k m (g + a) / (2 mu_s), enough for two '
                        'pads (the default in config); paper, its eq. 23, mu_s m (g + a)')
    p.add_argument('--serve', action='store_true',
                   help='keep the graph up as simulated hardware and answer grasp, release, '
                        'stop and sim/* from other processes')
    p.add_argument('--foxglove', type=int, nargs='?', const=DEFAULT_PORT, default=None,
                   metavar='PORT',
                   help='serve the graph live to Foxglove over its WebSocket protocol, on PORT '
                        '(default %(const)s; 0: any free port); with --serve or realtime time')
    p.add_argument('--foxglove-address', default=DEFAULT_ADDRESS, metavar='ADDRESS',
                   help='where the live view listens (default %(default)s: this machine only; '
                        '0.0.0.0: every interface)')
    p.add_argument('--namespace', default=DEFAULT_NAMESPACE,
                   help='ROS namespace of this gripper (default %(default)s: /gripper/...)')
    p.add_argument('--prefix', default=None,
                   help="put before the joint's and the URDF's names, so before every TF frame "
                        '(default: from the namespace: none in /gripper, left_ in /left)')
    p.add_argument('--time-mode', choices=TIME_MODE_CHOICES, default=None,
                   help='realtime: paced to the wall clock, always running (default with '
                        '--serve); fast: as fast as the graph goes while a grasp runs (default)')
    p.add_argument('--real-time-factor', type=float, default=1.0,
                   help='realtime: simulated seconds per wall second (default 1)')
    p.add_argument('--no-clock', action='store_true',
                   help='do not publish /clock (another simulator on the domain does)')
    p.add_argument('--use-sim-time', action='store_true',
                   help='with --serve: every node on the /clock of a world simulator (Gazebo, '
                        'MuJoCo), the simulation in step with it; publishes no /clock')
    p.add_argument('--no-record', action='store_true', help='do not write bags')
    p.add_argument('--output', default='bags', help='folder for bags and the figure')
    p.add_argument('--overwrite', action='store_true', help='replace existing bag folders')
    p.add_argument('--no-plot', action='store_true', help='do not write the figure')
    p.add_argument('--executor', choices=[k.value for k in ExecutorKind],
                   default=ExecutorKind.EVENTS.value)
    p.add_argument('--position-controller', choices=[k.value for k in PositionControllerKind],
                   default=DEFAULT_POSITION_CONTROLLER.value)
    p.add_argument('--force-controller', choices=[k.value for k in ForceControllerKind],
                   default=DEFAULT_FORCE_CONTROLLER.value,
                   help='contact_aware: rigid and compliant objects; pi / mpc_pi: the paper')
    p.add_argument('--approach-force-margin', type=float, default=DEFAULT_APPROACH_FORCE_MARGIN,
                   help='pi / mpc_pi: voltage cap before contact, x stall voltage of F_sp '
                        '(0 = off)')
    p.add_argument('--config', default='', help='YAML parameter file (default: installed)')
    return p


def _output_problem(folder: Path) -> str:
    """Why bags and figures cannot be written under ``folder`` ('' when they can).

    The folder is made if it is missing; a file in the way, a read-only place or a path that
    cannot exist is said in one line before anything starts.
    """
    if folder.exists() and not folder.is_dir():
        return f'--output {folder}: not a folder'
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f'--output {folder}: cannot make the folder: {exc.strerror}'
    if not os.access(folder, os.W_OK | os.X_OK):
        return f'--output {folder}: the folder is not writable'
    return ''


def _fail(message: str) -> int:
    print(f'grasp_demo: {message}', file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.utilities import remove_ros_args

    try:
        user_args = remove_ros_args(sys.argv if argv is None else ['grasp_demo', *argv])[1:]
    except RCLError as exc:          # e.g. a --params-file that is missing or not YAML
        return _fail(f'bad --ros-args: {" ".join(str(exc).split())}')
    args = build_parser().parse_args(user_args)
    if (args.width is None) != (args.mass is None):
        return _fail('--width and --mass go together')
    from gripper_ros.studies.paper import PAPER_OBJECTS
    objects = PAPER_OBJECTS if args.width is None else ((args.width, args.mass),)
    for w, m in objects:
        if not (math.isfinite(w) and math.isfinite(m)):
            return _fail(f'width and mass must be finite, got {w!r}, {m!r}')
    from gripper_ros.apps.common import friction_option, negative_option
    negative = negative_option(args, ('lift', 'lift_delay', 'lift_duration', 'object_mass',
                                      'static_friction', 'kinetic_friction', 'lift_off')) or \
        friction_option(args)
    if negative:
        return _fail(negative)
    from gripper_ros.core.physics.hold import MAX_LIFT_OFF_S
    if args.lift_off > MAX_LIFT_OFF_S:
        return _fail(f'--lift-off must be <= {MAX_LIFT_OFF_S:g} s, got {args.lift_off!r}')
    if args.lift_off and not (args.lift or args.profile):
        return _fail('--lift-off needs a lift (--lift or --profile)')
    if args.unannounced and not (args.lift or args.profile):
        return _fail('--unannounced needs a lift (--lift or --profile)')
    if args.profile is not None:
        from gripper_ros.core.physics.hold import parse_profile
        if args.lift:
            return _fail('--lift and --profile do not go together (--lift A is step:A)')
        try:
            args.profile = parse_profile(args.profile)
        except ValueError as exc:
            return _fail(f'--profile: {exc}')
        args.lift = args.profile[1]

    from gripper_ros.apps.common import run_graph
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.nodes.names import namespace_as_given
    from gripper_ros.nodes.process import (APP_BAGS_LIMIT_S, ExecutorKind,
                                           exit_without_a_last_collection,
                                           raise_keyboard_interrupt, StopSignals)
    from gripper_ros.nodes.recording import ServeRecorder
    from gripper_ros.text import one_line
    from gripper_ros.wire import check_namespace, NAME_CHARACTERS, TimeMode

    try:
        check_namespace(args.namespace)
    except ValueError as exc:
        return _fail(str(exc))
    if args.prefix is not None and not set(args.prefix) <= NAME_CHARACTERS:
        return _fail(f'--prefix may hold only ASCII letters, digits and _, got {args.prefix!r}')
    if not (args.no_record and (args.serve or args.no_plot)):
        problem = _output_problem(Path(args.output))
        if problem:
            return _fail(problem)
    if not (math.isfinite(args.real_time_factor) and 0.0 < args.real_time_factor <= 100.0):
        return _fail(f'--real-time-factor must be in (0, 100], got {args.real_time_factor!r}')
    if args.use_sim_time and not args.serve:
        return _fail("--use-sim-time serves the graph on a world's /clock: it needs --serve")
    if args.use_sim_time and args.time_mode == TimeMode.FAST.parameter:
        return _fail('--use-sim-time follows the /clock of a world simulator: not with '
                     '--time-mode fast')
    time_mode = args.time_mode or (TimeMode.REALTIME if args.serve else TimeMode.FAST).parameter
    if args.foxglove is not None:
        if not 0 <= args.foxglove <= 65535:
            return _fail(f'--foxglove: a port is 0-65535, got {args.foxglove}')
        if time_mode != TimeMode.REALTIME.parameter:
            return _fail('--foxglove shows the graph as it runs: use it with --serve or '
                         '--time-mode realtime')
    from rclpy.signals import SignalHandlerOptions
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.utilities import ok
    try:
        rclpy.init(args=None if argv is None else ['grasp_demo', *argv],
                   signal_handler_options=SignalHandlerOptions.NO)
        # one namespace, however it is given: --namespace, or a remap -r __ns:=/x (which wins,
        # as for every ROS node): the banner, the name claim and the bags all use this one
        namespace = check_namespace(namespace_as_given(args.namespace))
    except (ValueError, InvalidNamespaceException) as exc:
        if ok():
            rclpy.try_shutdown()
        return _fail(one_line(exc))
    except RCLError as exc:
        return _fail(f'bad --ros-args: {one_line(exc)}')
    # Ctrl-C and SIGTERM end the demo here, not inside rclpy: the graph stops its executor,
    # closes its bags and only then shuts the context down. Serving, a signal is the way to
    # stop (exit 0); during grasps it interrupts the one running (KeyboardInterrupt, exit 130).
    # A later signal is ignored: it must not cut the closing of a bag short. The first one
    # starts the stop's bound (bags, then nodes: close_app_graph), which needs no GIL.
    exit_without_a_last_collection()
    signals = StopSignals(on_first=None if args.serve else raise_keyboard_interrupt,
                          hard_bound_s=APP_BAGS_LIMIT_S)
    signals.__enter__()

    def demo(graph) -> int:
        if args.foxglove is not None:
            from gripper_ros.nodes.live_view import serve_live
            serve_live('grasp_demo', graph, args.foxglove_address, args.foxglove)
        if args.serve:
            if not args.no_record:
                ServeRecorder(graph, args.output)
            return _serve(graph, args, signals)
        records = [_grasp_one(graph, args, w, m, i, len(objects))
                   for i, (w, m) in enumerate(objects, 1)]
        _summarise(graph, records, args)
        return 0 if all(r.final_outcome.name == 'HOLDING' for r in records) else 1
    return run_graph('grasp_demo', lambda: GripperGraph(GraphOptions(
        executor=ExecutorKind(args.executor), config_file=args.config, namespace=namespace,
        prefix=args.prefix,
        time_mode=time_mode, real_time_factor=args.real_time_factor,
        publish_clock=not args.no_clock, use_sim_time=args.use_sim_time,
        position_controller=args.position_controller,
        force_controller=args.force_controller, approach_force_margin=args.approach_force_margin,
        supervisor_parameters={} if args.force_law is None else
        {'supervisor.force_law': args.force_law})), demo, signals, 'bags')


SERVE_POLL_S = 0.1
"""How often a serving demo looks for a stop signal, a dead executor or a shut context."""


def _serve(graph, args, signals) -> int:
    """Serve until a signal, or until the graph stops spinning (its context shut down)."""
    from gripper_ros.wire import qualified, TOPIC_OUTCOME
    where = 'not recording' if args.no_record else f'one bag per grasp in {args.output}/'
    names = ', '.join(qualified(graph.namespace, n) for n in graph.served_names())
    print(f'grasp_demo: serving {names}, publishing the latched '
          f'{qualified(graph.namespace, TOPIC_OUTCOME)} ({graph.time_text}, '
          f'{where}); joint {graph.plant.joint_name}, TF frames under {graph.plant.frame_id}; '
          'Ctrl-C to stop', flush=True)
    while not signals.received and graph.spinning:
        time.sleep(SERVE_POLL_S)
    return 0


def _bag_dir(output: Path, i: int, width_m: float, mass_kg: float, overwrite: bool) -> Path:
    """Return the bag folder of grasp ``i``: a fresh, unique one (the named one, ``overwrite``)."""
    from gripper_ros.bags.recorder import unique_bag_dir
    stamp = datetime.now().strftime('%Y%m%d_%H%M%S')
    stem = f'grasp_{stamp}_{i}_w{width_m * 1e3:.0f}mm_m{mass_kg:g}kg'
    return output / stem if overwrite else unique_bag_dir(output, stem)


def _recorded(fields: dict) -> dict:
    """Return ``fields`` as recorded_grasp takes them (the object's mass by its own name)."""
    out = dict(fields)
    if 'mass_kg' in out:
        out['object_mass_kg'] = out.pop('mass_kg')
    return out


def _grasp_one(graph, args, width_m: float, mass_kg: float, i: int, n: int):
    """Grasp one object; its :class:`~gripper_ros.nodes.recording.RecordedGrasp`."""
    from gripper_ros.apps.common import set_object_fields
    from gripper_ros.bags.recorder import RecordingError
    from gripper_ros.nodes.graph import GraphError
    from gripper_ros.nodes.recording import recorded_grasp, RecordedGrasp
    lift = f', lifted at {args.lift:g} m/s^2' if args.lift else ''
    print(f'[{i}/{n}] grasping width {width_m:g} m, mass {mass_kg:g} kg{lift} ...', flush=True)
    if i > 1:                        # the previous object is still held: open the fingers
        graph.release()
    if args.no_record:
        t0 = time.perf_counter()
        placed = graph.set_object(graph.simulated_width_m(width_m, args.object_width),
                                  args.stiffness, args.damping, **set_object_fields(args))
        if not placed.success:
            raise GraphError(f'set_object: {placed.message}')
        response = graph.grasp(width_m, mass_kg, args.friction, args.lift,
                               width_tolerance_m=args.width_tolerance)
        graph.wait_still()
        logic = graph.supervisor.logic
        return RecordedGrasp(response, None, {}, {}, time.perf_counter() - t0, logic.outcome,
                             logic.message, width_m=width_m, mass_kg=mass_kg)
    run = recorded_grasp(graph, _bag_dir(Path(args.output), i, width_m, mass_kg,
                                         args.overwrite), width_m, mass_kg, args.friction,
                         args.stiffness, args.damping, args.overwrite,
                         width_tolerance_m=args.width_tolerance,
                         object_width_m=args.object_width, acceleration_mps2=args.lift,
                         stop_on_error=True, **_recorded(set_object_fields(args)))
    if run.recording_error:
        raise RecordingError(run.recording_error)
    return run


def _dash(value: float, fmt: str) -> str:
    """``value`` formatted, or a dash of the same width when it is NaN (never happened)."""
    width = int(fmt.split('.')[0])
    return f'{"-":>{width}s}' if value != value else f'{value:{fmt}}'


def _summarise(graph, records: list, args) -> None:
    lifted = bool(args.lift) and not args.no_record
    print(f'\n{"width m":>8s} {"mass kg":>8s} {"outcome":>11s} {"contact s":>10s} '
          f'{"switch s":>9s} {"criterion":>18s} {"pos err mm":>11s} {"force N":>8s} '
          f'{"F_sp N":>8s} {"peak N":>8s} {"peak/F_sp":>9s} {"max|V|":>7s} '
          + (f'{"slip mm":>8s} {"lost s":>7s} {"margin":>6s} {"max":>6s} ' if lifted else '')
          + f'{"wall s":>7s}')
    from gripper_ros.wire import Outcome
    series, rows = [], {}
    if not args.no_record:
        from gripper_ros.bags.analyze import analyze_series
        from gripper_ros.bags.series import load_grasp_series
        for i, r in enumerate(records):
            if r.response.outcome == Outcome.REFUSED:     # nothing ran: a bag without a grasp
                continue
            s = load_grasp_series(r.bag_dir)
            series.append(s)
            rows[i] = analyze_series(s, graph.plant.config.plant.voltage_limit_v)
    for i, r in enumerate(records):
        resp = r.response
        outcome = Outcome(resp.outcome).name
        if resp.outcome != Outcome.REFUSED:                     # refused: nothing ran after
            outcome = r.final_outcome.name
        pos_err_mm = (resp.final_position_m - resp.position_setpoint_m) * 1e3
        if i in rows:
            m = rows[i]
            extra = (f'{m.time_to_contact_s:10.3f} {m.switch_time_s:9.3f} '
                     f'{m.switch_criterion:>18s} {pos_err_mm:11.4f} {resp.final_force_n:8.3f} '
                     f'{resp.force_setpoint_n:8.3f} {m.peak_contact_force_n:8.3f} '
                     f'{m.peak_force_ratio:9.3f} {m.max_abs_voltage_v:7.2f}')
            if lifted:
                extra += (f' {_dash(m.max_slip_m * 1e3, "8.2f")} {_dash(m.lost_at_s, "7.3f")}'
                          f' {_dash(m.hold_margin_mean, "6.2f")}'
                          f' {_dash(m.hold_margin_max, "6.2f")}')
        else:
            extra = (f'{"":>10s} {resp.switch_time_s:9.3f} {"":>18s} {pos_err_mm:11.4f} '
                     f'{resp.final_force_n:8.3f} {resp.force_setpoint_n:8.3f} {"":>8s} '
                     f'{"":>9s} {"":>7s}')
        print(f'{r.width_m:8.3f} {r.mass_kg:8.3f} {outcome:>11s} {extra} {r.wall_s:7.2f}')
        if not resp.success:
            print(f'    {resp.message}')
        elif outcome != 'HOLDING':
            print(f'    answered HOLDING, then {outcome}: {r.final_message}')
    for r in records:
        if r.bag_dir is not None:
            print(f'bag: {r.bag_dir}')
    if args.no_record:
        lift = ", the lift's slip mm, lost s, margin and max" if args.lift else ''
        print(f'--no-record: contact s, criterion, peak N, peak/F_sp and max|V|{lift} come from '
              f'the bags, as does the figure: left out')
    if series and not args.no_plot:
        from gripper_ros.bags.analyze import plot
        png = Path(args.output) / 'grasp_demo.png'
        plot(series, list(rows.values()), str(png))
        print(f'figure: {png}')


if __name__ == '__main__':
    sys.exit(main())
