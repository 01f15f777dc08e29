"""The gripper's robot description: its URDF and the transforms of its fingers, from the config.

One base link and two finger links: the fixed finger and the moving one on the prismatic joint
``finger_joint`` (the position joint_states carries: the finger's travel from fully open, m).
The closing axis is the base's x; each finger frame sits on its pad face, so the distance of
the two frames along x is the width between the pads (``max_travel_m - position``). The joint's
limits are the plant's: the lead screw's travel, the force and the free speed at the voltage
limit. No rclpy and no xacro: the description node and ``gripper_urdf`` both write it from here.
"""
from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from gripper_ros.core.config import GripperConfig
from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER,
                              ROBOT_NAME)

FIXED_FINGER_JOINT = 'fixed_finger_joint'
"""The fixed joint that holds the fixed finger on the base."""
MOUNT_JOINT = 'gripper_mount_joint'
"""The xacro's fixed joint from the ``parent`` link (an arm's flange) to the base."""
MATERIAL = 'grey'
PREFIX = '${prefix}'
"""What the xacro macro puts before every link, joint and material name."""


@dataclass(frozen=True)
class FingerFrames:
    """Where the finger frames sit on the base (m, in the base frame)."""

    fixed_finger_xyz: tuple[float, float, float]
    moving_finger_open_xyz: tuple[float, float, float]
    """The moving finger's frame at position 0 (fully open); it moves along +x."""
    travel_m: float

    def moving_finger_xyz(self, position_m: float) -> tuple[float, float, float]:
        """Return the moving finger's frame at joint position ``position_m`` (travel from open)."""
        x, y, z = self.moving_finger_open_xyz
        return (x + position_m, y, z)


def finger_frames(config: GripperConfig) -> FingerFrames:
    """Return the finger frames of ``config``: pad faces max_travel_m apart when fully open."""
    half = config.plant.max_travel_m / 2.0
    top = config.geometry.base_height_m
    return FingerFrames((half, 0.0, top), (-half, 0.0, top), config.plant.max_travel_m)


def _num(value: float) -> str:
    """Write a number as the URDF has it: 12 significant digits, no float noise (0.17)."""
    text = format(float(value), '.12g')
    return '0' if text == '-0' else text


def _xyz(values) -> str:
    return ' '.join(_num(v) for v in values)


def _box_inertia(mass_kg: float, size) -> tuple[float, float, float]:
    """Return the principal moments (kg m^2) of a solid box of ``mass_kg`` and ``size`` (m)."""
    x, y, z = size
    return (mass_kg * (y * y + z * z) / 12.0, mass_kg * (x * x + z * z) / 12.0,
            mass_kg * (x * x + y * y) / 12.0)


def _box_link(name: str, size, offset, mass_kg: float, material: str) -> list[str]:
    """Return a link drawn, collided and weighed as one solid box of ``size`` at ``offset``."""
    origin = f'      <origin xyz="{_xyz(offset)}" rpy="0 0 0"/>\n'
    shape = origin + f'      <geometry><box size="{_xyz(size)}"/></geometry>\n'
    ixx, iyy, izz = _box_inertia(mass_kg, size)
    return [f'  <link name={quoteattr(name)}>\n',
            '    <inertial>\n', origin, f'      <mass value="{_num(mass_kg)}"/>\n',
            f'      <inertia ixx="{_num(ixx)}" ixy="0" ixz="0" iyy="{_num(iyy)}" iyz="0" '
            f'izz="{_num(izz)}"/>\n', '    </inertial>\n',
            '    <visual>\n', shape, f'      <material name={quoteattr(material)}/>\n',
            '    </visual>\n',
            '    <collision>\n', shape, '    </collision>\n',
            '  </link>\n']


