r"""grasp_client: request a grasp from another process (the ``ros2`` CLI is not installable here).

    ros2 run gripper_ros grasp_client --width 0.05 --mass 1.69

With a full ROS 2 the equivalent calls are:

    ros2 service call /gripper/sim/set_object gripper_interfaces/srv/SetObject \
        "{width_m: 0.05, open_fingers: true}"      # (refused while an object is held)
    ros2 service call /gripper/grasp gripper_interfaces/srv/Grasp "{width_m: 0.05, mass_kg: 1.69}"
    ros2 action send_goal --feedback /gripper/grasp_action gripper_interfaces/action/Grasp \
        "{width_m: 0.05, mass_kg: 1.69}"                    # the same, as an action (--action)

By default the client first places a matching simulated object (``/gripper/sim/set_object``,
like spawning a model in a simulator; an object still held from an earlier grasp is released
first); ``--object-width`` places a different one (e.g. to see NO_OBJECT) and ``--no-place``
leaves the simulation as it is. ``--namespace left`` talks to the gripper ``/left``. Exit code:
0 when the object is held, 1 for any other outcome, 2 when the graph cannot be reached.
``--action`` sends the grasp as a goal to ``/gripper/grasp_action`` instead, prints its feedback
(phase, opening, force) as it comes, and cancels the goal on Ctrl-C or SIGTERM: it prints the
server's answer (outcome STOPPED) and exits 130. Without ``--action`` a signal exits 130 at once
(a service call cannot be cancelled: ``/gripper/stop`` ends the grasp).
``--profile step:5`` (``pick-and-place:A``, ``shake:A,HZ``) places the object with the arm's motion
after HOLDING, which the simulated arm announces on ``/gripper/arm/planned_acceleration`` ahead of
time (``--unannounced``: without notice); ``--object-mass`` and the frictions are the real
object's, not told to the controller (``--mass 0``: the load-tracking grip).

``--release`` opens the fingers instead (``/gripper/release``, std_srvs/Trigger; with a full
ROS 2: ``ros2 service call /gripper/release std_srvs/srv/Trigger``): exit code 0 once open, 1 if
refused (e.g. a grasp is running: call ``/gripper/stop`` first).
"""
from __future__ import annotations

import argparse
import os
import sys

from gripper_ros.nodes.process import StopSignals
from gripper_ros.nodes.services import call_spinning, call_until_answered, spin_until_done
from gripper_ros.wire import (ACTION_GRASP, check_namespace, DEFAULT_NAMESPACE, Outcome, Phase,
                              SERVICE_GRASP, SERVICE_RELEASE, SERVICE_SET_OBJECT)

EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='grasp_client', description=__doc__.splitlines()[0])
    p.add_argument('--width', type=float, help='expected object width (m); needed for a grasp')
    p.add_argument('--mass', type=float,
                   help='object mass (kg); needed for a grasp; 0 = unknown: the grip tracks '
                        'the load the pads measure')
    p.add_argument('--release', action='store_true',
                   help='open the fingers (/gripper/release) instead of grasping')
    p.add_argument('--friction', type=float, default=0.0, help='mu_s (0 = supervisor default)')
    p.add_argument('--acceleration', type=float, default=0.0, help='a in eq. 23 (m/s^2)')
    p.add_argument('--timeout', type=float, default=0.0,
                   help='simulated-time budget in s (0 = supervisor default)')
    p.add_argument('--width-tolerance', type=float, default=0.0,
                   help='the object may be this much wider or narrower, m (0 = default)')
    p.add_argument('--object-width', type=float, help='simulated object width (default --width)')
    p.add_argument('--stiffness', type=float, default=0.0, help='object stiffness N/m (0 rigid)')
    p.add_argument('--no-place', action='store_true', help='do not call /gripper/sim/set_object')
    p.add_argument('--profile', default=None, metavar='NAME:A[,HZ]',
                   help="the arm's motion after HOLDING (as grasp_demo's): step:A, "
                        'pick-and-place:A or shake:A,HZ; announced ahead on '
                        'arm/planned_acceleration unless --unannounced')
    p.add_argument('--unannounced', action='store_true',
                   help='the arm plays --profile without notice')
    p.add_argument('--lift-off', type=float, default=0.0, metavar='S',
                   help='the arm hands the weight to the pads over S seconds (0 = configured)')
    p.add_argument('--object-mass', type=float, default=0.0, metavar='KG',
                   help="the simulated object's real mass (0 = the requested --mass)")
    p.add_argument('--static-friction', type=float, default=None, metavar='MU',
                   help='its real mu_s on the pads (0 = frictionless; with --kinetic-friction, '
                        'neither = the configured friction)')
    p.add_argument('--kinetic-friction', type=float, default=None, metavar='MU',
                   help='its real mu_k (0 = it slides without friction)')
    p.add_argument('--wait', type=float, default=10.0, help='seconds to wait for the services')
    p.add_argument('--call-timeout', type=float, default=600.0, help='wall seconds per call')
    p.add_argument('--action', action='store_true',
                   help='use the grasp_action action: feedback, Ctrl-C cancels')
    p.add_argument('--namespace', default=DEFAULT_NAMESPACE,
                   help='the gripper to talk to (default %(default)s: /gripper/...)')
    return p


