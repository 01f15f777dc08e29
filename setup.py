from glob import glob

from gripper_ros.executables import EXECUTABLES
from setuptools import Extension, find_packages, setup

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
    zip_safe=False,
    maintainer='gripper_ros maintainers',
    maintainer_email='maintainer@example.com',
    description='Simulated electric parallel gripper: MPC-PD position and PI force control, '
                'rclpy nodes, demo and rosbag2 (MCAP) tools.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {package_name}.executables:{name}'
                            for name in EXECUTABLES],
    },
    ext_modules=[
        # preloaded into the package's processes (gripper_ros/native); a machine without a C
        # compiler builds the package without it
        Extension(package_name + '.native.cond_wait_fix', ['gripper_ros/native/cond_wait_fix.c'],
                  libraries=['dl'], optional=True),
    ],
)
