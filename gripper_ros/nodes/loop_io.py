"""The graph's messages as bytes on rclpy publishers and subscriptions.

The loop messages are taken raw and published pre-serialised with the byte layouts of
:mod:`gripper_ros.wire`; a message in another encapsulation is deserialised by rclpy and
repacked (:func:`in_layout`), so any DDS peer is understood. The state topics are packed by
template (:class:`MessageTemplate`).
"""
from __future__ import annotations

from collections import namedtuple
import functools
import struct

from gripper_ros.wire import CDR_LITTLE_ENDIAN as CDR_HEADER, LoopLayout
from rclpy.serialization import deserialize_message


def in_layout(layout: LoopLayout, data: bytes, msg_cls) -> bytes:
    """Return a loop message serialised in another form (big-endian...) in ``layout``'s form."""
    msg = deserialize_message(data, msg_cls)
    return layout.pack(*(getattr(msg, name) for name in layout.fields))


_SLOT_FORMATS = {'double': 'd', 'float': 'f', 'int64': 'q', 'uint64': 'Q', 'int32': 'i',
                 'uint32': 'I', 'int16': 'h', 'uint16': 'H', 'int8': 'b', 'uint8': 'B',
                 'octet': 'B', 'char': 'B', 'byte': 'B', 'boolean': '?'}


_LENGTH = struct.Struct('<I')
"""A CDR string's length (its bytes and the terminating NUL)."""


class _CdrPlan:
    """The plain-CDR form of one message value, piece by piece.

    Constant bytes that matter (lengths, string text, numbers not in ``fields``), padding, and
    the named fields.
    """

    def __init__(self, fields: tuple[str, ...]):
        self.fields = fields
        self.at = 0                          # offset in the payload (after the 4-byte header)
        self.pieces: list[tuple] = []        # ('const' | 'text', bytes) | ('pad', n) |
        #                                      ('field', i, fmt)
        self.found: set[str] = set()

    def _align(self, n: int) -> None:
        pad = -self.at % n
        if pad:
            self.pieces.append(('pad', pad))
            self.at += pad

    def number(self, fmt: str, value, path: str) -> None:
        size = struct.calcsize('<' + fmt)
        self._align(size)
        if path in self.fields:
            self.pieces.append(('field', self.fields.index(path), fmt))
            self.found.add(path)
        else:
            self.pieces.append(('const', struct.pack('<' + fmt, value)))
        self.at += size

    def string(self, text: str, path: str) -> None:
        if path in self.fields:
            raise ValueError(f'{path}: a string cannot be a field of a fixed layout')
        data = text.encode('utf-8') + b'\0'
        self._align(4)
        self.pieces.append(('text', struct.pack('<I', len(data)) + data))
        self.at += 4 + len(data)

    def message(self, msg, prefix: str = '') -> None:
        for name, slot in msg.get_fields_and_field_types().items():
            value, path = getattr(msg, name), prefix + name
            if slot in _SLOT_FORMATS:
                self.number(_SLOT_FORMATS[slot], value, path)
            elif slot == 'string' or slot.startswith('string<'):
                self.string(value, path)
            elif slot.startswith('sequence<'):
                inner = slot[len('sequence<'):-1].partition(',')[0]
                self._align(4)
                self.pieces.append(('const', struct.pack('<I', len(value))))
                self.at += 4
                for i, item in enumerate(value):
                    if inner in _SLOT_FORMATS:
                        self.number(_SLOT_FORMATS[inner], item, f'{path}[{i}]')
                    elif inner == 'string' or inner.startswith('string<'):
                        self.string(item, f'{path}[{i}]')
                    else:
                        self.message(item, f'{path}[{i}].')
            elif '[' in slot:
                raise ValueError(f'{path}: fixed-size arrays ({slot}) are not supported')
            else:
                self.message(value, path + '.')


