"""What goes over the wire: names, the codes the messages carry, the lockstep byte layouts.

The one home of every topic, service and node name and of every code the nodes, the numeric
core and the bag tools share. It imports no rclpy, so the core and the bag readers use it
without a ROS installation; tests tie each code to the constant generated from its ``.msg`` /
``.srv`` file and each byte layout to rclpy's own serialisation.

Names are relative: a node in namespace ``left`` publishes ``/left/joint_states``. The default
namespace is ``gripper``. ``/clock`` is global, as everywhere in ROS.
"""
from __future__ import annotations

import collections
import enum
import string
import struct
from typing import NamedTuple

import numpy as np

DEFAULT_NAMESPACE = 'gripper'

# Lockstep keeps at most a few messages in flight; the depth is there so that a slow recorder
# callback never loses one (a reliable keep_last writer drops what its history cannot hold).
GRAPH_QOS_DEPTH = 1000
"""History depth of every graph topic and service queue, the recorder's and the replay's."""

DEFAULT_STATE_RATE_HZ = 100.0
"""Rate (per simulated second) of joint_states, force_sensor, sim/object_state and /clock."""

FORCE_SAMPLE_S = 1.0e-4
"""The force loop's period, the paper's 0.1 ms (the shipped ``force_control.sample_time_s``):
the hold's shake pieces, the benchmarks' force budget, the bound on sim/step's ticks."""

GRAPH_NOT_READY = 'graph not ready'
"""In the refusal of a request made before the supervisor has heard every loop node and the
plant's first tick (a graph still starting): a client may ask again."""

STATUS_HEARTBEAT_S = 1.0
"""Wall seconds between the supervisor's status messages when nothing changes (a paused or idle
graph): the controllers' watchdogs count their silence against it."""

REPUBLISH_AFTER_S = 0.5
"""A tick nobody has answered for this long (wall) is published again (discovery, late peers);
the supervisor's watchdog tells a silent plant by it."""


def stamp_ns(stamp) -> int:
    """Return a ``builtin_interfaces/Time`` (anything with ``sec`` and ``nanosec``) in ns.

    Integer nanoseconds are the time of the core and of the bags.
    """
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# --- lockstep topics: one message per tick each (see docs/ARCHITECTURE.md) ---------------------
TOPIC_TICK = 'loop/tick'
"""PlantTick, plant -> supervisor: the measurement of tick t."""
TOPIC_POSITION_REFERENCE = 'loop/position_reference'
"""StageReference, supervisor -> position controller, on the ticks it names that stage."""
TOPIC_FORCE_REFERENCE = 'loop/force_reference'
"""StageReference, supervisor -> force controller, on the ticks it names that stage."""
TOPIC_MOTOR_COMMAND = 'loop/motor_command'
"""MotorCommand, the named stage -> plant: the voltage held from tick t."""

# --- state topics for other programs: at the state rate while simulated time runs --------------
TOPIC_CLOCK = '/clock'
TOPIC_JOINT_STATES = 'joint_states'
TOPIC_FORCE_SENSOR = 'force_sensor'
TOPIC_STATUS = 'supervisor/status'
TOPIC_OUTCOME = 'supervisor/outcome'
"""The final status of the last request, latched (transient local, depth 1)."""
TOPIC_OBJECT_STATE = 'sim/object_state'
TOPIC_OBJECT_MARKER = 'sim/object_marker'
"""visualization_msgs/Marker, with each sim/object_state: the object as the plant has it, drawn
in the base frame (nodes/object_marker.py)."""
TOPIC_SIM_STATUS = 'sim/status'
TOPIC_LOAD_ACCELERATION = 'sim/load_acceleration'
"""geometry_msgs/AccelStamped, an arm (simulator) -> plant: the arm's acceleration while it holds;
``accel.linear.z`` (upward, m/s^2) loads the pads with gravity."""

