"""The state-topic templates: struct-packed messages that equal rclpy's own serialisation."""
import math

from gripper_ros.nodes import loop_io
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message


def _templates():
    return {
        'joint_states': loop_io.joint_state_template('finger_joint', 'gripper_base'),
        'clock': loop_io.clock_template(),
        'force_sensor': loop_io.force_sensor_template('left_gripper/base'),
        'object_state': loop_io.object_state_template(''),
        'status': loop_io.status_template(),
    }


def _get(msg, path):
    *parents, last = path.split('.')
    for name in parents:
        msg = getattr(msg, name)
    if last.endswith(']'):
        last, _, index = last.partition('[')
        return getattr(msg, last)[int(index[:-1])]
    return getattr(msg, last)


def _random(fmt, rng):
    if fmt == 'd':
        return float(rng.choice([rng.normal() * 10.0 ** rng.integers(-9, 9), -0.0,
                                 float('inf'), float('nan')]))
    if fmt == '?':
        return bool(rng.integers(0, 2))
    if fmt == 'i':
        return int(rng.integers(-2 ** 31, 2 ** 31))
    if fmt == 'I':
        return int(rng.integers(0, 2 ** 32))
    return int(rng.integers(0, 256))


def _same(a, b):
    return a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


@pytest.mark.parametrize('name', list(_templates()))
def test_template_is_rclpys_serialisation_both_ways(name):
    """The template and rclpy read what the other writes, field by field.

    rclpy reads what the template packs, and the template reads what rclpy writes (its
    alignment padding uninitialised), for random values, NaN included.
    """
    template = _templates()[name]
    formats = template.formats
    rng = np.random.default_rng(3)
    for _ in range(100):
        values = tuple(_random(f, rng) for f in formats)
        back = deserialize_message(template.pack(*values), template.msg_cls)
        for path, want in zip(template.fields, values):
            assert _same(_get(back, path), want), path
        again = template.unpack(serialize_message(back))
        assert again is not None and all(_same(a, b) for a, b in zip(again, values))


def test_template_refuses_a_message_of_another_form():
    """Another frame_id is not in the layout: None."""
    force = loop_io.force_sensor_template('gripper_base')
    other = deserialize_message(force.pack(1, 2, 3.0, 4.0, 5.0), force.msg_cls)
    other.header.frame_id = 'elsewhere'
    assert force.unpack(serialize_message(other)) is None


def test_a_status_with_a_text_is_read_and_written_by_its_template():
    """A status's message (the held grasp's, on every status while it holds) is any text.

    The template packs it as rclpy serialises it (rclpy reads text and numbers back), and reads
    the numbers of what rclpy writes whatever the text (none, ASCII or not).
    """
    status = loop_io.status_template()
    values = (3, 2, 1, 7, 9, 4, True, 0, 0.14, 0.14, 18.5, 1.27, 0.1399, 18.4, 0.0101, True)
    for text in ('', 'why', 'holding 11.036 N (setpoint 11.036 N) at 0.05000 m', 'µ 0.6 → 0.5'):
        packed = status.pack(5, 6, *values, text=text)
        back = deserialize_message(packed, status.msg_cls)
        assert back.message == text and back.grasp_id == 7 and back.force_n == 18.4
        written = serialize_message(loop_io.status_message(5_000_000_006, values, text))
        assert status.unpack(written) == status.unpack(packed) == (5, 6, *values)
        assert loop_io.read_status(written).grasp_id == 7
    assert status.unpack(status.pack(5, 6, *values, text='why')[:-1]) is None    # cut short


def test_a_string_cannot_be_a_template_field():
    from gripper_interfaces.msg import ForceSensor
    with pytest.raises(ValueError, match='string'):
        loop_io.MessageTemplate(ForceSensor(), ('header.frame_id',))
    with pytest.raises(ValueError, match='not numbers'):
        loop_io.MessageTemplate(ForceSensor(), ('no_such_field',))
