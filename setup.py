"""ament_python setup for tensegrity_stiffness."""

from glob import glob

from setuptools import setup

PACKAGE_NAME = 'tensegrity_stiffness'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=[PACKAGE_NAME, PACKAGE_NAME + '.ros', 'msg_tools'],
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        ('share/' + PACKAGE_NAME + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE_NAME + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'PyYAML', 'rosbags'],
    extras_require={'plots': ['matplotlib']},
    zip_safe=True,
    maintainer='tensegrity_stiffness maintainers',
    maintainer_email='maintainers@tensegrity-stiffness.invalid',
    description='Screw-theory stiffness of tensegrity joints for ROS 2 control stacks.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'stiffness_node = tensegrity_stiffness.ros.stiffness_node:main',
            'spine_node = tensegrity_stiffness.ros.spine_node:main',
            'sim_node = tensegrity_stiffness.ros.sim_node:main',
            'twin_demo = tensegrity_stiffness.ros.twin_demo:main',
            'estimator_node = tensegrity_stiffness.ros.estimator_node:main',
            'spine_estimator_node = tensegrity_stiffness.ros.spine_estimator_node:main',
            'tensegrity-stiffness = tensegrity_stiffness.cli:main',
        ],
    },
)