TOPIC_PLANNED_ACCELERATION = 'arm/planned_acceleration'
"""geometry_msgs/AccelStamped, an arm -> supervisor: the arm's plan, ahead of its motion. Each
message is a breakpoint: from ``header.stamp`` (simulated time) on, the upward acceleration along
the pads is ``accel.linear.z`` (m/s^2), until the next breakpoint; one at or before an earlier
one's stamp replaces the plan from there. It must arrive ``load_grip.ANTICIPATION_S`` before its
stamp; the grip of a grasp of unknown mass rises with the load the motion will bring."""

TOPIC_JOINT_COMMANDS = 'joint_commands'
"""sensor_msgs/JointState, ros2_control's topic-based hardware -> the gripper: finger_joint's
position (travel from fully open, m), optionally a speed limit (velocity) and an effort limit;
each new command becomes a move (move_action_server)."""

TOPIC_SERVO_SETPOINT = 'servo_setpoint'
"""ServoSetpoint, trajectory_action_server -> supervisor: a setpoint with its velocity and
acceleration, in force at once as a joint_commands setpoint is (a graph topic)."""

TOPIC_GRIPPER_STATUS = 'gripper_status'
"""diagnostic_msgs/DiagnosticStatus, latched: how the last request ended, for a ros2_control user
(no gripper_interfaces): outcome, stalled, object_detected, position_m, width_m, effort_n."""

# --- the robot description: what robot_state_publisher would publish for this gripper ----------
TOPIC_ROBOT_DESCRIPTION = 'robot_description'
"""std_msgs/String, latched: the gripper's URDF (core/description.py)."""
TOPIC_TF = '/tf'
TOPIC_TF_STATIC = '/tf_static'

SERVICE_GRASP = 'grasp'
SERVICE_STOP = 'stop'
SERVICE_RELEASE = 'release'
SERVICE_MOVE = 'move'
SERVICE_SET_OBJECT = 'sim/set_object'
SERVICE_PAUSE = 'sim/pause'
SERVICE_RESUME = 'sim/resume'
SERVICE_STEP = 'sim/step'
SERVICE_EXCITE = 'excite'
"""std_srvs/Trigger: the identification experiment (excitation_server)."""
ACTION_GRASP = 'grasp_action'
ACTION_MOVE = 'move_action'
ACTION_GRIPPER_CMD = 'gripper_cmd'
"""control_msgs/action/ParallelGripperCommand, the name MoveIt's parallel-gripper handle uses."""
ACTION_GRIPPER_COMMAND = 'gripper_action_controller/gripper_cmd'
"""control_msgs/action/GripperCommand: where ros2_controllers' GripperActionController (a
controller named as its parameters' namespace) serves it, ``<controller>/gripper_cmd``."""
ACTION_FOLLOW_JOINT_TRAJECTORY = 'joint_trajectory_controller/follow_joint_trajectory'
"""control_msgs/action/FollowJointTrajectory: where joint_trajectory_controller serves it,
``<controller>/follow_joint_trajectory``."""
CONTROL_ACTIONS = {ACTION_GRIPPER_CMD: 'ParallelGripperCommand',
                   ACTION_GRIPPER_COMMAND: 'GripperCommand',
                   ACTION_FOLLOW_JOINT_TRAJECTORY: 'FollowJointTrajectory'}
"""The control_msgs actions served where control_msgs is installed: name -> action type."""

NODE_PLANT = 'plant_simulator'
NODE_POSITION_CONTROLLER = 'position_controller'
NODE_FORCE_CONTROLLER = 'force_controller'
NODE_SUPERVISOR = 'supervisor'
NODE_GRASP_ACTION = 'grasp_action_server'
NODE_MOVE_ACTION = 'move_action_server'
NODE_EXCITATION = 'excitation_server'
NODE_DESCRIPTION = 'description_publisher'
NODE_TRAJECTORY_ACTION = 'trajectory_action_server'
LAUNCHED_NODES = (NODE_PLANT, NODE_POSITION_CONTROLLER, NODE_FORCE_CONTROLLER, NODE_SUPERVISOR,
                  NODE_GRASP_ACTION, NODE_MOVE_ACTION, NODE_TRAJECTORY_ACTION, NODE_DESCRIPTION)