class MessageTemplate:
    """One message type with fixed strings and sequence lengths, serialised by :mod:`struct`.

    Built from a ``template`` message whose constant parts (frame_id, joint names, sequence
    lengths) every publication carries; ``fields`` name the numbers that change
    ('header.stamp.sec', 'position[0]'...). The layout is plain little-endian CDR, as rmw
    serialises it (alignment counted from the end of the encapsulation header; padding
    written as zeros): :meth:`pack` costs a fraction of converting a Python message for
    ``publish``, and :meth:`unpack` of taking one. A message in another form (another
    frame_id, a string of other length, big-endian) unpacks to None.

    ``last_text``: the message's last field is a string of any text (a status's message):
    :meth:`pack` takes it as ``text``, :meth:`unpack` reads the numbers whatever it says.
    """

    def __init__(self, template, fields: tuple[str, ...], last_text: bool = False):
        self.msg_cls = type(template)
        self.fields = tuple(fields)
        plan = _CdrPlan(self.fields)
        plan.message(template)
        missing = set(self.fields) - plan.found
        if missing:
            raise ValueError(f'{sorted(missing)}: not numbers of {self.msg_cls.__name__}')
        pieces = plan.pieces
        if last_text:
            if not pieces or pieces[-1][0] != 'text':
                raise ValueError(f'{self.msg_cls.__name__}: its last field is not a string')
            pieces = pieces[:-1]
        self.last_text = last_text
        write_fmt, read_fmt, self._args, self._checks, self._order = '<4s', '<4x', \
            [CDR_HEADER], [], []
        offset = 4
        formats = [''] * len(self.fields)
        for piece in pieces:
            if piece[0] in ('const', 'text'):
                write_fmt += f'{len(piece[1])}s'
                read_fmt += f'{len(piece[1])}x'
                self._args.append(piece[1])
                self._checks.append((offset, offset + len(piece[1]), piece[1]))
                offset += len(piece[1])
            elif piece[0] == 'pad':
                write_fmt += f'{piece[1]}x'
                read_fmt += f'{piece[1]}x'
                offset += piece[1]
            else:
                write_fmt += piece[2]
                read_fmt += piece[2]
                formats[piece[1]] = piece[2]
                self._args.append(piece[1])
                self._order.append(piece[1])
                offset += struct.calcsize('<' + piece[2])
        self.formats = tuple(formats)
        """The :mod:`struct` format of each field, in field order."""
        self._writer = struct.Struct(write_fmt)
        self._reader = struct.Struct(read_fmt)
        self.size = self._writer.size
        self._identity = self._order == list(range(len(self.fields)))

    def pack(self, *values, text: str = '') -> bytes:
        """Return the serialised message with ``values`` for :attr:`fields`, in that order.

        ``text``: the last string's (``last_text`` templates only).
        """
        head = self._writer.pack(*[values[a] if a.__class__ is int else a for a in self._args])
        if not self.last_text:
            return head
        data = text.encode('utf-8') + b'\0'
        return head + _LENGTH.pack(len(data)) + data

    def unpack(self, data) -> tuple | None:
        """Return the values of :attr:`fields` in ``data``; None when it is in another form."""
        if self.last_text:
            if len(data) < self.size + 5 or \
                    _LENGTH.unpack_from(data, self.size)[0] != len(data) - self.size - 4:
                return None
        elif len(data) != self.size:
            return None
        for start, stop, part in self._checks:
            if data[start:stop] != part:
                return None
        read = self._reader.unpack_from(data)
        if self._identity:
            return read
        values = [None] * len(read)
        for k, i in enumerate(self._order):
            values[i] = read[k]
        return tuple(values)


# ------------------------------------------------------------------ the state topics
STAMP = ('header.stamp.sec', 'header.stamp.nanosec')


def split_ns(t_ns: int) -> tuple[int, int]:
    """builtin_interfaces/Time (sec, nanosec) of ``t_ns``."""
    return t_ns // 1_000_000_000, t_ns % 1_000_000_000


