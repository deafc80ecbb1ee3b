"""``pip install .``: the library and the command line alone (no ROS needed).

colcon builds the ROS package from CMakeLists.txt (interfaces, compiled kernel, nodes, launch
files); this file is not used there. A pip install has the numpy path of the library (the compiled
kernel is built by colcon), the ``tensegrity-stiffness`` command (``bag`` included) and the
packaged configs under ``<prefix>/share/tensegrity_stiffness/config`` (the worked examples of
docs/your_joint.md under ``config/examples``).
"""

from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'tensegrity_stiffness'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    # the library's subpackages; the ROS layer (tensegrity_stiffness.ros) is colcon's
    packages=find_packages(include=[PACKAGE_NAME, PACKAGE_NAME + '.*'],
                           exclude=[PACKAGE_NAME + '.ros', PACKAGE_NAME + '.ros.*']),
    data_files=[('share/' + PACKAGE_NAME + '/config', glob('config/*.yaml')),
                ('share/' + PACKAGE_NAME + '/config/examples', glob('config/examples/*.yaml')),
                ('share/' + PACKAGE_NAME + '/msg', glob('msg/*.msg'))],
    python_requires='>=3.10',
    install_requires=['numpy', 'scipy', 'PyYAML', 'rosbags', 'tqdm', 'threadpoolctl'],
    extras_require={'plots': ['matplotlib', 'pillow'], 'simulation': ['mujoco']},
    zip_safe=False,
    maintainer='tensegrity_stiffness maintainers',
    maintainer_email='maintainers@tensegrity-stiffness.invalid',
    description='Screw-theory stiffness of tensegrity joints for ROS 2 control stacks.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'tensegrity-stiffness = tensegrity_stiffness.cli:main',
        ],
    },
)
