"""Screw-theory stiffness of tensegrity joints (pure numpy/scipy core; no rclpy import here).

The colcon build installs this package together with the service interfaces generated from
``srv/`` (``tensegrity_stiffness.srv``, the ROS types ``tensegrity_stiffness/srv/<Name>``), in one
folder. ``extend_path`` lets a source checkout that comes first on ``sys.path`` (``python -m
pytest`` in the repository) still find those generated modules in the installed folder.
"""

from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)

__version__ = '0.1.0'
