"""The configuration as ROS parameters: the file gives the defaults, the parameters the truth.

Every key of the config sections a node uses is declared as a parameter named by its dotted
path (``position_control.mpc_pd.kc``, ``supervisor.force_law``), with the value of the config
file (``config_file``, default the installed ``config/gripper.yaml``) as its default, so that
``ros2 param get/set``, rqt_reconfigure and ``--params-file`` (a standard
``node: ros__parameters:`` YAML, nested or dotted) work as for any ROS node. A node's own
sections are writable; the sections or keys it only reads (the plant model a controller
predicts with) are read-only there. A key another node also uses is writable nowhere
(``START_UP_ONLY``): a change on one node would not reach the others. Each key's description,
range, type and run-time-ness come from its declaration in the config schema
(:data:`gripper_ros.core.config.SCHEMA`). Every value, at start-up
and at run time, goes through the one config reader
(:func:`gripper_ros.core.config.parse_config`), with its bounds and cross-field checks, and
then through the node's own ``check`` (a controller builds the stage it would use): a bad one is
refused with the message naming the key, and nothing changes.
"""
from __future__ import annotations

import copy
from typing import Callable

from gripper_ros.core.config import (ConfigError, dotted_section, find_unknown, flatten,
                                     GripperConfig, load_config, nested, parse_config, SCHEMA)
from gripper_ros.nodes.startup import StartupError
from gripper_ros.text import one_line
from gripper_ros.wire import FINGER_JOINT, NAME_CHARACTERS, namespace_prefix
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rcl_interfaces.srv import ListParameters
from rclpy.exceptions import ParameterNotDeclaredException
from rclpy.node import Node
from rclpy.parameter import Parameter

START_UP_ONLY = frozenset(dotted for dotted, spec in SCHEMA.items() if not spec.runtime)
"""Keys read-only even in their owner's writable section (their description says why)."""

INTEGER_KEYS = frozenset(dotted for dotted, spec in SCHEMA.items() if spec.integer)
"""Keys whose values are whole numbers (INTEGER parameters); every other number is a double."""


def config_descriptor(dotted: str, read_only: bool) -> ParameterDescriptor:
    """Return the descriptor of config key ``dotted``: its description and range, as declared.

    A range is closed in ROS; an end the key refuses (> 0, ``open_high``) the config reader
    refuses after it.
    """
    spec = SCHEMA[dotted]
    descriptor = ParameterDescriptor(description=spec.description, read_only=read_only)
    if spec.bounds is not None and spec.integer:
        descriptor.integer_range = [IntegerRange(from_value=int(spec.bounds[0]),
                                                 to_value=int(spec.bounds[1]), step=0)]
    elif spec.bounds is not None:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.bounds[0]), to_value=float(spec.bounds[1]), step=0.0)]
    return descriptor


def declare_controller(node: Node, kind_cls, default, description: str = ''):
    """Declare a stage's read-only ``controller`` parameter; return its value as a ``kind_cls``.

    ``description`` defaults to the kinds' values; a value that is none of them is refused at
    start-up with the parameter named (ConfigError).
    """
    from gripper_ros.core.control.stages import parse_kind    # the compiled core: stages only
    value = node.declare_parameter('controller', default.value, ParameterDescriptor(
        description=description or ' | '.join(k.value for k in kind_cls), read_only=True)).value
    return parse_kind(kind_cls, value)


def _as_parameter_value(dotted: str, value):
    """Return a config value in the type its parameter is declared with."""
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float)):
        return int(value) if dotted in INTEGER_KEYS else float(value)
    return value


def _whole_number_as_double(parameter: Parameter) -> Parameter:
    return Parameter(parameter.name, Parameter.Type.DOUBLE, float(parameter.value))


def declared_names(node: Node) -> list[str]:
    """Return the names of every parameter ``node`` has declared."""
    return list(node.list_parameters([], ListParameters.Request.DEPTH_RECURSIVE).names)


