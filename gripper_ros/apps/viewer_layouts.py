"""viewer_layouts: the Foxglove layout and the RViz config of one gripper, live or from a bag.

    python -m gripper_ros.apps.viewer_layouts                        # print both file names
    python -m gripper_ros.apps.viewer_layouts --namespace left --output viewers_left

The shipped ``viewers/gripper.foxglove.json`` and ``viewers/gripper.rviz`` (installed to
``share/gripper_ros/viewers``) are this program's output for the default namespace; a test holds
them to it. The Foxglove layout (built with ``foxglove.layouts``, Foxglove's own layout model): a
3D panel with the URDF from ``robot_description``, the fingers' TF and the object's marker; plots
of the finger's position against the position setpoint, of the measured force against the force
setpoint, and of the motor voltage; the supervisor's status. Every topic either names is one the
live view serves and a bag records. The RViz config: RobotModel from ``robot_description``, TF
and the object's Marker, in the base frame.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys

from gripper_ros.wire import (DEFAULT_NAMESPACE, FRAME_BASE, namespace_prefix, qualified,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_OBJECT_MARKER, TOPIC_ROBOT_DESCRIPTION, TOPIC_STATUS)

FOXGLOVE_LAYOUT = 'gripper.foxglove.json'
RVIZ_CONFIG = 'gripper.rviz'
PLOT_WINDOW_S = 10.0
"""Seconds of each plot's sliding window (live: the latest ten seconds)."""


def foxglove_layout(namespace: str = DEFAULT_NAMESPACE, prefix: str | None = None) -> str:
    """Return the Foxglove layout (JSON text) of the gripper in ``namespace``."""
    import foxglove.layouts as fl
    prefix = namespace_prefix(namespace) if prefix is None else prefix

    def topic(name: str) -> str:
        return qualified(namespace, name)

    def plot(title: str, unit: str, *series: tuple[str, str, str]) -> fl.PlotPanel:
        return fl.PlotPanel(title=title, config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=value, label=label, color=color,
                                 timestamp_method='receiveTime')
                   for value, label, color in series],
            y_axis_label=unit, show_legend=True, legend_display='top',
            x_axis_val='timestamp', following_view_width=PLOT_WINDOW_S, is_synced=True))

    status = topic(TOPIC_STATUS)
    scene = fl.ThreeDeePanel(title='gripper', config=fl.ThreeDeeConfig(
        follow_tf=prefix + FRAME_BASE, follow_mode='follow-pose',
        camera_state=fl.ThreeDeeCameraState(distance=0.45, phi=60.0, theta_offset=35.0,
                                            perspective=True, target_offset=(0.0, 0.0, 0.06)),
        topics={topic(TOPIC_ROBOT_DESCRIPTION): fl.BaseRendererUrdfTopicSettings(visible=True),
                topic(TOPIC_OBJECT_MARKER): fl.BaseRendererRosMarkerTopicSettings(
                    visible=True)}))
    plots = fl.SplitContainer(direction='column', items=[
        fl.SplitItem(content=plot(
            'position', 'm',
            (f'{topic(TOPIC_JOINT_STATES)}.position[0]', 'finger position', '#4e98e2'),
            (f'{status}.position_setpoint_m', 'position setpoint', '#f5774d'))),
        fl.SplitItem(content=plot(
            'force', 'N',
            (f'{topic(TOPIC_FORCE_SENSOR)}.force_n', 'measured force', '#4e98e2'),
            (f'{status}.force_setpoint_n', 'force setpoint', '#f5774d'))),
        fl.SplitItem(content=plot(
            'motor voltage', 'V',
            (f'{topic(TOPIC_MOTOR_COMMAND)}.voltage_v', 'motor voltage', '#f7df71'))),
    ])
    left = fl.SplitContainer(direction='column', items=[
        fl.SplitItem(proportion=2, content=scene),
        fl.SplitItem(proportion=1, content=fl.RawMessagesPanel(
            title='status', config=fl.RawMessagesConfig(topic_path=status)))])
    layout = fl.Layout(content=fl.SplitContainer(direction='row', items=[
        fl.SplitItem(proportion=1, content=left), fl.SplitItem(proportion=1, content=plots)]))
    return json.dumps(json.loads(layout.to_json()), indent=1) + '\n'