def _body(config: GripperConfig, prefix: str) -> list[str]:
    """Return the material, links and joints, each name led by ``prefix`` (text, or xacro's)."""
    geo, plant = config.geometry, config.plant
    frames = finger_frames(config)
    t = geo.finger_thickness_m
    finger = (t, geo.finger_width_m, geo.finger_length_m)
    base = (plant.max_travel_m + 2.0 * t, geo.base_width_m, geo.base_height_m)
    grey = prefix + MATERIAL
    lines = [f'  <material name={quoteattr(grey)}><color rgba="0.6 0.6 0.6 1"/></material>\n']
    lines += _box_link(prefix + FRAME_BASE, base, (0.0, 0.0, geo.base_height_m / 2.0),
                       geo.base_mass_kg, grey)
    lines += _box_link(prefix + FRAME_FIXED_FINGER, finger,
                       (t / 2.0, 0.0, geo.finger_length_m / 2.0), geo.finger_mass_kg, grey)
    lines += _box_link(prefix + FRAME_MOVING_FINGER, finger,
                       (-t / 2.0, 0.0, geo.finger_length_m / 2.0), geo.finger_mass_kg, grey)
    lines += [f'  <joint name={quoteattr(prefix + FIXED_FINGER_JOINT)} type="fixed">\n',
              f'    <parent link={quoteattr(prefix + FRAME_BASE)}/>\n',
              f'    <child link={quoteattr(prefix + FRAME_FIXED_FINGER)}/>\n',
              f'    <origin xyz="{_xyz(frames.fixed_finger_xyz)}" rpy="0 0 0"/>\n',
              '  </joint>\n',
              f'  <joint name={quoteattr(prefix + FINGER_JOINT)} type="prismatic">\n',
              f'    <parent link={quoteattr(prefix + FRAME_BASE)}/>\n',
              f'    <child link={quoteattr(prefix + FRAME_MOVING_FINGER)}/>\n',
              f'    <origin xyz="{_xyz(frames.moving_finger_open_xyz)}" rpy="0 0 0"/>\n',
              '    <axis xyz="1 0 0"/>\n',
              f'    <limit lower="0" upper="{_num(plant.max_travel_m)}" '
              f'effort="{_num(plant.max_force_n)}" '
              f'velocity="{_num(plant.max_free_speed_mps)}"/>\n',
              '  </joint>\n']
    return lines


_WRITTEN = '<!-- Written by gripper_urdf from config/gripper.yaml; do not edit by hand. -->\n'


def urdf_text(config: GripperConfig, prefix: str = '') -> str:
    """Return the gripper's URDF for ``config``, each name led by ``prefix``.

    With no prefix: the text of ``urdf/gripper.urdf``.
    """
    return ''.join(['<?xml version="1.0"?>\n', _WRITTEN,
                    f'<robot name={quoteattr(ROBOT_NAME)}>\n', *_body(config, prefix),
                    '</robot>\n'])


def xacro_macro_text(config: GripperConfig) -> str:
    """Return the xacro macro ``gripper``, the text of ``urdf/gripper.macro.xacro``.

    The URDF's links and joints named ``${prefix}...``, fixed to link ``parent`` at
    ``xyz``/``rpy`` when one is given: the gripper on an arm's flange.
    """
    mount = [
        '  <xacro:if value="${parent != \'\'}">\n',
        f'  <joint name={quoteattr(PREFIX + MOUNT_JOINT)} type="fixed">\n',
        '    <parent link="${parent}"/>\n',
        f'    <child link={quoteattr(PREFIX + FRAME_BASE)}/>\n',
        '    <origin xyz="${xyz}" rpy="${rpy}"/>\n',
        '  </joint>\n',
        '  </xacro:if>\n']
    return ''.join([
        '<?xml version="1.0"?>\n', _WRITTEN,
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n',
        '<xacro:macro name="gripper" params="prefix:=\'\' parent:=\'\' xyz:=\'0 0 0\' '
        'rpy:=\'0 0 0\'">\n', *mount, *_body(config, PREFIX), '</xacro:macro>\n',
        '</robot>\n'])