"""What launch/gripper.launch.py starts, one process each; each the executable and the node."""
ROBOT_STATE_PUBLISHER = 'robot_state_publisher'
"""The package (and its node) the launch file runs instead of description_publisher where it is
installed: one publisher of robot_description and /tf, never both."""

FINGER_JOINT = 'finger_joint'
"""The one joint: the moving finger's travel from fully open (m), in joint_states and the URDF."""
ROBOT_NAME = 'gripper'
"""The URDF's robot name."""
FRAME_BASE = 'gripper_base'
"""The base link, frame_id of every header the plant publishes and root of the URDF."""
FRAME_FIXED_FINGER = 'fixed_finger'
FRAME_MOVING_FINGER = 'moving_finger'
"""The fingers' links; each frame sits on the finger's pad face."""

LOOP_TOPICS: dict[str, str] = {
    TOPIC_TICK: 'gripper_interfaces/msg/PlantTick',
    TOPIC_POSITION_REFERENCE: 'gripper_interfaces/msg/StageReference',
    TOPIC_FORCE_REFERENCE: 'gripper_interfaces/msg/StageReference',
    TOPIC_MOTOR_COMMAND: 'gripper_interfaces/msg/MotorCommand',
}
STATE_TOPICS: dict[str, str] = {
    TOPIC_JOINT_STATES: 'sensor_msgs/msg/JointState',
    TOPIC_FORCE_SENSOR: 'gripper_interfaces/msg/ForceSensor',
    TOPIC_STATUS: 'gripper_interfaces/msg/SupervisorStatus',
    TOPIC_OBJECT_STATE: 'gripper_interfaces/msg/ObjectState',
    TOPIC_OBJECT_MARKER: 'visualization_msgs/msg/Marker',
    TOPIC_SIM_STATUS: 'gripper_interfaces/msg/SimStatus',
}
GRAPH_TOPICS: dict[str, str] = {**LOOP_TOPICS, **STATE_TOPICS}
"""Every topic of one gripper's graph but /clock and the description, with its type."""
DESCRIPTION_TOPICS: dict[str, str] = {
    TOPIC_ROBOT_DESCRIPTION: 'std_msgs/msg/String',
    TOPIC_TF: 'tf2_msgs/msg/TFMessage',
    TOPIC_TF_STATIC: 'tf2_msgs/msg/TFMessage',
}
"""What description_publisher publishes (latched: robot_description and /tf_static)."""
LATCHED_DESCRIPTION_TOPICS = (TOPIC_ROBOT_DESCRIPTION, TOPIC_TF_STATIC)
BAG_TOPICS: dict[str, str] = {**GRAPH_TOPICS, **DESCRIPTION_TOPICS}
"""What a grasp bag of a graph with its description records: a viewer draws the fingers."""
LIVE_TOPICS: dict[str, str] = {**BAG_TOPICS,
                               TOPIC_GRIPPER_STATUS: 'diagnostic_msgs/msg/DiagnosticStatus'}
"""What the live view serves (nodes/live_view.py): a bag's topics and gripper_status."""
LATCHED_LIVE_TOPICS = (*LATCHED_DESCRIPTION_TOPICS, TOPIC_GRIPPER_STATUS)
"""The live view's latched topics: each new subscriber gets the last message."""


def qualified(namespace: str, name: str) -> str:
    """Return the absolute name of relative ``name`` in ``namespace`` (``/clock`` stays)."""
    if name.startswith('/'):
        return name
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return f'{ns}/{name}'


