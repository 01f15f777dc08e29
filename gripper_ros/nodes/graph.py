"""The whole node graph in one process under one executor, with real service clients.

Used by ``grasp_demo``, the tests and the benchmarks: the four nodes talk only over topics and
services (DDS), the executor spins in a background thread, and requests go through
``/gripper/sim/set_object`` and ``/gripper/grasp`` exactly as from another process.
"""
from __future__ import annotations

import functools
import math
import threading
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import rclpy
from gripper_interfaces.srv import Grasp, SetObject
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.task import Future

from gripper_ros.core.stages import DEFAULT_FORCE_CONTROLLER
from gripper_ros.nodes.force_controller_node import ForceControllerNode
from gripper_ros.nodes.grasp_action_node import GraspActionServer
from gripper_ros.nodes.plant_simulator_node import PlantSimulatorNode
from gripper_ros.nodes.position_controller_node import PositionControllerNode
from gripper_ros.nodes.common import (GRAPH_TOPICS, SERVICE_GRASP, SERVICE_QOS, SERVICE_SET_OBJECT, TOPIC_CLOCK,
                         TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                         TOPIC_MOTOR_STATE, TOPIC_STATUS, ExecutorKind, make_executor,
                         spin_until_stopped)
from gripper_ros.nodes.supervisor_node import SupervisorNode


class GraphError(RuntimeError):
    """The graph did not come up or a call did not return in time."""


@dataclass
class RecordedGrasp:
    """A grasp's answer, its bag, and how many messages the graph published per topic."""

    response: Grasp.Response
    bag_dir: object
    published: dict
    recorded: dict
    wall_s: float


@dataclass
class GraphOptions:
    executor: ExecutorKind = ExecutorKind.EVENTS
    config_file: str = ''
    position_controller: str = 'mpc_pd'
    force_controller: str = DEFAULT_FORCE_CONTROLLER.value
    approach_force_margin: float = 1.0
    action_server: bool = True     # also serve the grasp as an action (feedback, cancel)