def rviz_config(namespace: str = DEFAULT_NAMESPACE, prefix: str | None = None) -> str:
    """Return the RViz 2 config (YAML text) of the gripper in ``namespace``."""
    import yaml
    prefix = namespace_prefix(namespace) if prefix is None else prefix

    def subscription(name: str, latched: bool) -> dict:
        """Return what RViz subscribes with: the publisher's reliability and durability."""
        return {'Value': qualified(namespace, name), 'Depth': 1 if latched else 5,
                'History Policy': 'Keep Last', 'Reliability Policy': 'Reliable',
                'Durability Policy': 'Transient Local' if latched else 'Volatile'}

    config = {
        'Panels': [{'Class': 'rviz_common/Displays', 'Name': 'Displays'}],
        'Visualization Manager': {
            'Class': '',
            'Displays': [
                {'Class': 'rviz_default_plugins/Grid', 'Name': 'Grid', 'Enabled': True,
                 'Cell Size': 0.05, 'Plane Cell Count': 10,
                 'Reference Frame': '<Fixed Frame>', 'Value': True},
                {'Class': 'rviz_default_plugins/RobotModel', 'Name': 'RobotModel',
                 'Enabled': True, 'Description Source': 'Topic',
                 'Description Topic': subscription(TOPIC_ROBOT_DESCRIPTION, True),
                 'TF Prefix': '', 'Visual Enabled': True, 'Collision Enabled': False,
                 'Alpha': 1.0, 'Value': True},
                {'Class': 'rviz_default_plugins/TF', 'Name': 'TF', 'Enabled': True,
                 'Show Names': True, 'Show Axes': True, 'Show Arrows': False,
                 'Marker Scale': 0.2, 'Value': True},
                {'Class': 'rviz_default_plugins/Marker', 'Name': 'object', 'Enabled': True,
                 'Topic': subscription(TOPIC_OBJECT_MARKER, False), 'Value': True},
            ],
            'Enabled': True,
            'Global Options': {'Fixed Frame': prefix + FRAME_BASE,
                               'Background Color': '48; 48; 48', 'Frame Rate': 30},
            'Name': 'root',
            'Tools': [{'Class': 'rviz_default_plugins/Interact', 'Hide Inactive Objects': True},
                      {'Class': 'rviz_default_plugins/MoveCamera'}],
            'Value': True,
            'Views': {'Current': {'Class': 'rviz_default_plugins/Orbit', 'Name': 'Current View',
                                  'Distance': 0.45, 'Pitch': 0.5, 'Yaw': 0.8,
                                  'Focal Point': {'X': 0.0, 'Y': 0.0, 'Z': 0.06},
                                  'Target Frame': '<Fixed Frame>',
                                  'Value': 'Orbit (rviz_default_plugins)'},
                      'Saved': None},
        },
        'Window Geometry': {'Height': 800, 'Width': 1200},
    }
    return yaml.safe_dump(config, sort_keys=False)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='viewer_layouts', description=__doc__.splitlines()[0])
    parser.add_argument('--namespace', default=DEFAULT_NAMESPACE,
                        help="the gripper's namespace (default %(default)s)")
    parser.add_argument('--prefix', default=None,
                        help="its frames' prefix (default: from the namespace)")
    parser.add_argument('--output', default='.', help='folder to write both files to')
    args = parser.parse_args(argv)
    from gripper_ros.wire import check_namespace
    try:
        namespace = check_namespace(args.namespace)
    except ValueError as exc:
        print(f'viewer_layouts: {exc}', file=sys.stderr)
        return 2
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in ((FOXGLOVE_LAYOUT, foxglove_layout(namespace, args.prefix)),
                       (RVIZ_CONFIG, rviz_config(namespace, args.prefix))):
        (out / name).write_text(text, encoding='utf-8')
        print(out / name)
    return 0


if __name__ == '__main__':
    sys.exit(main())