def unknown_and_hint(names: list[str], declared) -> tuple[str, str]:
    """Return the first of ``names`` (none declared) and what it was likely meant to be.

    The config's own nearest-name rule (:func:`gripper_ros.core.config.find_unknown`): the
    closest declared name in the same group, or the group's names when none is close.
    """
    found = find_unknown(nested(names), nested(declared))
    if found is None:                    # the name of a group, as supervisor of supervisor.x
        return names[0], f'it names a group of parameters ({names[0]}.*), not one'
    return found


def strict_parameters(node: Node) -> None:
    """Hold a set of ``node``'s parameters to what ROS users expect: names said, whole numbers.

    - A set of a name the node does not declare (``ros2 param set``) is refused naming it and
      the closest declared name. rclpy's own refusal names none (its
      ``_check_undeclared_parameters`` hands ``ParameterNotDeclaredException`` a generator that
      its ``any()`` has consumed: ``Invalid access to undeclared parameter(s): []``); the same
      exception is raised here first, with the names, and the parameter service answers with it.
    - A whole number is taken for a double parameter, as users type it: ``kc 900`` is
      ``900.0``. ``ros2 param set`` and ``-p name:=900`` send an INTEGER, which rclpy refuses
      for a DOUBLE. A start-up override is converted before the node declares it (only the keys
      of ``INTEGER_KEYS`` are integers); a set at run time is converted when the parameter is
      a declared double. Ranges and the config reader then check the value as for ``900.0``.

    One pre-set callback does both (rclpy joins the lists several of them return). Call it
    first thing in a node's constructor; a second call does nothing.
    """
    if getattr(node, '_strict_parameters', False):
        return
    node._strict_parameters = True
    overrides = node._parameter_overrides          # rclpy reads these at declare_parameter
    for name, parameter in list(overrides.items()):
        if parameter.type_ is Parameter.Type.INTEGER and name not in INTEGER_KEYS:
            overrides[name] = _whole_number_as_double(parameter)

    def as_declared(parameters: list[Parameter]) -> list[Parameter]:
        undeclared = [p.name for p in parameters if not node.has_parameter(p.name)]
        if undeclared:
            _, hint = unknown_and_hint(undeclared, sorted(declared_names(node)))
            raise ParameterNotDeclaredException(f'{undeclared}; {hint}')
        return [_whole_number_as_double(p)
                if p.type_ is Parameter.Type.INTEGER
                and node.describe_parameter(p.name).type == ParameterType.PARAMETER_DOUBLE
                else p for p in parameters]

    node.add_pre_set_parameters_callback(as_declared)


def refuse_unknown_overrides(nodes: list[Node], known: tuple[str, ...] = ()) -> None:
    """Refuse a start-up parameter (``-p``, ``--params-file``) that none of ``nodes`` declares.

    rclpy keeps such an override without a word: a node declares only what it asks for
    (``allow_undeclared_parameters`` and ``automatically_declare_parameters_from_overrides``
    false, rclpy's defaults), and an override that names nothing is never read. Call it once
    every node of the process has declared its parameters; a ``-p`` or a ``/**`` file reaches
    every node of a process, so a name counts as known when one of them declares it, or when
    it is in ``known`` (what the process reads itself). A ConfigError names the first unknown
    one and the closest declared name, as a typo in ``config_file`` is named.
    """
    declared = sorted({name for node in nodes for name in declared_names(node)} | set(known))
    given = sorted({name for node in nodes for name in node._parameter_overrides} -
                   set(declared))
    if given:
        name, hint = unknown_and_hint(given, declared)
        raise ConfigError(f'unknown parameter "{name}"; {hint}')