NAME_CHARACTERS = frozenset(string.ascii_letters + string.digits + '_')
"""What a part of a ROS name may hold (ASCII only: rcl refuses other letters)."""
MAX_NAMESPACE_LENGTH = 174
"""Longest namespace (without its slashes) allowed: every node's, topic's, service's and
action's full name under it must fit rcl's limit, 247 characters (255 less 8 for the DDS
suffixes). The longest name under it is FollowJointTrajectory's cancel service,
``/<ns>/joint_trajectory_controller/follow_joint_trajectory/_action/cancel_goal``: 73 more
characters. ``test_hostile_graph`` grasps under this one."""


def check_namespace(namespace: str) -> str:
    """``namespace`` without slashes at its ends, or ValueError saying what a ROS name allows."""
    ns = namespace.strip('/')
    parts = ns.split('/') if ns else []
    for part in parts:
        if not part or part[0].isdigit() or not set(part) <= NAME_CHARACTERS:
            raise ValueError(f'namespace {namespace!r} is not a ROS name: each part must start '
                             'with an ASCII letter or _ and hold only ASCII letters, digits '
                             'and _')
    if len(ns) > MAX_NAMESPACE_LENGTH:
        raise ValueError(f'namespace is {len(ns)} characters long; at most '
                         f'{MAX_NAMESPACE_LENGTH} leave room for the names under it')
    return ns


def namespace_prefix(namespace: str) -> str:
    """Return the prefix of the joint's and the URDF's names that ``namespace`` gives by default.

    None in the default namespace (one gripper keeps the plain names) or the root one; else the
    namespace's parts joined by ``_``, and a ``_``: ``left`` -> ``left_``, ``arm2/left`` ->
    ``arm2_left_``. Grippers in different namespaces so publish no frame and no joint in common.
    """
    ns = namespace.strip('/')
    return '' if ns in ('', DEFAULT_NAMESPACE) else ns.replace('/', '_') + '_'


class Phase(enum.IntEnum):
    """``SupervisorStatus.PHASE_*``: where the supervisor's state machine stands."""

    IDLE = 0
    POSITION = 1
    FORCE = 2
    HOLDING = 3
    DONE = 4
    FAILED = 5
    RELEASING = 6
    MOVING = 7


class Controller(enum.IntEnum):
    """``SupervisorStatus.CONTROLLER_*`` and ``MotorCommand.SOURCE_*``: who drives the motor."""

    NONE = 0
    POSITION = 1
    FORCE = 2


STAGE_NODES = {Controller.POSITION: NODE_POSITION_CONTROLLER,
               Controller.FORCE: NODE_FORCE_CONTROLLER}
"""The node that runs each stage."""
STAGE_REFERENCE_TOPICS = {Controller.POSITION: TOPIC_POSITION_REFERENCE,
                          Controller.FORCE: TOPIC_FORCE_REFERENCE}
"""Each stage's references: the supervisor to the node it names, on the ticks it names it."""


class PositionControllerKind(enum.Enum):
    """The position stage's law (position_controller's parameter ``controller``; Table II)."""

    PD = 'pd'
    PID = 'pid'
    MPC_PD = 'mpc_pd'


class ForceControllerKind(enum.Enum):
    """The force stage's law (force_controller's parameter ``controller``; Table II, and ours)."""

    PI = 'pi'                           # the paper's structure, our discrete gains
    MPC_PI = 'mpc_pi'                   # DMC over that PI
    CONTACT_AWARE = 'contact_aware'     # ours: rigid and compliant objects (contact_force.py)


DEFAULT_POSITION_CONTROLLER = PositionControllerKind.MPC_PD
DEFAULT_FORCE_CONTROLLER = ForceControllerKind.CONTACT_AWARE
DEFAULT_APPROACH_FORCE_MARGIN = 1.0
"""force_controller's parameter ``approach_force_margin``: the force stage's voltage before
contact is capped at this many times F_sp / (N per V)."""


class SwitchCriterion(enum.IntEnum):
    """``SupervisorStatus.SWITCH_*``: what ended the position stage."""

    NONE = 0
    POSITION_TOLERANCE = 1
    SENSOR_VOLTAGE = 2


