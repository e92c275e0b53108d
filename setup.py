"""Build script of the grazing_control ament_python package.

Works both for ``colcon build`` (which runs setuptools with the ``[develop]`` and
``[install]`` script directories of setup.cfg, so ``ros2 run grazing_control <exe>``
finds the executables in ``lib/grazing_control``) and for ``pip install -e .`` in a
plain virtual environment (PEP 660: console scripts go to the environment's ``bin``).
"""
from glob import glob

from setuptools import find_packages, setup

package_name = 'grazing_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=[package_name, package_name + '.*', 'sim_node', 'sim_node.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', sorted(glob('launch/*.py'))),
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml') + glob('config/*.json'))),
        ('share/' + package_name + '/config/models', sorted(glob('config/models/*.yaml'))),
        ('share/' + package_name + '/config/rigs', sorted(glob('config/rigs/*.yaml'))),
        ('share/' + package_name + '/drivers', sorted(glob('drivers/*.py'))),
    ],
    package_data={package_name + '.ros': ['fastdds_profile.xml']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='grazing_control maintainers',
    maintainer_email='maintainers@users.noreply.h-seed-07fe806f.example',
    description='Grazing-bifurcation control of an impact oscillator, with ROS 2 nodes.',
    license='Apache-2.0',
    python_requires='>=3.10',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'grazing = grazing_control.cli.console:main',
            'sim_node = grazing_control.ros.entry:sim_node',
            'controller_node = grazing_control.ros.entry:controller_node',
            'recorder_node = grazing_control.ros.entry:recorder_node',
            'live_node = grazing_control.ros.entry:live_node',
            'effort_bridge = grazing_control.ros.entry:effort_bridge',
            'rig_mock = grazing_control.ros.entry:rig_mock',
        ],
    },
)