class ConfigParameters:
    """The config sections of one node as its ROS parameters.

    ``writable`` names sections; ``read_only`` names sections or single keys
    (``force_control.sample_time_s``) the node reads and never changes.
    ``check(config)`` is called with a candidate config before a change is accepted: it returns
    what ``on_change`` needs (a controller it built) or raises ValueError to refuse the change.
    ``on_change(config, keys, checked)`` is called (on the executor thread, between callbacks)
    after an accepted change, with the new :class:`GripperConfig`, the dotted keys that changed
    and what ``check`` returned.
    """

    def __init__(self, node: Node, writable: tuple[str, ...], read_only: tuple[str, ...] = (),
                 on_change: Callable[[GripperConfig, list[str], object], None] | None = None,
                 check: Callable[[GripperConfig], object] | None = None):
        strict_parameters(node)
        path = node.declare_parameter('config_file', '', ParameterDescriptor(
            description='YAML file of every default, read once at start-up',
            read_only=True)).value
        base = load_config(path or None)
        self.source = base.source
        self.writable = tuple(writable)
        self.data = copy.deepcopy(base.data)
        self.keys: set[str] = set()
        self._on_change = on_change
        self._check = check
        for entry in (*writable, *read_only):
            section, _, leaf = entry.partition('.')
            if section not in self.data or (leaf and leaf not in self.data[section]):
                continue
            values = {entry: self.data[section][leaf]} if leaf else \
                flatten(self.data[section], section + '.')
            for dotted, value in values.items():
                fixed = entry in read_only or dotted in START_UP_ONLY
                declared = node.declare_parameter(dotted, _as_parameter_value(dotted, value),
                                                  config_descriptor(dotted, fixed)).value
                holder, key = dotted_section(self.data, dotted)
                holder[key] = declared
                self.keys.add(dotted)
        self.config = parse_config(self.data, self.source)   # start-up overrides, validated
        self._pending: dict | None = None
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    def _validate(self, parameters) -> SetParametersResult:
        changes = {p.name: p.value for p in parameters if p.name in self.keys}
        if not changes:
            return SetParametersResult(successful=True)
        candidate = copy.deepcopy(self.data)
        for name, value in changes.items():
            section, key = dotted_section(candidate, name)
            section[key] = value
        try:
            config = parse_config(candidate, self.source)
            checked = self._check(config) if self._check is not None else None
        except ValueError as exc:            # ConfigError too
            return SetParametersResult(successful=False, reason=one_line(exc))
        self._pending = (candidate, config, sorted(changes), checked)
        return SetParametersResult(successful=True)

    def _apply(self, parameters) -> None:
        pending, self._pending = self._pending, None
        if pending is None:
            return
        self.data, self.config, keys, checked = pending
        if self._on_change is not None:
            self._on_change(self.config, keys, checked)


def follow(node: Node, kinds: dict[str, type]) -> None:
    """Keep ``node.NAME`` at each named parameter's accepted value, as ``kinds[NAME](value)``.

    For a node's own parameters that take effect from the next check or message; their
    descriptors refuse bad values.
    """
    def apply(parameters) -> None:
        for p in parameters:
            if p.name in kinds:
                setattr(node, p.name, kinds[p.name](p.value))
    node.add_post_set_parameters_callback(apply)


def declare_config(node: Node) -> GripperConfig:
    """Declare ``config_file`` (empty = the installed config/gripper.yaml) and load it.

    A bad file raises ConfigError naming the key; the node does not start. A whole number is
    taken for every double parameter of the node (:func:`strict_parameters`).
    """
    strict_parameters(node)
    path = node.declare_parameter('config_file', '', ParameterDescriptor(
        description='YAML file, read once at start-up', read_only=True)).value
    return load_config(path or None)


def declare_prefix(node: Node) -> str:
    """Declare ``prefix`` (read-only) and return it: what goes before the joint's and links' names.

    The xacro's ``prefix``: the ros2_control joint is ``prefix`` + finger_joint, and the
    simulator's joint_states and joint_commands must carry that name for JointStateTopicSystem
    to find it. By default it comes from the node's namespace (:func:`wire.namespace_prefix`), so
    grippers side by side share no name; a value given (``''`` too) wins.
    """
    default = namespace_prefix(node.get_namespace())
    prefix = node.declare_parameter('prefix', default, ParameterDescriptor(
        description=f'put before {FINGER_JOINT} in joint_states and joint_commands and before '
                    "every name of the URDF (the xacro's prefix); default: from the namespace, "
                    f'{default!r} here', read_only=True)).value
    if not set(prefix) <= NAME_CHARACTERS:
        raise StartupError(f'parameter "prefix" may hold only ASCII letters, digits and _, '
                           f'got {prefix!r}')
    return prefix