class Outcome(enum.IntEnum):
    """``Grasp.Response.OUTCOME_*``: how a grasp or release ended."""

    UNKNOWN = 0
    HOLDING = 1
    NO_OBJECT = 2
    OBJECT_LOST = 3
    TIMEOUT = 4
    STOPPED = 5
    REFUSED = 6
    FAULT = 7
    RELEASED = 8
    MOVED = 9
    STALLED = 10
    OVERLOADED = 11


class FaultKind(enum.IntEnum):
    """``SetObject.Request.FAULT_*``: a fault the simulator injects at an exact instant."""

    NONE = 0
    OBJECT_REMOVED = 1
    OBJECT_SLIPPING = 2
    SENSOR_DROPOUT = 3


class LiftProfile(enum.IntEnum):
    """``SetObject.Request.LIFT_*``: how the arm moves the held object (core/physics/hold.py)."""

    STEP = 0
    PICK_AND_PLACE = 1
    SHAKE = 2


class HoldState(enum.IntEnum):
    """``ObjectState.STATE_*``: the grasped object along the finger pads (ground truth)."""

    NONE = 0
    RESTING = 1
    STUCK = 2
    SLIDING = 3
    LOST = 4


class PendingRequest(enum.IntEnum):
    """``SupervisorStatus.REQUEST_*``: a request accepted that starts at the next tick."""

    NONE = 0
    GRASP = 1
    RELEASE = 2
    MOVE = 3


class TimeMode(enum.IntEnum):
    """``SimStatus.TIME_MODE_*``: how the simulator's time runs."""

    REALTIME = 0
    FAST = 1
    SIM_TIME = 2

    @property
    def parameter(self) -> str:
        """The plant's ``time_mode`` parameter value: ``realtime`` or ``fast``."""
        return self.name.lower()

    @property
    def text(self) -> str:
        """How this time runs, in a banner: ``realtime time``, ``sim time: follows /clock``."""
        return 'sim time: follows /clock' if self is TimeMode.SIM_TIME else \
            f'{self.parameter} time'


TIME_MODE_CHOICES = (TimeMode.REALTIME.parameter, TimeMode.FAST.parameter)
"""What ``time_mode`` (parameter, launch argument, ``--time-mode``) accepts; ``use_sim_time``
chooses SIM_TIME."""


WIRE_CODES = (
    (Phase, 'gripper_interfaces.msg', 'SupervisorStatus', 'PHASE_'),
    (Controller, 'gripper_interfaces.msg', 'SupervisorStatus', 'CONTROLLER_'),
    (Controller, 'gripper_interfaces.msg', 'MotorCommand', 'SOURCE_'),
    (SwitchCriterion, 'gripper_interfaces.msg', 'SupervisorStatus', 'SWITCH_'),
    (Outcome, 'gripper_interfaces.srv', 'Grasp.Response', 'OUTCOME_'),
    (FaultKind, 'gripper_interfaces.srv', 'SetObject.Request', 'FAULT_'),
    (HoldState, 'gripper_interfaces.msg', 'ObjectState', 'STATE_'),
    (LiftProfile, 'gripper_interfaces.srv', 'SetObject.Request', 'LIFT_'),
    (TimeMode, 'gripper_interfaces.msg', 'SimStatus', 'TIME_MODE_'),
    (PendingRequest, 'gripper_interfaces.msg', 'SupervisorStatus', 'REQUEST_'),
)
"""Each code enum and the generated constants it mirrors: (enum, module, class, prefix)."""


def enum_name(enum_cls: type[enum.IntEnum], value: int) -> str:
    """Return the member name of ``value``, or the number itself for a code unknown here."""
    try:
        return enum_cls(int(value)).name
    except ValueError:
        return str(int(value))


# --- byte layouts of the lockstep messages ---------------------------------------------------

