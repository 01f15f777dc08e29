"""One gripper's whole node graph in one process under one executor, with real service clients.

Used by ``grasp_demo``, the tests and the benchmarks: the nodes talk only over topics and
services, the executor spins in a background thread, and requests go through
``sim/set_object``, ``grasp``, ``release``, ``move`` and ``stop`` exactly as from another
process. The loop topics between the four loop nodes are handed over in the process
(:mod:`gripper_ros.nodes.intra_process`); everything else, and the loop topics for any other
subscriber, goes over DDS.
Recording lives in :mod:`gripper_ros.nodes.recording`.
"""
from __future__ import annotations

from collections import Counter
import copy
from dataclasses import dataclass, field
import math
import threading
import time

from gripper_interfaces.srv import Grasp, Move, SetObject, SimStep
from gripper_ros.core.config import load_config
from gripper_ros.nodes.description_node import DescriptionPublisher
from gripper_ros.nodes.excitation_node import ExcitationServer
from gripper_ros.nodes.force_controller_node import ForceControllerNode
from gripper_ros.nodes.grasp_action_node import GraspActionServer
from gripper_ros.nodes.intra_process import IntraProcessBus
from gripper_ros.nodes.move_action_node import MoveActionServer
from gripper_ros.nodes.names import destroy_probes, NameClaim
from gripper_ros.nodes.parameters import refuse_unknown_overrides, strict_parameters
from gripper_ros.nodes.plant_simulator_node import PlantSimulatorNode
from gripper_ros.nodes.position_controller_node import PositionControllerNode
from gripper_ros.nodes.process import (build_node, CLEAN_UP_STEP_S, ExecutorKind,
                                       load_bound_s, make_executor, release_nodes,
                                       spin_until_stopped)
from gripper_ros.nodes.qos import SERVICE_QOS
from gripper_ros.nodes.services import call_and_wait, wait_until
from gripper_ros.nodes.supervisor_node import SupervisorNode
from gripper_ros.nodes.trajectory_action_node import TrajectoryActionServer
from gripper_ros.wire import (ACTION_FOLLOW_JOINT_TRAJECTORY, ACTION_GRASP, ACTION_GRIPPER_CMD,
                              ACTION_GRIPPER_COMMAND, ACTION_MOVE, check_namespace,
                              DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                              DEFAULT_NAMESPACE, DEFAULT_POSITION_CONTROLLER,
                              DEFAULT_STATE_RATE_HZ, namespace_prefix, NODE_PLANT, NODE_SUPERVISOR,
                              SERVICE_EXCITE, SERVICE_GRASP, SERVICE_MOVE, SERVICE_PAUSE,
                              SERVICE_RELEASE, SERVICE_RESUME, SERVICE_SET_OBJECT, SERVICE_STEP,
                              SERVICE_STOP, TimeMode)
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_srvs.srv import Trigger


class GraphError(RuntimeError):
    """The graph did not come up or a call did not return in time."""


@dataclass
class GraphOptions:
    executor: ExecutorKind = ExecutorKind.EVENTS
    config_file: str = ''
    namespace: str = DEFAULT_NAMESPACE
    # fast: the graph of a demo, a test or a sweep; serve: realtime
    time_mode: str = TimeMode.FAST.parameter
    real_time_factor: float = 1.0
    state_rate_hz: float = DEFAULT_STATE_RATE_HZ
    publish_clock: bool = True
    use_sim_time: bool = False       # every node on the /clock of a world (time_mode realtime)
    position_controller: str = DEFAULT_POSITION_CONTROLLER.value
    force_controller: str = DEFAULT_FORCE_CONTROLLER.value
    approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN
    action_server: bool = True       # also serve the grasp and the move as actions
    check_names: bool = True         # refuse to start when the namespace is taken
    description: bool = True         # robot_description, /tf_static and /tf (and in bags)
    prefix: str | None = None        # the xacro's prefix: the joint's and the URDF's names
    #                                  (None: from the namespace, wire.namespace_prefix)
    client_name: str = 'grasp_demo_client'   # the node of the graph's own service clients
    supervisor_parameters: dict = field(default_factory=dict)
    plant_parameters: dict = field(default_factory=dict)
    process_parameters: tuple = ()   # names the process reads itself (gripper_graph's settings)