def _request_fields(args) -> dict:
    """Return the grasp request of the command line (the service request and the goal alike)."""
    return {'width_m': args.width, 'mass_kg': args.mass, 'friction_coefficient': args.friction,
            'acceleration_mps2': args.acceleration, 'timeout_s': args.timeout,
            'width_tolerance_m': args.width_tolerance}


def _grasp_by_action(node, args, signals):
    """Send the goal, print feedback until the result; Ctrl-C cancels. None if no answer."""
    from gripper_interfaces.action import Grasp as GraspAction
    from rclpy.action import ActionClient

    client = ActionClient(node, GraspAction, ACTION_GRASP)
    if not client.wait_for_server(timeout_sec=args.wait):
        print(f'grasp_client: action {ACTION_GRASP} not available after {args.wait:g} s',
              file=sys.stderr)
        return None

    def on_feedback(msg):
        f = msg.feedback
        phase = Phase(f.phase).name if f.phase in Phase._value2member_map_ else str(f.phase)
        print(f'feedback: t={f.elapsed_s:7.4f} s  phase {phase:<8s} opening {f.width_m:.5f} m  '
              f'force {f.force_n:8.4f} N  contact {f.contact}', flush=True)

    sent = client.send_goal_async(GraspAction.Goal(**_request_fields(args)),
                                  feedback_callback=on_feedback)
    spin_until_done(node, sent, args.call_timeout)     # a goal sent is cancelled, not abandoned
    if not sent.done() or not sent.result().accepted:
        return None
    handle = sent.result()
    result = handle.get_result_async()
    if not spin_until_done(node, result, args.call_timeout, signals) and \
            signals.received is not None:
        print('grasp_client: cancelling the goal', file=sys.stderr, flush=True)
        spin_until_done(node, handle.cancel_goal_async(), args.wait)
        spin_until_done(node, result, args.wait)
    return result.result().result if result.done() else None