CDR_LITTLE_ENDIAN = b'\x00\x01\x00\x00'
"""The encapsulation header of a little-endian plain-CDR payload (the first four bytes)."""


_STRUCT_CODES = {'i8': 'q', 'u4': 'I', 'u1': 'B', 'f8': 'd'}
"""The struct code of each field type the loop layouts use (numpy's short names)."""


class LoopField(NamedTuple):
    """One field of a loop message: its name and type (``kind``), and where its value comes from.

    ``copied_from`` names the loop message whose field of the same name this one repeats
    (a reference relays its tick's measurement, a command echoes its reference's ids);
    ``default`` is what a sender that predates the field gives.
    """

    name: str
    kind: str                           # numpy's type: 'i8', 'u4', 'u1', 'f8'
    copied_from: str = ''
    default: float | None = None


class LoopLayout:
    """The one definition of a fixed-size lockstep message type, and all that derives from it.

    The nodes publish and take these messages as bytes: packing a handful of numbers with
    :mod:`struct` costs a fraction of rclpy's conversion to and from a Python message object,
    and the lockstep loop sends three of them every 0.1 ms. From the fields, in the ``.msg``
    file's order (``test_wire`` holds them to it and to rclpy's serialisation):

    - ``dtype``: the message as a numpy record (natural alignment, no header), what the compiled
      core reads and writes and a series keeps as its rows: CDR aligns each number to its size
      from the end of the 4-byte encapsulation header, as numpy does from the record's start,
      so the record's bytes are the message's CDR body;
    - ``body``: the struct format of those bytes, padding written out (:meth:`pack`,
      :meth:`unpack`, :meth:`reader`);
    - ``fields``: the names in order; ``tuple``: a namedtuple of them (defaults for the fields
      that have one); :meth:`copied_from`: the fields a kernel copies from another message.

    A message in another encapsulation (big-endian) or of another size is not for the fast
    path: :meth:`unpack` returns None and the caller deserialises it the general way.
    """

    __slots__ = ('msgtype', 'fields', 'body', 'size', 'dtype', 'tuple', '_specs', '_reader',
                 '_writer')

    def __init__(self, msgtype: str, fields: tuple):
        self.msgtype = msgtype
        self._specs = tuple(LoopField(*f) for f in fields)
        self.fields = tuple(f.name for f in self._specs)
        self.dtype = np.dtype([(f.name, '<' + f.kind if f.kind != 'u1' else f.kind)
                               for f in self._specs], align=True)
        body, at = '', 0
        for f in self._specs:
            offset = self.dtype.fields[f.name][1]
            body += (f'{offset - at}x' if offset > at else '') + _STRUCT_CODES[f.kind]
            at = offset + self.dtype[f.name].itemsize
        self.body = body
        self._reader = struct.Struct('<4x' + body)
        self._writer = struct.Struct('<4s' + body)
        self.size = self._reader.size
        if self.size != 4 + self.dtype.itemsize:
            raise ValueError(f'{msgtype}: the record ({self.dtype.itemsize} bytes) is not the '
                             f'CDR body ({self.size - 4} bytes)')
        defaults = [f.default for f in self._specs if f.default is not None]
        if any(f.default is None for f in self._specs[len(self._specs) - len(defaults):]):
            raise ValueError(f'{msgtype}: only the last fields may have defaults')
        self.tuple = collections.namedtuple(msgtype.rsplit('/', 1)[-1], self.fields,
                                            defaults=defaults)

    def copied_from(self, msgtype: str) -> tuple[str, ...]:
        """Return the fields this message repeats of loop message ``msgtype``, in order."""
        return tuple(f.name for f in self._specs if f.copied_from == msgtype)

    def pack(self, *values) -> bytes:
        """Return the CDR bytes of a message with ``values`` in field order (bools as 0/1)."""
        return self._writer.pack(CDR_LITTLE_ENDIAN, *values)

    def unpack(self, data) -> tuple | None:
        """Return the field values of CDR ``data`` in field order, or None.

        None when ``data`` is not little-endian or not of this layout's size (another version
        of the type, e.g. in an older bag).
        """
        if data[:4] != CDR_LITTLE_ENDIAN or len(data) != self.size:
            return None
        return self._reader.unpack_from(data)

    def reader(self, *names: str) -> struct.Struct:
        """Return a :class:`struct.Struct` whose ``unpack_from(data)`` gives ``names`` only.

        For a reader of a few fields of every message (``names`` in field order); ``data``
        must be in this layout's form (:meth:`unpack` says).
        """
        fmt, at = '<', 0
        for name in names:
            offset = 4 + self.dtype.fields[name][1]
            if offset < at:
                raise ValueError(f'{name}: fields must be given in message order')
            code = _STRUCT_CODES[self.dtype[name].str[1:]]
            fmt += f'{offset - at}x{code}' if offset > at else code
            at = offset + self.dtype[name].itemsize
        return struct.Struct(fmt)

    def as_dict(self, values: tuple) -> dict:
        """``values`` (as :meth:`unpack` returns them) by field name."""
        return dict(zip(self.fields, values))