class GripperGraph:
    """plant_simulator, position_controller, force_controller and supervisor, spinning."""

    def __init__(self, options: GraphOptions | None = None, context: Context | None = None):
        self.options = opts = options or GraphOptions()
        self.context = context
        self._owns_context = False          # set by in_own_context(): close() shuts it down
        self.namespace = check_namespace(opts.namespace)
        kw = {'namespace': self.namespace}
        if context is not None:
            kw['context'] = context
        self.nodes: list = []
        self.bus = IntraProcessBus(rclpy.logging.get_logger('gripper_ros.intra_process'))
        self.close_hooks: list = []          # run first by close() (e.g. open recordings)
        load_config(opts.config_file or None)   # a bad file is refused before a name is taken
        prefix = namespace_prefix(self.namespace) if opts.prefix is None else opts.prefix
        self._claim = None
        if opts.check_names:
            try:
                self._claim = NameClaim.take((NODE_PLANT, NODE_SUPERVISOR), (SERVICE_GRASP,),
                                             context, self.namespace, prefix)
            except BaseException:
                destroy_probes(self.context)
                raise
        try:
            self._build(opts, kw)
        except BaseException:
            self.close()
            raise
        destroy_probes(self.context)      # beside the graph's nodes: the participant stays

    def _build(self, opts: GraphOptions, client_kw: dict) -> None:
        sim_time = [Parameter('use_sim_time', value=True)] if opts.use_sim_time else []
        cfg = [Parameter('config_file', value=opts.config_file)] + sim_time   # every node
        named = cfg + ([] if opts.prefix is None else [Parameter('prefix', value=opts.prefix)])
        kw = {**client_kw, 'intra_process': self.bus}   # the graph's topics between its nodes
        self.plant = build_node(PlantSimulatorNode, parameter_overrides=named + [
            Parameter('time_mode', value=opts.time_mode),
            Parameter('real_time_factor', value=float(opts.real_time_factor)),
            Parameter('state_rate_hz', value=float(opts.state_rate_hz)),
            Parameter('publish_clock', value=bool(opts.publish_clock))] + [
            Parameter(k, value=v) for k, v in opts.plant_parameters.items()], **kw)
        self.nodes.append(self.plant)
        self.position = build_node(PositionControllerNode, parameter_overrides=cfg + [
            Parameter('controller', value=opts.position_controller)], **kw)
        self.nodes.append(self.position)
        self.force = build_node(ForceControllerNode, parameter_overrides=cfg + [
            Parameter('controller', value=opts.force_controller),
            Parameter('approach_force_margin', value=float(opts.approach_force_margin))],
            **kw)
        self.nodes.append(self.force)
        self.supervisor = build_node(SupervisorNode, parameter_overrides=named + [
            Parameter('status_rate_hz', value=float(opts.state_rate_hz))] + [
            Parameter(k, value=v) for k, v in opts.supervisor_parameters.items()], **kw)
        self.nodes.append(self.supervisor)
        self.client_node = rclpy.create_node(opts.client_name, parameter_overrides=sim_time,
                                             **client_kw)
        strict_parameters(self.client_node)
        self.nodes.append(self.client_node)
        self.action_server = self.move_action_server = self.excitation_server = None
        self.trajectory_action_server = None
        if opts.action_server:
            self.action_server = build_node(GraspActionServer, parameter_overrides=cfg, **kw)
            self.nodes.append(self.action_server)
            self.move_action_server = build_node(MoveActionServer, parameter_overrides=named, **kw)
            self.nodes.append(self.move_action_server)
            if self.move_action_server.gripper_command_served:   # control_msgs loads
                self.trajectory_action_server = build_node(TrajectoryActionServer,
                                                           parameter_overrides=named, **kw)
                self.nodes.append(self.trajectory_action_server)
            self.excitation_server = build_node(ExcitationServer, parameter_overrides=cfg, **kw)
            self.nodes.append(self.excitation_server)
        self.description = None
        if opts.description:
            self.description = build_node(DescriptionPublisher, parameter_overrides=named, **kw)
            self.nodes.append(self.description)
        refuse_unknown_overrides(self.nodes, opts.process_parameters)   # a -p naming nothing
        self._one_clock_subscription()
        self.executor = make_executor(opts.executor, self.context)
        for node in self.nodes:
            self.executor.add_node(node)
        self.bus.bind(self.executor)
        self._stop = Future()
        self._thread = threading.Thread(target=spin_until_stopped,
                                        args=(self.executor, self._stop),
                                        name='gripper_graph_executor', daemon=True)
        self._thread.start()
        client = self.client_node.create_client
        self._set_object = client(SetObject, SERVICE_SET_OBJECT, qos_profile=SERVICE_QOS)
        self._grasp = client(Grasp, SERVICE_GRASP, qos_profile=SERVICE_QOS)
        self._release = client(Trigger, SERVICE_RELEASE, qos_profile=SERVICE_QOS)
        self._move = client(Move, SERVICE_MOVE, qos_profile=SERVICE_QOS)
        self._stop_client = client(Trigger, SERVICE_STOP, qos_profile=SERVICE_QOS)
        self._pause = client(Trigger, SERVICE_PAUSE, qos_profile=SERVICE_QOS)
        self._resume = client(Trigger, SERVICE_RESUME, qos_profile=SERVICE_QOS)
        self._step = client(SimStep, SERVICE_STEP, qos_profile=SERVICE_QOS)
        for c in (self._set_object, self._grasp, self._release, self._move):
            if not c.wait_for_service(timeout_sec=load_bound_s(10.0)):
                raise GraphError(f'service {c.srv_name} did not come up')
        if self.plant.time_mode is not TimeMode.SIM_TIME and \
                not wait_until(lambda: self.supervisor.measured, load_bound_s(10.0)):
            raise GraphError(f'{NODE_SUPERVISOR} has no measurement from {NODE_PLANT}')

    def _one_clock_subscription(self) -> None:
        """Under use_sim_time, set every node's ROS clock from the plant's /clock subscription.

        rclpy gives each node a TimeSource of its own, each subscribing to /clock
        (``time_source.py``): nine subscriptions in one process, each message taken nine times
        (a world at 1 kHz cost a quarter of a core). The others' clocks are attached to the
        plant's TimeSource instead (``attach_clock``), and their own subscription goes
        (``detach_node``); their ``use_sim_time`` stays as given. rclpy keeps a node's
        TimeSource in ``Node._time_source``.
        """
        source = self.plant._time_source
        if not source.ros_time_is_active:
            return
        for node in self.nodes:
            own = node._time_source
            if node is not self.plant and own.ros_time_is_active:
                own.detach_node()
                source.attach_clock(node.get_clock())

    # ------------------------------------------------------------------ nodes
    def add_node(self, node) -> None:
        self.nodes.append(node)
        self.executor.add_node(node)

    def kill_node(self, node, timeout_s: float = 5.0) -> None:
        """Take ``node`` out of the running graph as if its process died (fault tests, demos).

        Removal and destruction run on the executor thread, in two steps: the EventsExecutor still
        dispatches events queued for a node before its removal, so the node is destroyed only by
        a second task, queued behind those events. Destroying a node from another thread, or
        while events for it are queued, makes rclpy raise ``InvalidHandle`` inside the executor
        and ends the whole graph.
        """
        done = threading.Event()
        failure: list[BaseException] = []

        def destroy():
            try:
                node.destroy_node()
            except BaseException as exc:  # reported to the caller below
                failure.append(exc)
            done.set()

        def remove():
            try:
                self.bus.detach(node)
                self.executor.remove_node(node)
            except BaseException as exc:
                failure.append(exc)
                done.set()
                return
            self.executor.create_task(destroy)

        name = node.get_name()
        self.executor.create_task(remove)
        bound_s = load_bound_s(timeout_s)
        if not done.wait(bound_s):
            raise GraphError(f'node {name} could not be removed within {bound_s:.1f} s')
        if failure:
            raise GraphError(f'removing node {name} failed: {failure[0]}')
        self.nodes.remove(node)

    def run_in_executor(self, function, timeout_s: float = 5.0):
        """Run ``function()`` on the executor thread (between callbacks) and return its value."""
        done = threading.Event()
        result: list = []

        def task():
            try:
                result.append((True, function()))
            except BaseException as exc:  # handed to the caller
                result.append((False, exc))
            done.set()

        self.executor.create_task(task)
        bound_s = load_bound_s(timeout_s)
        if not done.wait(bound_s):
            raise GraphError(f'the executor did not run a task within {bound_s:.1f} s')
        ok, value = result[0]
        if not ok:
            raise value
        return value

    # ------------------------------------------------------------------ calls
    def call(self, client, request, timeout_s: float):
        """Make a real service call from this process; wait in this (non-executor) thread.

        ``timeout_s`` is for free cores: a loaded machine waits longer (:func:`load_bound_s`).
        """
        bound_s = load_bound_s(timeout_s)
        response = call_and_wait(client, request, bound_s)
        if response is None:
            raise GraphError(f'{client.srv_name} did not answer within {bound_s:.1f} s')
        return response

    def set_object(self, width_m: float, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, open_fingers: bool = True,
                   timeout_s: float = 10.0, fault: int = 0, fault_at_s: float = 0.0,
                   fault_time_constant_s: float = 0.0, **hold) -> SetObject.Response:
        """Place an object, with an optional fault and hold scenario for the next grasp.

        ``fault`` (SetObject.FAULT_*) fires ``fault_at_s`` s into the next grasp; ``hold`` sets
        the SetObject hold and lift fields (mass_kg, lift_delay_s...). An object still held from
        an earlier grasp is released first (the plant refuses to replace an object the fingers
        hold).
        """
        if self.supervisor.logic.holding:
            self.release()
        request = SetObject.Request(
            width_m=float(width_m), stiffness_n_per_m=float(stiffness_n_per_m),
            damping_n_s_per_m=float(damping_n_s_per_m), open_fingers=open_fingers,
            fault=int(fault), fault_at_s=float(fault_at_s),
            fault_time_constant_s=float(fault_time_constant_s))
        for name, value in hold.items():        # each as its field's type (lift_profile: int)
            setattr(request, name, type(getattr(request, name))(value))
        return self.call(self._set_object, request, timeout_s)

    def grasp(self, width_m: float, mass_kg: float, friction_coefficient: float = 0.0,
              acceleration_mps2: float = 0.0, timeout_s: float = 0.0,
              wall_timeout_s: float = 600.0, width_tolerance_m: float = 0.0) -> Grasp.Response:
        return self.call(self._grasp, Grasp.Request(
            width_m=float(width_m), mass_kg=float(mass_kg),
            friction_coefficient=float(friction_coefficient),
            acceleration_mps2=float(acceleration_mps2), timeout_s=float(timeout_s),
            width_tolerance_m=float(width_tolerance_m)),
            wall_timeout_s)

    def grasp_async(self, width_m: float, mass_kg: float, timeout_s: float = 0.0):
        """Send a grasp request and return its future at once (it is done when the grasp ends).

        For a caller that acts while the grasp runs; :meth:`forget` stops waiting for it.
        """
        return self._grasp.call_async(Grasp.Request(width_m=float(width_m),
                                                    mass_kg=float(mass_kg),
                                                    timeout_s=float(timeout_s)))

    def forget(self, future) -> None:
        """Stop waiting for the answer of a :meth:`grasp_async` request (its grasp goes on)."""
        if not future.done():
            self._grasp.remove_pending_request(future)

    def move(self, width_m: float, speed_mps: float = 0.0, max_effort_n: float = 0.0,
             timeout_s: float = 0.0, wall_timeout_s: float = 600.0) -> Move.Response:
        return self.call(self._move, Move.Request(
            width_m=float(width_m), speed_mps=float(speed_mps),
            max_effort_n=float(max_effort_n), timeout_s=float(timeout_s)), wall_timeout_s)

    def release(self, wall_timeout_s: float = 120.0) -> Trigger.Response:
        return self.call(self._release, Trigger.Request(), wall_timeout_s)

    def stop(self, wall_timeout_s: float = 10.0) -> Trigger.Response:
        return self.call(self._stop_client, Trigger.Request(), wall_timeout_s)

    def pause(self) -> Trigger.Response:
        return self.call(self._pause, Trigger.Request(), 10.0)

    def resume(self) -> Trigger.Response:
        return self.call(self._resume, Trigger.Request(), 10.0)

    def step(self, ticks: int = 0, duration_s: float = 0.0,
             wall_timeout_s: float = 600.0) -> SimStep.Response:
        return self.call(self._step, SimStep.Request(ticks=int(ticks),
                                                     duration_s=float(duration_s)),
                         wall_timeout_s)

    # ------------------------------------------------------------------ state
    def controller_settings(self) -> dict:
        """Return what a re-simulation of this graph's bags needs to rebuild its controllers.

        The approach margin is the one the next force stage runs with: ``approach_force_margin``
        is a writable parameter, and a change at run time must be recorded as it is used.
        """
        o = self.options
        return {'position_controller': o.position_controller,
                'force_controller': o.force_controller,
                'approach_force_margin': float(self.force.approach_margin),
                'config_file': o.config_file}

    def config_data(self) -> dict:
        """Return the configuration the graph runs with now, as a config file would hold it.

        Each section comes from the node that owns it (a gain set at run time included).
        """
        data = copy.deepcopy(self.plant.parameters.data)
        for node in (self.position, self.force, self.supervisor):
            for section in node.parameters.writable:
                data[section] = copy.deepcopy(node.parameters.data[section])
        return data

    def published_counts(self) -> Counter:
        """Count the messages published so far on every graph topic (relative names).

        These are the nodes' own counters, repeats of an unanswered tick included; not the
        description's (/tf follows joint_states one for one).
        """
        total: Counter = Counter()
        for node in (self.plant, self.supervisor, self.position, self.force):
            total.update(node.published)
        return total

    def served_names(self) -> list[str]:
        """Return every service and action this graph serves (relative names), services first."""
        names = [SERVICE_GRASP, SERVICE_MOVE, SERVICE_STOP, SERVICE_RELEASE, SERVICE_SET_OBJECT,
                 SERVICE_PAUSE, SERVICE_RESUME, SERVICE_STEP]
        if self.excitation_server is not None:
            names.append(SERVICE_EXCITE)
        if self.action_server is not None:
            names.append(ACTION_GRASP)
        if self.move_action_server is not None:
            names.append(ACTION_MOVE)
            if self.move_action_server.gripper_command_served:
                names += [ACTION_GRIPPER_CMD, ACTION_GRIPPER_COMMAND]
        if self.trajectory_action_server is not None:
            names.append(ACTION_FOLLOW_JOINT_TRAJECTORY)
        return names

    @property
    def spinning(self) -> bool:
        """True while the executor thread runs (it ends when the context is shut down)."""
        return self._thread.is_alive() and rclpy.ok(context=self.executor.context)

    @property
    def sim_time_ns(self) -> int:
        return self.plant.plant.t_ns

    @property
    def time_text(self) -> str:
        """Say how the graph's time runs, as its banners do (``TimeMode.text``)."""
        return self.plant.time_mode.text

    def stands_still(self) -> bool:
        """Tell whether simulated time stands still now; ask it on the executor thread.

        Every loop message has been handed over, and the plant is paused or (fast mode) has
        found that nothing needs time.
        """
        return self.bus.idle and (self.plant.paused or not self.plant.advancing)

    def wait_still(self, quiet_s: float = 0.05, timeout_s: float = 30.0) -> bool:
        """Wait until simulated time stands still: the plant waits and nothing is in flight.

        Asked on the executor thread, between two callbacks (:meth:`stands_still`). In fast
        mode that means the request and its hold scenario are over; paused, that a step's last
        tick has been answered. The answer must hold twice, ``quiet_s`` apart, with no tick in
        between (an input from outside the process may still wake the plant). False on timeout
        (realtime: time never stands still unless paused).
        """
        plant = self.plant
        deadline = time.monotonic() + timeout_s
        seen = None                     # ticks_published when the graph was last found still
        while time.monotonic() < deadline:
            try:
                now_still = self.run_in_executor(self.stands_still,
                                                 max(0.1, deadline - time.monotonic()))
            except GraphError:
                return False
            ticks = plant.ticks_published
            if now_still and seen == ticks:
                return True
            seen = ticks if now_still else None
            time.sleep(quiet_s if now_still else 0.005)
        return False

    def simulated_width_m(self, width_m: float, object_width_m: float | None = None) -> float:
        """Return the width of the object to place for a grasp of ``width_m``.

        ``object_width_m`` when given, else the requested width, or nothing (0) when that width
        is not one an object can have (the request will be refused; an invalid object must not
        fail the placement first).
        """
        if object_width_m is not None:
            return object_width_m
        valid = math.isfinite(width_m) and 0.0 < width_m < self.plant.config.plant.max_travel_m
        return width_m if valid else 0.0

    # ------------------------------------------------------------------ lifecycle
    @classmethod
    def in_own_context(cls, options: GraphOptions | None = None,
                       domain_id: int | None = None,
                       args: list[str] | None = None) -> GripperGraph:
        """Start a graph in a fresh rclpy context that :meth:`close` shuts down.

        The context is on ``domain_id`` (default ROS_DOMAIN_ID), with ``args`` as a process's
        command line (``['--ros-args', '-p', ...]``, for every node). Several graphs, or a graph
        and other rclpy users, can share a process without sharing a context.
        """
        context = Context()
        rclpy.init(args=args, context=context,
                   **({} if domain_id is None else {'domain_id': domain_id}))
        try:
            graph = cls(options, context=context)
        except BaseException:
            rclpy.try_shutdown(context=context)
            raise
        graph._owns_context = True
        return graph

    def close_recordings(self) -> None:
        """Run the close hooks (open recordings end with whole ticks), the last opened first."""
        for hook in reversed(self.close_hooks):
            hook()
        self.close_hooks = []

    def close(self) -> None:
        """Stop spinning and destroy every node (and the context it owns); safe to call twice.

        Recordings close first, while the executor still runs; every node leaves the stopped
        executor before it is destroyed. The executor's end is awaited within a node process's
        clean-up bound (:data:`~gripper_ros.nodes.process.CLEAN_UP_STEP_S`, scaled by the
        machine's load); an executor still in a callback then is ended by shutting the owned
        context down. Nodes an executor may still be using are never destroyed (rclpy frees
        their handles under the running callback: a crash in C); they are left to the process's
        exit, said in one line.
        """
        self.close_recordings()
        destroy_probes(self.context)      # a graph refused or stopped while starting
        if hasattr(self, '_stop'):
            if not self._stop.done():
                self._stop.set_result(True)
            self._thread.join(timeout=load_bound_s(CLEAN_UP_STEP_S))
            if self._thread.is_alive() and self._owns_context:
                rclpy.try_shutdown(context=self.context)
                self._thread.join(timeout=load_bound_s(CLEAN_UP_STEP_S))
            if self._thread.is_alive():
                rclpy.logging.get_logger('gripper_ros').error(
                    f"the graph's executor did not stop within "
                    f'{2 * load_bound_s(CLEAN_UP_STEP_S):.1f} s; its {len(self.nodes)} nodes are '
                    "left to the process's exit")
                self.nodes = []
            else:
                release_nodes(self.executor, self.nodes)
        for node in self.nodes:
            node.destroy_node()
        self.nodes = []
        if self._claim is not None:
            self._claim.release()
            self._claim = None
        if self._owns_context:
            rclpy.try_shutdown(context=self.context)
            self._owns_context = False

    def __enter__(self) -> GripperGraph:
        return self

    def __exit__(self, *exc) -> None:
        if self.nodes:
            self.close()