def joint_state_template(joint: str, frame_id: str) -> MessageTemplate:
    """sensor_msgs/JointState of one joint: stamp, position, velocity, effort."""
    from sensor_msgs.msg import JointState
    msg = JointState(name=[joint], position=[0.0], velocity=[0.0], effort=[0.0])
    msg.header.frame_id = frame_id
    return MessageTemplate(msg, STAMP + ('position[0]', 'velocity[0]', 'effort[0]'))


def transform_template(parent: str, child: str) -> MessageTemplate:
    """tf2_msgs/TFMessage of one transform ``parent`` -> ``child``: stamp and translation.

    The rotation is the identity (a prismatic joint's child frame only moves).
    """
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    transform = TransformStamped(child_frame_id=child)
    transform.header.frame_id = parent
    transform.transform.rotation.w = 1.0
    at = 'transforms[0].'
    return MessageTemplate(TFMessage(transforms=[transform]), (
        at + 'header.stamp.sec', at + 'header.stamp.nanosec', at + 'transform.translation.x',
        at + 'transform.translation.y', at + 'transform.translation.z'))


def clock_template() -> MessageTemplate:
    from rosgraph_msgs.msg import Clock
    return MessageTemplate(Clock(), ('clock.sec', 'clock.nanosec'))


def force_sensor_template(frame_id: str) -> MessageTemplate:
    from gripper_interfaces.msg import ForceSensor
    msg = ForceSensor()
    msg.header.frame_id = frame_id
    return MessageTemplate(msg, STAMP + ('force_n', 'peak_force_n', 'voltage_v'))


OBJECT_STATE_FIELDS = ('state', 'slip_m', 'slip_speed_mps', 'load_n', 'capacity_n',
                       'lift_acceleration_mps2')


def object_state_template(frame_id: str) -> MessageTemplate:
    from gripper_interfaces.msg import ObjectState
    msg = ObjectState()
    msg.header.frame_id = frame_id
    return MessageTemplate(msg, STAMP + OBJECT_STATE_FIELDS)


STATUS_FIELDS = ('phase', 'active_controller', 'switch_criterion', 'grasp_id', 'stage_id',
                 'outcome', 'running', 'pending_request', 'position_setpoint_m',
                 'approach_setpoint_m', 'force_setpoint_n', 'mass_kg', 'position_m', 'force_n',
                 'width_m', 'contact')
StatusView = namedtuple('StatusView', ('sec', 'nanosec') + STATUS_FIELDS)
"""The numbers of a gripper_interfaces/SupervisorStatus (all but its message)."""


@functools.lru_cache(maxsize=None)
def status_template() -> MessageTemplate:
    """Return the template of a SupervisorStatus with an empty frame_id, its message any text."""
    from gripper_interfaces.msg import SupervisorStatus
    return MessageTemplate(SupervisorStatus(), STAMP + STATUS_FIELDS, last_text=True)


def read_status(data: bytes) -> StatusView:
    """Read the numbers of a serialised status.

    By layout when it has the usual form, else by rclpy's deserialisation (another frame_id,
    a big-endian peer).
    """
    values = status_template().unpack(data)
    if values is None:
        from gripper_interfaces.msg import SupervisorStatus
        msg = deserialize_message(data, SupervisorStatus)
        values = (msg.header.stamp.sec, msg.header.stamp.nanosec) + tuple(
            getattr(msg, name) for name in STATUS_FIELDS)
    return StatusView._make(values)


def status_message(t_ns: int, values: tuple, message: str):
    """Build a SupervisorStatus message of stamp ``t_ns``, ``values`` (STATUS_FIELDS), text."""
    from gripper_interfaces.msg import SupervisorStatus
    msg = SupervisorStatus(message=message)
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
    if values is not None:
        for name, value in zip(STATUS_FIELDS, values):
            setattr(msg, name, value)
    return msg