class GripperGraph:
    """plant_simulator, position_controller, force_controller and supervisor, spinning."""

    def __init__(self, options: GraphOptions | None = None, context: Context | None = None):
        self.options = opts = options or GraphOptions()
        self.context = context
        self._owns_context = False          # set by in_own_context(): close() shuts it down
        cfg = [Parameter('config_file', value=opts.config_file)]
        sim = cfg + [Parameter('use_sim_time', value=True)]
        kw = {'context': context} if context is not None else {}
        self.plant = PlantSimulatorNode(parameter_overrides=cfg, **kw)
        self.position = PositionControllerNode(
            parameter_overrides=sim + [Parameter('controller', value=opts.position_controller)],
            **kw)
        self.force = ForceControllerNode(
            parameter_overrides=sim + [
                Parameter('controller', value=opts.force_controller),
                Parameter('approach_force_margin', value=float(opts.approach_force_margin))],
            **kw)
        self.supervisor = SupervisorNode(parameter_overrides=sim, **kw)
        self.client_node = rclpy.create_node('grasp_demo_client', **kw)
        self.nodes = [self.plant, self.position, self.force, self.supervisor, self.client_node]
        self.action_server = None
        if opts.action_server:
            self.action_server = GraspActionServer(parameter_overrides=cfg, **kw)
            self.nodes.append(self.action_server)
        self.executor = make_executor(opts.executor, context)
        for node in self.nodes:
            self.executor.add_node(node)
        self._stop = Future()
        self._thread = threading.Thread(target=spin_until_stopped, args=(self.executor, self._stop),
                                        name='gripper_graph_executor', daemon=True)
        self._thread.start()
        self._tap = _RecorderTap(self.client_node, lambda: self.plant.plant.t_ns)
        self._set_object = self.client_node.create_client(SetObject, SERVICE_SET_OBJECT)
        self._grasp = self.client_node.create_client(Grasp, SERVICE_GRASP,
                                                     qos_profile=SERVICE_QOS)
        for client in (self._set_object, self._grasp):
            if not client.wait_for_service(timeout_sec=10.0):
                self.close()
                raise GraphError(f'service {client.srv_name} did not come up')

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
                self.executor.remove_node(node)
            except BaseException as exc:
                failure.append(exc)
                done.set()
                return
            self.executor.create_task(destroy)

        name = node.get_name()
        self.executor.create_task(remove)
        if not done.wait(timeout_s):
            raise GraphError(f'node {name} could not be removed within {timeout_s:g} s')
        if failure:
            raise GraphError(f'removing node {name} failed: {failure[0]}')
        self.nodes.remove(node)

    def call(self, client, request, timeout_s: float):
        """A real service call from this process; waits in this (non-executor) thread."""
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout_s):
            client.remove_pending_request(future)
            raise GraphError(f'{client.srv_name} did not answer within {timeout_s:g} s')
        return future.result()

    def set_object(self, width_m: float, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, open_fingers: bool = True,
                   timeout_s: float = 10.0, fault: int = 0, fault_at_s: float = 0.0,
                   fault_time_constant_s: float = 0.0) -> SetObject.Response:
        """Place an object; ``fault`` (SetObject.FAULT_*) fires ``fault_at_s`` s into the next
        grasp."""
        return self.call(self._set_object, SetObject.Request(
            width_m=float(width_m), stiffness_n_per_m=float(stiffness_n_per_m),
            damping_n_s_per_m=float(damping_n_s_per_m), open_fingers=open_fingers,
            fault=int(fault), fault_at_s=float(fault_at_s),
            fault_time_constant_s=float(fault_time_constant_s)), timeout_s)

    def grasp(self, width_m: float, mass_kg: float, friction_coefficient: float = 0.0,
              acceleration_mps2: float = 0.0, timeout_s: float = 0.0,
              wall_timeout_s: float = 600.0, width_tolerance_m: float = 0.0) -> Grasp.Response:
        return self.call(self._grasp, Grasp.Request(
            width_m=float(width_m), mass_kg=float(mass_kg),
            friction_coefficient=float(friction_coefficient),
            acceleration_mps2=float(acceleration_mps2), timeout_s=float(timeout_s),
            width_tolerance_m=float(width_tolerance_m)),
            wall_timeout_s)

    def controller_settings(self) -> dict:
        """What a re-simulation of this graph's bags needs to rebuild the same controllers.

        The approach margin is the force stage's current one: ``approach_force_margin`` is a
        writable parameter, and a change at run time must be recorded as it is used."""
        o = self.options
        return {'position_controller': o.position_controller,
                'force_controller': o.force_controller,
                'approach_force_margin': float(self.force.stage.approach_margin),
                'config_file': o.config_file}

    def record_every_grasp(self, output_dir) -> None:
        """Serve mode: record one bag per grasp, whoever requested it."""
        self._tap.record_every_grasp(output_dir)

    def served_bags(self) -> list:
        """Serve mode: the bag folders recorded so far, oldest first."""
        return list(self._tap.auto_bags)

    @property
    def recording(self) -> bool:
        """A bag is open (a grasp is being recorded)."""
        return self._tap.sink is not None

    def wait_quiet(self, quiet_s: float = 0.05, timeout_s: float = 5.0) -> None:
        """Return once no graph message has arrived for ``quiet_s`` (so that what was published
        before a grasp, e.g. set_object's sample, is not counted with it)."""
        self._tap.wait_quiet(quiet_s, timeout_s)

    def published_counts(self) -> dict:
        """Messages published so far on every graph topic (from the nodes' own counters)."""
        ticks = self.plant.ticks_published
        return {TOPIC_CLOCK: ticks, TOPIC_JOINT_STATES: ticks, TOPIC_FORCE_SENSOR: ticks,
                TOPIC_MOTOR_STATE: ticks, TOPIC_STATUS: self.supervisor.statuses_published,
                TOPIC_MOTOR_COMMAND: (self.position.commands_published
                                      + self.force.commands_published)}

    def simulated_width_m(self, width_m: float, object_width_m: float | None = None) -> float:
        """The object to place for a grasp of ``width_m``: ``object_width_m`` when given, else
        the requested width, or nothing (0) when that width is not one an object can have (the
        request will be refused; an invalid object must not fail the placement first)."""
        if object_width_m is not None:
            return object_width_m
        valid = math.isfinite(width_m) and 0.0 < width_m < self.plant.config.plant.max_travel_m
        return width_m if valid else 0.0

    def recorded_grasp(self, bag_dir, width_m: float, mass_kg: float,
                       friction_coefficient: float = 0.0, stiffness_n_per_m: float = 0.0,
                       damping_n_s_per_m: float = 0.0, overwrite: bool = False,
                       wall_timeout_s: float = 600.0, width_tolerance_m: float = 0.0,
                       object_width_m: float | None = None) -> RecordedGrasp:
        """Place the object (``object_width_m``, default the requested ``width_m``), record
        every graph topic into ``bag_dir`` and grasp it.

        The bag is closed (summary, metadata.yaml) whatever happens, Ctrl-C included.
        """
        from gripper_ros.bags.recorder import BagRecorder
        from gripper_ros.core.supervisor import Outcome

        placed_width = self.simulated_width_m(width_m, object_width_m)
        placed = self.set_object(placed_width, stiffness_n_per_m, damping_n_s_per_m)
        if not placed.success:
            raise GraphError(f'set_object: {placed.message}')
        self._tap.wait_quiet()
        recorder = BagRecorder(
            self.client_node, bag_dir, GRAPH_TOPICS, overwrite=overwrite, subscribe=False,
            time_source=lambda: self.plant.plant.t_ns,
            custom_data={'request': {'width_m': width_m, 'mass_kg': mass_kg,
                                     'friction_coefficient': friction_coefficient,
                                     'stiffness_n_per_m': stiffness_n_per_m,
                                     'width_tolerance_m': width_tolerance_m,
                                     'object_width_m': placed_width},
                         'controllers': self.controller_settings()})
        response = None
        before = self.published_counts()
        self._tap.sink = recorder
        t0 = time.perf_counter()
        try:
            response = self.grasp(width_m, mass_kg, friction_coefficient,
                                  wall_timeout_s=wall_timeout_s,
                                  width_tolerance_m=width_tolerance_m)
        finally:
            published = {t: n - before[t] for t, n in self.published_counts().items()}
            self._drain(recorder, published)
            self._tap.sink = None
            if response is not None:
                recorder.set_custom_data({
                    'outcome': Outcome(response.outcome).name, 'success': response.success,
                    'message': response.message,
                    'position_setpoint_m': response.position_setpoint_m,
                    'force_setpoint_n': response.force_setpoint_n})
            recorded = dict(recorder.counts)
            recorder.close()
        return RecordedGrasp(response, recorder.bag_dir, published, recorded,
                             time.perf_counter() - t0)

    @staticmethod
    def _drain(recorder, published: dict, timeout_s: float = 10.0) -> None:
        """Wait until the recorder holds every message published during the grasp."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            counts = recorder.counts
            if all(counts.get(t, 0) >= n for t, n in published.items()):
                return
            time.sleep(0.005)

    @classmethod
    def in_own_context(cls, options: GraphOptions | None = None,
                       domain_id: int | None = None) -> GripperGraph:
        """A graph in a fresh rclpy context (on ``domain_id``, default ROS_DOMAIN_ID) that
        :meth:`close` shuts down: several graphs, or a graph and other rclpy users, can share a
        process without sharing a context."""
        context = Context()
        rclpy.init(context=context, **({} if domain_id is None else {'domain_id': domain_id}))
        try:
            graph = cls(options, context=context)
        except BaseException:
            rclpy.try_shutdown(context=context)
            raise
        graph._owns_context = True
        return graph

    def close(self) -> None:
        """Stop spinning and destroy every node (and the context it owns); safe to call
        twice."""
        if not self._stop.done():
            self._stop.set_result(True)
        self._thread.join(timeout=10.0)
        sink, self._tap.sink = self._tap.sink, None
        if sink is not None:  # interrupted mid-grasp: the bag still gets its summary
            sink.close()
        self.executor.shutdown(timeout_sec=2.0)
        for node in self.nodes:
            node.destroy_node()
        self.nodes = []
        if self._owns_context:
            rclpy.try_shutdown(context=self.context)
            self._owns_context = False

    def __enter__(self) -> GripperGraph:
        return self

    def __exit__(self, *exc) -> None:
        if self.nodes:
            self.close()



class _RecorderTap:
    """Long-lived raw subscriptions on every graph topic, forwarding to the current recorder.

    Created with the graph, so they are matched long before any grasp: a volatile reader created
    just before a grasp can miss the first sample of a writer that had been idle (seen with Fast
    DDS: the first force-controller command of every grasp after the first).
    """

    def __init__(self, node, time_source):
        from gripper_ros.bags.schema import import_message_class
        from gripper_ros.nodes.common import GRAPH_QOS
        self.sink = None
        self._node = node
        self._time_source = time_source
        self._auto_dir = None           # serve mode: one bag per grasp under this folder
        self.auto_bags: list = []
        self.received = {topic: 0 for topic in GRAPH_TOPICS}
        for topic, msgtype in GRAPH_TOPICS.items():
            node.create_subscription(import_message_class(msgtype), topic,
                                     functools.partial(self._on_message, topic), GRAPH_QOS,
                                     raw=True)

    def record_every_grasp(self, output_dir) -> None:
        """Open a bag when a grasp starts and close it when it ends (for grasps requested by
        other processes, which the demo cannot wrap in recorded_grasp())."""
        self._auto_dir = output_dir

    def _on_message(self, topic: str, data: bytes) -> None:
        self.received[topic] += 1
        if self._auto_dir is not None and topic == TOPIC_STATUS:
            self._auto_record(data)
            return
        sink = self.sink
        if sink is not None:
            sink.write(topic, data)

    def _auto_record(self, data: bytes) -> None:
        from gripper_interfaces.msg import SupervisorStatus
        from rclpy.serialization import deserialize_message

        from gripper_ros.bags.recorder import BagRecorder
        status = deserialize_message(data, SupervisorStatus)
        if self.sink is None and status.phase == SupervisorStatus.PHASE_POSITION:
            stamp = datetime.now().strftime('%Y%m%d_%H%M%S')
            bag_dir = Path(self._auto_dir) / f'grasp_{stamp}_id{status.grasp_id}'
            self.sink = BagRecorder(self._node, bag_dir, GRAPH_TOPICS, subscribe=False,
                                    time_source=self._time_source, custom_data={
                                        'request': {'position_setpoint_m':
                                                    status.position_setpoint_m,
                                                    'force_setpoint_n': status.force_setpoint_n}})
            self.auto_bags.append(bag_dir)
        sink = self.sink
        if sink is None:
            return
        sink.write(TOPIC_STATUS, data)
        if status.outcome != 0:
            sink.set_custom_data({'outcome_code': int(status.outcome)})
            sink.close()
            self.sink = None

    def wait_quiet(self, quiet_s: float = 0.05, timeout_s: float = 5.0) -> None:
        """Return once nothing has arrived for ``quiet_s``: what was published before a recording
        starts (e.g. set_object's sample) is not recorded."""
        deadline = time.monotonic() + timeout_s
        last, since = sum(self.received.values()), time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - since < quiet_s:
            time.sleep(0.005)
            now = sum(self.received.values())
            if now != last:
                last, since = now, time.monotonic()
