"""Screw-theory stiffness of tensegrity joints (pure numpy/scipy core; no rclpy import here)."""

__version__ = '0.1.0'
