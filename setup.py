from glob import glob

from setuptools import find_packages, setup

package_name = 'gripper_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=[package_name, package_name + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + package_name + '/launch', sorted(glob('launch/*.launch.py'))),
        ('share/' + package_name + '/urdf', sorted(glob('urdf/*.urdf') + glob('urdf/*.xacro'))),
        ('share/' + package_name + '/viewers', sorted(glob('viewers/*.json') +
                                                      glob('viewers/*.rviz'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='gripper_ros maintainers',
    maintainer_email='maintainer@example.com',
    description='Simulated electric parallel gripper: MPC-PD position and PI force control, '
                'rclpy nodes, demo and rosbag2 (MCAP) tools.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'plant_simulator = gripper_ros.nodes.plant_simulator_node:main',
            'position_controller = gripper_ros.nodes.position_controller_node:main',
            'force_controller = gripper_ros.nodes.force_controller_node:main',
            'supervisor = gripper_ros.nodes.supervisor_node:main',
            'grasp_demo = gripper_ros.apps.grasp_demo:main',
            'grasp_client = gripper_ros.apps.grasp_client:main',
            'grasp_action_server = gripper_ros.nodes.grasp_action_node:main',
            'move_action_server = gripper_ros.nodes.move_action_node:main',
            'trajectory_action_server = gripper_ros.nodes.trajectory_action_node:main',
            'excitation_server = gripper_ros.nodes.excitation_node:main',
            'description_publisher = gripper_ros.nodes.description_node:main',
            'gripper_graph = gripper_ros.nodes.graph_process:main',
            'gripper_urdf = gripper_ros.apps.gripper_urdf:main',
            'paper_tables = gripper_ros.apps.paper_tables:main',
            'position_limit = gripper_ros.apps.position_limit:main',
            'bag_info = gripper_ros.bags.info:main',
            'bag_replay = gripper_ros.bags.replay:main',
            'bag_analyze = gripper_ros.bags.analyze:main',
            'bag_identify = gripper_ros.bags.identify:main',
            'excite = gripper_ros.apps.excite:main',
            'bench_graph = gripper_ros.bench.graph:main',
            'contact_sweep = gripper_ros.apps.contact_sweep:main',
            'bench_soak = gripper_ros.bench.soak:main',
            'bench_controllers = gripper_ros.bench.controllers:main',
            'lift_table = gripper_ros.apps.lift_table:main',
            'grip_study = gripper_ros.apps.grip_study:main',
            'bench_realtime = gripper_ros.bench.realtime:main',
            'bench_headless = gripper_ros.bench.headless:main',
            'bench_launch_stop = gripper_ros.bench.launch_stop:main',
            'bench_trees = gripper_ros.bench.trees:main',
            'tune = gripper_ros.apps.tune:main',
        ],
    },
)