MSG_TICK = 'gripper_interfaces/msg/PlantTick'
MSG_REFERENCE = 'gripper_interfaces/msg/StageReference'
MSG_COMMAND = 'gripper_interfaces/msg/MotorCommand'

TICK_LAYOUT = LoopLayout(MSG_TICK, (
    ('stamp_ns', 'i8'), ('position_m', 'f8'), ('velocity_mps', 'f8'), ('force_n', 'f8'),
    ('peak_force_n', 'f8'), ('sensor_voltage_v', 'f8'), ('motor_voltage_v', 'f8'),
    ('current_a', 'f8'), ('speed_rad_s', 'f8'), ('applied_source', 'u1'), ('revision', 'u4'),
    ('pad1_shear_n', 'f8'), ('pad2_shear_n', 'f8'), ('pad1_displacement_m', 'f8'),
    ('pad2_displacement_m', 'f8')))
REFERENCE_LAYOUT = LoopLayout(MSG_REFERENCE, (
    ('stamp_ns', 'i8', MSG_TICK), ('grasp_id', 'u4'), ('stage_id', 'u4'),
    ('revision', 'u4', MSG_TICK), ('phase', 'u1'), ('outcome', 'u1'), ('controller', 'u1'),
    ('running', 'u1'), ('contact', 'u1'), ('position_setpoint_m', 'f8'),
    ('approach_setpoint_m', 'f8'), ('force_setpoint_n', 'f8'), ('position_m', 'f8', MSG_TICK),
    ('velocity_mps', 'f8', MSG_TICK), ('force_n', 'f8', MSG_TICK), ('seed_voltage_v', 'f8'),
    ('speed_limit_mps', 'f8', '', 0.0), ('voltage_limit_v', 'f8', '', 0.0),
    ('approach_velocity_mps', 'f8', '', 0.0), ('approach_acceleration_mps2', 'f8', '', 0.0)))
COMMAND_LAYOUT = LoopLayout(MSG_COMMAND, (
    ('stamp_ns', 'i8', MSG_REFERENCE), ('grasp_id', 'u4', MSG_REFERENCE),
    ('stage_id', 'u4', MSG_REFERENCE), ('revision', 'u4', MSG_REFERENCE), ('source', 'u1'),
    ('phase', 'u1', MSG_REFERENCE), ('outcome', 'u1', MSG_REFERENCE),
    ('running', 'u1', MSG_REFERENCE), ('finite', 'u1'), ('voltage_v', 'f8'), ('hold_s', 'f8'),
    ('inner_setpoint', 'f8')))
LOOP_LAYOUTS = {layout.msgtype: layout for layout in (TICK_LAYOUT, REFERENCE_LAYOUT,
                                                      COMMAND_LAYOUT)}