def _release(node, args, signals: StopSignals) -> int:
    from std_srvs.srv import Trigger

    client = node.create_client(Trigger, SERVICE_RELEASE)
    if not client.wait_for_service(timeout_sec=args.wait):
        print(f'grasp_client: service {SERVICE_RELEASE} not available after {args.wait:g} s',
              file=sys.stderr)
        return 2
    response = call_spinning(node, client, Trigger.Request(), args.call_timeout, signals)
    if response is None:
        print(f'grasp_client: the release did not answer within {args.call_timeout:g} s',
              file=sys.stderr)
        return 2
    print(f'success: {response.success}\nmessage: {response.message}')
    return 0 if response.success else 1


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import remove_ros_args

    parser = build_parser()
    args = parser.parse_args(
        remove_ros_args(sys.argv if argv is None else ['grasp_client', *argv])[1:])
    if not args.release and (args.width is None or args.mass is None):
        parser.error('--width and --mass are required for a grasp (or give --release)')
    try:
        namespace = check_namespace(args.namespace)
    except ValueError as exc:
        parser.error(str(exc))
    if (args.unannounced or args.lift_off) and args.profile is None:
        parser.error('--unannounced and --lift-off need --profile')
    from gripper_ros.apps.common import friction_option
    if friction_option(args):
        parser.error(friction_option(args))
    if args.profile is not None:
        from gripper_ros.core.physics.hold import parse_profile
        try:
            args.profile = parse_profile(args.profile)
        except ValueError as exc:
            parser.error(f'--profile: {exc}')
    with StopSignals() as signals:
        # the signal is seen here, not in rclpy: a cancelled goal's answer is still received
        rclpy.init(args=None if argv is None else [],
                   signal_handler_options=SignalHandlerOptions.NO)
        return _run(rclpy, args, namespace, signals)


def _run(rclpy, args, namespace: str, signals: StopSignals) -> int:
    from gripper_interfaces.srv import Grasp, SetObject
    from gripper_ros.apps.common import set_object_fields
    from rclpy.executors import ExternalShutdownException

    node = rclpy.create_node('grasp_client', namespace=namespace)
    try:
        if args.release:
            return _release(node, args, signals)
        grasp = node.create_client(Grasp, SERVICE_GRASP)
        place = node.create_client(SetObject, SERVICE_SET_OBJECT)
        needed = [grasp] if args.no_place else [grasp, place]
        for client in needed:
            if not client.wait_for_service(timeout_sec=args.wait):
                print(f'grasp_client: service {client.srv_name} not available after '
                      f'{args.wait:g} s (is grasp_demo --serve running on this '
                      f'ROS_DOMAIN_ID?)', file=sys.stderr)
                return 2
        if not args.no_place:
            width = args.width if args.object_width is None else args.object_width
            request = SetObject.Request(width_m=width, stiffness_n_per_m=args.stiffness,
                                        open_fingers=True, **set_object_fields(args))
            placed = call_until_answered(node, place, request, args.call_timeout, signals)
            if placed is not None and not placed.success and 'is held' in placed.message:
                print('grasp_client: an object is held: releasing it first', flush=True)
                if _release(node, args, signals) == 0:
                    placed = call_until_answered(node, place, request, args.call_timeout,
                                                 signals)
            if placed is None:
                print('grasp_client: set_object did not answer', file=sys.stderr)
                return 2
            if not placed.success:
                print(f'grasp_client: set_object: {placed.message}', file=sys.stderr)
        if args.action:
            response = _grasp_by_action(node, args, signals)
        else:
            response = call_spinning(node, grasp, Grasp.Request(**_request_fields(args)),
                                     args.call_timeout, signals)
        if response is None and signals.received is not None:
            print('grasp_client: interrupted before the answer', file=sys.stderr)
            return EXIT_INTERRUPTED
        if response is None:
            print(f'grasp_client: the grasp did not answer within {args.call_timeout:g} s',
                  file=sys.stderr)
            return 2
        outcome = Outcome(response.outcome).name if response.outcome in \
            Outcome._value2member_map_ else str(response.outcome)
        print(f'outcome: {outcome}\nsuccess: {response.success}\nmessage: {response.message}\n'
              f'position_setpoint_m: {response.position_setpoint_m:.6f}\n'
              f'force_setpoint_n: {response.force_setpoint_n:.4f}\n'
              f'final_position_m: {response.final_position_m:.6f}\n'
              f'final_width_m: {response.final_width_m:.6f}\n'
              f'final_force_n: {response.final_force_n:.4f}\n'
              f'switch_time_s: {response.switch_time_s:.4f}\ngrasp_id: {response.grasp_id}')
        if signals.received is not None:
            return EXIT_INTERRUPTED
        return 0 if response.success else 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return EXIT_INTERRUPTED
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
