"""Recordings: rosbag2 reading and writing through ``rosbags`` (pure Python, no ROS): the bag
command that replays a recording through the nodes' code (:mod:`.bag`) and the calibration
recordings (:mod:`.calibration_recording`).

May import: :mod:`tensegrity_stiffness.nodes` and everything below it; no rclpy.
"""
